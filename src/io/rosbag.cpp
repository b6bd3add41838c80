// ROS 1 bags through the ROS bag library (rosbag_storage): the only translation unit of
// lex3d that includes a ROS header. The library finds the messages; their bytes are read
// here as serialized PointCloud2 (pointcloud2.cpp) or Ouster packets (ouster.cpp), every
// length checked, rather than through sensor_msgs's generated deserializer, which trusts the
// lengths it reads. Bags are written with sensor_msgs's generated PointCloud2 type, so the
// message definition and MD5 sum in the bag are ROS's own.

#include "lex3d/io/rosbag.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <map>
#include <memory>
#include <new>
#include <set>
#include <stdexcept>

#include "io/internal.hpp"
#include "io/rosbag_internal.hpp"
#include "io/sensor_log_internal.hpp"
#include "lex3d/io/mapped_file.hpp"

#ifdef LEX3D_WITH_ROSBAG
#include <console_bridge/console.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/PointCloud2.h>
#endif

namespace lex3d::io {

bool is_rosbag(const std::string& path) {
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (f == nullptr) return detail::extension_lower(path) == ".bag";
  char head[9] = {0};
  const std::size_t n = std::fread(head, 1, sizeof head, f);
  std::fclose(f);
  return n == sizeof head && std::memcmp(head, "#ROSBAG V", 9) == 0;
}

#ifndef LEX3D_WITH_ROSBAG

bool rosbag_supported() noexcept { return false; }

namespace {
Status unsupported(const std::string& path) {
  return bad_data(detail::msg(path, "a ROS bag, and this lex3d was built without ROS bag support (install "
                                    "librosbag-storage-dev and libsensor-msgs-dev, then configure again)"));
}
}  // namespace

StatusOr<BagInfo> read_bag_info(const std::string& path) { return unsupported(path); }
StatusOr<BagScans> read_bag(const std::string& path, const std::string&, const ReadOptions&) { return unsupported(path); }
Status write_bag(const std::string& path, const std::vector<BagScan>&, const std::string&) { return unsupported(path); }

#else

bool rosbag_supported() noexcept { return true; }

namespace {

constexpr const char* kPointCloud2 = "sensor_msgs/PointCloud2";

bool is_packet_type(const std::string& type) {
  return type == "ouster_ros/PacketMsg" || type == "ouster_sensor_msgs/PacketMsg";
}

/// The library's own log lines (console_bridge) would break the one-line errors: off.
void quiet_library() {
  static const bool done = [] {
    console_bridge::setLogLevel(console_bridge::CONSOLE_BRIDGE_LOG_NONE);
    return true;
  }();
  (void)done;
}

/// A bag checked (check_bag_container) and opened; the library's Bag is made only for a
/// file that passes (making one costs a few ms).
Status open_bag(const std::string& path, std::unique_ptr<rosbag::Bag>& bag, std::uint64_t& file_bytes) {
  quiet_library();
  auto mapped = MappedFile::open(path);
  if (!mapped.ok()) return mapped.status();
  const MappedFile& f = *mapped.value();
  file_bytes = f.size();
  if (f.size() == 0) return bad_data(detail::msg(path, "file is empty"), 0);
  Status s = detail::check_bag_container(path, f.data(), f.size());
  if (!s.ok()) return s;
  bag = std::make_unique<rosbag::Bag>();
  bag->open(path, rosbag::bagmode::Read);
  return {};
}

std::string topic_list(const BagInfo& info) {
  std::string s;
  for (const auto& t : info.topics)
    s += (s.empty() ? "" : ", ") + t.name + " (" + t.type + ", " + std::to_string(t.messages) + ")";
  return s.empty() ? std::string("no topics") : s;
}

BagInfo bag_info(rosbag::Bag& bag, std::uint64_t file_bytes) {
  BagInfo info;
  info.file_bytes = file_bytes;
  rosbag::View all(bag);
  std::map<std::string, std::set<std::string>> types;
  for (const rosbag::ConnectionInfo* c : all.getConnections()) types[c->topic].insert(c->datatype);
  for (const auto& [topic, ts] : types) {
    BagTopic t;
    t.name = detail::printable(topic, 256);  // names as they appear in messages: one line
    for (const auto& ty : ts) t.type += (t.type.empty() ? "" : " | ") + detail::printable(ty, 256);
    t.messages = rosbag::View(bag, rosbag::TopicQuery(topic)).size();
    info.messages += t.messages;
    info.topics.push_back(std::move(t));
  }
  if (info.messages > 0) {
    info.start_s = all.getBeginTime().toSec();
    info.end_s = all.getEndTime().toSec();
  }
  return info;
}

/// The bytes of one message.
void message_bytes(const rosbag::MessageInstance& m, std::vector<std::uint8_t>& buf) {
  const std::uint32_t n = m.size();
  buf.resize(n);
  ros::serialization::OStream os(buf.data(), n);
  m.write(os);
}

void add_unique(std::vector<std::string>& list, const std::string& s) {
  if (std::find(list.begin(), list.end(), s) == list.end()) list.push_back(s);
}

Status read_clouds(const std::string& path, rosbag::Bag& bag, const BagTopic& topic, BagScans& out) {
  rosbag::View view(bag, rosbag::TopicQuery(topic.name));
  for (const rosbag::ConnectionInfo* c : view.getConnections())
    if (c->md5sum != ros::message_traits::MD5Sum<sensor_msgs::PointCloud2>::value())
      return bad_data(detail::msg(path, "topic " + topic.name + ": a PointCloud2 of another definition (MD5 " +
                                            detail::printable(c->md5sum, 40) + ")"));
  std::vector<std::uint8_t> buf;
  std::size_t k = 0;
  for (const rosbag::MessageInstance& m : view) {
    const std::string where = detail::msg(path, "message " + std::to_string(k) + " on " + topic.name);
    message_bytes(m, buf);
    detail::PointCloud2Msg pm;
    Status s = detail::parse_pointcloud2(where, buf.data(), buf.size(), pm);
    if (!s.ok()) return s;
    ReadResult r;
    s = detail::pointcloud2_to_cloud(where, pm, r);
    if (!s.ok()) return s;
    BagScan scan;
    scan.cloud = std::move(r.cloud);
    scan.frame_id = pm.frame_id;
    scan.stamp_sec = pm.stamp_sec;
    scan.stamp_nsec = pm.stamp_nsec;
    if (scan.stamp_sec == 0 && scan.stamp_nsec == 0) {  // no header stamp: the bag's time
      scan.stamp_sec = m.getTime().sec;
      scan.stamp_nsec = m.getTime().nsec;
    }
    out.non_finite_dropped += r.non_finite_dropped;
    out.no_return_dropped += r.no_return_dropped;
    for (const auto& f : r.dropped_fields) add_unique(out.dropped_fields, f);
    for (const auto& n : r.notes) add_unique(out.notes, n);
    out.scans.push_back(std::move(scan));
    ++k;
  }
  return {};
}

Status read_packets(const std::string& path, rosbag::Bag& bag, const BagInfo& info, const BagTopic& topic,
                    const ReadOptions& options, BagScans& out) {
  std::vector<std::uint8_t> metadata;
  std::string metadata_name = options.metadata_path;
  std::vector<std::uint8_t> buf;
  if (!metadata_name.empty()) {
    auto text = read_file(metadata_name, 64ULL << 20);
    if (!text.ok()) return text.status();
    metadata = std::move(text).value();
  } else {
    // the bag's metadata: a std_msgs/String topic named ".../metadata", else its only String topic
    const BagTopic* meta = nullptr;
    std::size_t strings = 0;
    for (const auto& t : info.topics) {
      if (t.type != "std_msgs/String" || t.messages == 0) continue;
      ++strings;
      const bool named = t.name.size() >= 8 && t.name.compare(t.name.size() - 8, 8, "metadata") == 0;
      if (named || meta == nullptr) meta = &t;
    }
    if (meta == nullptr || (strings > 1 && meta->name.find("metadata") == std::string::npos))
      return bad_data(detail::msg(path, "topic " + topic.name + " holds Ouster packets but the bag has no metadata "
                                        "topic (std_msgs/String named .../metadata): give the sensor's metadata JSON "
                                        "with --metadata"));
    rosbag::View mv(bag, rosbag::TopicQuery(meta->name));
    for (const rosbag::MessageInstance& m : mv) {
      message_bytes(m, buf);
      const std::uint8_t* b = nullptr;
      std::size_t n = 0;
      if (!detail::parse_byte_array(buf.data(), buf.size(), b, n))
        return bad_data(detail::msg(path, "topic " + meta->name + ": a truncated std_msgs/String"));
      metadata.assign(b, b + n);
      break;
    }
    metadata_name = path + " topic " + meta->name;
  }
  std::vector<detail::Datagram> datagrams;
  rosbag::View view(bag, rosbag::TopicQuery(topic.name));
  std::size_t k = 0;
  for (const rosbag::MessageInstance& m : view) {
    ++k;
    message_bytes(m, buf);
    const std::uint8_t* b = nullptr;
    std::size_t n = 0;
    if (!detail::parse_byte_array(buf.data(), buf.size(), b, n))
      return bad_data(detail::msg(path, "message " + std::to_string(k) + " on " + topic.name + ": a truncated packet message"));
    detail::Datagram d;
    d.record = k;
    d.payload.assign(b, b + n);
    datagrams.push_back(std::move(d));
  }
  SensorLog log;
  Status s = detail::decode_ouster_packets(path, metadata_name, metadata, datagrams, true, log, topic.name);
  if (!s.ok()) return s;
  // each frame's time: the bag time of its frame id's first packet
  std::map<std::uint64_t, ros::Time> first_seen;
  {
    std::size_t j = 0;
    rosbag::View again(bag, rosbag::TopicQuery(topic.name));
    for (const rosbag::MessageInstance& m : again) {
      const auto& p = datagrams[j++].payload;
      std::uint16_t id = 0;
      if (p.size() >= 12) std::memcpy(&id, p.data() + (log.info.profile == "LEGACY" ? 10 : 2), 2);
      first_seen.emplace(id, m.getTime());
      if (j == datagrams.size()) break;
    }
  }
  out.sensor = log.info.sensor;
  out.incomplete_frames = log.info.incomplete_frames;
  out.no_return_dropped = log.info.no_returns;
  if (log.info.other_packets > 0)
    out.notes.push_back(std::to_string(log.info.other_packets) + " messages on " + topic.name +
                        " are not lidar packets of the metadata's size: skipped");
  if (log.info.second_returns > 0)
    out.notes.push_back(std::to_string(log.info.second_returns) + " second returns not kept");
  for (std::size_t i = 0; i < log.scans.size(); ++i) {
    BagScan scan;
    scan.cloud = std::move(log.scans[i]);
    const auto it = first_seen.find(log.frame_ids[i] & 0xFFFFU);
    if (it != first_seen.end()) {
      scan.stamp_sec = it->second.sec;
      scan.stamp_nsec = it->second.nsec;
    }
    out.scans.push_back(std::move(scan));
  }
  if (out.scans.empty())
    return bad_data(detail::msg(path, "topic " + topic.name + ": no complete frame (" +
                                          std::to_string(log.info.lidar_packets) + " packets, " +
                                          std::to_string(log.info.incomplete_frames) + " incomplete frame(s) dropped)"));
  return {};
}

StatusOr<BagScans> read_bag_impl(const std::string& path, const std::string& topic, const ReadOptions& options) {
  std::unique_ptr<rosbag::Bag> opened;
  std::uint64_t bytes = 0;
  Status s = open_bag(path, opened, bytes);
  if (!s.ok()) return s;
  rosbag::Bag& bag = *opened;
  const BagInfo info = bag_info(bag, bytes);
  const BagTopic* chosen = nullptr;
  if (!topic.empty()) {
    for (const auto& t : info.topics)
      if (t.name == topic) chosen = &t;
    if (chosen == nullptr)
      return bad_data(detail::msg(path, "no topic " + detail::quoted(topic) + " in the bag; it holds " + topic_list(info)));
  } else {
    std::vector<const BagTopic*> clouds, packets;
    for (const auto& t : info.topics) {
      if (t.type == kPointCloud2) clouds.push_back(&t);
      if (is_packet_type(t.type) && t.name.find("imu") == std::string::npos) packets.push_back(&t);
    }
    if (clouds.size() == 1) chosen = clouds.front();
    else if (clouds.empty() && packets.size() == 1) chosen = packets.front();
    else
      return bad_data(detail::msg(path, std::string(clouds.size() + packets.size() == 0 ? "no point cloud topic"
                                                                                       : "several point cloud topics") +
                                            " (give one with --topic); the bag holds " + topic_list(info)));
  }
  BagScans out;
  out.topic = chosen->name;
  out.type = chosen->type;
  if (chosen->type == kPointCloud2) s = read_clouds(path, bag, *chosen, out);
  else if (is_packet_type(chosen->type)) s = read_packets(path, bag, info, *chosen, options, out);
  else
    return bad_data(detail::msg(path, "topic " + chosen->name + " holds " + chosen->type +
                                          " messages; lex3d reads sensor_msgs/PointCloud2 and Ouster packets "
                                          "(ouster_ros/PacketMsg)"));
  if (!s.ok()) return s;
  if (out.scans.empty()) return bad_data(detail::msg(path, "topic " + chosen->name + " holds no message"));
  return out;
}

template <typename Fn>
auto guarded(const std::string& path, Fn&& fn) -> decltype(fn()) {
  try {
    return fn();
  } catch (const std::bad_alloc&) {
    return out_of_memory(detail::msg(path, "out of memory reading the bag"));
  } catch (const std::length_error&) {
    return out_of_memory(detail::msg(path, "out of memory reading the bag"));
  } catch (const std::exception& e) {
    // the ROS bag library's exceptions (BagFormatException, BagIOException, ...)
    return bad_data(detail::msg(path, "corrupt or truncated bag: " + detail::printable(e.what(), 160)));
  }
}

/// PointField datatypes.
constexpr std::uint8_t kU16 = 4, kF32 = 7, kF64 = 8;

sensor_msgs::PointCloud2 to_message(const BagScan& scan, const ros::Time& stamp) {
  const Cloud& c = scan.cloud;
  sensor_msgs::PointCloud2 m;
  m.header.stamp = stamp;
  m.header.frame_id = scan.frame_id;
  std::uint32_t step = 0;
  auto field = [&](const char* name, std::uint8_t type, std::uint32_t size) {
    sensor_msgs::PointField f;
    f.name = name;
    f.offset = step;
    f.datatype = type;
    f.count = 1;
    m.fields.push_back(f);
    step += size;
    return f.offset;
  };
  const std::uint32_t ox = field("x", kF32, 4), oy = field("y", kF32, 4), oz = field("z", kF32, 4);
  const bool in = c.has_intensity(), ring = c.has_rings(), time = c.has_time(), rgb = c.has_rgb();
  const std::uint32_t oi = in ? field("intensity", kF32, 4) : 0;
  const std::uint32_t orgb = rgb ? field("rgb", kF32, 4) : 0;
  const std::uint32_t oring = ring ? field("ring", kU16, 2) : 0;
  step = (step + 7U) & ~7U;  // the double time aligned
  const std::uint32_t ot = time ? field("time", kF64, 8) : 0;
  m.point_step = step;
  m.is_bigendian = false;
  // organised: every point has a distinct pixel (row, column) of the shape
  std::vector<std::size_t> pixel;  // point -> pixel
  bool organised = c.rows > 1 && c.columns > 0 && c.has_rings() && c.has_columns() &&
                   static_cast<std::uint64_t>(c.rows) * c.columns <= (1ULL << 32);
  if (organised) {
    std::vector<std::uint8_t> used(static_cast<std::size_t>(c.rows) * c.columns, 0);
    pixel.resize(c.size());
    for (std::size_t i = 0; organised && i < c.size(); ++i) {
      if (c.ring[i] >= c.rows || c.column[i] >= c.columns) {
        organised = false;
        break;
      }
      const std::size_t px = static_cast<std::size_t>(c.ring[i]) * c.columns + c.column[i];
      if (used[px] != 0) organised = false;
      used[px] = 1;
      pixel[i] = px;
    }
  }
  m.height = organised ? c.rows : 1;
  m.width = organised ? c.columns : static_cast<std::uint32_t>(c.size());
  m.row_step = m.width * step;
  m.is_dense = !organised;
  m.data.assign(static_cast<std::size_t>(m.row_step) * m.height, 0);
  if (organised) {  // no-return pixels: NaN positions
    const float nan = std::nanf("");
    for (std::size_t px = 0; px < static_cast<std::size_t>(m.width) * m.height; ++px)
      for (std::uint32_t o : {ox, oy, oz}) std::memcpy(&m.data[px * step + o], &nan, 4);
  }
  for (std::size_t i = 0; i < c.size(); ++i) {
    std::uint8_t* p = &m.data[(organised ? pixel[i] : i) * step];
    std::memcpy(p + ox, &c.points[i].x(), 4);
    std::memcpy(p + oy, &c.points[i].y(), 4);
    std::memcpy(p + oz, &c.points[i].z(), 4);
    if (in) std::memcpy(p + oi, &c.intensity[i], 4);
    if (rgb) {
      const std::uint32_t v = (std::uint32_t{c.rgb[i][0]} << 16) | (std::uint32_t{c.rgb[i][1]} << 8) | c.rgb[i][2];
      std::memcpy(p + orgb, &v, 4);
    }
    if (ring) std::memcpy(p + oring, &c.ring[i], 2);
    if (time) std::memcpy(p + ot, &c.time[i], 8);
  }
  return m;
}

}  // namespace

StatusOr<BagInfo> read_bag_info(const std::string& path) {
  return guarded(path, [&]() -> StatusOr<BagInfo> {
    std::unique_ptr<rosbag::Bag> bag;
    std::uint64_t bytes = 0;
    Status s = open_bag(path, bag, bytes);
    if (!s.ok()) return s;
    return bag_info(*bag, bytes);
  });
}

StatusOr<BagScans> read_bag(const std::string& path, const std::string& topic, const ReadOptions& options) {
  return guarded(path, [&]() -> StatusOr<BagScans> { return read_bag_impl(path, topic, options); });
}

Status write_bag(const std::string& path, const std::vector<BagScan>& scans, const std::string& topic) {
  quiet_library();
  if (topic.empty() || topic.front() != '/')
    return Status(ErrorCode::kInvalidArgument, "write_bag: topic must start with '/', got '" + topic + "'");
  const std::string tmp = temporary_path_for(path);
  try {
    {
      rosbag::Bag bag;
      bag.open(tmp, rosbag::bagmode::Write);
      bag.setCompression(rosbag::compression::Uncompressed);
      ros::Time last(0, 0);
      for (const BagScan& s : scans) {
        // a bag cannot hold time 0: a scan without a stamp is placed 1 s after the one before
        // (the first at 1 s), so that the bag's time order is the scans' order
        const bool stamped = s.stamp_sec != 0 || s.stamp_nsec != 0;
        const ros::Time t = stamped ? ros::Time(s.stamp_sec, s.stamp_nsec) : last + ros::Duration(1, 0);
        last = t;
        bag.write(topic, t, to_message(s, t));
      }
      bag.close();
    }
    return rename_file(tmp, path);
  } catch (const std::bad_alloc&) {
    remove_file_quietly(tmp);
    return out_of_memory(detail::msg(path, "out of memory writing the bag"));
  } catch (const std::exception& e) {
    remove_file_quietly(tmp);
    return io_error(detail::msg(path, std::string("cannot write the bag: ") + detail::printable(e.what(), 160)));
  }
}

#endif  // LEX3D_WITH_ROSBAG

}  // namespace lex3d::io
