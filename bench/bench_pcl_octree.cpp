// PCL's octree point cloud compression (pcl::io::OctreePointCloudCompression<PointXYZ>)
// as a baseline codec for bench/rd.sh, in two steps so that each has its own process
// (and peak memory):
//   lex3d_bench_pcl_octree encode INPUT STREAM (--profile NAME | --resolution R)
//   lex3d_bench_pcl_octree decode STREAM OUTPUT
// encode reads INPUT with lex3d::io::read_cloud (x y z only) and writes PCL's compressed
// stream to STREAM. --profile is one of PCL's predefined profiles without colour
// (LOW_RES_ONLINE, MED_RES_ONLINE, HIGH_RES_ONLINE, LOW_RES_OFFLINE, MED_RES_OFFLINE,
// HIGH_RES_OFFLINE; "_COMPRESSION_WITHOUT_COLOR" may be appended); --resolution R (metres)
// is MANUAL_CONFIGURATION with point resolution = octree resolution = R, no voxel-grid
// down-sampling (every point is coded), no colour. decode reads STREAM and writes the
// decoded cloud (format from OUTPUT's extension, e.g. .ply). Each prints one JSON line:
// encode {"points", "bytes", "encode_ms"}, decode {"points", "decode_ms"}; the times
// cover PCL's encodePointCloud / decodePointCloud only (no file I/O).
// Exit codes: 0 ok, 1 usage, 2 bad data, 3 I/O.

#include <cstdio>
#include <cstdlib>
#include <exception>
#include <fstream>
#include <iterator>
#include <sstream>
#include <string>
#include <utility>

#include <pcl/compression/octree_pointcloud_compression.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include "lex3d/core/timer.hpp"
#include "bench_driver.hpp"
#include "lex3d/io/io.hpp"

using namespace lex3d;

namespace {

constexpr char kTool[] = "lex3d_bench_pcl_octree";

using Compression = pcl::io::OctreePointCloudCompression<pcl::PointXYZ>;

int usage() {
  std::fprintf(stderr,
               "usage: lex3d_bench_pcl_octree encode INPUT STREAM (--profile NAME | --resolution R)\n"
               "       lex3d_bench_pcl_octree decode STREAM OUTPUT\n");
  return 1;
}

bool parse_profile(std::string name, pcl::io::compression_Profiles_e& out) {
  const std::string suffix = "_COMPRESSION_WITHOUT_COLOR";
  if (name.size() > suffix.size() && name.compare(name.size() - suffix.size(), suffix.size(), suffix) == 0) {
    name.resize(name.size() - suffix.size());
  }
  if (name == "LOW_RES_ONLINE") out = pcl::io::LOW_RES_ONLINE_COMPRESSION_WITHOUT_COLOR;
  else if (name == "MED_RES_ONLINE") out = pcl::io::MED_RES_ONLINE_COMPRESSION_WITHOUT_COLOR;
  else if (name == "HIGH_RES_ONLINE") out = pcl::io::HIGH_RES_ONLINE_COMPRESSION_WITHOUT_COLOR;
  else if (name == "LOW_RES_OFFLINE") out = pcl::io::LOW_RES_OFFLINE_COMPRESSION_WITHOUT_COLOR;
  else if (name == "MED_RES_OFFLINE") out = pcl::io::MED_RES_OFFLINE_COMPRESSION_WITHOUT_COLOR;
  else if (name == "HIGH_RES_OFFLINE") out = pcl::io::HIGH_RES_OFFLINE_COMPRESSION_WITHOUT_COLOR;
  else return false;
  return true;
}

int encode(const std::string& input, const std::string& stream_path, const std::string& profile_name,
           double resolution) {
  int rc = 0;
  const auto input_cloud = bench::read_input(kTool, input, rc);
  if (!input_cloud) return rc;
  const Cloud& cloud = *input_cloud;
  pcl::PointCloud<pcl::PointXYZ>::Ptr pcl_cloud(new pcl::PointCloud<pcl::PointXYZ>);
  pcl_cloud->reserve(cloud.size());
  for (const auto& p : cloud.points) pcl_cloud->push_back(pcl::PointXYZ(p.x(), p.y(), p.z()));

  pcl::io::compression_Profiles_e profile = pcl::io::MANUAL_CONFIGURATION;
  if (!profile_name.empty() && !parse_profile(profile_name, profile)) return usage();
  // Manual: point resolution = octree resolution, no down-sampling, i-frame only, no colour.
  Compression encoder(profile, false, resolution, resolution, false, 1, false, 8);

  std::stringstream out;
  const Stopwatch sw;
  encoder.encodePointCloud(pcl_cloud, out);
  const double ms = sw.elapsed_ms();
  const std::string bytes = out.str();
  if (const int w = bench::write_stream(kTool, stream_path, bytes); w != 0) return w;
  std::printf("{\"points\": %zu, \"bytes\": %zu, \"encode_ms\": %.3f}\n", cloud.size(), bytes.size(), ms);
  return 0;
}

int decode(const std::string& stream_path, const std::string& output) {
  std::ifstream file(stream_path, std::ios::binary);
  if (!file) {
    std::fprintf(stderr, "lex3d_bench_pcl_octree: %s: cannot open\n", stream_path.c_str());
    return 3;
  }
  std::stringstream in;
  in << file.rdbuf();
  Compression decoder(pcl::io::MANUAL_CONFIGURATION, false);
  pcl::PointCloud<pcl::PointXYZ>::Ptr pcl_cloud(new pcl::PointCloud<pcl::PointXYZ>);
  const Stopwatch sw;
  decoder.decodePointCloud(in, pcl_cloud);
  const double ms = sw.elapsed_ms();
  Cloud cloud;
  cloud.points.reserve(pcl_cloud->size());
  for (const auto& p : *pcl_cloud) cloud.points.emplace_back(p.x, p.y, p.z);
  return bench::write_decoded(kTool, output, cloud, ms);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 4) return usage();
  const std::string mode = argv[1];
  std::string profile;
  double resolution = 0.0;
  for (int i = 4; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--profile" && i + 1 < argc) {
      profile = argv[++i];
    } else if (arg == "--resolution" && i + 1 < argc) {
      char* end = nullptr;
      resolution = std::strtod(argv[++i], &end);
      if (*end != '\0' || !(resolution > 0.0)) return usage();
    } else {
      return usage();
    }
  }
  try {
    if (mode == "encode") {
      if (profile.empty() == (resolution == 0.0)) return usage();
      return encode(argv[2], argv[3], profile, resolution > 0.0 ? resolution : 0.01);
    }
    if (mode == "decode") {
      if (argc != 4) return usage();
      return decode(argv[2], argv[3]);
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "lex3d_bench_pcl_octree: %s\n", e.what());
    return 2;
  }
  return usage();
}
