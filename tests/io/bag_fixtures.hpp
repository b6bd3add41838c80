#pragma once
// ROS bags for the tests, written with the ROS bag library and sensor_msgs's own
// PointCloud2 type (so the bytes are what a ROS driver records): known clouds, and
// messages whose fields do not fit, one fault each.

#include <rosbag/bag.h>
#include <sensor_msgs/PointCloud2.h>
#include <std_msgs/String.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

namespace bagfix {

struct Field {
  const char* name;
  std::uint8_t datatype;
  std::uint32_t size;
};

/// A cloud of `height` x `width` points with `fields` packed in order (point_step their
/// sum); value(field, point) gives each value as a double, stored in the field's type.
template <typename Fn>
sensor_msgs::PointCloud2 make_cloud(std::uint32_t height, std::uint32_t width, const std::vector<Field>& fields, Fn value,
                                    std::uint32_t stamp_sec = 1700000000, std::uint32_t stamp_nsec = 250000000) {
  sensor_msgs::PointCloud2 m;
  m.header.stamp = ros::Time(stamp_sec, stamp_nsec);
  m.header.frame_id = "lidar";
  m.height = height;
  m.width = width;
  std::uint32_t step = 0;
  for (const Field& f : fields) {
    sensor_msgs::PointField pf;
    pf.name = f.name;
    pf.offset = step;
    pf.datatype = f.datatype;
    pf.count = 1;
    m.fields.push_back(pf);
    step += f.size;
  }
  m.point_step = step;
  m.row_step = step * width;
  m.is_bigendian = false;
  m.is_dense = false;
  m.data.assign(static_cast<std::size_t>(m.row_step) * height, 0);
  for (std::size_t i = 0; i < static_cast<std::size_t>(width) * height; ++i) {
    for (std::size_t k = 0; k < fields.size(); ++k) {
      std::uint8_t* p = &m.data[i * step + m.fields[k].offset];
      const double v = value(k, i);
      switch (fields[k].datatype) {
        case sensor_msgs::PointField::FLOAT32: { const auto x = static_cast<float>(v); std::memcpy(p, &x, 4); break; }
        case sensor_msgs::PointField::FLOAT64: std::memcpy(p, &v, 8); break;
        case sensor_msgs::PointField::UINT16: { const auto x = static_cast<std::uint16_t>(v); std::memcpy(p, &x, 2); break; }
        case sensor_msgs::PointField::UINT32: { const auto x = static_cast<std::uint32_t>(v); std::memcpy(p, &x, 4); break; }
        case sensor_msgs::PointField::UINT8: *p = static_cast<std::uint8_t>(v); break;
        default: break;
      }
    }
  }
  return m;
}

constexpr std::uint8_t F32 = sensor_msgs::PointField::FLOAT32, F64 = sensor_msgs::PointField::FLOAT64,
                       U16 = sensor_msgs::PointField::UINT16, U32 = sensor_msgs::PointField::UINT32;

/// Point i of the driver-like cloud: a ring of 16 lasers, 25 columns.
inline double driver_value(std::size_t field, std::size_t i) {
  const double az = 2.0 * M_PI * static_cast<double>(i % 25) / 25.0;
  const double el = (static_cast<double>(i / 25) - 7.5) * 0.03;
  const double r = 5.0 + 0.01 * static_cast<double>(i);
  switch (field) {
    case 0: return r * std::cos(el) * std::cos(az);
    case 1: return r * std::cos(el) * std::sin(az);
    case 2: return r * std::sin(el);
    case 3: return static_cast<double>(i % 97);            // intensity
    case 4: return static_cast<double>(i / 25);             // ring
    case 5: return 1000.0 * static_cast<double>(i);         // t, ns
    case 6: return static_cast<double>(3 * i % 1000);       // reflectivity (a named field)
  }
  return 0.0;
}

/// 400 points as the ouster_ros driver lays them out: x y z intensity ring t(ns) reflectivity.
inline sensor_msgs::PointCloud2 driver_cloud(std::uint32_t sec = 1700000000, std::uint32_t nsec = 250000000) {
  return make_cloud(1, 400, {{"x", F32, 4}, {"y", F32, 4}, {"z", F32, 4}, {"intensity", F32, 4}, {"ring", U16, 2},
                             {"t", U32, 4}, {"reflectivity", U16, 2}},
                    driver_value, sec, nsec);
}

/// An organised 4 x 8 cloud; pixel (1, 3) and (2, 5) are no-returns (NaN).
inline sensor_msgs::PointCloud2 organised_cloud() {
  return make_cloud(4, 8, {{"x", F32, 4}, {"y", F32, 4}, {"z", F32, 4}, {"intensity", F32, 4}},
                    [](std::size_t f, std::size_t i) {
                      if ((i == 1 * 8 + 3 || i == 2 * 8 + 5) && f < 3) return std::nan("");
                      return f == 3 ? static_cast<double>(i) : 1.0 + static_cast<double>(i) * (f + 1) * 0.1;
                    },
                    1700000001, 0);
}

/// Writes `clouds` on `topic` (one a second from t0), and optionally more topics, in chunks
/// of `compression` (the library's default chunk threshold: 768 KiB uncompressed).
inline void write(const std::string& path, const std::string& topic, const std::vector<sensor_msgs::PointCloud2>& clouds,
                  bool extra_topic = true, rosbag::CompressionType compression = rosbag::compression::Uncompressed,
                  std::uint32_t chunk_threshold = 768 * 1024) {
  rosbag::Bag bag;
  bag.open(path, rosbag::bagmode::Write);
  bag.setCompression(compression);
  bag.setChunkThreshold(chunk_threshold);
  for (std::size_t i = 0; i < clouds.size(); ++i)
    bag.write(topic, ros::Time(1700000000 + static_cast<std::uint32_t>(i), 0), clouds[i]);
  if (extra_topic) {
    std_msgs::String s;
    s.data = "not a cloud";
    bag.write("/note", ros::Time(1700000000, 1), s);
  }
  bag.close();
}

/// A velodyne_msgs/VelodyneScan as its serialized bytes (velodyne_msgs is not packaged: the
/// bag library writes these bytes under that type, as velodyne_driver records them).
struct VelodyneScanBytes {
  std::vector<std::uint8_t> bytes;
};

/// One VelodyneScan message: header (seq, stamp, frame_id "velodyne"), then each packet's
/// stamp and its 1206 bytes.
struct StampedPacket {
  std::uint32_t sec = 0, nsec = 0;
  std::vector<std::uint8_t> data;  // 1206 bytes
};
inline VelodyneScanBytes velodyne_scan(std::uint32_t seq, const std::vector<StampedPacket>& packets) {
  VelodyneScanBytes m;
  auto u32 = [&](std::uint32_t v) {
    for (int k = 0; k < 4; ++k) m.bytes.push_back(static_cast<std::uint8_t>(v >> (8 * k)));
  };
  u32(seq);
  u32(packets.empty() ? 0 : packets.front().sec);
  u32(packets.empty() ? 0 : packets.front().nsec);
  const std::string frame = "velodyne";
  u32(static_cast<std::uint32_t>(frame.size()));
  m.bytes.insert(m.bytes.end(), frame.begin(), frame.end());
  u32(static_cast<std::uint32_t>(packets.size()));
  for (const StampedPacket& p : packets) {
    u32(p.sec);
    u32(p.nsec);
    m.bytes.insert(m.bytes.end(), p.data.begin(), p.data.end());
  }
  return m;
}

/// Where the first chunk record of a bag lies: its `size` field's 4 bytes (the declared
/// uncompressed size) and its data.
struct ChunkAt {
  std::size_t record = 0, size_field = 0, data = 0, data_len = 0;
  std::uint32_t declared = 0;
};

inline std::uint32_t u32_at(const std::vector<char>& b, std::size_t at) {
  std::uint32_t v = 0;
  std::memcpy(&v, b.data() + at, 4);
  return v;
}

/// The first chunk after the file header (bag 2.0: the magic line, then the file header record).
inline ChunkAt first_chunk(const std::vector<char>& b) {
  ChunkAt c;
  const std::size_t fh = 13;
  c.record = fh + 4 + u32_at(b, fh);
  c.record += 4 + u32_at(b, c.record);  // past the file header's data (padding)
  const std::size_t hlen = u32_at(b, c.record);
  for (std::size_t o = c.record + 4; o < c.record + 4 + hlen;) {
    const std::size_t flen = u32_at(b, o);
    const std::string field(b.data() + o + 4, flen);
    if (field.rfind("size=", 0) == 0) c.size_field = o + 4 + 5;
    o += 4 + flen;
  }
  c.data_len = u32_at(b, c.record + 4 + hlen);
  c.data = c.record + 4 + hlen + 4;
  c.declared = u32_at(b, c.size_field);
  return c;
}

/// A top-level record of a bag: where it starts, its op and its data.
struct RecordAt {
  std::size_t at = 0, data = 0, data_len = 0;
  std::uint8_t op = 0;
};

/// The top-level records after the magic line, in file order.
inline std::vector<RecordAt> records(const std::vector<char>& b) {
  std::vector<RecordAt> out;
  for (std::size_t at = 13; at + 8 <= b.size();) {
    RecordAt r;
    r.at = at;
    const std::size_t hlen = u32_at(b, at);
    for (std::size_t o = at + 4; o + 4 <= at + 4 + hlen;) {
      const std::size_t flen = u32_at(b, o);
      if (flen == 4 && std::memcmp(b.data() + o + 4, "op=", 3) == 0) r.op = static_cast<std::uint8_t>(b[o + 7]);
      o += 4 + flen;
    }
    r.data_len = u32_at(b, at + 4 + hlen);
    r.data = at + 4 + hlen + 4;
    out.push_back(r);
    at = r.data + r.data_len;
  }
  return out;
}

}  // namespace bagfix

namespace ros {
namespace message_traits {
template <>
struct MD5Sum<bagfix::VelodyneScanBytes> {
  static const char* value() { return "50804fc9533a0e579e6322c04ae70566"; }
  static const char* value(const bagfix::VelodyneScanBytes&) { return value(); }
};
template <>
struct DataType<bagfix::VelodyneScanBytes> {
  static const char* value() { return "velodyne_msgs/VelodyneScan"; }
  static const char* value(const bagfix::VelodyneScanBytes&) { return value(); }
};
template <>
struct Definition<bagfix::VelodyneScanBytes> {
  static const char* value() {
    return "Header header\nVelodynePacket[] packets\n================\nMSG: velodyne_msgs/VelodynePacket\ntime stamp\n"
           "uint8[1206] data\n";
  }
  static const char* value(const bagfix::VelodyneScanBytes&) { return value(); }
};
}  // namespace message_traits
namespace serialization {
template <>
struct Serializer<bagfix::VelodyneScanBytes> {
  template <typename Stream>
  static void write(Stream& stream, const bagfix::VelodyneScanBytes& m) {
    std::memcpy(stream.advance(static_cast<std::uint32_t>(m.bytes.size())), m.bytes.data(), m.bytes.size());
  }
  template <typename Stream>
  static void read(Stream& stream, bagfix::VelodyneScanBytes& m) {
    m.bytes.resize(stream.getLength());
    std::memcpy(m.bytes.data(), stream.advance(stream.getLength()), m.bytes.size());
  }
  static std::uint32_t serializedLength(const bagfix::VelodyneScanBytes& m) { return static_cast<std::uint32_t>(m.bytes.size()); }
};
}  // namespace serialization
}  // namespace ros
