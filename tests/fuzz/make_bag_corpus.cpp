// Writes the seeds of the bag reader's fuzz target (tests/fuzz/readers/bag/) with the ROS
// bag library: a few small PointCloud2 bags, one for each chunk compression the format has
// (none, bz2, lz4), one organised with no-return pixels, and one of two chunks. Small on
// purpose: libFuzzer mutates them thousands of times a second.
//
//   make_bag_corpus DIR
#include <cstdio>
#include <string>

#include "bag_fixtures.hpp"

namespace {

/// `width` points of the driver layout (x y z intensity ring t), stamped `sec`.
sensor_msgs::PointCloud2 small_cloud(std::uint32_t width, std::uint32_t sec) {
  return bagfix::make_cloud(1, width,
                            {{"x", bagfix::F32, 4}, {"y", bagfix::F32, 4}, {"z", bagfix::F32, 4},
                             {"intensity", bagfix::F32, 4}, {"ring", bagfix::U16, 2}, {"t", bagfix::U32, 4}},
                            bagfix::driver_value, sec, 0);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s DIR\n", argv[0]);
    return 1;
  }
  const std::string dir = argv[1];
  const std::vector<sensor_msgs::PointCloud2> two{small_cloud(6, 1700000000), small_cloud(5, 1700000001)};
  bagfix::write(dir + "/cloud_none.bag", "/points", two, true, rosbag::compression::Uncompressed);
  bagfix::write(dir + "/cloud_bz2.bag", "/points", two, true, rosbag::compression::BZ2);
  bagfix::write(dir + "/cloud_lz4.bag", "/points", two, true, rosbag::compression::LZ4);
  // a threshold below one message: every message in a chunk of its own
  bagfix::write(dir + "/two_chunks_lz4.bag", "/points", two, false, rosbag::compression::LZ4, 64);
  bagfix::write(dir + "/organised_none.bag", "/points", {bagfix::organised_cloud()}, false);
  return 0;
}
