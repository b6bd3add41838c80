// The ROS bag plugin liblex3d_rosbag.so: the only code of lex3d that includes a ROS header
// or calls the ROS libraries (rosbag_storage, roscpp_serialization, rostime, console_bridge).
// io loads it on the first bag it reads or writes (rosbag.cpp) and calls it through the C
// table of rosbag_plugin.h; every exception of the library is caught here and returned as
// a code and a message. Built when lex3d is configured with ROS bag support.

#ifdef LEX3D_WITH_ROSBAG

#include "io/rosbag_plugin.h"

#include <algorithm>
#include <cstring>
#include <exception>
#include <memory>
#include <new>
#include <string>
#include <vector>

#include <console_bridge/console.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/PointCloud2.h>

struct lex3d_bag {
  rosbag::Bag bag;
  std::vector<std::string> strings;  // the connections' texts, kept for the pointers below
  std::vector<lex3d_bag_connection> connections;
  std::vector<std::uint8_t> buffer;  // one message's bytes
};

namespace {

void set_error(lex3d_bag_error* err, const char* text) {
  if (err == nullptr) return;
  std::strncpy(err->text, text, sizeof err->text - 1);
  err->text[sizeof err->text - 1] = '\0';
}

/// Runs `fn`, turning every exception into a result code and a message.
template <typename Fn>
int guarded(lex3d_bag_error* err, Fn&& fn) noexcept {
  try {
    return fn();
  } catch (const std::bad_alloc&) {
    set_error(err, "out of memory");
    return LEX3D_BAG_NO_MEMORY;
  } catch (const std::length_error&) {
    set_error(err, "out of memory");
    return LEX3D_BAG_NO_MEMORY;
  } catch (const std::exception& e) {
    set_error(err, e.what());
    return LEX3D_BAG_ERROR;
  } catch (...) {
    set_error(err, "unknown exception");
    return LEX3D_BAG_ERROR;
  }
}

/// The library's own log lines (console_bridge) would break lex3d's one-line errors: off.
void quiet_library() {
  static const bool done = [] {
    console_bridge::setLogLevel(console_bridge::CONSOLE_BRIDGE_LOG_NONE);
    return true;
  }();
  (void)done;
}

int open_bag(const char* path, lex3d_bag** out, rosbag::bagmode::BagMode mode, lex3d_bag_error* err) {
  *out = nullptr;
  return guarded(err, [&] {
    quiet_library();
    auto b = std::make_unique<lex3d_bag>();
    b->bag.open(path, mode);
    if (mode == rosbag::bagmode::Write) b->bag.setCompression(rosbag::compression::Uncompressed);
    *out = b.release();
    return LEX3D_BAG_OK;
  });
}

int open_read(const char* path, lex3d_bag** bag, lex3d_bag_error* err) {
  return open_bag(path, bag, rosbag::bagmode::Read, err);
}

int open_write(const char* path, lex3d_bag** bag, lex3d_bag_error* err) {
  return open_bag(path, bag, rosbag::bagmode::Write, err);
}

int connections(lex3d_bag* b, const lex3d_bag_connection** list, size_t* count, lex3d_bag_error* err) {
  return guarded(err, [&] {
    if (b->connections.empty()) {
      rosbag::View all(b->bag);
      const auto cs = all.getConnections();
      b->strings.clear();
      b->strings.reserve(cs.size() * 3);  // no reallocation: the pointers below stay valid
      for (const rosbag::ConnectionInfo* c : cs) {
        b->strings.push_back(c->topic);
        b->strings.push_back(c->datatype);
        b->strings.push_back(c->md5sum);
      }
      for (std::size_t i = 0; i < cs.size(); ++i)
        b->connections.push_back({b->strings[3 * i].c_str(), b->strings[3 * i + 1].c_str(),
                                  b->strings[3 * i + 2].c_str()});
    }
    *list = b->connections.data();
    *count = b->connections.size();
    return LEX3D_BAG_OK;
  });
}

int count(lex3d_bag* b, const char* topic, uint64_t* messages, lex3d_bag_error* err) {
  return guarded(err, [&] {
    *messages = rosbag::View(b->bag, rosbag::TopicQuery(std::string(topic))).size();
    return LEX3D_BAG_OK;
  });
}

int time_range(lex3d_bag* b, lex3d_bag_time* begin, lex3d_bag_time* end, lex3d_bag_error* err) {
  return guarded(err, [&] {
    *begin = {0, 0};
    *end = {0, 0};
    rosbag::View all(b->bag);
    if (all.size() > 0) {
      const ros::Time t0 = all.getBeginTime(), t1 = all.getEndTime();
      *begin = {t0.sec, t0.nsec};
      *end = {t1.sec, t1.nsec};
    }
    return LEX3D_BAG_OK;
  });
}

int read_topic(lex3d_bag* b, const char* topic, lex3d_bag_message_fn fn, void* user, lex3d_bag_error* err) {
  return guarded(err, [&] {
    rosbag::View view(b->bag, rosbag::TopicQuery(std::string(topic)));
    for (const rosbag::MessageInstance& m : view) {
      const std::uint32_t n = m.size();
      b->buffer.resize(n);
      ros::serialization::OStream os(b->buffer.data(), n);
      m.write(os);
      if (fn(user, {m.getTime().sec, m.getTime().nsec}, b->buffer.data(), n) != 0) return LEX3D_BAG_STOPPED;
    }
    return LEX3D_BAG_OK;
  });
}

int write_pointcloud2(lex3d_bag* b, const char* topic, lex3d_bag_time time, const lex3d_bag_pointcloud2* msg,
                      lex3d_bag_error* err) {
  return guarded(err, [&] {
    sensor_msgs::PointCloud2 m;
    m.header.stamp = ros::Time(msg->stamp.sec, msg->stamp.nsec);
    m.header.frame_id = msg->frame_id;
    m.height = msg->height;
    m.width = msg->width;
    for (std::size_t i = 0; i < msg->field_count; ++i) {
      sensor_msgs::PointField f;
      f.name = msg->fields[i].name;
      f.offset = msg->fields[i].offset;
      f.datatype = msg->fields[i].datatype;
      f.count = msg->fields[i].count;
      m.fields.push_back(f);
    }
    m.is_bigendian = msg->is_bigendian != 0;
    m.point_step = msg->point_step;
    m.row_step = msg->row_step;
    m.data.assign(msg->data, msg->data + msg->data_size);
    m.is_dense = msg->is_dense != 0;
    b->bag.write(std::string(topic), ros::Time(time.sec, time.nsec), m);
    return LEX3D_BAG_OK;
  });
}

int close_bag(lex3d_bag* b, lex3d_bag_error* err) {
  if (b == nullptr) return LEX3D_BAG_OK;
  const std::unique_ptr<lex3d_bag> owned(b);
  return guarded(err, [&] {
    owned->bag.close();
    return LEX3D_BAG_OK;
  });
}

const lex3d_rosbag_plugin kTable = {
    LEX3D_ROSBAG_ABI,
    sizeof(lex3d_rosbag_plugin),
    ros::message_traits::MD5Sum<sensor_msgs::PointCloud2>::value(),
    open_read,
    open_write,
    connections,
    count,
    time_range,
    read_topic,
    write_pointcloud2,
    close_bag,
};

}  // namespace

extern "C" __attribute__((visibility("default"))) const lex3d_rosbag_plugin* lex3d_rosbag_plugin_v1() {
  return &kTable;
}

#endif  // LEX3D_WITH_ROSBAG
