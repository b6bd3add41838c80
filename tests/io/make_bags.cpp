// Writes the ROS bags of the command-line tests (tests/cli/bag_tests.cmake) into a folder:
// a drive of driver-like clouds, one bag for each fault of a PointCloud2, and bz2 and LZ4
// bags, whole and with a compressed chunk spoilt.
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "bag_fixtures.hpp"

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s DIR\n", argv[0]);
    return 1;
  }
  const std::string dir = argv[1];
  bagfix::write(dir + "/drive.bag", "/points",
                {bagfix::driver_cloud(1700000000, 100000000), bagfix::driver_cloud(1700000000, 200000000),
                 bagfix::driver_cloud(1700000000, 300000000)});
  bagfix::write(dir + "/organised.bag", "/points", {bagfix::organised_cloud()}, false);
  auto spoilt = [&](const char* name, auto spoil) {
    sensor_msgs::PointCloud2 m = bagfix::driver_cloud();
    spoil(m);
    bagfix::write(dir + "/" + name + ".bag", "/points", {bagfix::driver_cloud(), m});
  };
  spoilt("point_step", [](sensor_msgs::PointCloud2& m) {
    m.point_step -= 2;
    m.row_step = m.point_step * m.width;
    m.data.resize(m.row_step);
  });
  spoilt("row_step", [](sensor_msgs::PointCloud2& m) { m.row_step -= 1; });
  spoilt("bigendian", [](sensor_msgs::PointCloud2& m) { m.is_bigendian = true; });
  spoilt("data_size", [](sensor_msgs::PointCloud2& m) { m.data.push_back(0); });
  spoilt("datatype", [](sensor_msgs::PointCloud2& m) { m.fields[3].datatype = 11; });
  // compressed chunks: whole, declaring one byte more than they hold, and with a byte changed
  for (const auto& [name, type] : {std::pair<std::string, rosbag::CompressionType>{"bz2", rosbag::compression::BZ2},
                                   std::pair<std::string, rosbag::CompressionType>{"lz4", rosbag::compression::LZ4}}) {
    const std::string whole = dir + "/packed_" + name + ".bag";
    bagfix::write(whole, "/points", {bagfix::driver_cloud(), bagfix::driver_cloud(1700000001, 0)}, true, type);
    std::vector<char> bytes;
    if (std::FILE* f = std::fopen(whole.c_str(), "rb")) {
      char buf[4096];
      for (std::size_t n; (n = std::fread(buf, 1, sizeof buf, f)) > 0;) bytes.insert(bytes.end(), buf, buf + n);
      std::fclose(f);
    }
    const bagfix::ChunkAt chunk = bagfix::first_chunk(bytes);
    auto save = [&](const std::string& what, const std::vector<char>& b) {
      std::FILE* f = std::fopen((dir + "/chunk_" + what + "_" + name + ".bag").c_str(), "wb");
      if (f == nullptr || std::fwrite(b.data(), 1, b.size(), f) != b.size()) std::perror(what.c_str());
      if (f != nullptr) std::fclose(f);
    };
    std::vector<char> b = bytes;
    const std::uint32_t more = chunk.declared + 1;
    std::memcpy(b.data() + chunk.size_field, &more, 4);
    save("size", b);
    b = bytes;
    b[chunk.data + chunk.data_len / 2] ^= 0x21;
    save("flip", b);
  }
  return 0;
}
