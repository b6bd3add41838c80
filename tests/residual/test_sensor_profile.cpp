// Sensor profiles (formats/sensor_profile.md): parsing (JSON and Velodyne XML, every kind of
// bad field), the laser and column assignment of a scan cast from a known table, the refusal
// of scans of another sensor, and a round trip through lex3d::compress keeping the bound.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <random>
#include <sstream>
#include <string>

#include "lex3d/eval/metrics.hpp"
#include "lex3d/io/io.hpp"
#include "lex3d/lex3d.hpp"
#include "lex3d/residual/sensor_profile.hpp"
#include "test_config.hpp"

namespace {

using lex3d::Cloud;
using lex3d::ErrorCode;
using lex3d::residual::apply_sensor_profile;
using lex3d::residual::parse_sensor_profile;
using lex3d::residual::SensorProfile;

constexpr double kPi = 3.14159265358979323846;

std::string bench_table(const std::string& name) {
  std::ifstream f(std::string(LEX3D_SAMPLES_DIR) + "/../bench/sensors/" + name);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

SensorProfile profile_of(const std::string& name) {
  auto p = parse_sensor_profile(bench_table(name), name);
  if (!p.ok()) throw std::runtime_error(p.status().to_string());
  return p.value();
}

/// A scan of `p`'s lasers in a room: a floor 1.6 m below the sensor and walls 12-25 m away,
/// as a clockwise-spinning sensor reports it (azimuth of a beam -(column step + offset),
/// points from the reported azimuth with 0.01 degree encoder steps, range in range steps).
/// `truth` gets each point's laser.
Cloud cast_scan(const SensorProfile& p, std::vector<std::uint16_t>* truth, std::uint32_t seed = 1) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> jitter(0.0, 0.003);
  Cloud c;
  const std::uint32_t columns = p.columns;
  for (std::uint32_t col = 0; col < columns; ++col) {
    const double reported = std::round((360.0 * col / columns + jitter(rng)) / 0.01) * 0.01;
    for (std::size_t l = 0; l < p.lasers.size(); ++l) {
      const auto& b = p.lasers[l];
      const double az = -(reported + b.azimuth_deg) * kPi / 180.0;
      const double el = b.elevation_deg * kPi / 180.0;
      const double dx = std::cos(az) * std::cos(el), dy = std::sin(az) * std::cos(el), dz = std::sin(el);
      // the nearest of the floor and the four walls
      double t = 1e9;
      if (dz < -1e-6) t = std::min(t, (-1.6 - b.z_offset) / dz);
      if (std::abs(dx) > 1e-9) t = std::min(t, (dx > 0 ? 25.0 : -12.0) / dx);
      if (std::abs(dy) > 1e-9) t = std::min(t, (dy > 0 ? 18.0 : -15.0) / dy);
      const double z = b.z_offset + t * dz;
      if (!(t > 0.5) || z > 4.0) continue;  // above the walls: no return
      const double r = std::round(t / p.range_step) * p.range_step;
      const double xy = r * std::cos(el);
      c.points.emplace_back(static_cast<float>(xy * std::cos(az) - b.horiz_offset * std::sin(az)),
                            static_cast<float>(xy * std::sin(az) + b.horiz_offset * std::cos(az)),
                            static_cast<float>(r * std::sin(el) + b.z_offset));
      if (truth) truth->push_back(static_cast<std::uint16_t>(l));
    }
  }
  return c;
}

void expect_bad(const std::string& text, const std::string& field) {
  auto p = parse_sensor_profile(text, "bad.json");
  ASSERT_FALSE(p.ok()) << text;
  EXPECT_EQ(p.status().code(), ErrorCode::kBadData);
  EXPECT_EQ(p.status().message().rfind("bad.json: ", 0), 0U) << p.status().message();
  EXPECT_NE(p.status().message().find(field), std::string::npos) << p.status().message();
}

const char* kGood = R"({"sensor": "two", "columns": 1800, "range_step": 0.002,
  "lasers": [{"elevation_deg": -1.5, "azimuth_deg": 0.5, "fire_us": 0, "z_offset": 0.01, "horiz_offset": 0.02},
             {"elevation_deg": 2.5}]})";

}  // namespace

TEST(SensorProfile, ParsesTheBenchTablesAndAMinimalOne) {
  const SensorProfile v = profile_of("velodyne_vlp_32c.json");
  EXPECT_EQ(v.sensor, "Velodyne VLP-32C");
  EXPECT_EQ(v.lasers.size(), 32U);
  EXPECT_EQ(v.columns, 1800U);
  EXPECT_GT(v.range_step, 0.0);
  EXPECT_EQ(v.origin, "velodyne_vlp_32c.json");
  auto p = parse_sensor_profile(kGood, "good.json");
  ASSERT_TRUE(p.ok()) << p.status().to_string();
  ASSERT_EQ(p.value().lasers.size(), 2U);
  EXPECT_DOUBLE_EQ(p.value().lasers[0].elevation_deg, -1.5);
  EXPECT_DOUBLE_EQ(p.value().lasers[0].horiz_offset, 0.02);
  EXPECT_DOUBLE_EQ(p.value().lasers[1].azimuth_deg, 0.0);  // optional fields default to 0
  EXPECT_DOUBLE_EQ(p.value().rate_hz, 10.0);
  for (const char* name : {"hesai_ot128.json", "hesai_pandar40p.json", "velodyne_hdl_64e_s2.json"})
    EXPECT_TRUE(parse_sensor_profile(bench_table(name), name).ok()) << name;
}

TEST(SensorProfile, MissingWrongTypedNonFiniteAndOutOfRangeFieldsNameTheFileAndField) {
  expect_bad(R"({"columns": 1800, "lasers": [{"elevation_deg": 1}]})", "range_step is missing");
  expect_bad(R"({"range_step": 0.002})", "lasers is missing");
  expect_bad(R"({"range_step": 0.002, "lasers": [{"azimuth_deg": 1}]})", "lasers[0].elevation_deg is missing");
  expect_bad(R"({"range_step": 0.002, "lasers": [{"elevation_deg": NaN}]})", "not a valid sensor profile JSON");
  expect_bad(R"({"range_step": 0.002, "lasers": [{"elevation_deg": 1e999}]})", "not a valid sensor profile JSON");
  expect_bad(R"({"range_step": "2 mm", "lasers": [{"elevation_deg": 1}]})", "range_step is string");
  expect_bad(R"({"range_step": 0.002, "columns": "1800", "lasers": [{"elevation_deg": 1}]})", "columns is string");
  expect_bad(R"({"range_step": 0.002, "columns": 1800.5, "lasers": [{"elevation_deg": 1}]})", "whole number");
  expect_bad(R"({"range_step": 0.002, "lasers": {"elevation_deg": 1}})", "lasers is object");
  expect_bad(R"({"range_step": 0.002, "lasers": [{"elevation_deg": true}]})", "lasers[0].elevation_deg is boolean");
  expect_bad(R"({"range_step": 0.002, "lasers": [{"elevation_deg": 91}]})", "lasers[0].elevation_deg is 91");
  expect_bad(R"({"range_step": 0, "lasers": [{"elevation_deg": 1}]})", "range_step is 0");
  expect_bad(R"({"range_step": 0.002, "lasers": []})", "lasers has 0 entries");
  expect_bad(R"([1, 2])", "expected an object");
  expect_bad("   ", "empty");
  expect_bad(R"({"range_step": 0.002, "lasers": [)", "not a valid sensor profile JSON");
}

TEST(SensorProfile, ReadsAVelodyneCalibrationXml) {
  const std::string xml = R"(<?xml version="1.0"?>
<boost_serialization signature="serialization::archive" version="4"><DB><distLSB_>0.2</distLSB_>
<points_ class_id="0"><count>2</count>
<item class_id="1"><px class_id="2"><id_>1</id_><rotCorrection_>-1.5</rotCorrection_><vertCorrection_>-7.25</vertCorrection_>
<vertOffsetCorrection_>20.1</vertOffsetCorrection_><horizOffsetCorrection_>2.6</horizOffsetCorrection_></px></item>
<item><px><id_>0</id_><rotCorrection_>3</rotCorrection_><vertCorrection_>2.0</vertCorrection_></px></item>
</points_></DB></boost_serialization>)";
  auto p = parse_sensor_profile(xml, "db.xml");
  ASSERT_TRUE(p.ok()) << p.status().to_string();
  ASSERT_EQ(p.value().lasers.size(), 2U);
  EXPECT_DOUBLE_EQ(p.value().range_step, 0.002);
  EXPECT_EQ(p.value().columns, 0U);  // found from the points
  EXPECT_DOUBLE_EQ(p.value().lasers[0].elevation_deg, 2.0);  // ordered by id_
  EXPECT_DOUBLE_EQ(p.value().lasers[0].azimuth_deg, -3.0);
  EXPECT_DOUBLE_EQ(p.value().lasers[1].z_offset, 0.201);
  EXPECT_DOUBLE_EQ(p.value().lasers[1].horiz_offset, 0.026);
  std::string no_lsb = xml;
  no_lsb.replace(no_lsb.find("<distLSB_>"), 26, "");
  auto q = parse_sensor_profile(no_lsb, "db.xml");
  ASSERT_FALSE(q.ok());
  EXPECT_NE(q.status().message().find("db.xml: distLSB_ is missing"), std::string::npos) << q.status().message();
  std::string bad_number = xml;
  bad_number.replace(bad_number.find("-7.25"), 5, "nan?!");
  EXPECT_FALSE(parse_sensor_profile(bad_number, "db.xml").ok());
  std::string gap = xml;
  gap.replace(gap.find("<id_>0</id_>"), 12, "<id_>2</id_>");
  EXPECT_FALSE(parse_sensor_profile(gap, "db.xml").ok());
}

TEST(SensorProfile, AssignsEveryPointToTheLaserThatCastIt) {
  for (const char* name : {"velodyne_vlp_32c.json", "hesai_pandar40p.json", "velodyne_hdl_64e_s2.json"}) {
    const SensorProfile p = profile_of(name);
    std::vector<std::uint16_t> truth;
    Cloud c = cast_scan(p, &truth);
    ASSERT_GT(c.size(), 10000U);
    auto fit = apply_sensor_profile(c, p, "scan");
    ASSERT_TRUE(fit.ok()) << name << ": " << fit.status().to_string();
    ASSERT_TRUE(c.has_rings() && c.has_columns() && c.geometry);
    EXPECT_EQ(c.geometry->lasers(), p.lasers.size());
    EXPECT_EQ(c.geometry->columns, p.columns);
    EXPECT_EQ(c.geometry->source, std::string("profile ") + name);
    std::size_t same = 0;
    for (std::size_t i = 0; i < c.size(); ++i) same += c.ring[i] == truth[i];
    EXPECT_GE(same, c.size() * 999 / 1000) << name;
    EXPECT_LT(fit.value().median_off_beam_m, p.range_step) << name;
    EXPECT_EQ(fit.value().direction, -1) << name;  // azimuths fall with the column, as cast
    // Deterministic.
    Cloud again = cast_scan(p, nullptr);
    ASSERT_TRUE(apply_sensor_profile(again, p, "scan").ok());
    EXPECT_EQ(again.ring, c.ring);
    EXPECT_EQ(again.column, c.column);
  }
}

TEST(SensorProfile, ScansOfAnotherSensorAreRefusedAndLeftAsTheyWere) {
  const SensorProfile vlp32 = profile_of("velodyne_vlp_32c.json");
  const SensorProfile hdl64 = profile_of("velodyne_hdl_64e_s2.json");
  const SensorProfile ot128 = profile_of("hesai_ot128.json");
  Cloud c = cast_scan(hdl64, nullptr);
  const Cloud before = c;
  auto fit = apply_sensor_profile(c, vlp32, "scan.bin");
  ASSERT_FALSE(fit.ok());
  EXPECT_EQ(fit.status().code(), ErrorCode::kBadData);
  EXPECT_EQ(fit.status().message().rfind("scan.bin: ", 0), 0U) << fit.status().message();
  EXPECT_NE(fit.status().message().find("velodyne_vlp_32c.json"), std::string::npos);
  EXPECT_FALSE(c.has_rings());
  EXPECT_FALSE(c.geometry);
  EXPECT_EQ(c.points, before.points);
  // A denser table than the scan's: most of its lasers get no points.
  Cloud sparse = cast_scan(vlp32, nullptr);
  auto dense = apply_sensor_profile(sparse, ot128, "scan.bin");
  ASSERT_FALSE(dense.ok());
  EXPECT_NE(dense.status().message().find("fewer lasers"), std::string::npos) << dense.status().message();
  // A ring field of another laser count.
  Cloud ringed = cast_scan(vlp32, nullptr);
  ringed.ring.assign(ringed.size(), 0);
  ringed.ring[0] = 63;
  auto rings = apply_sensor_profile(ringed, vlp32, "scan.pcd");
  ASSERT_FALSE(rings.ok());
  EXPECT_NE(rings.status().message().find("64 lasers"), std::string::npos) << rings.status().message();
  // An empty scan is left empty.
  Cloud empty;
  EXPECT_TRUE(apply_sensor_profile(empty, vlp32, "empty").ok());
  EXPECT_FALSE(empty.geometry);
}

TEST(SensorProfile, TheColumnsComeFromTheAzimuthStepWhenTheProfileGivesNone) {
  SensorProfile p = profile_of("velodyne_vlp_32c.json");
  Cloud c = cast_scan(p, nullptr);
  p.columns = 0;
  auto fit = apply_sensor_profile(c, p, "scan");
  ASSERT_TRUE(fit.ok()) << fit.status().to_string();
  EXPECT_EQ(c.geometry->columns, 1800U);
}

TEST(SensorProfile, CompressWithAProfileKeepsTheBoundAndCodesByTheTable) {
  const SensorProfile p = profile_of("hesai_pandar40p.json");
  const Cloud c = cast_scan(p, nullptr, 7);
  for (const double e : {0.005, 0.014}) {
    lex3d::CompressOptions o;
    o.max_error = e;
    o.sensor_profile = p;
    auto r = lex3d::compress(c, o);
    ASSERT_TRUE(r.ok()) << r.status().to_string();
    EXPECT_TRUE(r.value().layer.laser);
    EXPECT_EQ(r.value().layer.laser_table_source, "profile hesai_pandar40p.json");
    EXPECT_EQ(r.value().layer.lasers, 40U);
    auto again = lex3d::compress(c, o);
    ASSERT_TRUE(again.ok());
    EXPECT_EQ(again.value().bytes, r.value().bytes);  // deterministic
    auto d = lex3d::decompress(r.value().bytes);
    ASSERT_TRUE(d.ok()) << d.status().to_string();
    const auto dist = lex3d::eval::compare_clouds(c, d.value().cloud);
    EXPECT_LE(dist.hausdorff, e * (1 + 1e-6));
    EXPECT_FALSE(d.value().cloud.has_rings());  // the profile's lasers are not an attribute of the input
  }
  // Words only: a profile has no layer to serve.
  lex3d::CompressOptions words;
  words.sensor_profile = p;
  EXPECT_THROW(words.validate(), std::invalid_argument);
  // A scan of another sensor: bad data, nothing coded.
  lex3d::CompressOptions other;
  other.max_error = 0.014;
  other.sensor_profile = profile_of("velodyne_vlp_32c.json");
  auto refused = lex3d::compress(c, other);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), ErrorCode::kBadData);
}

TEST(SensorProfile, FitsTheVlp16CaptureWithItsPublishedTable) {
  const std::string path = std::string(LEX3D_SHARED_DATA_DIR) + "/velodyne/vlp16_velodyne_vlp16.pcap";
  if (!std::ifstream(path)) GTEST_SKIP() << "shared data not available: " << path;
  auto read = lex3d::io::read_cloud(path);
  ASSERT_TRUE(read.ok()) << read.status().to_string();
  Cloud c = read.value().cloud;
  const std::vector<std::uint16_t> rings = c.ring;  // the reader's lasers, lowest elevation first
  c.ring.clear();
  c.column.clear();
  c.geometry.reset();
  c.rows = c.columns = 0;
  // VLP-16 (user manual): laser l at elevation -15 + 2 l (even l) or 1 + 2 (l - 1) (odd l),
  // fired 2.304 us apart.
  std::ostringstream j;
  j << R"({"sensor": "VLP-16", "range_step": 0.002, "lasers": [)";
  for (int l = 0; l < 16; ++l)
    j << (l ? "," : "") << R"({"elevation_deg": )" << (l % 2 == 0 ? -15 + l : l) << R"(, "fire_us": )" << 2.304 * l << "}";
  j << "]}";
  auto p = parse_sensor_profile(j.str(), "vlp16.json");
  ASSERT_TRUE(p.ok()) << p.status().to_string();
  auto fit = apply_sensor_profile(c, p.value(), "vlp16");
  ASSERT_TRUE(fit.ok()) << fit.status().to_string();
  EXPECT_EQ(fit.value().lasers_hit, 16U);
  // the same lasers as the reader's (which numbers them by elevation)
  std::map<std::uint16_t, std::uint16_t> to_reader;
  std::size_t same = 0;
  for (std::size_t i = 0; i < c.size(); ++i) {
    const auto [it, fresh] = to_reader.emplace(c.ring[i], rings[i]);
    same += it->second == rings[i];
  }
  EXPECT_GE(same, c.size() * 999 / 1000);
  lex3d::CompressOptions o;
  o.max_error = 0.014;
  o.sensor_profile = p.value();
  auto r = lex3d::compress(read.value().cloud, o);
  ASSERT_TRUE(r.ok()) << r.status().to_string();
  auto d = lex3d::decompress(r.value().bytes);
  ASSERT_TRUE(d.ok());
  EXPECT_LE(lex3d::eval::compare_clouds(read.value().cloud, d.value().cloud).hausdorff, 0.014 * (1 + 1e-6));
}
