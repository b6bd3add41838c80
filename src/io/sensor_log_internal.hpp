#pragma once
// Private pieces of the raw-log reader: the UDP datagrams of a capture (pcap.cpp) and
// the per-vendor decoders (ouster.cpp, velodyne.cpp). Not installed.

#include <cstddef>
#include <cstdint>
#include <deque>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "lex3d/core/status.hpp"
#include "lex3d/io/sensor_log.hpp"

namespace lex3d::io::detail {

/// One UDP datagram of a capture, reassembled from its IPv4 fragments when it had several.
struct Datagram {
  std::uint32_t src_ip = 0;
  std::uint32_t dst_ip = 0;
  std::uint16_t src_port = 0;
  std::uint16_t dst_port = 0;
  std::size_t record = 0;  ///< 1-based capture record of its last fragment, or bag message (for messages)
  /// When that record was captured, nanoseconds since the epoch (the capture file's clock);
  /// 0 where not known (a bag's packets, a record stamped before 1970).
  std::uint64_t captured_ns = 0;
  /// The IPv4 or UDP length claims more bytes than the record holds: `payload` is what is
  /// there, `claimed` what the headers announce. A decoder refuses a truncated lidar packet
  /// and counts any other as skipped.
  bool truncated = false;
  std::size_t claimed = 0;
  std::vector<std::uint8_t> payload;
};

/// The named field of a dual-return turn's points saying which return each is (uint8: 0 the
/// sensor's first, 1 its second), written by the decoders and read by drop_second_returns.
constexpr char kReturnField[] = "return";

/// A turn's stamp from the capture time of its first packet (nullopt where not known).
inline std::optional<ScanStamp> capture_stamp(std::uint64_t captured_ns) {
  if (captured_ns == 0) return std::nullopt;
  ScanStamp s;
  s.source = ScanStamp::Source::kCapture;
  s.sec = captured_ns / 1000000000ULL;
  s.nsec = static_cast<std::uint32_t>(captured_ns % 1000000000ULL);
  return s;
}

/// Drops the second returns of a dual-return turn (the points whose `return` field is 1)
/// and the field itself, for ReadOptions::single_return; they stay counted.
void drop_second_returns(Cloud& turn);

/// The UDP/IPv4 datagrams of a libpcap/pcapng capture, read one at a time (as
/// read_udp_datagrams reads them all), counted into the SensorLogInfo given to open().
class PcapDatagrams {
 public:
  PcapDatagrams();
  ~PcapDatagrams();
  PcapDatagrams(const PcapDatagrams&) = delete;
  PcapDatagrams& operator=(const PcapDatagrams&) = delete;
  Status open(const std::string& path, SensorLogInfo& info);
  /// The next datagram into `out`: true, or false at the capture's end (after the checks of
  /// the fragment sets left over).
  StatusOr<bool> next(Datagram& out);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// A vendor's decoder fed one datagram at a time, in capture order: each turn goes to
/// `turns` once the packets that follow it close it; SensorLogInfo counts as it goes.
class LogDecoder {
 public:
  virtual ~LogDecoder() = default;
  /// One datagram (one that is not a lidar packet is counted and skipped).
  virtual Status push(const Datagram& d) = 0;
  /// The capture's end: the turn still open, and the checks that need every packet.
  virtual Status finish() = 0;
  std::deque<SensorTurn> turns;
};

/// Ouster: the decoder of the metadata's bytes (`metadata_path` names them in messages);
/// with `by_size` the lidar packets are the datagrams of the metadata's packet size,
/// whatever their ports (packets recorded without their UDP headers, as in a ROS bag).
/// `topic`: the bag topic the datagrams are the messages of (errors name "message N on
/// TOPIC", N being Datagram::record); empty for a capture ("capture record N").
StatusOr<std::unique_ptr<LogDecoder>> ouster_decoder(const std::string& path, const std::string& metadata_path,
                                                      const std::vector<std::uint8_t>& metadata, bool by_size,
                                                      SensorLogInfo& info, const std::string& topic = {});

/// Velodyne: the decoder of the data packets; `model` overrides the detected model (a key of
/// velodyne_models(); empty: detect); `calibration` (db.xml, VeloView XML or the ROS
/// driver's YAML; empty: none) gives the lasers' angles and offsets, and is required for an
/// HDL-64E. The model, return mode and packet period are read from the first
/// kVelodyneWindow lidar packets (the whole capture where it is shorter), held until then.
std::unique_ptr<LogDecoder> velodyne_decoder(const std::string& path, const std::string& model,
                                             const std::string& calibration, SensorLogInfo& info);
constexpr std::size_t kVelodyneWindow = 4096;

/// Reads every UDP/IPv4 datagram of a libpcap/pcapng capture (Ethernet with VLAN tags,
/// Linux cooked, raw IP or BSD loopback link types), reassembling IPv4 fragments. Fills the
/// capture counters of `info`. A datagram whose headers claim more bytes than were captured
/// is passed on marked `truncated` (only the decoder knows whether it is a lidar packet).
/// A damaged capture file, or a fragment set that
/// never completes between two complete fragmented datagrams of its source are errors; a
/// set cut by the capture's start or end is counted (info.incomplete_datagrams).
Status read_udp_datagrams(const std::string& path, std::vector<Datagram>& out, SensorLogInfo& info);

/// True when the payload looks like a Velodyne data packet (1206 bytes, first block flag).
bool is_velodyne_packet(const std::vector<std::uint8_t>& payload);

}  // namespace lex3d::io::detail
