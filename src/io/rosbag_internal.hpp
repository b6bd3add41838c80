#pragma once
// Private pieces of the ROS bag reader: a serialized sensor_msgs/PointCloud2 message read
// from its bytes (pointcloud2.cpp, no ROS header needed), and the container checks of a
// bag file made before the ROS bag library opens it (rosbag_check.cpp). Not installed.

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "lex3d/core/status.hpp"
#include "lex3d/io/io.hpp"

namespace lex3d::io::detail {

/// One sensor_msgs/PointField.
struct PointField2 {
  std::string name;
  std::uint32_t offset = 0;
  std::uint8_t datatype = 0;  ///< 1 INT8 ... 8 FLOAT64
  std::uint32_t count = 0;
};

/// A serialized sensor_msgs/PointCloud2, its data left in place (`data` points into the
/// message bytes).
struct PointCloud2Msg {
  std::uint32_t seq = 0, stamp_sec = 0, stamp_nsec = 0;
  std::string frame_id;
  std::uint32_t height = 0, width = 0;
  std::vector<PointField2> fields;
  bool is_bigendian = false;
  std::uint32_t point_step = 0, row_step = 0;
  const std::uint8_t* data = nullptr;
  std::size_t data_size = 0;
  bool is_dense = false;
};

/// Reads the ROS 1 serialization of a PointCloud2 (`n` bytes at `p`); every length is
/// checked against the bytes left. `where` starts each message ("<file>: message 3 on /points").
Status parse_pointcloud2(const std::string& where, const std::uint8_t* p, std::size_t n, PointCloud2Msg& out);

/// The cloud a PointCloud2 holds (fields as io/rosbag.hpp says), checked for consistency
/// (fields within point_step, row_step, data size, datatypes, byte order); fills `r` as a
/// reader does (cloud, colours in cloud.rgb, dropped fields, counts).
Status pointcloud2_to_cloud(const std::string& where, const PointCloud2Msg& m, ReadResult& r);

/// The ROS 1 serialization of a std_msgs/String or a uint8[] (`ouster_ros/PacketMsg`):
/// a u32 length and the bytes; false when the length runs past `n`.
bool parse_byte_array(const std::uint8_t* p, std::size_t n, const std::uint8_t*& bytes, std::size_t& size);

/// Walks the records of a bag 2.0 file (`size` bytes at `data`): the magic, the file header
/// (its index position), every top-level record's header and data lengths, each chunk's
/// compression and size, so that a truncated or corrupt file is refused with a one-line
/// message before the ROS bag library reads it.
Status check_bag_container(const std::string& path, const std::uint8_t* data, std::size_t size);

}  // namespace lex3d::io::detail
