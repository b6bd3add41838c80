// ROS 1 bags. The ROS bag library (rosbag_storage) is reached through the plugin
// liblex3d_rosbag.so (rosbag_plugin.cpp, rosbag_plugin.h), opened with dlopen on the first bag
// read or written, so that no lex3d program loads the ROS libraries before it needs them.
// The plugin finds the messages; their bytes are read here as serialized PointCloud2
// (pointcloud2.cpp) or Ouster packets (ouster.cpp), every length checked, rather than
// through sensor_msgs's generated deserializer, which trusts the lengths it reads. Bags are
// written by the plugin with sensor_msgs's generated PointCloud2 type, so the message
// definition and MD5 sum in the bag are ROS's own.

#include "lex3d/io/rosbag.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
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
#include <dlfcn.h>
#include <link.h>
#include <limits.h>
#include <stdlib.h>
#include <unistd.h>

#include <condition_variable>
#include <deque>
#include <mutex>
#include <optional>
#include <thread>

#include "io/rosbag_plugin.h"
#ifdef LEX3D_ROSBAG_BUILTIN
extern "C" const lex3d_rosbag_plugin* lex3d_rosbag_plugin_v1();
#endif
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
struct BagReader::Impl {};
BagReader::BagReader() = default;
BagReader::~BagReader() = default;
StatusOr<std::unique_ptr<BagReader>> BagReader::open(const std::string& path, const std::string&, const ReadOptions&) {
  return unsupported(path);
}
StatusOr<std::optional<BagScan>> BagReader::next() { return std::optional<BagScan>(); }
const BagScans& BagReader::summary() const {
  static const BagScans kNone;
  return kNone;
}
Status write_bag(const std::string& path, const std::vector<BagScan>&, const std::string&) { return unsupported(path); }
struct BagWriter::Impl {};
BagWriter::BagWriter() = default;
BagWriter::~BagWriter() = default;
StatusOr<std::unique_ptr<BagWriter>> BagWriter::open(const std::string& path, const std::string&) {
  return unsupported(path);
}
Status BagWriter::write(const BagScan&) { return Status(ErrorCode::kInvalidArgument, "no ROS bag support"); }
Status BagWriter::close() { return Status(ErrorCode::kInvalidArgument, "no ROS bag support"); }

#else

namespace {

// --- the plugin: found, opened and checked once a process, on the first bag ---

struct Plugin {
  const lex3d_rosbag_plugin* api = nullptr;
  std::string error;  ///< why there is none: "ROS bag support is not installed (...)"
};

#ifndef LEX3D_ROSBAG_BUILTIN
constexpr const char* kPluginFile = "liblex3d_rosbag.so";
// Where the plugin is installed, relative to the command's directory and absolute (CMake
// passes both from the install layout); the defaults are the GNU layout's.
#ifndef LEX3D_ROSBAG_PLUGIN_FROM_BINDIR
#define LEX3D_ROSBAG_PLUGIN_FROM_BINDIR "../lib/lex3d"
#endif
#ifndef LEX3D_ROSBAG_PLUGIN_INSTALL_DIR
#define LEX3D_ROSBAG_PLUGIN_INSTALL_DIR "/usr/local/lib/lex3d"
#endif

/// The file holding this code: liblex3d.so, the Python module, or the executable linking io.
std::string this_object_file() {
  Dl_info info{};
  link_map* map = nullptr;
  if (dladdr1(reinterpret_cast<void*>(&this_object_file), &info, reinterpret_cast<void**>(&map), RTLD_DL_LINKMAP) ==
      0)
    return {};
  // the executable's own entry has an empty name (dladdr would give argv[0])
  const std::string file =
      map != nullptr && map->l_name != nullptr && map->l_name[0] != '\0' ? map->l_name : "/proc/self/exe";
  char resolved[PATH_MAX];
  if (realpath(file.c_str(), resolved) == nullptr) return {};
  return resolved;
}

/// The files tried in order: $LEX3D_ROSBAG_PLUGIN alone when set; else beside the file
/// holding io (the build tree, an installed liblex3d.so's lib/, the Python package), in its
/// lex3d/ folder (lib/lex3d/ beside liblex3d.so), the install layout's plugin folder seen
/// from bin/ (the command, a program linking liblex3d.a installed beside it), the install
/// prefix's plugin folder, then the bare name (LD_LIBRARY_PATH, the caller's run path,
/// ld.so.cache).
std::vector<std::string> plugin_candidates() {
  const char* env = std::getenv("LEX3D_ROSBAG_PLUGIN");
  if (env != nullptr && *env != '\0') return {env};
  std::vector<std::string> c;
  const std::string self = this_object_file();
  const std::size_t slash = self.rfind('/');
  if (slash != std::string::npos) {
    const std::string dir = self.substr(0, slash + 1);
    c.push_back(dir + kPluginFile);
    c.push_back(dir + "lex3d/" + kPluginFile);
    c.push_back(dir + LEX3D_ROSBAG_PLUGIN_FROM_BINDIR "/" + kPluginFile);
  }
  c.push_back(std::string(LEX3D_ROSBAG_PLUGIN_INSTALL_DIR "/") + kPluginFile);
  c.push_back(kPluginFile);
  return c;
}

std::string dl_error() {
  const char* e = dlerror();
  return detail::printable(e != nullptr ? e : "unknown error", 200);
}

#endif  // LEX3D_ROSBAG_BUILTIN

Plugin load_plugin() {
  Plugin p;
#ifdef LEX3D_ROSBAG_BUILTIN  // the plugin's code linked in (the fuzz targets)
  p.api = lex3d_rosbag_plugin_v1();
  return p;
#else
  const char* named = std::getenv("LEX3D_ROSBAG_PLUGIN");
  for (const std::string& path : plugin_candidates()) {
    const bool bare = path.find('/') == std::string::npos;
    if (!bare && access(path.c_str(), F_OK) != 0) continue;
    void* handle = dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
    if (handle == nullptr) {
      const std::string why = dl_error();
      // the bare name not found anywhere: not installed; any other failure (a library the
      // plugin needs is missing) is reported as it is
      if (bare && why.rfind(path + ":", 0) == 0) break;
      p.error = "ROS bag support cannot be loaded (" + why + ")";
      return p;
    }
    auto entry = reinterpret_cast<lex3d_rosbag_entry_fn>(dlsym(handle, LEX3D_ROSBAG_ENTRY));
    const lex3d_rosbag_plugin* api = entry != nullptr ? entry() : nullptr;
    if (api == nullptr || api->abi != LEX3D_ROSBAG_ABI || api->table_size < sizeof(lex3d_rosbag_plugin)) {
      dlclose(handle);
      p.error = "ROS bag support cannot be loaded (" + detail::printable(path, 200) +
                " is not a ROS bag plugin of this lex3d: interface " +
                (api == nullptr ? std::string("missing") : std::to_string(api->abi)) + ", needed " +
                std::to_string(LEX3D_ROSBAG_ABI) + ")";
      return p;
    }
    p.api = api;  // never closed: the ROS libraries stay loaded for the process
    return p;
  }
  p.error = named != nullptr && *named != '\0'
                ? "ROS bag support is not installed (" + detail::printable(named, 200) +
                      ", named by LEX3D_ROSBAG_PLUGIN, not found)"
                : std::string("ROS bag support is not installed (") + kPluginFile + " not found)";
  return p;
#endif
}

const Plugin& plugin() {
  static const Plugin p = load_plugin();
  return p;
}

/// The plugin's table, or the one-line error naming `path`.
StatusOr<const lex3d_rosbag_plugin*> plugin_for(const std::string& path) {
  const Plugin& p = plugin();
  if (p.api == nullptr) return bad_data(detail::msg(path, p.error));
  return p.api;
}

/// A plugin's result as a Status: the library's refusal of a bag being read is bad data, of
/// one being written an I/O error.
Status plugin_status(const std::string& path, int rc, const lex3d_bag_error& err, bool writing) {
  const std::string text = detail::printable(err.text, 160);
  if (rc == LEX3D_BAG_NO_MEMORY)
    return out_of_memory(detail::msg(path, writing ? "out of memory writing the bag" : "out of memory reading the bag"));
  if (writing) return io_error(detail::msg(path, "cannot write the bag: " + text));
  return bad_data(detail::msg(path, "corrupt or truncated bag: " + text));
}

/// An open bag, closed when it goes out of scope.
class OpenBag {
 public:
  OpenBag(const lex3d_rosbag_plugin* api, lex3d_bag* bag) : api_(api), bag_(bag) {}
  OpenBag(const OpenBag&) = delete;
  OpenBag& operator=(const OpenBag&) = delete;
  ~OpenBag() {
    if (bag_ != nullptr) {
      lex3d_bag_error err{};
      (void)api_->close(bag_, &err);
    }
  }
  [[nodiscard]] const lex3d_rosbag_plugin& api() const { return *api_; }
  [[nodiscard]] lex3d_bag* get() const { return bag_; }
  /// Closes the bag (a written one: its index); the result of the plugin's close.
  int close(lex3d_bag_error& err) {
    if (bag_ == nullptr) return LEX3D_BAG_OK;
    lex3d_bag* b = bag_;
    bag_ = nullptr;
    return api_->close(b, &err);
  }

 private:
  const lex3d_rosbag_plugin* api_;
  lex3d_bag* bag_;
};

/// Calls `fn(time, bytes, size) -> Status` with each message of `topic`; the first non-ok
/// Status stops the reading and is returned. An exception of `fn` is caught before it
/// reaches the plugin and thrown again here.
template <typename Fn>
Status for_each_message(const std::string& path, OpenBag& bag, const std::string& topic, Fn&& fn) {
  struct Context {
    Fn* fn;
    Status status;
    std::exception_ptr failure;
  } ctx{&fn, {}, nullptr};
  lex3d_bag_error err{};
  const int rc = bag.api().read_topic(
      bag.get(), topic.c_str(),
      [](void* user, lex3d_bag_time t, const std::uint8_t* bytes, std::size_t size) -> int {
        auto& c = *static_cast<Context*>(user);
        try {
          c.status = (*c.fn)(t, bytes, size);
          return c.status.ok() ? 0 : 1;
        } catch (...) {
          c.failure = std::current_exception();
          return 1;
        }
      },
      &ctx, &err);
  if (ctx.failure) std::rethrow_exception(ctx.failure);
  if (rc == LEX3D_BAG_STOPPED) return ctx.status;
  if (rc != LEX3D_BAG_OK) return plugin_status(path, rc, err, false);
  return {};
}

constexpr const char* kPointCloud2 = "sensor_msgs/PointCloud2";

bool is_packet_type(const std::string& type) {
  return type == "ouster_ros/PacketMsg" || type == "ouster_sensor_msgs/PacketMsg";
}

/// velodyne_driver's recording of a Velodyne's packets (a scan's worth a message).
constexpr const char* kVelodyneScan = "velodyne_msgs/VelodyneScan";

/// A bag checked (check_bag_container) and opened; the library opens only a file that
/// passes (opening costs a few ms).
StatusOr<std::unique_ptr<OpenBag>> open_bag(const std::string& path, std::uint64_t& file_bytes) {
  auto api = plugin_for(path);
  if (!api.ok()) return api.status();
  {
    auto mapped = MappedFile::open(path);
    if (!mapped.ok()) return mapped.status();
    const MappedFile& f = *mapped.value();
    file_bytes = f.size();
    if (f.size() == 0) return bad_data(detail::msg(path, "file is empty"), 0);
    Status s = detail::check_bag_container(path, f.data(), f.size());
    if (!s.ok()) return s;
  }
  lex3d_bag* bag = nullptr;
  lex3d_bag_error err{};
  const int rc = api.value()->open_read(path.c_str(), &bag, &err);
  if (rc != LEX3D_BAG_OK) return plugin_status(path, rc, err, false);
  return std::make_unique<OpenBag>(api.value(), bag);
}

double seconds(lex3d_bag_time t) { return static_cast<double>(t.sec) + 1e-9 * static_cast<double>(t.nsec); }

std::string topic_list(const BagInfo& info) {
  std::string s;
  for (const auto& t : info.topics)
    s += (s.empty() ? "" : ", ") + t.name + " (" + t.type + ", " + std::to_string(t.messages) + ")";
  return s.empty() ? std::string("no topics") : s;
}

/// The topics of a bag, and (in `md5`) each topic's connections' MD5 sums.
StatusOr<BagInfo> bag_info(const std::string& path, OpenBag& bag, std::uint64_t file_bytes,
                           std::map<std::string, std::set<std::string>>* md5 = nullptr) {
  BagInfo info;
  info.file_bytes = file_bytes;
  lex3d_bag_error err{};
  const lex3d_bag_connection* list = nullptr;
  std::size_t n = 0;
  int rc = bag.api().connections(bag.get(), &list, &n, &err);
  if (rc != LEX3D_BAG_OK) return plugin_status(path, rc, err, false);
  std::map<std::string, std::set<std::string>> types;
  for (std::size_t i = 0; i < n; ++i) {
    types[list[i].topic].insert(list[i].datatype);
    if (md5 != nullptr) (*md5)[list[i].topic].insert(list[i].md5sum);
  }
  for (const auto& [topic, ts] : types) {
    BagTopic t;
    t.name = detail::printable(topic, 256);  // names as they appear in messages: one line
    for (const auto& ty : ts) t.type += (t.type.empty() ? "" : " | ") + detail::printable(ty, 256);
    rc = bag.api().count(bag.get(), topic.c_str(), &t.messages, &err);
    if (rc != LEX3D_BAG_OK) return plugin_status(path, rc, err, false);
    info.messages += t.messages;
    info.topics.push_back(std::move(t));
  }
  if (info.messages > 0) {
    lex3d_bag_time begin{}, end{};
    rc = bag.api().time_range(bag.get(), &begin, &end, &err);
    if (rc != LEX3D_BAG_OK) return plugin_status(path, rc, err, false);
    info.start_s = seconds(begin);
    info.end_s = seconds(end);
  }
  return info;
}

void add_unique(std::vector<std::string>& list, const std::string& s) {
  if (std::find(list.begin(), list.end(), s) == list.end()) list.push_back(s);
}

/// A message's stamp and frame, as a scan keeps them (Cloud::stamp).
ScanStamp message_stamp(const BagScan& scan) {
  ScanStamp s;
  s.source = ScanStamp::Source::kMessage;
  s.sec = scan.stamp_sec;
  s.nsec = scan.stamp_nsec;
  s.frame_id = scan.frame_id;
  return s;
}

/// A topic's scans, made from its messages one at a time (BagReader's producer side).
class TopicScans {
 public:
  virtual ~TopicScans() = default;
  /// One message of the topic (bag time `t`): the scans it completes go to `out`.
  virtual Status message(lex3d_bag_time t, const std::uint8_t* bytes, std::size_t size, std::vector<BagScan>& out) = 0;
  /// The topic's end: its last scans, and `summary` completed.
  virtual Status finish(std::vector<BagScan>& out) = 0;
  BagScans summary;  ///< the topic, its type and what reading dropped (no scans)
};

/// sensor_msgs/PointCloud2: a scan a message, stamped with its header's stamp (else its bag time).
class CloudScans final : public TopicScans {
 public:
  CloudScans(std::string path, std::string topic) : path_(std::move(path)), topic_(std::move(topic)) {}
  Status message(lex3d_bag_time t, const std::uint8_t* bytes, std::size_t size, std::vector<BagScan>& out) override {
    const std::string where = detail::msg(path_, "message " + std::to_string(k_) + " on " + topic_);
    detail::PointCloud2Msg pm;
    Status s = detail::parse_pointcloud2(where, bytes, size, pm);
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
      scan.stamp_sec = t.sec;
      scan.stamp_nsec = t.nsec;
    }
    scan.cloud.stamp = message_stamp(scan);
    summary.non_finite_dropped += r.non_finite_dropped;
    summary.no_return_dropped += r.no_return_dropped;
    for (const auto& f : r.dropped_fields) add_unique(summary.dropped_fields, f);
    for (const auto& n : r.notes) add_unique(summary.notes, n);
    out.push_back(std::move(scan));
    ++k_;
    return {};
  }
  Status finish(std::vector<BagScan>&) override { return {}; }

 private:
  std::string path_, topic_;
  std::size_t k_ = 0;
};

/// Packets (Ouster's, Velodyne's) through a capture's decoder: a scan a turn, stamped with
/// the time of its first packet (`Datagram::captured_ns`: an Ouster packet message's bag
/// time, a Velodyne packet's own stamp), framed `frame_id`.
class PacketScans : public TopicScans {
 public:
  PacketScans(std::string path, std::string topic, ReadOptions options, std::string skipped)
      : path_(std::move(path)), topic_(std::move(topic)), options_(std::move(options)), skipped_(std::move(skipped)) {}
  Status finish(std::vector<BagScan>& out) override {
    Status s = decoder_->finish();
    if (!s.ok()) return s;
    turns(out);
    if (options_.single_return && info_.second_returns > 0)
      summary.notes.push_back(std::to_string(info_.second_returns) + " second returns not kept (single return)");
    summary.sensor = info_.sensor;
    summary.incomplete_frames = info_.incomplete_frames;
    summary.no_return_dropped = info_.no_returns;
    if (info_.other_packets > 0)
      summary.notes.push_back(std::to_string(info_.other_packets) + " " + skipped_ + ": skipped");
    if (info_.frames == 0) return no_turn();
    return {};
  }

 protected:
  /// The decoder's finished turns as scans.
  void turns(std::vector<BagScan>& out) {
    for (SensorTurn& t : decoder_->turns) {
      BagScan scan;
      scan.cloud = std::move(t.cloud);
      if (options_.single_return) detail::drop_second_returns(scan.cloud);
      scan.stamp_sec = static_cast<std::uint32_t>(t.captured_ns / 1000000000ULL);
      scan.stamp_nsec = static_cast<std::uint32_t>(t.captured_ns % 1000000000ULL);
      scan.frame_id = frame_id_;
      scan.cloud.stamp = message_stamp(scan);
      out.push_back(std::move(scan));
    }
    decoder_->turns.clear();
  }
  Status push(const detail::Datagram& d, std::vector<BagScan>& out) {
    Status s = decoder_->push(d);
    if (!s.ok()) return s;
    turns(out);
    return {};
  }
  [[nodiscard]] virtual Status no_turn() const { return {}; }

  std::string path_, topic_;
  ReadOptions options_;
  std::string skipped_;
  SensorLogInfo info_;
  std::unique_ptr<detail::LogDecoder> decoder_;
  std::string frame_id_;
  std::size_t k_ = 0;  // messages so far
};

/// Ouster packets (ouster_ros/PacketMsg: a uint8[] each), with the bag's metadata.
class OusterScans final : public PacketScans {
 public:
  OusterScans(std::string path, std::string topic, ReadOptions options)
      : PacketScans(std::move(path), topic, std::move(options),
                    "messages on " + topic + " are not lidar packets of the metadata's size") {}
  Status start(const std::string& metadata_name, const std::vector<std::uint8_t>& metadata) {
    auto d = detail::ouster_decoder(path_, metadata_name, metadata, true, info_, topic_);
    if (!d.ok()) return d.status();
    decoder_ = std::move(d).value();
    return {};
  }
  Status message(lex3d_bag_time t, const std::uint8_t* bytes, std::size_t size, std::vector<BagScan>& out) override {
    ++k_;
    const std::uint8_t* b = nullptr;
    std::size_t n = 0;
    if (!detail::parse_byte_array(bytes, size, b, n))
      return bad_data(detail::msg(path_, "message " + std::to_string(k_) + " on " + topic_ + ": a truncated packet message"));
    detail::Datagram d;
    d.record = k_;
    d.captured_ns = static_cast<std::uint64_t>(t.sec) * 1000000000ULL + t.nsec;
    d.payload.assign(b, b + n);
    return push(d, out);
  }

 private:
  [[nodiscard]] Status no_turn() const override {
    return bad_data(detail::msg(path_, "topic " + topic_ + ": no complete frame (" + std::to_string(info_.lidar_packets) +
                                           " packets, " + std::to_string(info_.incomplete_frames) +
                                           " incomplete frame(s) dropped)"));
  }
};

/// The data packets of a topic of velodyne_msgs/VelodyneScan (ROS 1 serialization: a
/// std_msgs/Header, u32 seq, time stamp, string frame_id; then a u32 count of
/// velodyne_msgs/VelodynePacket, each a time stamp and 1206 bytes), decoded as a capture of
/// them is, each turn stamped with its first packet's stamp and framed as the first message.
/// The calibration (`--metadata`, required for an HDL-64E) and the model (`--sensor-model`)
/// as for a capture.
class VelodyneScans final : public PacketScans {
 public:
  VelodyneScans(std::string path, std::string topic, ReadOptions options)
      : PacketScans(path, topic, options, "packets on " + topic + " are not Velodyne data packets") {
    decoder_ = detail::velodyne_decoder(path_, options_.sensor_model, options_.metadata_path, info_);
  }
  Status message(lex3d_bag_time, const std::uint8_t* b, std::size_t n, std::vector<BagScan>& out) override {
    constexpr std::size_t kPacket = 1206, kStamped = 8 + kPacket;
    ++k_;
    const auto truncated = [&](const std::string& what) {
      return bad_data(detail::msg(path_, "message " + std::to_string(k_) + " on " + topic_ +
                                             ": a truncated velodyne_msgs/VelodyneScan (" + what + ")"));
    };
    if (n < 16) return truncated("its header");
    std::uint32_t frame_bytes = 0, count = 0;
    std::memcpy(&frame_bytes, b + 12, 4);
    if (frame_bytes > n - 16) return truncated("its frame_id");
    if (k_ == 1) frame_id_.assign(reinterpret_cast<const char*>(b + 16), frame_bytes);
    std::size_t at = 16 + static_cast<std::size_t>(frame_bytes);
    if (n - at < 4) return truncated("its packet count");
    std::memcpy(&count, b + at, 4);
    at += 4;
    if (count > (n - at) / kStamped)
      return truncated(std::to_string(count) + " packets announced, " + std::to_string((n - at) / kStamped) + " held");
    for (std::uint32_t i = 0; i < count; ++i, at += kStamped) {
      std::uint32_t sec = 0, nsec = 0;
      std::memcpy(&sec, b + at, 4);
      std::memcpy(&nsec, b + at + 4, 4);
      detail::Datagram d;
      d.record = k_;
      d.captured_ns = static_cast<std::uint64_t>(sec) * 1000000000ULL + nsec;
      d.claimed = kPacket;
      d.payload.assign(b + at + 8, b + at + kStamped);
      Status s = push(d, out);
      if (!s.ok()) return s;
    }
    return {};
  }
};

/// The bag's Ouster metadata for a packet topic: the JSON given, else the first message of a
/// std_msgs/String topic named ".../metadata" (or of its only String topic).
Status ouster_metadata(const std::string& path, OpenBag& bag, const BagInfo& info, const BagTopic& topic,
                       const ReadOptions& options, std::string& metadata_name, std::vector<std::uint8_t>& metadata) {
  metadata_name = options.metadata_path;
  if (!metadata_name.empty()) {
    auto text = read_file(metadata_name, 64ULL << 20);
    if (!text.ok()) return text.status();
    metadata = std::move(text).value();
    return {};
  }
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
  bool got = false;  // the first message
  Status s = for_each_message(path, bag, meta->name, [&](lex3d_bag_time, const std::uint8_t* bytes, std::size_t size) {
    if (got) return Status{};
    got = true;
    const std::uint8_t* b = nullptr;
    std::size_t n = 0;
    if (!detail::parse_byte_array(bytes, size, b, n))
      return bad_data(detail::msg(path, "topic " + meta->name + ": a truncated std_msgs/String"));
    metadata.assign(b, b + n);
    return Status{};
  });
  if (!s.ok()) return s;
  metadata_name = path + " topic " + meta->name;
  return {};
}

/// The topic `topic` names (empty: the bag's only PointCloud2 topic, else its only packet
/// topic) and the producer of its scans.
StatusOr<std::unique_ptr<TopicScans>> topic_scans(const std::string& path, OpenBag& bag, const std::string& topic,
                                                  const ReadOptions& options) {
  std::uint64_t bytes = 0;
  std::map<std::string, std::set<std::string>> md5;
  auto listed = bag_info(path, bag, bytes, &md5);
  if (!listed.ok()) return listed.status();
  const BagInfo& info = listed.value();
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
      if ((is_packet_type(t.type) && t.name.find("imu") == std::string::npos) || t.type == kVelodyneScan)
        packets.push_back(&t);
    }
    if (clouds.size() == 1) chosen = clouds.front();
    else if (clouds.empty() && packets.size() == 1) chosen = packets.front();
    else
      return bad_data(detail::msg(path, std::string(clouds.size() + packets.size() == 0 ? "no point cloud topic"
                                                                                       : "several point cloud topics") +
                                            " (give one with --topic); the bag holds " + topic_list(info)));
  }
  std::unique_ptr<TopicScans> out;
  if (chosen->type == kPointCloud2) {
    const std::string expected = bag.api().pointcloud2_md5;
    for (const std::string& m : md5[chosen->name])
      if (m != expected)
        return bad_data(detail::msg(path, "topic " + chosen->name + ": a PointCloud2 of another definition (MD5 " +
                                              detail::printable(m, 40) + ")"));
    out = std::make_unique<CloudScans>(path, chosen->name);
  } else if (is_packet_type(chosen->type)) {
    std::string metadata_name;
    std::vector<std::uint8_t> metadata;
    Status s = ouster_metadata(path, bag, info, *chosen, options, metadata_name, metadata);
    if (!s.ok()) return s;
    auto o = std::make_unique<OusterScans>(path, chosen->name, options);
    s = o->start(metadata_name, metadata);
    if (!s.ok()) return s;
    out = std::move(o);
  } else if (chosen->type == kVelodyneScan) {
    out = std::make_unique<VelodyneScans>(path, chosen->name, options);
  } else {
    return bad_data(detail::msg(path, "topic " + chosen->name + " holds " + chosen->type +
                                          " messages; lex3d reads sensor_msgs/PointCloud2, Ouster packets "
                                          "(ouster_ros/PacketMsg) and Velodyne packets (velodyne_msgs/VelodyneScan)"));
  }
  out->summary.topic = chosen->name;
  out->summary.type = chosen->type;
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
    return bad_data(detail::msg(path, "corrupt or truncated bag: " + detail::printable(e.what(), 160)));
  }
}

/// PointField datatypes.
constexpr std::uint8_t kU16 = 4, kI32 = 5, kF32 = 7, kF64 = 8;

/// A PointCloud2 message to write: the plugin's view of it (`view()`) points into it.
struct Message {
  lex3d_bag_time stamp{};
  std::string frame_id;
  std::vector<lex3d_bag_point_field> fields;
  std::vector<std::string> names;  // of the named fields, which `fields` point to (reserved, never grown)
  std::uint32_t height = 0, width = 0, point_step = 0, row_step = 0;
  bool is_dense = false;
  std::vector<std::uint8_t> data;

  [[nodiscard]] lex3d_bag_pointcloud2 view() const {
    lex3d_bag_pointcloud2 v{};
    v.stamp = stamp;
    v.frame_id = frame_id.c_str();
    v.height = height;
    v.width = width;
    v.fields = fields.data();
    v.field_count = fields.size();
    v.is_bigendian = 0;
    v.point_step = point_step;
    v.row_step = row_step;
    v.data = data.data();
    v.data_size = data.size();
    v.is_dense = is_dense ? 1 : 0;
    return v;
  }
};

Message to_message(const BagScan& scan, lex3d_bag_time stamp) {
  const Cloud& c = scan.cloud;
  Message m;
  m.stamp = stamp;
  m.frame_id = scan.frame_id.empty() && c.stamp ? c.stamp->frame_id : scan.frame_id;
  std::uint32_t step = 0;
  auto field = [&](const char* name, std::uint8_t type, std::uint32_t size) {
    m.fields.push_back({name, step, type, 1});
    step += size;
    return m.fields.back().offset;
  };
  const std::uint32_t ox = field("x", kF32, 4), oy = field("y", kF32, 4), oz = field("z", kF32, 4);
  const bool in = c.has_intensity(), ring = c.has_rings(), time = c.has_time(), rgb = c.has_rgb();
  // the ring, intensity and time in their sources' names and types where given
  const detail::SourceColumns sc = detail::source_columns(c);
  m.names.reserve(c.fields.size() + 4);
  // (PointCloud2's datatypes number the types as FieldType does; a field whose type is not
  // recorded is an INT32)
  const auto typed = [&](const IntegerField& f) {
    m.names.push_back(f.name);
    const std::uint8_t type = f.type == FieldType::kUnspecified ? kI32 : static_cast<std::uint8_t>(f.type);
    return field(m.names.back().c_str(), type, detail::field_bytes(f.type));
  };
  const std::uint32_t oi = !in ? 0 : sc.intensity ? typed(*sc.intensity) : field("intensity", kF32, 4);
  const std::uint32_t orgb = rgb ? field("rgb", kF32, 4) : 0;
  const std::uint32_t oring = !ring ? 0 : sc.ring ? typed(*sc.ring) : field("ring", kU16, 2);
  if (!sc.time) step = (step + 7U) & ~7U;  // the double time aligned (as before typed times)
  std::uint32_t ot = 0;
  if (time && sc.time) {
    ot = typed(*sc.time);
  } else if (time) {
    m.names.push_back(sc.time_name);
    ot = field(m.names.back().c_str(), kF64, 8);
  }
  // named fields (Cloud::fields), each in its type
  std::vector<std::uint32_t> onamed;
  for (const IntegerField& f : c.fields) onamed.push_back(typed(f));
  m.point_step = step;
  // organised: every point has a distinct pixel (row, column) of the shape
  std::vector<std::size_t> pixel;  // point -> pixel
  const std::vector<std::int64_t> at = pixel_points(c);
  const bool organised = !at.empty();
  if (organised) {
    pixel.resize(c.size());
    for (std::size_t px = 0; px < at.size(); ++px)
      if (at[px] >= 0) pixel[static_cast<std::size_t>(at[px])] = px;
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
    if (in && sc.intensity) detail::store_field(p + oi, *sc.intensity, i);
    else if (in) std::memcpy(p + oi, &c.intensity[i], 4);
    if (rgb) {
      const std::uint32_t v = (std::uint32_t{c.rgb[i][0]} << 16) | (std::uint32_t{c.rgb[i][1]} << 8) | c.rgb[i][2];
      std::memcpy(p + orgb, &v, 4);
    }
    if (ring && sc.ring) detail::store_field(p + oring, *sc.ring, i);
    else if (ring) std::memcpy(p + oring, &c.ring[i], 2);
    if (time && sc.time) detail::store_field(p + ot, *sc.time, i);
    else if (time) std::memcpy(p + ot, &c.time[i], 8);
    for (std::size_t k = 0; k < c.fields.size(); ++k) detail::store_field(p + onamed[k], c.fields[k], i);
  }
  return m;
}

}  // namespace

bool rosbag_supported() noexcept {
  try {
    return plugin().api != nullptr;
  } catch (...) {
    return false;
  }
}

StatusOr<BagInfo> read_bag_info(const std::string& path) {
  return guarded(path, [&]() -> StatusOr<BagInfo> {
    std::uint64_t bytes = 0;
    auto bag = open_bag(path, bytes);
    if (!bag.ok()) return bag.status();
    return bag_info(path, *bag.value(), bytes);
  });
}

/// The scans of one topic, made on a thread of their own a few ahead of their reader
/// (for_each_message hands the messages over one at a time, in a callback).
struct BagReader::Impl {
  static constexpr std::size_t kAhead = 2;  // scans made before the reader takes them
  std::string path;
  std::unique_ptr<OpenBag> bag;
  std::unique_ptr<TopicScans> topic;
  std::string topic_name;
  std::thread worker;
  std::mutex m;
  std::condition_variable cv;
  std::deque<BagScan> ready;
  bool done = false, stop = false;
  Status error;
  BagScans summary;
  std::size_t given = 0;

  ~Impl() {
    {
      const std::lock_guard<std::mutex> lock(m);
      stop = true;
    }
    cv.notify_all();
    if (worker.joinable()) worker.join();
  }

  /// Hands `made` to the reader, waiting while kAhead scans wait for it; not ok when the
  /// reader is gone.
  Status deliver(std::vector<BagScan>& made) {
    for (BagScan& scan : made) {
      std::unique_lock<std::mutex> lock(m);
      cv.wait(lock, [&] { return ready.size() < kAhead || stop; });
      if (stop) return bad_data("stopped");
      ready.push_back(std::move(scan));
      cv.notify_all();
    }
    made.clear();
    return {};
  }

  void run() {
    const Status s = guarded(path, [&]() -> Status {
      std::vector<BagScan> made;
      Status r = for_each_message(path, *bag, topic_name, [&](lex3d_bag_time t, const std::uint8_t* bytes, std::size_t size) {
        Status st = topic->message(t, bytes, size, made);
        return st.ok() ? deliver(made) : st;
      });
      if (!r.ok()) return r;
      r = topic->finish(made);
      return r.ok() ? deliver(made) : r;
    });
    const std::lock_guard<std::mutex> lock(m);
    if (!stop) error = s;
    summary = std::move(topic->summary);
    done = true;
    cv.notify_all();
  }

  StatusOr<std::optional<BagScan>> next() {
    std::unique_lock<std::mutex> lock(m);
    cv.wait(lock, [&] { return !ready.empty() || done; });
    if (!ready.empty()) {
      BagScan scan = std::move(ready.front());
      ready.pop_front();
      ++given;
      cv.notify_all();
      return std::optional<BagScan>(std::move(scan));
    }
    if (!error.ok()) return error;
    if (given == 0) return bad_data(detail::msg(path, "topic " + topic_name + " holds no message"));
    return std::optional<BagScan>();
  }
};

BagReader::BagReader() : impl_(std::make_unique<Impl>()) {}
BagReader::~BagReader() = default;

StatusOr<std::unique_ptr<BagReader>> BagReader::open(const std::string& path, const std::string& topic,
                                                     const ReadOptions& options) {
  return guarded(path, [&]() -> StatusOr<std::unique_ptr<BagReader>> {
    std::unique_ptr<BagReader> r(new BagReader());
    Impl& impl = *r->impl_;
    impl.path = path;
    std::uint64_t bytes = 0;
    auto opened = open_bag(path, bytes);
    if (!opened.ok()) return opened.status();
    impl.bag = std::move(opened).value();
    auto scans = topic_scans(path, *impl.bag, topic, options);
    if (!scans.ok()) return scans.status();
    impl.topic = std::move(scans).value();
    impl.topic_name = impl.topic->summary.topic;
    impl.summary.topic = impl.topic->summary.topic;
    impl.summary.type = impl.topic->summary.type;
    impl.worker = std::thread([&impl] { impl.run(); });
    return r;
  });
}

StatusOr<std::optional<BagScan>> BagReader::next() { return impl_->next(); }

const BagScans& BagReader::summary() const {
  const std::lock_guard<std::mutex> lock(impl_->m);
  return impl_->summary;
}

StatusOr<BagScans> read_bag(const std::string& path, const std::string& topic, const ReadOptions& options) {
  auto reader = BagReader::open(path, topic, options);
  if (!reader.ok()) return reader.status();
  std::vector<BagScan> scans;
  for (;;) {
    auto scan = reader.value()->next();
    if (!scan.ok()) return scan.status();
    if (!scan.value()) break;
    scans.push_back(std::move(*scan.value()));
  }
  BagScans out = reader.value()->summary();
  out.scans = std::move(scans);
  return out;
}

/// A bag being written to its temporary file; renamed over `path` by close().
struct BagWriter::Impl {
  std::string path, tmp, topic;
  std::unique_ptr<OpenBag> bag;
  std::uint64_t last_sec = 0, last_nsec = 0;  // the scan before's bag time
  bool closed = false;

  ~Impl() { abandon(); }
  /// The bag closed (already closed where its close failed) and its partial file removed.
  void abandon() {
    if (closed || !bag) return;
    lex3d_bag_error ignored{};
    (void)bag->close(ignored);
    remove_file_quietly(tmp);
    closed = true;
  }
  /// A failed write or close: the writer abandoned, the plugin's error.
  Status fail(int rc, const lex3d_bag_error& err) {
    abandon();
    return plugin_status(path, rc, err, true);
  }
};

BagWriter::BagWriter() : impl_(std::make_unique<Impl>()) {}
BagWriter::~BagWriter() = default;

StatusOr<std::unique_ptr<BagWriter>> BagWriter::open(const std::string& path, const std::string& topic) {
  if (topic.empty() || topic.front() != '/')
    return Status(ErrorCode::kInvalidArgument, "write_bag: topic must start with '/', got '" + topic + "'");
  auto api = plugin_for(path);
  if (!api.ok()) return api.status();
  std::unique_ptr<BagWriter> w(new BagWriter());
  Impl& impl = *w->impl_;
  impl.path = path;
  impl.topic = topic;
  impl.tmp = temporary_path_for(path);
  lex3d_bag* opened = nullptr;
  lex3d_bag_error err{};
  const int rc = api.value()->open_write(impl.tmp.c_str(), &opened, &err);
  if (rc != LEX3D_BAG_OK) {
    remove_file_quietly(impl.tmp);
    impl.closed = true;
    return plugin_status(path, rc, err, true);
  }
  impl.bag = std::make_unique<OpenBag>(api.value(), opened);
  return w;
}

Status BagWriter::write(const BagScan& scan) {
  Impl& impl = *impl_;
  if (impl.closed) return Status(ErrorCode::kInvalidArgument, detail::msg(impl.path, "the bag is closed"));
  if (Status s = detail::check_fields(impl.path, scan.cloud); !s.ok()) return s;
  try {
    // The scan's bag time: its stamp (the BagScan's, else its cloud's); a bag cannot hold
    // time 0, so a scan without one is placed 1 s after the one before (the first at 1 s).
    constexpr std::uint64_t kNs = 1000000000ULL;
    std::uint64_t sec = impl.last_sec + 1, nsec = impl.last_nsec;
    if (scan.stamp_sec != 0 || scan.stamp_nsec != 0) {
      sec = std::uint64_t{scan.stamp_sec} + scan.stamp_nsec / kNs;
      nsec = scan.stamp_nsec % kNs;
    } else if (scan.cloud.stamp && (scan.cloud.stamp->sec != 0 || scan.cloud.stamp->nsec != 0)) {
      sec = scan.cloud.stamp->sec + scan.cloud.stamp->nsec / kNs;
      nsec = scan.cloud.stamp->nsec % kNs;
    }
    if (sec > 0xFFFFFFFFULL) {
      impl.abandon();
      return io_error(detail::msg(impl.path, "cannot write the bag: a scan's time is beyond ROS time's range"));
    }
    const lex3d_bag_time t{static_cast<std::uint32_t>(sec), static_cast<std::uint32_t>(nsec)};
    impl.last_sec = sec;
    impl.last_nsec = nsec;
    const Message m = to_message(scan, t);
    const lex3d_bag_pointcloud2 v = m.view();
    lex3d_bag_error err{};
    const int rc = impl.bag->api().write_pointcloud2(impl.bag->get(), impl.topic.c_str(), t, &v, &err);
    if (rc != LEX3D_BAG_OK) return impl.fail(rc, err);
    return {};
  } catch (const std::bad_alloc&) {
    return out_of_memory(detail::msg(impl.path, "out of memory writing the bag"));
  } catch (const std::length_error&) {
    return out_of_memory(detail::msg(impl.path, "out of memory writing the bag"));
  }
}

Status BagWriter::close() {
  Impl& impl = *impl_;
  if (impl.closed) return Status(ErrorCode::kInvalidArgument, detail::msg(impl.path, "the bag is closed"));
  lex3d_bag_error err{};
  const int rc = impl.bag->close(err);
  if (rc != LEX3D_BAG_OK) return impl.fail(rc, err);
  impl.closed = true;
  return rename_file(impl.tmp, impl.path);
}

Status write_bag(const std::string& path, const std::vector<BagScan>& scans, const std::string& topic) {
  if (topic.empty() || topic.front() != '/')
    return Status(ErrorCode::kInvalidArgument, "write_bag: topic must start with '/', got '" + topic + "'");
  for (const BagScan& scan : scans)
    if (Status s = detail::check_fields(path, scan.cloud); !s.ok()) return s;
  auto w = BagWriter::open(path, topic);
  if (!w.ok()) return w.status();
  for (const BagScan& scan : scans)
    if (Status s = w.value()->write(scan); !s.ok()) return s;
  return w.value()->close();
}

#endif  // LEX3D_WITH_ROSBAG

}  // namespace lex3d::io
