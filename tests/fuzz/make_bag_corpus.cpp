// Writes the seeds of the bag reader's fuzz target (tests/fuzz/readers/bag/) with the ROS
// bag library: a few small PointCloud2 bags, one for each chunk compression the format has
// (none, bz2, lz4), one organised with no-return pixels, one of two chunks, and Ouster
// packets with their metadata (the first five lidar packets of the ouster seed capture, a
// frame and one packet of the next, and the metadata fuzz_readers.hpp gives that capture),
// and Velodyne packets as velodyne_driver records them (the VLP-16 seed capture's 24
// packets, two turns, in velodyne_msgs/VelodyneScan messages of 6).
// Small on purpose: libFuzzer mutates them hundreds of times a second.
//
//   make_bag_corpus DIR OUSTER_PCAP VELODYNE_PCAP
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "bag_fixtures.hpp"
#include "fuzz_readers.hpp"

/// ouster_ros/PacketMsg (`uint8[] buf`), declared here: no ROS package of it is installed.
namespace seed {
struct PacketMsg {
  std::vector<std::uint8_t> buf;
};
}  // namespace seed

namespace ros::message_traits {
template <>
struct MD5Sum<seed::PacketMsg> {
  static const char* value() { return "4f7b5949e76f86d01e96b0e33ba9b5e3"; }
  static const char* value(const seed::PacketMsg&) { return value(); }
};
template <>
struct DataType<seed::PacketMsg> {
  static const char* value() { return "ouster_ros/PacketMsg"; }
  static const char* value(const seed::PacketMsg&) { return value(); }
};
template <>
struct Definition<seed::PacketMsg> {
  static const char* value() { return "uint8[] buf\n"; }
  static const char* value(const seed::PacketMsg&) { return value(); }
};
}  // namespace ros::message_traits

namespace ros::serialization {
template <>
struct Serializer<seed::PacketMsg> {
  template <typename Stream, typename T>
  inline static void allInOne(Stream& stream, T m) {
    stream.next(m.buf);
  }
  ROS_DECLARE_ALLINONE_SERIALIZER
};
}  // namespace ros::serialization

namespace {

/// The UDP payloads of a capture's first `n` records (Ethernet + IPv4 + UDP: 42 bytes of headers).
std::vector<std::vector<std::uint8_t>> udp_payloads(const std::string& pcap, std::size_t n) {
  std::vector<std::uint8_t> b;
  if (std::FILE* f = std::fopen(pcap.c_str(), "rb")) {
    std::uint8_t buf[4096];
    for (std::size_t k; (k = std::fread(buf, 1, sizeof buf, f)) > 0;) b.insert(b.end(), buf, buf + k);
    std::fclose(f);
  }
  std::vector<std::vector<std::uint8_t>> out;
  for (std::size_t o = 24; o + 16 <= b.size() && out.size() < n;) {
    std::uint32_t incl = 0;
    std::memcpy(&incl, &b[o + 8], 4);
    o += 16;
    if (incl > 42 && o + incl <= b.size()) out.emplace_back(b.begin() + static_cast<std::ptrdiff_t>(o + 42),
                                                            b.begin() + static_cast<std::ptrdiff_t>(o + incl));
    o += incl;
  }
  return out;
}

/// `width` points of the driver layout (x y z intensity ring t), stamped `sec`.
sensor_msgs::PointCloud2 small_cloud(std::uint32_t width, std::uint32_t sec) {
  return bagfix::make_cloud(1, width,
                            {{"x", bagfix::F32, 4}, {"y", bagfix::F32, 4}, {"z", bagfix::F32, 4},
                             {"intensity", bagfix::F32, 4}, {"ring", bagfix::U16, 2}, {"t", bagfix::U32, 4}},
                            bagfix::driver_value, sec, 0);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 4) {
    std::fprintf(stderr, "usage: %s DIR OUSTER_PCAP VELODYNE_PCAP\n", argv[0]);
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
  const auto packets = udp_payloads(argv[2], 5);
  if (packets.size() != 5) {
    std::fprintf(stderr, "%s: not 5 packets\n", argv[2]);
    return 1;
  }
  rosbag::Bag bag;
  bag.open(dir + "/ouster_packets_lz4.bag", rosbag::bagmode::Write);
  bag.setCompression(rosbag::compression::LZ4);
  std_msgs::String meta;
  meta.data = lex3d::fuzz::ouster_metadata();
  bag.write("/os_node/metadata", ros::Time(1700000000, 0), meta);
  for (std::size_t i = 0; i < packets.size(); ++i) {
    seed::PacketMsg m;
    m.buf = packets[i];
    bag.write("/os_node/lidar_packets", ros::Time(1700000000, static_cast<std::uint32_t>(1 + i * 1562500)), m);
  }
  bag.close();
  const auto velodyne = udp_payloads(argv[3], 24);
  if (velodyne.size() != 24) {
    std::fprintf(stderr, "%s: not 24 packets\n", argv[3]);
    return 1;
  }
  rosbag::Bag vbag;
  vbag.open(dir + "/velodyne_packets_lz4.bag", rosbag::bagmode::Write);
  vbag.setCompression(rosbag::compression::LZ4);
  for (std::size_t at = 0; at < velodyne.size(); at += 6) {
    std::vector<bagfix::StampedPacket> part;
    for (std::size_t i = at; i < at + 6; ++i)
      part.push_back({1700000000, static_cast<std::uint32_t>(i * 552960), velodyne[i]});
    vbag.write("/velodyne_packets", ros::Time(part.front().sec, part.front().nsec),
               bagfix::velodyne_scan(static_cast<std::uint32_t>(at / 6), part));
  }
  vbag.close();
  return 0;
}
