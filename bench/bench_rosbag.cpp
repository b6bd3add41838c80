// ROS bag read and write speed: one point cloud written K times as PointCloud2 messages
// (io::write_bag), then the bag read back (io::read_bag) and the same cloud read from a
// binary PCD (io::read_cloud) for comparison; the median of R runs of each.
//   lex3d_bench_rosbag CLOUD WORKDIR [--messages K] [--runs R]
// Prints one JSON line: {"points_per_message", "messages", "bag_bytes", "write_ms",
// "read_ms", "read_points_per_s", "read_mb_per_s", "pcd_read_points_per_s"}.
// Exit codes: 0 ok, 1 usage, 2 bad data, 3 I/O.

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "lex3d/core/timer.hpp"
#include "lex3d/io/io.hpp"
#include "lex3d/io/rosbag.hpp"

using namespace lex3d;

namespace {

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

int fail(const Status& s) {
  std::fprintf(stderr, "lex3d_bench_rosbag: %s\n", s.to_string().c_str());
  return exit_code_for(s.code());
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: lex3d_bench_rosbag CLOUD WORKDIR [--messages K] [--runs R]\n");
    return 1;
  }
  const std::string input = argv[1], dir = argv[2];
  int messages = 20, runs = 5;
  for (int i = 3; i + 1 < argc; i += 2) {
    const std::string a = argv[i];
    if (a == "--messages") messages = std::atoi(argv[i + 1]);
    else if (a == "--runs") runs = std::atoi(argv[i + 1]);
    else {
      std::fprintf(stderr, "lex3d_bench_rosbag: unknown option %s\n", a.c_str());
      return 1;
    }
  }
  if (messages < 1 || runs < 1) {
    std::fprintf(stderr, "lex3d_bench_rosbag: --messages and --runs must be positive\n");
    return 1;
  }
  auto in = io::read_cloud(input);
  if (!in.ok()) return fail(in.status());
  const Cloud& cloud = in.value().cloud;
  std::vector<io::BagScan> scans(static_cast<std::size_t>(messages));
  for (int k = 0; k < messages; ++k) {
    scans[static_cast<std::size_t>(k)].cloud = cloud;
    scans[static_cast<std::size_t>(k)].stamp_sec = 1700000000U + static_cast<std::uint32_t>(k);
  }
  const std::string bag = dir + "/bench_rosbag.bag", pcd = dir + "/bench_rosbag.pcd";
  std::vector<double> write_ms, read_ms, pcd_ms;
  std::size_t points = 0;
  for (int r = 0; r < runs; ++r) {
    Stopwatch w;
    Status s = io::write_bag(bag, scans);
    if (!s.ok()) return fail(s);
    write_ms.push_back(w.elapsed_ms());
    Stopwatch rd;
    auto b = io::read_bag(bag, "/points");
    if (!b.ok()) return fail(b.status());
    read_ms.push_back(rd.elapsed_ms());
    points = 0;
    for (const auto& m : b.value().scans) points += m.cloud.size();
  }
  Status s = io::write_cloud(pcd, cloud);
  if (!s.ok()) return fail(s);
  for (int r = 0; r < runs; ++r) {
    Stopwatch rd;
    auto c = io::read_cloud(pcd);
    if (!c.ok()) return fail(c.status());
    pcd_ms.push_back(rd.elapsed_ms());
  }
  auto bytes = io::read_file(bag);
  const double bag_bytes = bytes.ok() ? static_cast<double>(bytes.value().size()) : 0.0;
  const double rm = median(read_ms);
  std::printf("{\"points_per_message\":%zu,\"messages\":%d,\"bag_bytes\":%.0f,\"write_ms\":%.1f,\"read_ms\":%.1f,"
              "\"read_points_per_s\":%.3g,\"read_mb_per_s\":%.1f,\"pcd_read_points_per_s\":%.3g}\n",
              cloud.size(), messages, bag_bytes, median(write_ms), rm, static_cast<double>(points) / (rm / 1000.0),
              bag_bytes / 1e6 / (rm / 1000.0), static_cast<double>(cloud.size()) / (median(pcd_ms) / 1000.0));
  return 0;
}
