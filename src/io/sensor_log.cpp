// SensorLogReader and read_sensor_log: the capture's datagrams one at a time (pcap.cpp),
// fed to the vendor's decoder (ouster.cpp with its metadata, velodyne.cpp), which hands on
// each turn as it closes.

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

/// Drops a dual-return turn's second returns (its points whose `return` field is 1) and the
/// field itself.
void detail::drop_second_returns(Cloud& c) {
  const auto it = std::find_if(c.fields.begin(), c.fields.end(), [](const IntegerField& f) { return f.name == detail::kReturnField; });
  if (it == c.fields.end()) return;
  const std::vector<std::int32_t> which = it->values;
  c.fields.erase(it);
  detail::keep_cloud_points(c, [&](std::size_t i) { return which[i] == 0; });
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

/// Datagrams held while the capture's vendor is not known (no metadata given or beside it
/// names one): at most this many before an Ouster metadata found beside the capture decides.
constexpr std::size_t kVendorWindow = 4096;

}  // namespace

struct SensorLogReader::Impl {
  std::string path;
  ReadOptions options;
  SensorLogInfo info;
  detail::PcapDatagrams capture;
  std::unique_ptr<detail::LogDecoder> decoder;
  // (Velodyne read for want of an Ouster metadata: no data packet then means neither)
  bool velodyne_by_default = false;
  std::vector<detail::Datagram> undecided;  // datagrams before the vendor is known
  std::size_t velodyne_seen = 0;
  bool ended = false;
  std::size_t turns_given = 0;
  Status failed;  // the error that ended the reading

  /// The Velodyne decoder, with a calibration given or beside the capture.
  void use_velodyne() {
    std::string calibration = options.metadata_path;
    if (calibration.empty()) calibration = metadata_beside(path, {".xml", ".yaml", ".yml"});
    decoder = detail::velodyne_decoder(path, options.sensor_model, calibration, info);
  }
  /// The Ouster decoder with `metadata`'s bytes.
  Status use_ouster(const std::string& metadata) {
    auto text = read_file(metadata, 64ULL << 20);
    if (!text.ok()) return text.status();
    auto d = detail::ouster_decoder(path, metadata, text.value(), false, info);
    if (!d.ok()) return d.status();
    decoder = std::move(d).value();
    return {};
  }
  [[nodiscard]] std::string ouster_metadata() const {
    return options.metadata_path.empty() ? metadata_beside(path) : options.metadata_path;
  }
  [[nodiscard]] Status no_lidar_packets() const {
    const std::string what = info.udp_datagrams == 0
                                 ? "no lidar packets: the capture holds no UDP datagrams (" +
                                       std::to_string(info.pcap_packets) + " records)"
                                 : "no lidar packets: " + std::to_string(info.udp_datagrams) +
                                       " UDP datagrams, none a Velodyne data packet; an Ouster capture needs its "
                                       "metadata JSON beside it (same stem) or given (--metadata)";
    return bad_data(detail::msg(path, what));
  }

  /// The vendor from what is known so far: a calibration given (Velodyne) or an Ouster
  /// metadata JSON given; else a Velodyne data packet seen (Velodyne), or `at_end` or
  /// kVendorWindow datagrams without one (Ouster where its metadata is found; else read as
  /// Velodyne, which then finds no packet). Returns whether it is decided.
  StatusOr<bool> decide(bool at_end) {
    const std::string ext = detail::extension_lower(options.metadata_path);
    const bool calibration = ext == ".xml" || ext == ".yaml" || ext == ".yml";
    if (calibration) {
      use_velodyne();
      return true;
    }
    if (ext == ".json") {
      Status s = use_ouster(options.metadata_path);
      if (!s.ok()) return s;
      return true;
    }
    if (velodyne_seen > 0) {
      use_velodyne();
      return true;
    }
    if (!at_end && undecided.size() < kVendorWindow) return false;
    const std::string metadata = ouster_metadata();
    if (metadata.empty()) {
      if (at_end) return no_lidar_packets();
      use_velodyne();
      velodyne_by_default = true;
      return true;
    }
    Status s = use_ouster(metadata);
    if (!s.ok()) return s;
    return true;
  }

  Status feed_undecided() {
    for (const detail::Datagram& d : undecided) {
      Status s = decoder->push(d);
      if (!s.ok()) return s;
    }
    undecided.clear();
    undecided.shrink_to_fit();
    return {};
  }

  StatusOr<std::optional<SensorTurn>> next() {
    for (;;) {
      if (decoder && !decoder->turns.empty()) {
        SensorTurn t = std::move(decoder->turns.front());
        decoder->turns.pop_front();
        if (options.single_return) detail::drop_second_returns(t.cloud);
        ++turns_given;
        return std::optional<SensorTurn>(std::move(t));
      }
      if (ended) {
        if (turns_given == 0)
          return bad_data(detail::msg(path, "no complete turn: " + std::to_string(info.lidar_packets) + " " + info.sensor +
                                                " packets, " + std::to_string(info.incomplete_frames) +
                                                " incomplete turn(s) dropped"));
        return std::optional<SensorTurn>();
      }
      detail::Datagram d;
      auto more = capture.next(d);
      if (!more.ok()) return more.status();
      if (!more.value()) {
        ended = true;
        if (!decoder) {
          auto decided = decide(true);
          if (!decided.ok()) return decided.status();
          Status s = feed_undecided();
          if (!s.ok()) return s;
        }
        if (velodyne_by_default && info.lidar_packets == 0) return no_lidar_packets();
        Status s = decoder->finish();
        if (!s.ok()) return s;
        continue;
      }
      if (decoder) {
        Status s = decoder->push(d);
        if (!s.ok()) return s;
        continue;
      }
      velodyne_seen += detail::is_velodyne_packet(d.payload) ? 1 : 0;
      undecided.push_back(std::move(d));
      auto decided = decide(false);
      if (!decided.ok()) return decided.status();
      if (decided.value()) {
        Status s = feed_undecided();
        if (!s.ok()) return s;
      }
    }
  }
};

SensorLogReader::SensorLogReader() : impl_(std::make_unique<Impl>()) {}
SensorLogReader::~SensorLogReader() = default;

StatusOr<std::unique_ptr<SensorLogReader>> SensorLogReader::open(const std::string& path, const ReadOptions& options) {
  static_assert(!detail::kHostBigEndian, "the packet decoders assume a little-endian host");
  std::unique_ptr<SensorLogReader> r(new SensorLogReader());
  r->impl_->path = path;
  r->impl_->options = options;
  Status s = r->impl_->capture.open(path, r->impl_->info);
  if (!s.ok()) return s;
  return r;
}

StatusOr<std::optional<SensorTurn>> SensorLogReader::next() {
  // (an error ends the reading: every call after it gives it again)
  if (!impl_->failed.ok()) return impl_->failed;
  try {
    auto r = impl_->next();
    if (!r.ok()) impl_->failed = r.status();
    return r;
  } catch (const std::bad_alloc&) {
    impl_->failed = out_of_memory(detail::msg(impl_->path, "out of memory reading the capture"));
  } catch (const std::length_error&) {
    impl_->failed = out_of_memory(detail::msg(impl_->path, "out of memory reading the capture"));
  }
  return impl_->failed;
}

const SensorLogInfo& SensorLogReader::info() const { return impl_->info; }

namespace {

StatusOr<SensorLog> read_sensor_log_impl(const std::string& path, const ReadOptions& options) {
  auto reader = SensorLogReader::open(path, options);
  if (!reader.ok()) return reader.status();
  SensorLog log;
  for (;;) {
    auto turn = reader.value()->next();
    if (!turn.ok()) return turn.status();
    if (!turn.value()) break;
    SensorTurn& t = *turn.value();
    log.no_returns.push_back(t.no_returns);
    log.frame_ids.push_back(t.frame_id);
    log.captured_ns.push_back(t.captured_ns);
    log.scans.push_back(std::move(t.cloud));
  }
  log.info = reader.value()->info();
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
