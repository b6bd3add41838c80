// ROS bags (io/rosbag.hpp): bags written with the ROS bag library hold known clouds that
// must come back field by field; malformed messages, missing topics, truncated and
// corrupt bags are refused with one line naming the file; the shared Ouster bag (raw
// packets and metadata) decodes to its 128 x 512 frame when ../shared/data is present.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include <random>

#include <dlfcn.h>

#include "bag_fixtures.hpp"
#include "io/rosbag_internal.hpp"
#include "io/rosbag_plugin.h"
#include "io/sensor_log_internal.hpp"
#include "lex3d/io/sensor_log.hpp"
#include "lex3d/io/io.hpp"
#include "lex3d/io/rosbag.hpp"
#include "test_config.hpp"

namespace fs = std::filesystem;
using namespace lex3d;

namespace {

std::string temp_dir() {
  const fs::path d = fs::temp_directory_path() / ("lex3d_test_rosbag_" + std::to_string(::getpid()));
  fs::create_directories(d);
  return d.string();
}

std::vector<char> slurp(const std::string& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

void spit(const std::string& p, const std::vector<char>& b, std::size_t n) {
  std::ofstream out(p, std::ios::binary | std::ios::trunc);
  out.write(b.data(), static_cast<std::streamsize>(n));
}

class Bags : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { dir_ = temp_dir(); }
  static void TearDownTestSuite() { fs::remove_all(dir_); }
  static std::string path(const std::string& name) { return dir_ + "/" + name; }
  static std::string dir_;
};
std::string Bags::dir_;

}  // namespace

TEST_F(Bags, SupportIsBuilt) { EXPECT_TRUE(io::rosbag_supported()); }

// The plugin's C table (io/rosbag_plugin.h) directly: its interface version, the library's
// refusals turned into a code and a message (no exception crosses it), a callback that stops
// the reading, and messages handed over in bag order with their times.
TEST_F(Bags, PluginTableReturnsCodesNotExceptions) {
  void* handle = dlopen("liblex3d_rosbag.so", RTLD_NOW | RTLD_LOCAL);  // the build tree's (run path)
  ASSERT_NE(handle, nullptr) << dlerror();
  auto entry = reinterpret_cast<lex3d_rosbag_entry_fn>(dlsym(handle, LEX3D_ROSBAG_ENTRY));
  ASSERT_NE(entry, nullptr);
  const lex3d_rosbag_plugin* api = entry();
  ASSERT_NE(api, nullptr);
  EXPECT_EQ(api->abi, LEX3D_ROSBAG_ABI);
  EXPECT_EQ(api->table_size, sizeof(lex3d_rosbag_plugin));
  EXPECT_EQ(std::string(api->pointcloud2_md5), ros::message_traits::MD5Sum<sensor_msgs::PointCloud2>::value());

  lex3d_bag* bag = nullptr;
  lex3d_bag_error err{};
  EXPECT_EQ(api->open_read(path("absent.bag").c_str(), &bag, &err), LEX3D_BAG_ERROR);
  EXPECT_EQ(bag, nullptr);
  EXPECT_GT(std::strlen(err.text), 0U);
  err = {};
  EXPECT_EQ(api->open_write((dir_ + "/no_such_dir/out.bag").c_str(), &bag, &err), LEX3D_BAG_ERROR);
  EXPECT_GT(std::strlen(err.text), 0U);

  const std::string p = path("plugin_table.bag");
  bagfix::write(p, "/points", {bagfix::driver_cloud(1700000000, 100), bagfix::driver_cloud(1700000001, 200),
                               bagfix::driver_cloud(1700000002, 300)});
  ASSERT_EQ(api->open_read(p.c_str(), &bag, &err), LEX3D_BAG_OK) << err.text;
  const lex3d_bag_connection* list = nullptr;
  std::size_t n = 0;
  ASSERT_EQ(api->connections(bag, &list, &n, &err), LEX3D_BAG_OK);
  std::vector<std::string> topics;
  for (std::size_t i = 0; i < n; ++i) topics.emplace_back(list[i].topic);
  EXPECT_NE(std::find(topics.begin(), topics.end(), "/points"), topics.end());
  std::uint64_t count = 0;
  ASSERT_EQ(api->count(bag, "/points", &count, &err), LEX3D_BAG_OK);
  EXPECT_EQ(count, 3U);
  struct Seen {
    std::vector<std::uint32_t> sec;
    std::size_t stop_after = 0;
  } seen;
  auto collect = [](void* user, lex3d_bag_time t, const std::uint8_t*, std::size_t size) -> int {
    auto& s = *static_cast<Seen*>(user);
    if (size > 0) s.sec.push_back(t.sec);
    return s.sec.size() == s.stop_after ? 1 : 0;
  };
  ASSERT_EQ(api->read_topic(bag, "/points", collect, &seen, &err), LEX3D_BAG_OK);
  EXPECT_EQ(seen.sec, (std::vector<std::uint32_t>{1700000000, 1700000001, 1700000002}));  // bag times
  seen = {{}, 2};
  EXPECT_EQ(api->read_topic(bag, "/points", collect, &seen, &err), LEX3D_BAG_STOPPED);
  EXPECT_EQ(seen.sec.size(), 2U);
  EXPECT_EQ(api->close(bag, &err), LEX3D_BAG_OK);
  EXPECT_EQ(api->close(nullptr, &err), LEX3D_BAG_OK);
}

TEST_F(Bags, DriverCloudFieldsAreKeptAndOthersReported) {
  const std::string p = path("driver.bag");
  bagfix::write(p, "/points", {bagfix::driver_cloud(), bagfix::driver_cloud(1700000000, 350000000)});
  EXPECT_TRUE(io::is_rosbag(p));
  auto info = io::read_bag_info(p);
  ASSERT_TRUE(info.ok()) << info.status().to_string();
  ASSERT_EQ(info.value().topics.size(), 2U);
  EXPECT_EQ(info.value().topics[1].name, "/points");
  EXPECT_EQ(info.value().topics[1].type, "sensor_msgs/PointCloud2");
  EXPECT_EQ(info.value().topics[1].messages, 2U);
  EXPECT_EQ(info.value().topics[0].name, "/note");

  auto r = io::read_bag(p, "");  // the only PointCloud2 topic
  ASSERT_TRUE(r.ok()) << r.status().to_string();
  const io::BagScans& b = r.value();
  EXPECT_EQ(b.topic, "/points");
  ASSERT_EQ(b.scans.size(), 2U);
  EXPECT_EQ(b.scans[0].stamp_sec, 1700000000U);
  EXPECT_EQ(b.scans[0].stamp_nsec, 250000000U);
  EXPECT_EQ(b.scans[1].stamp_nsec, 350000000U);
  EXPECT_EQ(b.scans[0].frame_id, "lidar");
  // the cloud keeps them (through a model file, Cloud::stamp)
  ASSERT_TRUE(b.scans[1].cloud.stamp.has_value());
  EXPECT_EQ(b.scans[1].cloud.stamp->source, ScanStamp::Source::kMessage);
  EXPECT_EQ(b.scans[1].cloud.stamp->sec, 1700000000U);
  EXPECT_EQ(b.scans[1].cloud.stamp->nsec, 350000000U);
  EXPECT_EQ(b.scans[1].cloud.stamp->frame_id, "lidar");
  const Cloud& c = b.scans[0].cloud;
  ASSERT_EQ(c.size(), 400U);
  ASSERT_TRUE(c.has_intensity() && c.has_rings() && c.has_time());
  EXPECT_EQ(c.rows, 0U);  // height 1: unorganised
  for (std::size_t i = 0; i < c.size(); ++i) {
    ASSERT_EQ(c.points[i].x(), static_cast<float>(bagfix::driver_value(0, i)));
    ASSERT_EQ(c.points[i].z(), static_cast<float>(bagfix::driver_value(2, i)));
    ASSERT_EQ(c.intensity[i], static_cast<float>(i % 97));
    ASSERT_EQ(c.ring[i], i / 25);
    ASSERT_NEAR(c.time[i], 1e-6 * static_cast<double>(i), 1e-15);  // t in ns
  }
  // the driver's reflectivity (uint16) is kept as a named integer field
  EXPECT_TRUE(b.dropped_fields.empty());
  const IntegerField* reflectivity = c.field("reflectivity");
  ASSERT_NE(reflectivity, nullptr);
  for (std::size_t i = 0; i < c.size(); ++i) ASSERT_EQ(reflectivity->values[i], static_cast<std::int32_t>(3 * i % 1000)) << i;
}

TEST_F(Bags, OrganisedCloudStaysOrganised) {
  const std::string p = path("organised.bag");
  bagfix::write(p, "/os/points", {bagfix::organised_cloud()});
  auto r = io::read_bag(p, "/os/points");
  ASSERT_TRUE(r.ok()) << r.status().to_string();
  const Cloud& c = r.value().scans.at(0).cloud;
  EXPECT_EQ(c.rows, 4U);
  EXPECT_EQ(c.columns, 8U);
  EXPECT_EQ(c.size(), 30U);
  EXPECT_EQ(r.value().no_return_dropped, 2U);
  ASSERT_TRUE(c.has_rings() && c.has_columns());
  // the point after the no-return at (1, 3) is pixel (1, 4)
  EXPECT_EQ(c.ring[11], 1U);
  EXPECT_EQ(c.column[11], 4U);
  EXPECT_EQ(c.intensity[11], 12.0F);
}

TEST_F(Bags, WrittenBagReadsBackExactly) {
  Cloud c;
  for (int i = 0; i < 50; ++i) {
    c.points.emplace_back(0.5F * static_cast<float>(i), -0.25F * static_cast<float>(i), 1.0F + 0.1F * static_cast<float>(i));
    c.intensity.push_back(static_cast<float>(i * 3));
    c.ring.push_back(static_cast<std::uint16_t>(i % 5));
    c.column.push_back(static_cast<std::uint32_t>(i / 5));
    c.time.push_back(1700000000.0 + 1e-4 * i);
    c.rgb.push_back({static_cast<std::uint8_t>(i), 7, 200});
  }
  // named fields: one whose type is not recorded (an INT32), a uint8, a float32 and a float64
  c.fields = {{"classification", {}}, {"scan_angle", {}}, {"label", {}, FieldType::kUint8},
              {"normal_x", {}, FieldType::kFloat32}, {"offset", {}, FieldType::kFloat64}};
  for (int i = 0; i < 50; ++i) {
    c.fields[0].values.push_back(i % 9);
    c.fields[1].values.push_back(-3000 + 97 * i);
    c.fields[2].values.push_back(255 - i);
    c.fields[3].values.push_back(float_key(static_cast<float>(i) / 7.0F));
    c.fields[4].values.push_back(float_key(-0.5F * static_cast<float>(i)));
  }
  c.rows = 5;
  c.columns = 12;  // 60 pixels, 50 points: 10 no-returns written as NaN
  Cloud plain = c;
  plain.ring.clear();
  plain.column.clear();
  plain.rows = plain.columns = 0;
  // (the second scan's intensity and time as a driver stored them: a uint16, and a float64
  // `timestamp`, which comes back under that name)
  plain.intensity_source = {"intensity", FieldType::kUint16};
  plain.time_source = {"timestamp", FieldType::kFloat64};
  std::vector<io::BagScan> scans(3);
  scans[0].cloud = c;
  scans[0].stamp_sec = 1700000123;
  scans[0].stamp_nsec = 5;
  scans[1].cloud = plain;
  // (the third's stamp and frame from its cloud, as a decoded model file gives them)
  scans[2].cloud = plain;
  scans[2].cloud.stamp = ScanStamp{ScanStamp::Source::kCapture, 1700000200, 75, "os_lidar"};
  const std::string p = path("written.bag");
  ASSERT_TRUE(io::write_bag(p, scans, "/lex3d/points").ok());
  auto r = io::read_bag(p, "/lex3d/points");
  ASSERT_TRUE(r.ok()) << r.status().to_string();
  ASSERT_EQ(r.value().scans.size(), 3U);
  EXPECT_TRUE(r.value().dropped_fields.empty());
  const io::BagScan& a = r.value().scans[0];
  EXPECT_EQ(a.stamp_sec, 1700000123U);
  EXPECT_EQ(a.stamp_nsec, 5U);
  EXPECT_EQ(r.value().scans[2].stamp_sec, 1700000200U);
  EXPECT_EQ(r.value().scans[2].stamp_nsec, 75U);
  EXPECT_EQ(r.value().scans[2].frame_id, "os_lidar");
  EXPECT_EQ(a.cloud.rows, 5U);
  EXPECT_EQ(a.cloud.columns, 12U);
  EXPECT_EQ(r.value().no_return_dropped, 10U);
  ASSERT_EQ(a.cloud.size(), 50U);
  // organised output is in pixel order: find each input point by its pixel
  for (std::size_t i = 0; i < a.cloud.size(); ++i) {
    const std::size_t k = std::size_t{a.cloud.column[i]} * 5 + a.cloud.ring[i];
    ASSERT_LT(k, 50U);
    EXPECT_EQ(a.cloud.points[i], c.points[k]);
    EXPECT_EQ(a.cloud.intensity[i], c.intensity[k]);
    EXPECT_EQ(a.cloud.time[i], c.time[k]);
    EXPECT_EQ(a.cloud.rgb[i], c.rgb[k]);
    ASSERT_EQ(a.cloud.fields.size(), 5U);
    EXPECT_EQ(a.cloud.fields[0].name, "classification");
    EXPECT_EQ(a.cloud.fields[0].type, FieldType::kInt32);
    for (std::size_t f = 0; f < 5; ++f) EXPECT_EQ(a.cloud.fields[f].values[i], c.fields[f].values[k]) << f;
    for (std::size_t f = 2; f < 5; ++f) EXPECT_EQ(a.cloud.fields[f].type, c.fields[f].type) << f;
  }
  const io::BagScan& b = r.value().scans[1];
  EXPECT_EQ(b.stamp_sec, 1700000124U);  // no stamp: 1 s after the scan before
  EXPECT_EQ(b.stamp_nsec, 5U);
  ASSERT_EQ(b.cloud.size(), 50U);
  for (std::size_t i = 0; i < 50; ++i) {
    EXPECT_EQ(b.cloud.points[i], plain.points[i]);
    EXPECT_EQ(b.cloud.time[i], plain.time[i]);
    EXPECT_EQ(b.cloud.intensity[i], plain.intensity[i]);
  }
  EXPECT_FALSE(b.cloud.has_rings());
  EXPECT_EQ(b.cloud.intensity_source.type, FieldType::kUint16);
  EXPECT_EQ(b.cloud.time_source.name, "timestamp");
  EXPECT_EQ(b.cloud.time_source.type, FieldType::kFloat64);
  EXPECT_EQ(a.cloud.intensity_source.type, FieldType::kFloat32);  // the first scan's: the writer's own
}

// BagReader gives a topic's scans one at a time, as read_bag gives them all: 40 written
// clouds come back in order with their stamps; a reader dropped after a few stops its
// thread (no hang, no crash); the summary is read_bag's.
TEST_F(Bags, ReaderGivesTheScansOneAtATime) {
  std::vector<io::BagScan> scans(40);
  for (std::size_t k = 0; k < scans.size(); ++k) {
    Cloud& c = scans[k].cloud;
    for (int i = 0; i < 30; ++i) {
      c.points.emplace_back(static_cast<float>(k), 0.5F * static_cast<float>(i), 1.0F);
      c.intensity.push_back(static_cast<float>(i + k));
    }
    scans[k].stamp_sec = 1700000000U + static_cast<std::uint32_t>(k);
    scans[k].stamp_nsec = 1000U * static_cast<std::uint32_t>(k);
  }
  const std::string p = path("forty.bag");
  ASSERT_TRUE(io::write_bag(p, scans, "/points").ok());
  auto reader = io::BagReader::open(p, "");
  ASSERT_TRUE(reader.ok()) << reader.status().to_string();
  std::size_t k = 0;
  for (;; ++k) {
    auto s = reader.value()->next();
    ASSERT_TRUE(s.ok()) << s.status().to_string();
    if (!s.value()) break;
    ASSERT_LT(k, scans.size());
    EXPECT_EQ(s.value()->stamp_sec, scans[k].stamp_sec);
    EXPECT_EQ(s.value()->stamp_nsec, scans[k].stamp_nsec);
    EXPECT_EQ(s.value()->cloud.points, scans[k].cloud.points);
    EXPECT_EQ(s.value()->cloud.intensity, scans[k].cloud.intensity);
  }
  EXPECT_EQ(k, scans.size());
  EXPECT_EQ(reader.value()->summary().topic, "/points");
  EXPECT_EQ(reader.value()->summary().type, "sensor_msgs/PointCloud2");
  auto again = reader.value()->next();  // past the end: still the end
  ASSERT_TRUE(again.ok());
  EXPECT_FALSE(again.value().has_value());
  for (int taken = 0; taken < 3; ++taken) {  // dropped early, with scans still being made
    auto early = io::BagReader::open(p, "/points");
    ASSERT_TRUE(early.ok());
    for (int j = 0; j < taken; ++j) ASSERT_TRUE(early.value()->next().ok());
  }
  auto missing = io::BagReader::open(p, "/other");
  ASSERT_FALSE(missing.ok());
  EXPECT_NE(missing.status().to_string().find("no topic"), std::string::npos);
}

// BagWriter writes message by message the bag write_bag writes (the same bytes); a writer
// dropped before close(), or one whose scan has a field that does not fit, leaves nothing.
TEST_F(Bags, WriterWritesWhatWriteBagWrites) {
  std::vector<io::BagScan> scans(5);
  for (std::size_t k = 0; k < scans.size(); ++k) {
    for (int i = 0; i < 20; ++i) scans[k].cloud.points.emplace_back(static_cast<float>(k), static_cast<float>(i), 0.0F);
    if (k != 2) scans[k].stamp_sec = 1700000000U + static_cast<std::uint32_t>(k);  // the third: 1 s after the second
  }
  const std::string whole = path("whole.bag"), streamed = path("streamed.bag"), dropped = path("dropped.bag");
  ASSERT_TRUE(io::write_bag(whole, scans, "/points").ok());
  {
    auto w = io::BagWriter::open(streamed, "/points");
    ASSERT_TRUE(w.ok()) << w.status().to_string();
    for (const auto& s : scans) ASSERT_TRUE(w.value()->write(s).ok());
    ASSERT_TRUE(w.value()->close().ok());
  }
  EXPECT_EQ(slurp(whole), slurp(streamed));
  {
    auto w = io::BagWriter::open(dropped, "/points");
    ASSERT_TRUE(w.ok());
    ASSERT_TRUE(w.value()->write(scans[0]).ok());
  }
  EXPECT_FALSE(fs::exists(dropped));
  std::size_t left = 0;
  for (const auto& e : fs::directory_iterator(dir_)) left += e.path().filename().string().find("dropped") != std::string::npos;
  EXPECT_EQ(left, 0U);  // nor its temporary file
  io::BagScan bad = scans[0];
  bad.cloud.fields = {{"label", {1, 2, 3}, FieldType::kUint8}};  // 3 values for 20 points
  auto w = io::BagWriter::open(dropped, "/points");
  ASSERT_TRUE(w.ok());
  EXPECT_FALSE(w.value()->write(bad).ok());
  EXPECT_FALSE(io::BagWriter::open(dropped, "points").ok());  // a topic must start with '/'
}

TEST_F(Bags, MissingTopicListsTheTopics) {
  const std::string p = path("topics.bag");
  bagfix::write(p, "/points", {bagfix::driver_cloud()});
  auto r = io::read_bag(p, "/velodyne_points");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), ErrorCode::kBadData);
  const std::string m = r.status().to_string();
  EXPECT_NE(m.find("topics.bag"), std::string::npos) << m;
  EXPECT_NE(m.find("'/velodyne_points'"), std::string::npos) << m;
  EXPECT_NE(m.find("/points (sensor_msgs/PointCloud2, 1)"), std::string::npos) << m;
  EXPECT_NE(m.find("/note (std_msgs/String, 1)"), std::string::npos) << m;
  EXPECT_EQ(m.find('\n'), std::string::npos);
  auto other = io::read_bag(p, "/note");
  ASSERT_FALSE(other.ok());
  EXPECT_NE(other.status().to_string().find("std_msgs/String"), std::string::npos);
}

TEST_F(Bags, InconsistentFieldsAreBadData) {
  struct Case {
    const char* name;
    void (*spoil)(sensor_msgs::PointCloud2&);
    const char* expect;
  };
  const Case cases[] = {
      {"point_step", [](sensor_msgs::PointCloud2& m) { m.point_step -= 2; m.row_step = m.point_step * m.width;
                                                       m.data.resize(m.row_step); },
       "does not fit point_step"},
      {"row_step", [](sensor_msgs::PointCloud2& m) { m.row_step -= 1; }, "row_step"},
      {"bigendian", [](sensor_msgs::PointCloud2& m) { m.is_bigendian = true; }, "is_bigendian"},
      {"data_size", [](sensor_msgs::PointCloud2& m) { m.data.push_back(0); }, "data holds"},
      {"datatype", [](sensor_msgs::PointCloud2& m) { m.fields[3].datatype = 9; }, "unknown datatype 9"},
      {"no_z", [](sensor_msgs::PointCloud2& m) { m.fields[2].name = "w"; }, "no 'z' field"},
      {"duplicate", [](sensor_msgs::PointCloud2& m) { m.fields[4].name = "intensity"; }, "appears twice"},
      {"ring_value", [](sensor_msgs::PointCloud2& m) { m.fields[4].datatype = sensor_msgs::PointField::FLOAT32;
                                                       m.fields[4].offset = 0; }, "not a laser index"},
  };
  for (const Case& k : cases) {
    sensor_msgs::PointCloud2 m = bagfix::driver_cloud();
    k.spoil(m);
    const std::string p = path(std::string("bad_") + k.name + ".bag");
    bagfix::write(p, "/points", {bagfix::driver_cloud(), m});
    auto r = io::read_bag(p, "/points");
    ASSERT_FALSE(r.ok()) << k.name;
    EXPECT_EQ(r.status().code(), ErrorCode::kBadData) << k.name;
    const std::string msg = r.status().to_string();
    EXPECT_NE(msg.find(p + ": message 1 on /points: "), std::string::npos) << k.name << ": " << msg;
    EXPECT_NE(msg.find(k.expect), std::string::npos) << k.name << ": " << msg;
    EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
  }
}

TEST_F(Bags, TruncatedBagIsBadDataAtEveryLength) {
  const std::string p = path("whole.bag");
  bagfix::write(p, "/points", {bagfix::driver_cloud()});
  const std::vector<char> bytes = slurp(p);
  ASSERT_GT(bytes.size(), 4096U);
  const std::string cut = path("cut.bag");
  std::size_t refused = 0;
  // every length through the magic and the file header's fields, then every 29th
  for (std::size_t n = 0; n < bytes.size(); n += (n < 200 ? 1 : 29)) {
    spit(cut, bytes, n);
    auto r = io::read_bag(cut, "/points");
    ASSERT_FALSE(r.ok()) << "cut at " << n;
    ASSERT_EQ(r.status().code(), ErrorCode::kBadData) << n << ": " << r.status().to_string();
    ASSERT_NE(r.status().to_string().find("cut.bag"), std::string::npos);
    ++refused;
  }
  EXPECT_GT(refused, 200U + (bytes.size() - 200) / 29);
}

TEST_F(Bags, CorruptBytesNeverCrash) {
  const std::string p = path("whole2.bag");
  bagfix::write(p, "/points", {bagfix::driver_cloud(), bagfix::organised_cloud()});
  const std::vector<char> bytes = slurp(p);
  const std::string bad = path("corrupt.bag");
  std::size_t refused = 0, read = 0;
  // every byte of the magic and the file header fields, every 17th of the first chunk's headers and of the
  // index at the end, every 197th elsewhere
  for (std::size_t i = 0; i < bytes.size(); i += (i < 120 ? 1 : i < 4400 || i + 600 > bytes.size() ? 17 : 197)) {
    std::vector<char> b = bytes;
    b[i] = static_cast<char>(b[i] ^ 0x5A);
    spit(bad, b, b.size());
    auto r = io::read_bag(bad, "/points");
    if (r.ok()) ++read;
    else {
      ++refused;
      ASSERT_EQ(r.status().to_string().find('\n'), std::string::npos);
    }
  }
  EXPECT_GT(refused, 0U);
  EXPECT_GT(read, 0U);  // flipped point values still read
}

TEST_F(Bags, NotABag) {
  const std::string p = path("text.bag");
  spit(p, std::vector<char>{'#', 'R', 'O', 'S', 'B', 'A', 'G', ' ', 'V', '1', '.', '2', '\n'}, 13);
  auto r = io::read_bag(p, "");
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().to_string().find("2.0"), std::string::npos) << r.status().to_string();
  auto missing = io::read_bag(path("missing.bag"), "");
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), ErrorCode::kIoError);
}

TEST_F(Bags, SharedOusterPacketBag) {
  const std::string p = std::string(LEX3D_SHARED_DATA_DIR) + "/rosbag/ouster_512x10_raw.bag";
  if (!fs::exists(p)) GTEST_SKIP() << "no " << p;
  auto r = io::read_bag(p, "");
  ASSERT_TRUE(r.ok()) << r.status().to_string();
  const io::BagScans& b = r.value();
  EXPECT_EQ(b.topic, "/os_node0/lidar_packets");
  EXPECT_EQ(b.sensor.substr(0, 4), "OS-0");
  ASSERT_EQ(b.scans.size(), 1U);
  const Cloud& c = b.scans[0].cloud;
  EXPECT_EQ(c.rows, 128U);
  EXPECT_EQ(c.columns, 512U);
  EXPECT_EQ(c.size() + b.no_return_dropped, 128U * 512U);
  EXPECT_GT(c.size(), 128U * 512U / 4);  // 28,751 returns: an indoor frame
  ASSERT_TRUE(c.geometry.has_value());
  EXPECT_EQ(c.geometry->lasers(), 128U);
  EXPECT_NE(b.scans[0].stamp_sec, 0U);
  // the imu topic is not a point cloud
  auto imu = io::read_bag(p, "/os_node0/imu_packets");
  EXPECT_FALSE(imu.ok());
  // read_cloud gives the same first scan
  auto first = io::read_cloud(p);
  ASSERT_TRUE(first.ok()) << first.status().to_string();
  EXPECT_EQ(first.value().cloud.size(), c.size());
}

/// The VLP-16 sample's packets recorded as velodyne_driver records them (VelodyneScan
/// messages of 40 packets, each packet stamped with its capture time): the same turn as the
/// capture, point for point, with its times, stamped with its first packet's time. A
/// message that announces more packets than it holds is refused naming it.
TEST_F(Bags, VelodyneScanPacketsReadAsTheirCapture) {
  const std::string pcap = std::string(LEX3D_SAMPLES_DIR) + "/vlp16_velodyne_example.pcap";
  auto capture = io::read_sensor_log(pcap);
  ASSERT_TRUE(capture.ok()) << capture.status().to_string();
  std::vector<io::detail::Datagram> datagrams;
  io::SensorLogInfo info;
  ASSERT_TRUE(io::detail::read_udp_datagrams(pcap, datagrams, info).ok());
  std::vector<bagfix::StampedPacket> packets;
  for (const auto& d : datagrams)
    if (io::detail::is_velodyne_packet(d.payload))
      packets.push_back({static_cast<std::uint32_t>(d.captured_ns / 1000000000ULL),
                         static_cast<std::uint32_t>(d.captured_ns % 1000000000ULL), d.payload});
  ASSERT_GT(packets.size(), 80U);
  const std::string bag_path = path("velodyne_packets.bag");
  {
    rosbag::Bag bag;
    bag.open(bag_path, rosbag::bagmode::Write);
    for (std::size_t at = 0, seq = 0; at < packets.size(); at += 40, ++seq) {
      const std::vector<bagfix::StampedPacket> part(packets.begin() + static_cast<std::ptrdiff_t>(at),
                                                    packets.begin() + static_cast<std::ptrdiff_t>(std::min(packets.size(), at + 40)));
      bag.write("/velodyne_packets", ros::Time(part.front().sec, part.front().nsec),
                bagfix::velodyne_scan(static_cast<std::uint32_t>(seq), part));
    }
    bag.close();
  }
  auto r = io::read_bag(bag_path, "");
  ASSERT_TRUE(r.ok()) << r.status().to_string();
  const io::BagScans& b = r.value();
  EXPECT_EQ(b.topic, "/velodyne_packets");
  EXPECT_EQ(b.sensor, "VLP-16");
  ASSERT_EQ(b.scans.size(), capture.value().scans.size());
  const Cloud& c = b.scans[0].cloud;
  const Cloud& want = capture.value().scans[0];
  EXPECT_EQ(c.points, want.points);
  EXPECT_EQ(c.ring, want.ring);
  EXPECT_EQ(c.column, want.column);
  EXPECT_EQ(c.time, want.time);
  EXPECT_EQ(b.scans[0].frame_id, "velodyne");
  EXPECT_EQ(static_cast<std::uint64_t>(b.scans[0].stamp_sec) * 1000000000ULL + b.scans[0].stamp_nsec,
            capture.value().captured_ns[0]);
  // a message announcing a packet more than it holds
  {
    rosbag::Bag bag;
    bag.open(path("velodyne_short.bag"), rosbag::bagmode::Write);
    bagfix::VelodyneScanBytes m = bagfix::velodyne_scan(0, {packets[0], packets[1]});
    m.bytes[16 + 8] = 3;  // the count (after the header: seq, stamp, "velodyne")
    bag.write("/velodyne_packets", ros::Time(packets[0].sec, packets[0].nsec), m);
    bag.close();
  }
  auto bad = io::read_bag(path("velodyne_short.bag"), "");
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), ErrorCode::kBadData);
  EXPECT_NE(bad.status().message().find("message 1 on /velodyne_packets: a truncated velodyne_msgs/VelodyneScan (3 packets announced, 2 held)"),
            std::string::npos)
      << bad.status().to_string();
}

TEST_F(Bags, AnOusterPacketErrorNamesTheMessage) {
  // The shared bag with the packet type of its third lidar packet message spoiled: the error
  // names that message on its topic (there are no capture records in a bag).
  const std::string p = std::string(LEX3D_SHARED_DATA_DIR) + "/rosbag/ouster_512x10_raw.bag";
  if (!fs::exists(p)) GTEST_SKIP() << "no " << p;
  std::vector<char> bytes = slurp(p);
  // A lidar packet message: its u32 length (8448 bytes, RNG15_RFL8_NIR8 at 128 beams) and the
  // packet's u16 type 1.
  const std::string packet_start("\x00\x21\x00\x00\x01\x00", 6);
  std::size_t at = std::string::npos, found = 0;
  for (std::size_t i = 0; i + packet_start.size() <= bytes.size() && found < 3; ++i)
    if (std::equal(packet_start.begin(), packet_start.end(), bytes.begin() + static_cast<std::ptrdiff_t>(i))) {
      at = i;
      ++found;
    }
  ASSERT_EQ(found, 3U);
  bytes[at + 4] = 7;  // packet type 7
  const std::string bad = path("ouster_type.bag");
  spit(bad, bytes, bytes.size());
  auto r = io::read_bag(bad, "");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), ErrorCode::kBadData);
  const std::string msg = r.status().to_string();
  EXPECT_NE(msg.find("ouster_type.bag: message 3 on /os_node0/lidar_packets: packet type 7 is not a lidar data packet"),
            std::string::npos) << msg;
  EXPECT_EQ(msg.find("capture record"), std::string::npos) << msg;
}

TEST_F(Bags, MutatedPointCloud2BytesAreReadOrRefused) {
  // the serialized message as a bag holds it, then 20,000 copies with 1-4 bytes changed or
  // cut short (fixed seed): each is read or refused with one line, never a crash
  const sensor_msgs::PointCloud2 m = bagfix::driver_cloud();
  std::vector<std::uint8_t> bytes(ros::serialization::serializationLength(m));
  ros::serialization::OStream os(bytes.data(), static_cast<std::uint32_t>(bytes.size()));
  ros::serialization::serialize(os, m);
  {
    io::detail::PointCloud2Msg pm;
    ASSERT_TRUE(io::detail::parse_pointcloud2("m", bytes.data(), bytes.size(), pm).ok());
    EXPECT_EQ(pm.width, 400U);
    EXPECT_EQ(pm.fields.size(), 7U);
  }
  std::mt19937 rng(1);
  std::size_t read = 0, refused = 0;
  const std::size_t header = 200;  // most changes go to the header and field table
  for (int k = 0; k < 20000; ++k) {
    std::vector<std::uint8_t> b = bytes;
    const int changes = 1 + static_cast<int>(rng() % 4);
    for (int c = 0; c < changes; ++c) {
      const std::size_t at = rng() % 4 == 0 ? rng() % b.size() : rng() % header;
      b[at] = static_cast<std::uint8_t>(rng());
    }
    if (rng() % 8 == 0) b.resize(rng() % b.size());
    io::detail::PointCloud2Msg pm;
    Status s = io::detail::parse_pointcloud2("m", b.data(), b.size(), pm);
    io::ReadResult r;
    if (s.ok()) s = io::detail::pointcloud2_to_cloud("m", pm, r);
    if (s.ok()) {
      ++read;
      ASSERT_LE(r.cloud.size(), std::size_t{pm.width} * pm.height);
    } else {
      ++refused;
      ASSERT_EQ(s.to_string().find('\n'), std::string::npos) << s.to_string();
    }
  }
  EXPECT_GT(read, 0U);
  EXPECT_GT(refused, 0U);
}

namespace {

struct Compression {
  const char* name;
  rosbag::CompressionType type;
};
const Compression kCompressions[] = {{"bz2", rosbag::compression::BZ2}, {"lz4", rosbag::compression::LZ4}};

}  // namespace

TEST_F(Bags, CompressedChunksReadAsUncompressed) {
  const std::string plain = path("plain.bag");
  bagfix::write(plain, "/points", {bagfix::driver_cloud(), bagfix::organised_cloud()});
  const auto want = io::read_bag(plain, "/points");
  ASSERT_TRUE(want.ok()) << want.status().to_string();
  for (const auto& c : kCompressions) {
    for (const std::uint32_t threshold : {768U * 1024U, 64U}) {  // one chunk; a chunk a message
      const std::string p = path(std::string("packed_") + c.name + ".bag");
      bagfix::write(p, "/points", {bagfix::driver_cloud(), bagfix::organised_cloud()}, true, c.type, threshold);
      const std::vector<char> bytes = slurp(p);
      const bagfix::ChunkAt chunk = bagfix::first_chunk(bytes);
      const std::string header(bytes.data() + chunk.record, bytes.data() + chunk.data);
      ASSERT_NE(header.find(std::string("compression=") + c.name), std::string::npos) << c.name;
      EXPECT_LT(chunk.data_len, chunk.declared) << c.name;  // it is compressed
      const auto r = io::read_bag(p, "/points");
      ASSERT_TRUE(r.ok()) << c.name << ": " << r.status().to_string();
      ASSERT_EQ(r.value().scans.size(), 2U);
      for (std::size_t s = 0; s < 2; ++s) {
        const Cloud& a = want.value().scans[s].cloud;
        const Cloud& b = r.value().scans[s].cloud;
        ASSERT_EQ(a.size(), b.size()) << c.name;
        for (std::size_t i = 0; i < a.size(); ++i) ASSERT_EQ(a.points[i], b.points[i]) << c.name << " " << i;
        EXPECT_EQ(a.intensity, b.intensity);
        EXPECT_EQ(a.ring, b.ring);
      }
    }
  }
}

TEST_F(Bags, ImplausibleChunkSizeIsRefusedNamingTheChunk) {
  // a declared uncompressed size beyond what the chunk's compressed bytes can expand to
  // (LZ4: 255:1, bzip2: 65536:1) is refused before anything is allocated for it
  for (const auto& c : kCompressions) {
    const std::string p = path(std::string("size_") + c.name + ".bag");
    bagfix::write(p, "/points", {bagfix::driver_cloud()}, false, c.type);
    std::vector<char> bytes = slurp(p);
    const bagfix::ChunkAt chunk = bagfix::first_chunk(bytes);
    const std::uint32_t ratio = std::string(c.name) == "lz4" ? 255U : 65536U;
    for (const std::uint32_t declared : {0xFFFFFFFFU, static_cast<std::uint32_t>(ratio * chunk.data_len + 1)}) {
      std::vector<char> b = bytes;
      std::memcpy(b.data() + chunk.size_field, &declared, 4);
      const std::string bad = path(std::string("size_bad_") + c.name + ".bag");
      spit(bad, b, b.size());
      const auto r = io::read_bag(bad, "/points");
      ASSERT_FALSE(r.ok()) << c.name << " " << declared;
      EXPECT_EQ(r.status().code(), ErrorCode::kBadData);
      const std::string m = r.status().to_string();
      EXPECT_NE(m.find(bad), std::string::npos) << m;
      EXPECT_EQ(m.find('\n'), std::string::npos) << m;
      EXPECT_NE(m.find("chunk 1 at byte " + std::to_string(chunk.record) + " (" + c.name), std::string::npos) << m;
      // (the larger one is past the 2 GiB cap on any chunk)
      EXPECT_NE(m.find(declared == 0xFFFFFFFFU ? "a chunk may hold" : ":1)"), std::string::npos) << m;
      EXPECT_FALSE(io::read_bag_info(bad).ok());
    }
  }
}

TEST_F(Bags, ChunkOfAnotherSizeThanDeclaredIsRefused) {
  // one byte more or less declared than the chunk holds: the ROS bag library would keep
  // a short bz2 chunk's stale buffer tail as message bytes
  for (const auto& c : kCompressions) {
    const std::string p = path(std::string("off_") + c.name + ".bag");
    bagfix::write(p, "/points", {bagfix::driver_cloud()}, false, c.type);
    const std::vector<char> bytes = slurp(p);
    const bagfix::ChunkAt chunk = bagfix::first_chunk(bytes);
    for (const int delta : {+1, -1, +1000}) {
      std::vector<char> b = bytes;
      const std::uint32_t declared = chunk.declared + static_cast<std::uint32_t>(delta);
      std::memcpy(b.data() + chunk.size_field, &declared, 4);
      const std::string bad = path(std::string("off_bad_") + c.name + ".bag");
      spit(bad, b, b.size());
      const auto r = io::read_bag(bad, "/points");
      ASSERT_FALSE(r.ok()) << c.name << " " << delta;
      EXPECT_EQ(r.status().code(), ErrorCode::kBadData);
      const std::string m = r.status().to_string();
      const std::string head = bad + ": corrupt bag: chunk 1 at byte " + std::to_string(chunk.record) + " (" + c.name + ", " +
                               std::to_string(chunk.data_len) + " bytes) decompresses to ";
      EXPECT_NE(m.find(head), std::string::npos) << m;
      EXPECT_NE(m.find(delta > 0 ? "fewer than the " + std::to_string(declared) : "more than the " + std::to_string(declared)),
                std::string::npos)
          << m;
      EXPECT_EQ(m.find('\n'), std::string::npos) << m;
    }
  }
}

TEST_F(Bags, CorruptCompressedBytesAreRefusedNamingTheChunk) {
  // every 7th byte of the compressed data flipped, and the data cut short: refused with one
  // line naming the file and the chunk (both codings carry a checksum of their content), or,
  // where a flip lands on bytes the decoder does not check, read as a bag that holds what
  // it holds
  for (const auto& c : kCompressions) {
    const std::string p = path(std::string("flip_") + c.name + ".bag");
    bagfix::write(p, "/points", {bagfix::driver_cloud()}, false, c.type);
    const std::vector<char> bytes = slurp(p);
    const bagfix::ChunkAt chunk = bagfix::first_chunk(bytes);
    const std::string bad = path(std::string("flip_bad_") + c.name + ".bag");
    const std::string names_chunk = "chunk 1 at byte " + std::to_string(chunk.record) + " (" + c.name;
    std::size_t refused = 0, tried = 0;
    for (std::size_t i = chunk.data; i < chunk.data + chunk.data_len; i += 7) {
      std::vector<char> b = bytes;
      b[i] = static_cast<char>(b[i] ^ 0x21);
      spit(bad, b, b.size());
      ++tried;
      const auto r = io::read_bag(bad, "/points");
      if (r.ok()) continue;
      ++refused;
      EXPECT_EQ(r.status().code(), ErrorCode::kBadData);
      const std::string m = r.status().to_string();
      ASSERT_NE(m.find(bad + ": corrupt bag: " + names_chunk), std::string::npos) << i << ": " << m;
      ASSERT_EQ(m.find('\n'), std::string::npos) << m;
    }
    EXPECT_GT(refused, tried * 9 / 10) << c.name << ": " << refused << " of " << tried;
    // the compressed data cut by 10 bytes, the record's length kept right (the bytes after it moved up)
    std::vector<char> cut(bytes.begin(), bytes.begin() + static_cast<std::ptrdiff_t>(chunk.data + chunk.data_len - 10));
    cut.insert(cut.end(), bytes.begin() + static_cast<std::ptrdiff_t>(chunk.data + chunk.data_len), bytes.end());
    const std::uint32_t len = static_cast<std::uint32_t>(chunk.data_len - 10);
    std::memcpy(cut.data() + chunk.data - 4, &len, 4);
    spit(bad, cut, cut.size());
    const auto r = io::read_bag(bad, "/points");
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.status().to_string().find(names_chunk), std::string::npos) << r.status().to_string();
  }
}

TEST_F(Bags, ConnectionDataFieldRunningPastItIsRefused) {
  // A connection record's data is a list of fields (topic=, type=, ...) that the ROS bag
  // library parses without checking a field's length against the data (found by
  // fuzz_reader_bag: a heap overflow in ros::Header::parse). Each connection record of the
  // bag, the one in its chunk and the one in its index, with its first field's length past
  // the data: refused.
  const std::string p = path("conn.bag");
  bagfix::write(p, "/points", {bagfix::driver_cloud()}, false);
  const std::vector<char> bytes = slurp(p);
  std::vector<std::size_t> conn_data;  // data offsets of the connection records
  for (const auto& r : bagfix::records(bytes)) {
    if (r.op == 0x07) conn_data.push_back(r.data);
    if (r.op == 0x05)  // inside the (uncompressed) chunk
      for (const auto& inner : bagfix::records(std::vector<char>(bytes.begin() + static_cast<std::ptrdiff_t>(r.data) - 13,
                                                                  bytes.begin() + static_cast<std::ptrdiff_t>(r.data + r.data_len))))
        if (inner.op == 0x07) conn_data.push_back(inner.data + r.data - 13);
  }
  ASSERT_EQ(conn_data.size(), 2U);
  for (const std::size_t at : conn_data) {
    std::vector<char> b = bytes;
    const std::uint32_t flen = bagfix::u32_at(b, at) + 5000;
    std::memcpy(b.data() + at, &flen, 4);
    const std::string bad = path("conn_bad.bag");
    spit(bad, b, b.size());
    for (const bool info : {false, true}) {
      const Status s = info ? io::read_bag_info(bad).status() : io::read_bag(bad, "").status();
      ASSERT_FALSE(s.ok()) << at;
      EXPECT_EQ(s.code(), ErrorCode::kBadData);
      EXPECT_NE(s.to_string().find(bad + ": "), std::string::npos) << s.to_string();
      EXPECT_NE(s.to_string().find("corrupt connection data: a field of"), std::string::npos) << s.to_string();
    }
  }
}

TEST_F(Bags, IndexThatDisagreesWithItsChunkIsRefused) {
  // the index data after a chunk: an entry's offset moved off its message record, or the
  // record's connection changed (the ROS bag library would then drop the topic's messages
  // without a word and read the bag as holding only /note)
  const std::string p = path("index.bag");
  bagfix::write(p, "/points", {bagfix::driver_cloud(), bagfix::driver_cloud(1700000001, 0)});
  const std::vector<char> bytes = slurp(p);
  std::size_t index_data = 0, conn_field = 0;
  for (const auto& r : bagfix::records(bytes))
    if (r.op == 0x04 && index_data == 0) {
      index_data = r.data;
      const std::string header(bytes.data() + r.at, bytes.data() + r.data);
      conn_field = r.at + header.find("conn=") + 5;
    }
  ASSERT_NE(index_data, 0U);
  struct Case {
    const char* name;
    std::size_t at;
    std::uint32_t add;
    const char* expect;
  };
  for (const Case& c : {Case{"offset", index_data + 8, 1, "is not the start of a message record of the chunk at byte"},
                        Case{"conn", conn_field, 7, "lists other connections or message counts than the index data"}}) {
    std::vector<char> b = bytes;
    const std::uint32_t v = bagfix::u32_at(b, c.at) + c.add;
    std::memcpy(b.data() + c.at, &v, 4);
    const std::string bad = path(std::string("index_") + c.name + ".bag");
    spit(bad, b, b.size());
    for (const bool info : {false, true}) {
      const Status s = info ? io::read_bag_info(bad).status() : io::read_bag(bad, "/points").status();
      ASSERT_FALSE(s.ok()) << c.name;
      EXPECT_EQ(s.code(), ErrorCode::kBadData);
      EXPECT_NE(s.to_string().find(bad + ": corrupt bag: "), std::string::npos) << s.to_string();
      EXPECT_NE(s.to_string().find(c.expect), std::string::npos) << s.to_string();
      EXPECT_EQ(s.to_string().find('\n'), std::string::npos);
    }
  }
}
