#pragma once
// Shared by the input-reader libFuzzer targets (fuzz_reader.cpp, one executable a format)
// and their replay driver (reader_replay.cpp): feed one input to one reader through the
// public entry point a user's file goes through (io::read_cloud, io::read_sensor_log,
// io::read_pose_list) and abort when a documented property fails. A crash, a hang or a
// sanitizer report is caught by the tools themselves.
//
// Properties (io.hpp, sensor_log.hpp, DESIGN.md "errors"):
// - a failure is kBadData (content) or kOutOfMemory (an allocation the input asked for),
//   a one-line message that names the file;
// - a success is a consistent cloud: finite points, every per-point attribute empty or one
//   a point, an organised shape that holds the points, finite beam tables;
// - a cloud that was read writes as PCD and reads back with the same points.
//
// The bytes go through a file (one per process, in $TMPDIR), as a user's would: the
// readers map their input, and the raw-log reader takes a path for libpcap.

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <string_view>
#include <vector>

#include "lex3d/io/io.hpp"
#include "lex3d/io/rosbag.hpp"
#include "lex3d/io/sensor_log.hpp"
#include "lex3d/codec/cloud_bytes.hpp"

namespace lex3d::fuzz {

/// The inputs one reader target takes.
enum class Reader { kPcd, kPly, kKitti, kBinXyz, kXyz, kUos, kLas, kPcap, kOuster, kHdl64, kPoses, kBag, kCloudBytes };

struct ReaderKind {
  Reader reader;
  const char* name;       ///< target suffix and corpus folder (tests/fuzz/readers/<name>)
  const char* extension;  ///< the input file's name ends with it
};

inline constexpr ReaderKind kReaderKinds[] = {
    {Reader::kPcd, "pcd", ".pcd"},       {Reader::kPly, "ply", ".ply"},       {Reader::kKitti, "kitti", ".bin"},
    {Reader::kBinXyz, "binxyz", ".bin"}, {Reader::kXyz, "xyz", ".xyz"},       {Reader::kUos, "uos", ".3d"},
    {Reader::kLas, "las", ".las"},       {Reader::kPcap, "pcap", ".pcap"},    {Reader::kOuster, "ouster", ".pcap"},
    {Reader::kHdl64, "hdl64", ".pcap"},   {Reader::kPoses, "poses", ".txt"},    {Reader::kBag, "bag", ".bag"},
    {Reader::kCloudBytes, "cloudbytes", ".l3dc"},  // a pickled lex3d.Scan's cloud (codec/cloud_bytes.hpp)
};

inline const ReaderKind* find_reader(std::string_view name) {
  for (const auto& k : kReaderKinds)
    if (name == k.name) return &k;
  return nullptr;
}

[[noreturn]] inline void reader_fail(const char* what, const std::string& detail) {
  std::fprintf(stderr, "fuzz property violated: %s: %s\n", what, detail.c_str());
  std::abort();
}

inline void remove_scratch();

/// A private directory for this process's input files (one small file each, overwritten for
/// every input; removed at a normal exit, kept after an abort: the last input is there).
/// Never destroyed, so that the exit handler can still use it.
inline const std::string& scratch_dir() {
  static const std::string* dir = [] {
    const char* t = std::getenv("TMPDIR");
    std::string templ = std::string(t && *t ? t : "/tmp") + "/lex3d_fuzz_XXXXXX";
    std::vector<char> buf(templ.begin(), templ.end());
    buf.push_back('\0');
    if (mkdtemp(buf.data()) == nullptr) reader_fail("cannot create a scratch directory", templ);
    auto* d = new std::string(buf.data());
    std::atexit(remove_scratch);
    return d;
  }();
  return *dir;
}

inline void remove_scratch() {
  const std::string& d = scratch_dir();
  for (const char* f : {"/input.pcd", "/input.ply", "/input.bin", "/input.xyz", "/input.3d", "/input.las",
                        "/input.pcap", "/input.json", "/input.yaml", "/input.txt", "/input.bag", "/keep.bag", "/back.pcd"})
    std::remove((d + f).c_str());
  std::remove(d.c_str());
}

inline void write_whole(const std::string& path, const std::uint8_t* data, std::size_t size) {
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (f == nullptr) reader_fail("cannot write the scratch file", path);
  if (size > 0 && std::fwrite(data, 1, size, f) != size) reader_fail("short write", path);
  std::fclose(f);
}

/// The Ouster metadata JSON given with every `ouster` input: a 16-beam LEGACY sensor whose
/// azimuth window is 64 of its 1024 columns, so that a complete frame is 4 packets (as
/// tests/fuzz/make_reader_corpus.py builds them).
inline const char* ouster_metadata() {
  return R"({"lidar_mode": "1024x10", "prod_line": "OS-1-16", "prod_sn": "992029000001", "build_rev": "v2.1.1",
 "beam_altitude_angles": [15.4, 13.3, 11.2, 9.1, 7.0, 4.9, 2.8, 0.7, -1.4, -3.5, -5.6, -7.7, -9.8, -11.9, -14.0, -16.1],
 "beam_azimuth_angles": [3.1, 1.0, -1.0, -3.1, 3.1, 1.0, -1.0, -3.1, 3.1, 1.0, -1.0, -3.1, 3.1, 1.0, -1.0, -3.1],
 "lidar_origin_to_beam_origin_mm": 15.806,
 "lidar_to_sensor_transform": [-1, 0, 0, 0, 0, -1, 0, 0, 0, 0, 1, 36.18, 0, 0, 0, 1],
 "data_format": {"pixels_per_column": 16, "columns_per_packet": 16, "columns_per_frame": 1024,
   "pixel_shift_by_row": [12, 8, 4, 0, 12, 8, 4, 0, 12, 8, 4, 0, 12, 8, 4, 0],
   "column_window": [0, 63], "udp_profile_lidar": "LEGACY", "udp_profile_imu": "LEGACY"}})";
}

/// The calibration given with every `hdl64` input (the ROS driver's YAML): 64 lasers from
/// -24.8° to +2°, rotation corrections within ±8°, distance corrections near 1.3 m, beam
/// origins 15-22 cm up their normals and 2.6 cm aside, two-point corrections on the even
/// lasers (as tests/fuzz/make_reader_corpus.py builds the captures for).
inline std::string hdl64_calibration() {
  std::string y = "distance_resolution: 0.002\nlasers:\n";
  char buf[512];
  for (int l = 0; l < 64; ++l) {
    const int k = l < 32 ? l : l - 32;
    const double vert = (l < 32 ? 2.0 - 0.34 * (k * 7 % 32) : -8.8 - 0.5 * (k * 5 % 32)) * 3.14159265358979 / 180;
    const double rot = 8.0 * std::sin(1.7 * l + 0.3) * 3.14159265358979 / 180, dist = 1.2 + 0.005 * (l * 13 % 40);
    std::snprintf(buf, sizeof buf,
                  "- {laser_id: %d, rot_correction: %.12g, vert_correction: %.12g, dist_correction: %.6g, "
                  "dist_correction_x: %.6g, dist_correction_y: %.6g, vert_offset_correction: %.6g, "
                  "horiz_offset_correction: %.6g, two_pt_correction_available: %s}\n",
                  l, rot, vert, dist, dist + 0.03, dist - 0.02, l < 32 ? 0.215 : 0.16, l % 2 == 0 ? 0.026 : -0.026,
                  l % 2 == 0 ? "true" : "false");
    y += buf;
  }
  return y;
}

inline void check_failure(const Status& s, const std::string& path) {
  if (s.code() != ErrorCode::kBadData && s.code() != ErrorCode::kOutOfMemory)
    reader_fail("unexpected error code", s.to_string());
  const std::string text = s.to_string();
  if (s.message().empty() || text.find('\n') != std::string::npos) reader_fail("message not one line", text);
  if (text.find(path) == std::string::npos) reader_fail("message does not name the file", text);
}

template <typename T>
inline void check_per_point(const std::vector<T>& v, std::size_t n, const char* what) {
  if (!v.empty() && v.size() != n) reader_fail("attribute not one a point", what);
}

inline void check_cloud(const Cloud& c) {
  const std::size_t n = c.points.size();
  for (const auto& p : c.points)
    if (!p.allFinite()) reader_fail("non-finite point", "");
  for (const auto& d : c.no_return_directions)
    if (!d.allFinite()) reader_fail("non-finite no-return direction", "");
  check_per_point(c.intensity, n, "intensity");
  check_per_point(c.ring, n, "ring");
  check_per_point(c.column, n, "column");
  check_per_point(c.time, n, "time");
  check_per_point(c.rgb, n, "rgb");
  // (a pixel holds one point, or two in a dual-return turn: its second return)
  if (c.rows > 0 && 2 * static_cast<std::uint64_t>(c.rows) * c.columns < n) reader_fail("organised shape too small for the cloud", "");
  // (A ring field may name more lasers than an organised cloud has rows: its values are
  // the file's, and the laser coder sizes its tables by both.)
  if (c.rows > 0 && !c.column.empty())
    for (const auto col : c.column)
      if (col >= c.columns) reader_fail("column past the columns", std::to_string(col));
  if (c.geometry)
    for (const auto* table : {&c.geometry->elevation, &c.geometry->beam_azimuth, &c.geometry->column_azimuth,
                              &c.geometry->z_offset, &c.geometry->radial_offset})
      for (const double v : *table)
        if (!std::isfinite(v)) reader_fail("non-finite beam table value", "");
  if (!c.T_world_cloud.matrix().allFinite() || !c.T_cloud_sensor.matrix().allFinite()) reader_fail("non-finite pose", "");
}

/// A small cloud that was read writes as PCD (binary) and reads back with its points.
inline void check_write_back(const Cloud& c) {
  if (c.points.empty() || c.points.size() > 20000) return;
  const std::string out = scratch_dir() + "/back.pcd";
  io::WriteOptions w;
  const Status s = io::write_cloud(out, c, w);
  if (!s.ok()) {
    if (s.code() == ErrorCode::kBadData || s.code() == ErrorCode::kInvalidArgument) return;  // said why
    reader_fail("writing a cloud that was read failed", s.to_string());
  }
  io::ReadOptions o;
  o.format = io::Format::kPcd;
  const auto back = io::read_cloud(out, o);
  if (!back.ok()) reader_fail("a written cloud does not read back", back.status().to_string());
  if (back.value().cloud.points.size() != c.points.size())
    reader_fail("a written cloud reads back with another point count",
                std::to_string(c.points.size()) + " -> " + std::to_string(back.value().cloud.points.size()));
}

/// Everything one reader target does with one input.
inline void check_reader(const ReaderKind& kind, const std::uint8_t* data, std::size_t size) {
  const std::string path = scratch_dir() + "/input" + kind.extension;
  write_whole(path, data, size);
  switch (kind.reader) {
    case Reader::kCloudBytes: {
      // read from memory; what reads writes back to the same bytes (nothing invented or lost)
      const auto r = codec::cloud_from_bytes(data, size);
      if (!r.ok()) {
        if (r.status().code() != ErrorCode::kBadData) reader_fail("not kBadData", r.status().to_string());
        if (r.status().message().find('\n') != std::string::npos) reader_fail("multi-line error", r.status().message());
        return;
      }
      const std::vector<std::uint8_t> again = codec::cloud_to_bytes(r.value());
      if (again.size() != size || !std::equal(again.begin(), again.end(), data)) reader_fail("cloud bytes do not write back", "");
      return;
    }
    case Reader::kPoses: {
      const auto r = io::read_pose_list(path);
      if (!r.ok()) return check_failure(r.status(), path);
      for (const auto& p : r.value())
        if (!p.matrix().allFinite()) reader_fail("non-finite pose", "");
      return;
    }
    case Reader::kBag: {
      // the topics, then the scans of the bag's one point cloud topic and of its first topic
      // (each read opens the bag anew, which costs the ROS bag library a 4 MiB buffer)
      const auto info = io::read_bag_info(path);
      if (!info.ok()) return check_failure(info.status(), path);
      if (info.value().file_bytes != size) reader_fail("file_bytes is not the input's size", std::to_string(size));
      std::uint64_t messages = 0;
      for (const auto& t : info.value().topics) messages += t.messages;
      if (messages != info.value().messages) reader_fail("topic message counts do not add up", "");
      std::vector<std::string> topics{""};
      if (!info.value().topics.empty()) topics.push_back(info.value().topics.front().name);
      for (const auto& topic : topics) {
        const auto r = io::read_bag(path, topic);
        if (!r.ok()) {
          check_failure(r.status(), path);
          continue;
        }
        const auto& bag = r.value();
        if (bag.scans.empty()) reader_fail("a bag read with no scan", topic);
        for (const auto& s : bag.scans) check_cloud(s.cloud);
        check_write_back(bag.scans.front().cloud);
      }
      return;
    }
    case Reader::kPcap:
    case Reader::kOuster:
    case Reader::kHdl64: {
      io::ReadOptions o;
      if (kind.reader == Reader::kOuster) {
        o.metadata_path = scratch_dir() + "/input.json";
        const char* meta = ouster_metadata();
        write_whole(o.metadata_path, reinterpret_cast<const std::uint8_t*>(meta), std::string_view(meta).size());
      }
      if (kind.reader == Reader::kHdl64) {
        o.metadata_path = scratch_dir() + "/input.yaml";
        static const std::string calibration = hdl64_calibration();
        write_whole(o.metadata_path, reinterpret_cast<const std::uint8_t*>(calibration.data()), calibration.size());
      }
      const auto r = io::read_sensor_log(path, o);
      if (!r.ok()) return check_failure(r.status(), path);
      const auto& log = r.value();
      if (log.scans.size() != log.info.frames || log.no_returns.size() != log.scans.size())
        reader_fail("sensor log counts disagree", "");
      for (const auto& c : log.scans) check_cloud(c);
      if (!log.scans.empty()) check_write_back(log.scans.front());
      return;
    }
    default: break;
  }
  io::ReadOptions o;
  switch (kind.reader) {
    case Reader::kPcd: o.format = io::Format::kPcd; break;
    case Reader::kPly: o.format = io::Format::kPly; break;
    case Reader::kKitti: o.format = io::Format::kKitti; break;
    case Reader::kBinXyz: o.format = io::Format::kBinXyz; break;
    case Reader::kXyz: o.format = io::Format::kXyz; break;
    case Reader::kUos: o.format = io::Format::kUos3d; o.load_pose = false; break;
    case Reader::kLas: o.format = io::Format::kLas; break;
    default: break;
  }
  const auto r = io::read_cloud(path, o);
  if (!r.ok()) return check_failure(r.status(), path);
  const auto& res = r.value();
  check_cloud(res.cloud);
  check_per_point(res.colors, res.cloud.points.size(), "colors");
  if (res.file_bytes != size) reader_fail("file_bytes is not the input's size", std::to_string(res.file_bytes));
  check_write_back(res.cloud);
}

}  // namespace lex3d::fuzz
