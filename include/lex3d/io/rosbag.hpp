#pragma once
/// \file
/// ROS 1 bag files (format 2.0): the point clouds of one topic read as scans, and scans
/// written back as `sensor_msgs/PointCloud2` messages. Built on the ROS bag library when
/// lex3d is configured with LEX3D_WITH_ROSBAG (AUTO: on when the library is found); without it,
/// every function but is_rosbag and rosbag_supported returns kBadData naming the file
/// ("built without ROS bag support"). No ROS header is included here, and no ROS library is
/// linked: the first bag read or written loads the plugin liblex3d_rosbag.so, found beside
/// the library or program holding this code, in its lex3d/ folder, in ../lib/lex3d/ from a
/// bin/ folder, in the install prefix's lib/lex3d/, then on the library search path (or the
/// file the environment variable LEX3D_ROSBAG_PLUGIN names). Without it these functions
/// return kBadData naming the file ("ROS bag support is not installed (liblex3d_rosbag.so
/// not found)").
///
/// A topic of `sensor_msgs/PointCloud2` gives one scan a message. Its fields are read as a
/// PCD file's are: `x y z` (any numeric type; required, one element each), `intensity`,
/// `ring` (also `laser_id`, `ring_id`; else an organised cloud's row), `time` / `t` /
/// `timestamp` (seconds; an integer field is nanoseconds, as ouster_ros writes `t`), a packed
/// 32-bit `rgb` / `rgba`; every other field is listed in ReadResult::dropped_fields. An
/// organised message (height > 1) stays organised: rows are lasers, columns azimuth steps,
/// NaN and (0, 0, 0) pixels no-returns. A topic of Ouster packets (`ouster_ros/PacketMsg`,
/// `ouster_sensor_msgs/PacketMsg`) is decoded with the sensor metadata the bag holds on a
/// `std_msgs/String` topic (or the JSON given as ReadOptions::metadata_path), one scan a
/// complete frame, exactly as a pcap capture of the same packets (sensor_log.hpp); a topic
/// of Velodyne packets (`velodyne_msgs/VelodyneScan`, as velodyne_driver records them) one
/// scan a complete turn, as a capture of them.

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

/// True when this lex3d reads and writes ROS bags: built with the support and its plugin
/// found (the first call loads it).
[[nodiscard]] bool rosbag_supported() noexcept;

/// True when `path` starts with the ROS bag 2.0 magic line ("#ROSBAG V2.0\n"), or, when it
/// cannot be read, is named `.bag`.
[[nodiscard]] bool is_rosbag(const std::string& path);

/// One topic of a bag.
struct BagTopic {
  std::string name;          ///< e.g. "/points"
  std::string type;          ///< message type, e.g. "sensor_msgs/PointCloud2"
  std::uint64_t messages = 0;
};

/// What a bag holds.
struct BagInfo {
  std::vector<BagTopic> topics;  ///< in name order
  std::uint64_t messages = 0;
  double start_s = 0.0, end_s = 0.0;  ///< first and last message times (ROS time, seconds)
  std::uint64_t file_bytes = 0;
};

/// Lists the topics of a bag. Errors (kBadData, one line naming the file): not a bag, a
/// truncated or corrupt one, one never closed (no index).
[[nodiscard]] StatusOr<BagInfo> read_bag_info(const std::string& path);

/// One scan of a bag.
struct BagScan {
  Cloud cloud;
  /// The message header's stamp (PointCloud2), else its bag time. Reading sets the cloud's
  /// stamp (Cloud::stamp) to it and the frame too; writing takes the cloud's where these
  /// are 0 and empty.
  std::uint32_t stamp_sec = 0;
  std::uint32_t stamp_nsec = 0;
  std::string frame_id;          ///< the message header's frame (PointCloud2; empty for packets)
};

/// The scans of one topic, in bag time order, and what reading them dropped.
struct BagScans {
  std::string topic;
  std::string type;
  std::vector<BagScan> scans;
  std::size_t non_finite_dropped = 0;  ///< over all scans, as ReadResult counts them
  std::size_t no_return_dropped = 0;
  std::vector<std::string> dropped_fields;  ///< fields not kept (any message), e.g. "reflectivity"
  std::vector<std::string> notes;
  std::string sensor;  ///< packets: the sensor the metadata names (e.g. "OS-0-128")
  std::size_t incomplete_frames = 0;  ///< packets: frames cut by the bag's start or end, dropped
};

/// Reads the scans of `topic` (empty: the bag's only PointCloud2 topic, else its only
/// Ouster lidar-packet or velodyne_msgs/VelodyneScan topic). `options.metadata_path`
/// overrides the bag's metadata topic for Ouster packets and gives a Velodyne's calibration
/// (`options.sensor_model` its model, as for a capture); a Velodyne turn is stamped with its
/// first packet's stamp, and its frame is the first message's. Errors (kBadData, one line naming the file): no such topic (the message
/// lists the bag's topics), a topic of another type, a PointCloud2 with fields that do not
/// fit (a field beyond point_step, row_step smaller than width × point_step, data not
/// row_step × height bytes, an unknown datatype, no x/y/z field, is_bigendian set), a
/// truncated or corrupt bag (a bz2 or LZ4 chunk is decompressed and checked before the ROS
/// bag library reads it: a declared size beyond what its bytes can expand to, a chunk that
/// decompresses to more or fewer bytes than declared or not at all is named with its
/// position); kIoError when the file cannot be opened.
[[nodiscard]] StatusOr<BagScans> read_bag(const std::string& path, const std::string& topic,
                                          const ReadOptions& options = {});

/// Reads the scans of one topic one at a time (read_bag collects them): the scans read_bag
/// gives, in the same order, made a couple ahead of the caller on a thread of the reader's
/// own, so that a bag of any length is read in the memory of a few scans. open() chooses the
/// topic and reads an Ouster packet topic's metadata (its errors are read_bag's); an error
/// in a message comes from the next() that reaches it, after the scans before it.
class BagReader {
 public:
  [[nodiscard]] static StatusOr<std::unique_ptr<BagReader>> open(const std::string& path, const std::string& topic,
                                                                 const ReadOptions& options = {});
  ~BagReader();
  BagReader(const BagReader&) = delete;
  BagReader& operator=(const BagReader&) = delete;
  /// The next scan; std::nullopt after the last (a topic with none is an error, as read_bag's).
  [[nodiscard]] StatusOr<std::optional<BagScan>> next();
  /// The topic, its type and what reading dropped (BagScans without its scans): complete
  /// once next() gave std::nullopt.
  [[nodiscard]] const BagScans& summary() const;

 private:
  BagReader();
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Writes scans one at a time as write_bag writes them (their stamps, fields and shapes the
/// same), into a temporary file that close() renames over `path`: a writer destroyed before
/// close(), or a write that fails, leaves nothing at `path`. For sequences of any length.
class BagWriter {
 public:
  [[nodiscard]] static StatusOr<std::unique_ptr<BagWriter>> open(const std::string& path,
                                                                 const std::string& topic = "/points");
  ~BagWriter();
  BagWriter(const BagWriter&) = delete;
  BagWriter& operator=(const BagWriter&) = delete;
  /// The next message: `scan` at its stamp (or 1 s after the scan before).
  [[nodiscard]] Status write(const BagScan& scan);
  /// Writes the bag's index and puts the bag at `path`.
  [[nodiscard]] Status close();

 private:
  BagWriter();
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Writes `scans` as `sensor_msgs/PointCloud2` messages on `topic` (uncompressed chunks),
/// each at its stamp (a scan without one 1 s after the scan before it, the first at 1 s),
/// atomically (a temporary file renamed over `path`). Fields: x y z
/// (float32), then those the cloud has: intensity (float32), ring (uint16), time (float64
/// seconds), rgb (packed float32). A cloud with a range-image shape and each point's row and
/// column is written organised (height = rows, no-return pixels NaN), any other with
/// height 1, both in the cloud's point order.
[[nodiscard]] Status write_bag(const std::string& path, const std::vector<BagScan>& scans,
                               const std::string& topic = "/points");

}  // namespace lex3d::io

#pragma GCC visibility pop
