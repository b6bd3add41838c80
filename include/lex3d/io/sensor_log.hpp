#pragma once
/// \file
/// Raw spinning-lidar logs: a libpcap capture of the sensor's UDP packets, decoded into
/// one organised Cloud a complete turn, with each point's laser (`Cloud::ring`), azimuth
/// column (`Cloud::column`), the range-image shape and the sensor's beam layout
/// (`Cloud::geometry`).
///
/// - Ouster (LEGACY, RNG19_RFL8_SIG16_NIR16, RNG19_RFL8_SIG16_NIR16_DUAL, RNG15_RFL8_NIR8),
///   with the sensor's metadata JSON (fw 2.x flat layout or the fw 3 nested one). A turn is
///   one frame_id whose columns cover the metadata's column_window. Rows are the beams in
///   the metadata's order (highest first), columns the destaggered measurement columns
///   (pixel_shift_by_row), and each point is placed as Ouster's beam model places it, in
///   the "sensor" frame (lidar_to_sensor_transform), so the geometry reproduces it exactly.
///   Intensity is the reflectivity channel. Zero-range pixels are no-returns (counted, not
///   points); the dual profile's second returns are points of their own at their pixel
///   (their reflectivity and signal), marked by a uint8 `return` field (0 the strongest, 1
///   the second strongest; ReadOptions::single_return drops them). Each point's
///   time is its measurement column's timestamp less the frame's first (`t`, uint32 ns, as
///   Ouster's ROS driver gives it); a frame whose timestamps span more than 2^32 ns has none.
/// - Velodyne VLP-16, Puck Hi-Res, HDL-32E and VLP-32C, single or dual return (dual: the
///   last return and the other where it differs, a uint8 `return` field 0 and 1), with the published per-model tables (elevation, and
///   the VLP-32C's azimuth offsets) and firing timing, or the unit's calibration where one
///   is given (db.xml, VeloView XML, the ROS driver's YAML: `metadata_path`, else beside the
///   capture); the HDL-64E (single return) with its calibration only. Rings are the
///   lasers ordered by elevation, lowest first (ring 0 = lowest beam); a column is one firing
///   of all lasers, counted from the start of its turn. A turn is 360° of azimuth starting at
///   the log's first firing (so a log of 1.1 turns gives one). The points use each firing's
///   own azimuth from the packets (and each laser's firing time within it); the geometry is
///   the best regular grid (columns = the firings of the turn, 360°/columns apart, column 0
///   placed by least squares over the turn's firings), not an exact one. Each point's time
///   is its firing's (the packet's timestamp plus the firing periods and its laser's slot
///   before it; an HDL-64E's firing period is the packet period over its firings) less
///   the turn's first firing's (`time`, float32 seconds, as Velodyne's ROS driver gives
///   it); a turn whose packet timestamps run backwards or over a second has none.

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "lex3d/core/cloud.hpp"
#include "lex3d/core/status.hpp"
#include "lex3d/io/io.hpp"

// The public API: exported by liblex3d.so, which hides everything else.
#pragma GCC visibility push(default)

namespace lex3d::io {

/// What a raw log held besides its turns.
struct SensorLogInfo {
  std::string vendor;        ///< "ouster" or "velodyne"
  std::string sensor;        ///< e.g. "OS-1-128", "VLP-16"
  std::string profile;       ///< Ouster udp_profile_lidar; Velodyne return mode ("strongest", "last")
  std::string metadata_path; ///< the Ouster metadata JSON or the Velodyne calibration read (empty: none)
  std::string model_note;    ///< how the Velodyne model was decided (factory byte, timing, override)
  std::uint32_t lasers = 0;   ///< beams (rows of a turn)
  std::uint32_t columns = 0;  ///< columns a turn (Ouster: columns_per_frame; Velodyne: median firings a turn)
  std::size_t frames = 0;     ///< complete turns decoded (= scans.size())
  std::size_t incomplete_frames = 0;  ///< turns cut by the capture's start or end, or missing packets: dropped
  std::size_t pcap_packets = 0;       ///< capture records read
  std::size_t udp_datagrams = 0;      ///< UDP datagrams after IPv4 reassembly
  std::size_t lidar_packets = 0;      ///< lidar data packets decoded
  std::size_t other_packets = 0;      ///< other datagrams and non-IPv4/UDP frames (IMU, GPS, ARP, ...), skipped
  std::size_t fragmented_datagrams = 0;  ///< datagrams reassembled from IPv4 fragments
  std::size_t incomplete_datagrams = 0;  ///< fragment sets cut by the capture's start or end, dropped
  std::size_t no_returns = 0;         ///< zero-range pixels of the decoded turns (not points)
  std::size_t second_returns = 0;     ///< dual-return profile: second returns (points of their own)
  std::size_t points = 0;             ///< points of all decoded turns
};

/// The turns of a raw log, in capture order.
struct SensorLog {
  SensorLogInfo info;
  std::vector<Cloud> scans;
  std::vector<std::uint64_t> frame_ids;        ///< Ouster frame_id, or the turn's index (Velodyne)
  /// Per scan: when the capture recorded the packet of the turn's first measurement,
  /// nanoseconds since the epoch (the capturing host's clock, the pcap record's time: the
  /// sensor's own clock may count from its boot or the hour); 0 where not known.
  std::vector<std::uint64_t> captured_ns;
  std::vector<std::size_t> no_returns;         ///< per scan
};

/// One turn of a raw log, as SensorLogReader gives it.
struct SensorTurn {
  Cloud cloud;
  std::uint64_t frame_id = 0;     ///< Ouster frame_id, or the turn's index (Velodyne)
  std::uint64_t captured_ns = 0;  ///< as SensorLog::captured_ns
  std::size_t no_returns = 0;     ///< zero-range pixels (not points)
};

/// Reads a raw log turn by turn: it holds the turn being assembled and the packets of the
/// capture's first moments (a Velodyne capture's model and packet period are read from its
/// first 4,096 data packets; without `metadata_path`, the vendor from the first Velodyne
/// packet, or from an Ouster metadata JSON beside the capture after 4,096 datagrams with
/// none), so a capture of any length is read in the memory of a few turns. The turns, counters and errors are
/// read_sensor_log's; an error met later in the capture comes from the next() that reaches
/// it, after the turns before it.
class SensorLogReader {
 public:
  /// Opens the capture (kIoError where it cannot be opened, kBadData where it is not a
  /// capture); the packets are read by next().
  [[nodiscard]] static StatusOr<std::unique_ptr<SensorLogReader>> open(const std::string& path,
                                                                      const ReadOptions& options = {});
  ~SensorLogReader();
  SensorLogReader(const SensorLogReader&) = delete;
  SensorLogReader& operator=(const SensorLogReader&) = delete;
  /// The next complete turn; std::nullopt at the capture's end (a capture with no complete
  /// turn is an error there, as read_sensor_log's).
  [[nodiscard]] StatusOr<std::optional<SensorTurn>> next();
  /// What was read so far: the sensor's fields once next() gave a turn, the counters for
  /// the whole capture once it gave std::nullopt.
  [[nodiscard]] const SensorLogInfo& info() const;

 private:
  SensorLogReader();
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// The Velodyne models a capture is read as (`ReadOptions::sensor_model` keys): "vlp16",
/// "puck-hires", "hdl32e", "vlp32c", "hdl64e".
[[nodiscard]] std::vector<std::string> velodyne_models();

/// True when `path` is named `.pcap`/`.pcapng` or starts with a libpcap or pcapng magic number.
[[nodiscard]] bool is_sensor_log(const std::string& path);

/// Reads every complete turn of a raw lidar log (see the file comment). `options` gives the
/// Ouster metadata path (`metadata_path`; default `<stem>.json` beside the capture) and a
/// Velodyne model override (`sensor_model`). Errors (kBadData, one line naming the file):
/// not a capture, no lidar packets, a truncated packet or capture record, metadata that does
/// not match the packets (size, beam count, profile, columns, serial number), a fragment set
/// that never completes in the middle of the capture, a non-finite or out-of-range angle in
/// the laser table, no complete turn. kIoError when a file cannot be opened.
[[nodiscard]] StatusOr<SensorLog> read_sensor_log(const std::string& path, const ReadOptions& options = {});

}  // namespace lex3d::io

#pragma GCC visibility pop
