// A Cloud as bytes and back (lex3d/codec/cloud_bytes.hpp): every member survives, a real
// capture's turn comes back equal, and bytes that are not a cloud (truncated at every length,
// altered bytes, counts beyond the bytes, another version) give an error, never a crash.

#include <gtest/gtest.h>

#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include "lex3d/codec/cloud_bytes.hpp"
#include "lex3d/io/sensor_log.hpp"
#include "support/test_support.hpp"

namespace lex3d::codec {
namespace {

using Bytes = std::vector<std::uint8_t>;

Pose pose(double a, double x) {
  Pose T = Pose::Identity();
  T.rotate(Eigen::AngleAxisd(a, Eigen::Vector3d(0.2, -0.3, 1.0).normalized()));
  T.translation() = Eigen::Vector3d(x, -2.0 * x, 0.25);
  return T;
}

/// A cloud with every member set to something other than its default.
Cloud full_cloud() {
  Cloud c;
  c.points = {{1.0F, 2.0F, 3.0F}, {-4.5F, 0.0F, 1e-7F}, {7.0F, -8.0F, 9.25F}};
  c.intensity = {0.5F, 100.0F, -1.0F};
  c.no_return_directions = {{0.0F, 0.0F, 1.0F}};
  c.T_cloud_sensor = pose(0.3, 1.5);
  c.T_world_cloud = pose(-1.1, 100.0);
  c.has_world_pose = true;
  c.ring = {0, 63, 7};
  c.column = {0, 2047, 12};
  c.rows = 64;
  c.columns = 2048;
  c.time = {0.0, 0.05, 1e-9};
  c.ring_source = {"ring", FieldType::kUint8};
  c.intensity_source = {"reflectivity", FieldType::kUint16};
  c.time_source = {"t", FieldType::kUint32};
  c.rgb = {{{1, 2, 3}}, {{255, 0, 128}}, {{9, 9, 9}}};
  SensorGeometry g;
  g.elevation = {0.1, -0.2};
  g.beam_azimuth = {0.01, -0.01};
  g.column_azimuth = {0.0, 0.003};
  g.z_offset = {0.03, 0.0};
  g.radial_offset = {0.015, 0.015};
  g.columns = 2048;
  g.azimuth0 = 3.14;
  g.direction = -1;
  g.T_sensor_head = pose(0.7, 0.036);
  g.source = "metadata";
  g.sensor = "OS-1-64";
  c.geometry = g;
  Georeference r;
  r.origin = {500000.25, 5403850.5, 120.0};
  r.unit_m = 0.3048;
  r.unit_name = "foot";
  r.vertical_unit_m = 1200.0 / 3937.0;
  r.crs_name = "NAD83 / Oregon GIC Lambert (ft)";
  r.epsg = 2992;
  r.crs_records = {{"LASF_Projection", 34735, "GeoKeys", {1, 2, 3, 0, 255}, false},
                   {"LASF_Projection", 2112, "WKT", {'P', 'R', 'O', 'J'}, true}};
  r.las_scale = {0.01, 0.01, 0.001};
  r.las_offset = {-0.0, 5e6, 0.0};
  r.las_version_minor = 4;
  r.las_point_format = 7;
  r.las_global_encoding = 17;
  r.las_system_id = "lidar";
  r.las_software = "lex3d";
  r.representation_error_m = 1.5e-4;
  c.georef = r;
  c.stamp = ScanStamp{ScanStamp::Source::kCapture, 1700000000ULL, 999999999U, "os_sensor"};
  c.fields = {{"classification", {2, 5, 31}, FieldType::kUint8},
              {"near_ir", {0, 65535, 12}, FieldType::kUint16},
              {"scan_angle", {float_key(-12.5F), float_key(0.0F), float_key(3.0F)}, FieldType::kFloat32},
              {"legacy", {-7, 0, 7}, FieldType::kUnspecified}};
  return c;
}

void expect_same_pose(const Pose& a, const Pose& b) { EXPECT_EQ(a.matrix(), b.matrix()); }

void expect_same(const Cloud& a, const Cloud& b) {
  EXPECT_EQ(a.points, b.points);
  EXPECT_EQ(a.intensity, b.intensity);
  EXPECT_EQ(a.no_return_directions, b.no_return_directions);
  expect_same_pose(a.T_cloud_sensor, b.T_cloud_sensor);
  expect_same_pose(a.T_world_cloud, b.T_world_cloud);
  EXPECT_EQ(a.has_world_pose, b.has_world_pose);
  EXPECT_EQ(a.ring, b.ring);
  EXPECT_EQ(a.column, b.column);
  EXPECT_EQ(a.rows, b.rows);
  EXPECT_EQ(a.columns, b.columns);
  EXPECT_EQ(a.time, b.time);
  for (auto [x, y] : {std::pair{&a.ring_source, &b.ring_source}, std::pair{&a.intensity_source, &b.intensity_source},
                      std::pair{&a.time_source, &b.time_source}}) {
    EXPECT_EQ(x->name, y->name);
    EXPECT_EQ(x->type, y->type);
  }
  EXPECT_EQ(a.rgb, b.rgb);
  ASSERT_EQ(a.geometry.has_value(), b.geometry.has_value());
  if (a.geometry) {
    const SensorGeometry &g = *a.geometry, &h = *b.geometry;
    EXPECT_EQ(g.elevation, h.elevation);
    EXPECT_EQ(g.beam_azimuth, h.beam_azimuth);
    EXPECT_EQ(g.column_azimuth, h.column_azimuth);
    EXPECT_EQ(g.z_offset, h.z_offset);
    EXPECT_EQ(g.radial_offset, h.radial_offset);
    EXPECT_EQ(g.columns, h.columns);
    EXPECT_EQ(g.azimuth0, h.azimuth0);
    EXPECT_EQ(g.direction, h.direction);
    expect_same_pose(g.T_sensor_head, h.T_sensor_head);
    EXPECT_EQ(g.source, h.source);
    EXPECT_EQ(g.sensor, h.sensor);
  }
  ASSERT_EQ(a.georef.has_value(), b.georef.has_value());
  if (a.georef) {
    test::expect_same_georef(*b.georef, *a.georef);
    EXPECT_EQ(a.georef->las_global_encoding, b.georef->las_global_encoding);
    EXPECT_EQ(a.georef->representation_error_m, b.georef->representation_error_m);
  }
  ASSERT_EQ(a.stamp.has_value(), b.stamp.has_value());
  if (a.stamp) {
    EXPECT_EQ(a.stamp->source, b.stamp->source);
    EXPECT_EQ(a.stamp->sec, b.stamp->sec);
    EXPECT_EQ(a.stamp->nsec, b.stamp->nsec);
    EXPECT_EQ(a.stamp->frame_id, b.stamp->frame_id);
  }
  ASSERT_EQ(a.fields.size(), b.fields.size());
  for (std::size_t k = 0; k < a.fields.size(); ++k) {
    EXPECT_EQ(a.fields[k].name, b.fields[k].name);
    EXPECT_EQ(a.fields[k].type, b.fields[k].type);
    EXPECT_EQ(a.fields[k].values, b.fields[k].values);
  }
}

TEST(CloudBytes, EveryMemberComesBack) {
  const Cloud c = full_cloud();
  const Bytes b = cloud_to_bytes(c);
  auto back = cloud_from_bytes(b.data(), b.size());
  ASSERT_TRUE(back.ok()) << back.status().to_string();
  expect_same(c, back.value());
  EXPECT_EQ(cloud_to_bytes(back.value()), b);  // and writes the same bytes again
}

TEST(CloudBytes, AnEmptyCloudAndOneWithoutOptionalMembers) {
  for (const Cloud& c : {Cloud{}, [] {
                           Cloud x;
                           x.points = {{1.0F, 1.0F, 1.0F}};
                           return x;
                         }()}) {
    const Bytes b = cloud_to_bytes(c);
    auto back = cloud_from_bytes(b.data(), b.size());
    ASSERT_TRUE(back.ok()) << back.status().to_string();
    expect_same(c, back.value());
  }
}

TEST(CloudBytes, ACapturesTurnComesBackEqual) {
  const std::string pcap = std::string(LEX3D_SAMPLES_DIR) + "/vlp16_velodyne_example.pcap";
  auto reader = io::SensorLogReader::open(pcap);
  ASSERT_TRUE(reader.ok()) << reader.status().to_string();
  auto turn = reader.value()->next();
  ASSERT_TRUE(turn.ok() && turn.value()) << turn.status().to_string();
  const Cloud& c = turn.value()->cloud;
  ASSERT_TRUE(c.geometry && c.has_rings() && c.has_columns() && c.has_time() && c.stamp);
  const Bytes b = cloud_to_bytes(c);
  auto back = cloud_from_bytes(b.data(), b.size());
  ASSERT_TRUE(back.ok()) << back.status().to_string();
  expect_same(c, back.value());
}

TEST(CloudBytes, EveryTruncationIsAnError) {
  const Bytes b = cloud_to_bytes(full_cloud());
  for (std::size_t n = 0; n < b.size(); ++n) {
    auto r = cloud_from_bytes(b.data(), n);
    ASSERT_FALSE(r.ok()) << n;
    EXPECT_EQ(r.status().code(), ErrorCode::kBadData);
    EXPECT_EQ(r.status().message().find('\n'), std::string::npos);
  }
  Bytes longer = b;
  longer.push_back(0);
  auto r = cloud_from_bytes(longer.data(), longer.size());
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("1 bytes after the cloud"), std::string::npos) << r.status().message();
}

TEST(CloudBytes, AnotherVersionAndHugeCountsAreRefused) {
  Bytes b = cloud_to_bytes(full_cloud());
  b[4] = 2;
  auto r = cloud_from_bytes(b.data(), b.size());
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("version 2"), std::string::npos) << r.status().message();
  b = cloud_to_bytes(full_cloud());
  for (int k = 0; k < 8; ++k) b[5 + static_cast<std::size_t>(k)] = 0xFF;  // the point count
  r = cloud_from_bytes(b.data(), b.size());
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("a count beyond the bytes in points"), std::string::npos) << r.status().message();
}

TEST(CloudBytes, AnArrayOfTheWrongLengthIsRefused) {
  Cloud c = full_cloud();
  c.intensity.pop_back();  // 2 values for 3 points
  const Bytes b = cloud_to_bytes(c);
  auto r = cloud_from_bytes(b.data(), b.size());
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("intensity holds 2 values for 3 points"), std::string::npos) << r.status().message();
}

TEST(CloudBytes, AlteredBytesNeverCrash) {
  const Bytes b = cloud_to_bytes(full_cloud());
  std::mt19937 rng(7);
  int refused = 0;
  for (int trial = 0; trial < 20000; ++trial) {
    Bytes m = b;
    const int edits = 1 + static_cast<int>(rng() % 4);
    for (int e = 0; e < edits; ++e) m[5 + rng() % (m.size() - 5)] = static_cast<std::uint8_t>(rng());
    auto r = cloud_from_bytes(m.data(), m.size());
    if (!r.ok()) {
      ++refused;
      continue;
    }
    // what reads back writes back to the bytes it came from (nothing invented or lost)
    EXPECT_EQ(cloud_to_bytes(r.value()), m) << trial;
  }
  EXPECT_GT(refused, 0);
}

}  // namespace
}  // namespace lex3d::codec
