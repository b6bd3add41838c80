// read_sensor_log: the capture's datagrams (pcap.cpp), then the vendor's decoder
// (ouster.cpp with its metadata, velodyne.cpp).

#include "lex3d/io/sensor_log.hpp"

#include <sys/stat.h>

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <new>
#include <stdexcept>

#include "io/internal.hpp"
#include "io/sensor_log_internal.hpp"

namespace lex3d::io {

void detail::drop_second_returns(SensorLog& log) {
  for (Cloud& c : log.scans) {
    const auto it = std::find_if(c.fields.begin(), c.fields.end(), [](const IntegerField& f) { return f.name == kReturnField; });
    if (it == c.fields.end()) continue;
    const std::vector<std::int32_t> which = it->values;
    c.fields.erase(it);
    keep_cloud_points(c, [&](std::size_t i) { return which[i] == 0; });
  }
}

namespace {

bool is_file(const std::string& p) {
  struct stat st {};
  return ::stat(p.c_str(), &st) == 0 && S_ISREG(st.st_mode);
}

/// The metadata beside a capture: `<stem>.json` (or another of `extensions`, in their
/// order), else the file named by the stem cut at its last '_' (repeatedly):
/// `OS-1-128_1024x10_run3.pcap` finds `OS-1-128_1024x10.json`. The packets are checked
/// against it (size, columns, serial number, laser count) when decoded.
std::string metadata_beside(const std::string& path, std::initializer_list<const char*> extensions = {".json"}) {
  const std::size_t slash = path.find_last_of('/');
  const std::size_t dot = path.find_last_of('.');
  std::string stem = (dot == std::string::npos || (slash != std::string::npos && dot < slash)) ? path : path.substr(0, dot);
  const std::size_t dir_end = slash == std::string::npos ? 0 : slash + 1;
  for (;;) {
    for (const char* ext : extensions)
      if (is_file(stem + ext)) return stem + ext;
    const std::size_t cut = stem.find_last_of('_');
    if (cut == std::string::npos || cut < dir_end + 1) return {};
    stem.resize(cut);
  }
}

StatusOr<SensorLog> read_sensor_log_impl(const std::string& path, const ReadOptions& options) {
  static_assert(!detail::kHostBigEndian, "the packet decoders assume a little-endian host");
  SensorLog log;
  std::vector<detail::Datagram> datagrams;
  Status s = detail::read_udp_datagrams(path, datagrams, log.info);
  if (!s.ok()) return s;
  std::size_t velodyne = 0;
  for (const auto& d : datagrams) velodyne += detail::is_velodyne_packet(d.payload) ? 1 : 0;
  std::string metadata = options.metadata_path;
  // (a calibration file given makes it a Velodyne capture; a metadata JSON an Ouster one)
  const std::string ext = detail::extension_lower(metadata);
  const bool calibration = ext == ".xml" || ext == ".yaml" || ext == ".yml";
  const bool ouster_json = ext == ".json";
  if (calibration || (velodyne > 0 && !ouster_json)) {
    // a Velodyne calibration given, or beside the capture (db.xml or the ROS driver's YAML)
    if (metadata.empty()) metadata = metadata_beside(path, {".xml", ".yaml", ".yml"});
    s = detail::decode_velodyne(path, options.sensor_model, metadata, datagrams, log);
  } else {
    if (metadata.empty()) metadata = metadata_beside(path);
    if (metadata.empty()) {
      const std::string what = datagrams.empty()
                                   ? "no lidar packets: the capture holds no UDP datagrams (" +
                                         std::to_string(log.info.pcap_packets) + " records)"
                                   : "no lidar packets: " + std::to_string(datagrams.size()) +
                                         " UDP datagrams, none a Velodyne data packet; an Ouster capture needs its "
                                         "metadata JSON beside it (same stem) or given (--metadata)";
      return bad_data(detail::msg(path, what));
    }
    s = detail::decode_ouster(path, metadata, datagrams, log);
  }
  if (!s.ok()) return s;
  if (options.single_return) detail::drop_second_returns(log);
  if (log.scans.empty())
    return bad_data(detail::msg(path, "no complete turn: " + std::to_string(log.info.lidar_packets) + " " + log.info.sensor +
                                          " packets, " + std::to_string(log.info.incomplete_frames) +
                                          " incomplete turn(s) dropped"));
  return log;
}

}  // namespace

bool is_sensor_log(const std::string& path) {
  const std::string ext = detail::extension_lower(path);
  if (ext == ".pcap" || ext == ".pcapng") return true;
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (f == nullptr) return false;
  std::uint8_t head[4] = {0};
  const std::size_t n = std::fread(head, 1, 4, f);
  std::fclose(f);
  if (n < 4) return false;
  std::uint32_t m = 0;
  std::memcpy(&m, head, 4);
  return m == 0xA1B2C3D4U || m == 0xD4C3B2A1U || m == 0xA1B23C4DU || m == 0x4D3CB2A1U || m == 0x0A0D0D0AU;
}

StatusOr<SensorLog> read_sensor_log(const std::string& path, const ReadOptions& options) {
  try {
    return read_sensor_log_impl(path, options);
  } catch (const std::bad_alloc&) {
    return out_of_memory(detail::msg(path, "out of memory reading the capture"));
  } catch (const std::length_error&) {
    return out_of_memory(detail::msg(path, "out of memory reading the capture"));
  }
}

}  // namespace lex3d::io
