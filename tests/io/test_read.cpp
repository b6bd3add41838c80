// Reading: real data from ../shared/data, small fixtures from tests/data/io,
// format detection and the pose/number lists.

#include <chrono>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "lex3d/io/io.hpp"
#include "support/test_support.hpp"

namespace lex3d::io {
namespace {

using test::write_bytes;

using test::has_shared_data;
using test::shared_data;
using test::temp_dir;

std::string fixture(const std::string& name) { return std::string(LEX3D_TEST_DATA_DIR) + "/io/" + name; }

ReadResult read_ok(const std::string& path, const ReadOptions& options = {}) {
  auto r = read_cloud(path, options);
  EXPECT_TRUE(r.ok()) << path << ": " << r.status().to_string();
  if (!r.ok()) return {};
  return std::move(r).value();
}

std::string floats_le(const std::vector<float>& v) {
  std::string s(v.size() * 4, '\0');
  std::memcpy(s.data(), v.data(), s.size());  // the test machine is little-endian
  return s;
}

float max_range(const Cloud& c) {
  float m = 0.0F;
  for (const auto& p : c.points) m = std::max(m, p.norm());
  return m;
}

// ------------------------------------------------------------------ real data

TEST(ReadReal, KittiBin) {
  LEX3D_REQUIRE_SHARED("kitti00/000000.bin");
  const ReadResult r = read_ok(shared_data("kitti00/000000.bin"));
  EXPECT_EQ(r.format, Format::kKitti);
  EXPECT_EQ(r.cloud.size(), 124668U);
  EXPECT_EQ(r.non_finite_dropped, 0U);
  EXPECT_EQ(r.file_bytes, 124668U * 16U);
  ASSERT_TRUE(r.cloud.has_intensity());
  float imin = 1e9F, imax = -1e9F;
  for (float i : r.cloud.intensity) {
    imin = std::min(imin, i);
    imax = std::max(imax, i);
  }
  EXPECT_GE(imin, 0.0F);
  EXPECT_LE(imax, 1.0F);
  EXPECT_GT(imax, 0.5F);
  // HDL-64E: returns out to ~120 m, first point about 52.9 m ahead
  EXPECT_GT(max_range(r.cloud), 50.0F);
  EXPECT_LT(max_range(r.cloud), 130.0F);
  EXPECT_FLOAT_EQ(r.cloud.points[0].x(), 52.89794F);
  EXPECT_FLOAT_EQ(r.cloud.intensity[0], 0.08F);
  EXPECT_FALSE(r.cloud.has_world_pose);
}

TEST(ReadReal, KittiBinIsFast) {
  LEX3D_REQUIRE_SHARED("kitti00/000000.bin");
  const std::string path = shared_data("kitti00/000000.bin");
  (void)read_cloud(path);  // warm the page cache
  constexpr int kRuns = 10;
  const auto t0 = std::chrono::steady_clock::now();
  std::size_t total = 0;
  for (int i = 0; i < kRuns; ++i) {
    auto r = read_cloud(path);
    ASSERT_TRUE(r.ok());
    total += r.value().cloud.size();
  }
  const double ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count() / kRuns;
  EXPECT_EQ(total, 124668U * kRuns);
  std::printf("[ timing ] read kitti00/000000.bin: %.2f ms per read\n", ms);
  RecordProperty("kitti_read_ms", std::to_string(ms));
  EXPECT_LT(ms, 250.0);  // generous: sanitizer builds and a busy machine
}

TEST(ReadReal, BalmBin) {
  LEX3D_REQUIRE_SHARED("balm/000000.bin");
  const ReadResult r = read_ok(shared_data("balm/000000.bin"));
  EXPECT_EQ(r.format, Format::kKitti);
  EXPECT_EQ(r.cloud.size(), 73452U);
  ASSERT_TRUE(r.cloud.has_intensity());
  for (float i : r.cloud.intensity) ASSERT_GE(i, 0.0F);
  EXPECT_GT(max_range(r.cloud), 5.0F);
  EXPECT_LT(max_range(r.cloud), 200.0F);
}

TEST(ReadReal, NewerCollegeIsDetectedAsBinXyz) {
  LEX3D_REQUIRE_SHARED("newer_college/raw_00.bin");
  const std::string path = shared_data("newer_college/raw_00.bin");
  auto f = detect_format(path);
  ASSERT_TRUE(f.ok()) << f.status().to_string();
  EXPECT_EQ(f.value(), Format::kBinXyz);
  const ReadResult r = read_ok(path);
  EXPECT_EQ(r.format, Format::kBinXyz);
  EXPECT_EQ(r.cloud.size(), 25109U);
  EXPECT_FALSE(r.cloud.has_intensity());
  EXPECT_FLOAT_EQ(r.cloud.points[0].x(), 42.374413F);
  EXPECT_LT(max_range(r.cloud), 200.0F);
}

TEST(ReadReal, RoomScanPcdBinaryCompressed) {
  LEX3D_REQUIRE_SHARED("indoor/room_scan1.pcd");
  const ReadResult r = read_ok(shared_data("indoor/room_scan1.pcd"));
  EXPECT_EQ(r.format, Format::kPcd);
  EXPECT_EQ(r.encoding, "binary_compressed");
  EXPECT_EQ(r.cloud.size() + r.non_finite_dropped, 112586U);
  EXPECT_EQ(r.cloud.size(), 112586U);
  EXPECT_FALSE(r.cloud.has_intensity());
  EXPECT_TRUE(r.colors.empty());
  const float m = max_range(r.cloud);
  EXPECT_GT(m, 1.0F);
  EXPECT_LT(m, 50.0F);  // a room
}

TEST(ReadReal, Uos3dWithNoReturnsAndPose) {
  LEX3D_REQUIRE_SHARED("indoor/scan000.3d");
  const std::string path = shared_data("indoor/scan000.3d");
  ReadOptions o;
  o.uos_no_return_cm = 3200.0F;
  const ReadResult r = read_ok(path, o);
  EXPECT_EQ(r.format, Format::kUos3d);
  EXPECT_EQ(r.no_return_dropped, 1492U);
  EXPECT_EQ(r.cloud.no_return_directions.size(), 1492U);
  EXPECT_EQ(r.cloud.size() + r.no_return_dropped + r.non_finite_dropped, 81360U);
  for (const auto& d : r.cloud.no_return_directions) ASSERT_NEAR(d.norm(), 1.0F, 1e-5F);
  // first line "10.1 0 0" (cm, x right) -> 0.101 m to the right = -y in lex3d's frame
  EXPECT_NEAR(r.cloud.points[0].x(), 0.0F, 1e-7F);
  EXPECT_NEAR(r.cloud.points[0].y(), -0.101F, 1e-6F);
  EXPECT_NEAR(r.cloud.points[0].z(), 0.0F, 1e-7F);
  EXPECT_LT(max_range(r.cloud), 32.0F);
  // scan000.pose is all zeros
  EXPECT_TRUE(r.cloud.has_world_pose);
  EXPECT_TRUE(r.cloud.T_world_cloud.matrix().isApprox(Eigen::Matrix4d::Identity()));

  // the default threshold (3270 cm) keeps the 11 far real returns at ~32.3 m
  const ReadResult d = read_ok(path);
  EXPECT_EQ(d.no_return_dropped, 1481U);
  EXPECT_EQ(d.cloud.size(), 81360U - 1481U);
}

TEST(ReadReal, Uos3dPoseIsConvertedToRightHandedMetres) {
  LEX3D_REQUIRE_SHARED("indoor/scan001.3d");
  const ReadResult r = read_ok(shared_data("indoor/scan001.3d"));
  ASSERT_TRUE(r.cloud.has_world_pose);
  // scan001.pose line 1: -3.10605 -7.50803 156.917 (cm, x right, y up, z forward)
  const Eigen::Vector3d t = r.cloud.T_world_cloud.translation();
  EXPECT_NEAR(t.x(), 1.56917, 1e-9);
  EXPECT_NEAR(t.y(), 0.0310605, 1e-9);
  EXPECT_NEAR(t.z(), -0.0750803, 1e-9);
  const Eigen::Matrix3d R = r.cloud.T_world_cloud.linear();
  EXPECT_TRUE((R.transpose() * R).isApprox(Eigen::Matrix3d::Identity(), 1e-12));
  EXPECT_NEAR(R.determinant(), 1.0, 1e-12);

  ReadOptions no_pose;
  no_pose.load_pose = false;
  EXPECT_FALSE(read_ok(shared_data("indoor/scan001.3d"), no_pose).cloud.has_world_pose);
}

TEST(ReadReal, KittiPoseListAndTimes) {
  LEX3D_REQUIRE_SHARED("kitti00/poses.txt");
  auto poses = read_pose_list(shared_data("kitti00/poses.txt"));
  ASSERT_TRUE(poses.ok()) << poses.status().to_string();
  ASSERT_EQ(poses.value().size(), 10U);
  EXPECT_TRUE(poses.value()[0].matrix().isApprox(Eigen::Matrix4d::Identity(), 1e-6));
  for (const Pose& p : poses.value()) {
    EXPECT_TRUE((p.linear().transpose() * p.linear()).isApprox(Eigen::Matrix3d::Identity(), 1e-12));
  }
  EXPECT_NEAR(poses.value()[1].translation().z(), 0.672716, 1e-9);
  auto times = read_number_list(shared_data("kitti00/times.txt"));
  ASSERT_TRUE(times.ok()) << times.status().to_string();
  ASSERT_EQ(times.value().size(), 10U);
  EXPECT_DOUBLE_EQ(times.value()[1], 0.1037359);
}

TEST(ReadReal, BalmPoseList) {
  LEX3D_REQUIRE_SHARED("balm/poses.txt");
  auto poses = read_pose_list(shared_data("balm/poses.txt"));
  ASSERT_TRUE(poses.ok()) << poses.status().to_string();
  EXPECT_EQ(poses.value().size(), 89U);
}

// ------------------------------------------------------------------ fixtures

TEST(ReadFixture, BigEndianPly) {
  const ReadResult r = read_ok(fixture("big_endian.ply"));
  EXPECT_EQ(r.format, Format::kPly);
  EXPECT_EQ(r.encoding, "binary_big_endian");
  ASSERT_EQ(r.cloud.size(), 3U);
  EXPECT_EQ(r.cloud.points[0], Eigen::Vector3f(1.5F, -2.25F, 3.0F));
  EXPECT_EQ(r.cloud.points[1], Eigen::Vector3f(-0.125F, 4.0F, 1e-3F));
  EXPECT_EQ(r.cloud.points[2], Eigen::Vector3f(100.0F, 200.5F, -300.25F));
  ASSERT_TRUE(r.cloud.has_intensity());
  EXPECT_EQ(r.cloud.intensity[1], 1.0F);
  ASSERT_EQ(r.colors.size(), 3U);
  EXPECT_EQ(r.colors[0], (std::array<std::uint8_t, 3>{10, 20, 30}));
  EXPECT_EQ(r.colors[1], (std::array<std::uint8_t, 3>{255, 0, 7}));
}

TEST(ReadFixture, PlyWithExtraPropertiesAndDoubleCoordinates) {
  const ReadResult r = read_ok(fixture("extra_props_double.ply"));
  EXPECT_EQ(r.encoding, "binary_little_endian");
  EXPECT_EQ(r.non_finite_dropped, 1U);  // the NaN vertex
  ASSERT_EQ(r.cloud.size(), 3U);
  EXPECT_EQ(r.cloud.points[0], Eigen::Vector3f(0.1F, 0.2F, 0.3F));
  EXPECT_EQ(r.cloud.points[2], Eigen::Vector3f(static_cast<float>(12345.678), 0.0F, -0.5F));
  ASSERT_TRUE(r.cloud.has_intensity());  // scalar_intensity
  EXPECT_EQ(r.cloud.intensity[2], 0.5F);
  EXPECT_TRUE(r.colors.empty());
}

TEST(ReadFixture, AsciiPlyWithFaces) {
  const ReadResult r = read_ok(fixture("ascii_faces.ply"));
  EXPECT_EQ(r.encoding, "ascii");
  ASSERT_EQ(r.cloud.size(), 3U);
  EXPECT_EQ(r.cloud.points[2], Eigen::Vector3f(0.0F, 1.5F, -2.0F));
  EXPECT_FALSE(r.cloud.has_intensity());
}

TEST(ReadFixture, PcdWithExtraFields) {
  const ReadResult r = read_ok(fixture("extra_fields.pcd"));
  EXPECT_EQ(r.format, Format::kPcd);
  EXPECT_EQ(r.encoding, "ascii");
  EXPECT_EQ(r.non_finite_dropped, 1U);
  ASSERT_EQ(r.cloud.size(), 3U);
  EXPECT_EQ(r.cloud.points[1], Eigen::Vector3f(-1.5F, 2.25F, -3.0F));
  ASSERT_TRUE(r.cloud.has_intensity());
  EXPECT_EQ(r.cloud.intensity[2], 7.0F);
}

TEST(ReadFixture, UnsignedThirtyTwoBitFieldsAreKeptWhileTheyFitIn31Bits) {
  // An Ouster driver's `range` (u32 millimetres) is kept; a u32 `label` with a value of
  // 2^31 or more cannot be an int32 field: it is dropped and named, whatever the encoding.
  const auto dir = temp_dir("u32_fields");
  const auto expect_fields = [](const ReadResult& r, const std::string& what) {
    ASSERT_EQ(r.cloud.size(), 2U) << what;
    const IntegerField* range = r.cloud.field("range");
    ASSERT_NE(range, nullptr) << what;
    EXPECT_EQ(range->values, (std::vector<std::int32_t>{12345, 2147483647})) << what;
    EXPECT_EQ(r.cloud.field("label"), nullptr) << what;
    ASSERT_EQ(r.dropped_fields.size(), 1U) << what;
    EXPECT_EQ(r.dropped_fields[0], "label (values above 2^31 - 1)") << what;
  };
  const std::string head = "VERSION 0.7\nFIELDS x y z range label\nSIZE 4 4 4 4 4\nTYPE F F F U U\n"
                           "WIDTH 2\nHEIGHT 1\nPOINTS 2\nDATA ";
  write_bytes((dir / "a.pcd").string(), head + "ascii\n1 2 3 12345 7\n4 5 6 2147483647 3000000000\n");
  expect_fields(read_ok((dir / "a.pcd").string()), "ascii PCD");
  std::string binary = head + "binary\n";
  const auto put = [&](auto v) { binary.append(reinterpret_cast<const char*>(&v), sizeof v); };
  put(1.0F), put(2.0F), put(3.0F), put(std::uint32_t{12345}), put(std::uint32_t{7});
  put(4.0F), put(5.0F), put(6.0F), put(std::uint32_t{2147483647}), put(std::uint32_t{3000000000U});
  write_bytes((dir / "b.pcd").string(), binary);
  expect_fields(read_ok((dir / "b.pcd").string()), "binary PCD");
  write_bytes((dir / "c.ply").string(),
              "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\n"
              "property uint range\nproperty uint label\nend_header\n1 2 3 12345 7\n4 5 6 2147483647 3000000000\n");
  expect_fields(read_ok((dir / "c.ply").string()), "ascii PLY");
}

TEST(ReadFixture, PcdViewpointIsTheSensorPose) {
  // PCL's VIEWPOINT (tx ty tz qw qx qy qz): the sensor pose in the points' frame.
  const auto dir = temp_dir("pcd_viewpoint");
  const std::string path = (dir / "world.pcd").string();
  write_bytes(path,
              "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1\nHEIGHT 1\n"
              "VIEWPOINT 10 -5 2.5 0.70710678118654757 0 0 0.70710678118654757\nPOINTS 1\nDATA ascii\n1 2 3\n");
  const ReadResult r = read_ok(path);
  ASSERT_EQ(r.cloud.size(), 1U);
  EXPECT_TRUE(r.cloud.T_cloud_sensor.translation().isApprox(Eigen::Vector3d(10.0, -5.0, 2.5)));
  // A quarter turn about z: the sensor's x axis is the cloud's y axis.
  EXPECT_TRUE((r.cloud.T_cloud_sensor.linear() * Eigen::Vector3d::UnitX()).isApprox(Eigen::Vector3d::UnitY(), 1e-12));
  // Written back, read again: the same pose.
  const std::string out = (dir / "again.pcd").string();
  ASSERT_TRUE(write_cloud(out, r.cloud).ok());
  const ReadResult back = read_ok(out);
  EXPECT_TRUE(back.cloud.T_cloud_sensor.isApprox(r.cloud.T_cloud_sensor, 1e-15));
  // The identity stays as PCL writes it, and is what a file without VIEWPOINT gets.
  const ReadResult plain = read_ok(fixture("extra_fields.pcd"));
  EXPECT_TRUE(plain.cloud.T_cloud_sensor.isApprox(Pose::Identity()));
}

TEST(ReadFixture, OrganizedPcdWithNaNsAndMixedTypes) {
  const ReadResult r = read_ok(fixture("organized_nan.pcd"));
  EXPECT_EQ(r.encoding, "binary");
  // An organised cloud's NaN holes (at 2 and 7) are the sensor's no-returns, not bad points.
  EXPECT_EQ(r.non_finite_dropped, 0U);
  EXPECT_EQ(r.no_return_dropped, 2U);
  ASSERT_EQ(r.cloud.size(), 10U);
  EXPECT_GT(r.cloud.rows, 1U);
  EXPECT_EQ(static_cast<std::size_t>(r.cloud.rows) * r.cloud.columns, 12U);
  ASSERT_TRUE(r.cloud.has_rings());
  EXPECT_EQ(r.cloud.ring[2], 0U);
  EXPECT_EQ(r.cloud.column[2], 3U);
  // point 3 (row 0, column 3): x = 1.5, y = 0, z = 4; intensity U2 = 103; rgb = (3, 6, 9)
  EXPECT_EQ(r.cloud.points[2], Eigen::Vector3f(1.5F, 0.0F, 4.0F));
  ASSERT_TRUE(r.cloud.has_intensity());
  EXPECT_EQ(r.cloud.intensity[2], 103.0F);
  ASSERT_EQ(r.colors.size(), 10U);
  EXPECT_EQ(r.colors[2], (std::array<std::uint8_t, 3>{3, 6, 9}));
  // last point (11): row 2, column 3
  EXPECT_EQ(r.cloud.points[9], Eigen::Vector3f(1.5F, -0.5F, 12.0F));
}

TEST(ReadFixture, XyzTextWithCommentsCommasAndTabs) {
  const ReadResult r = read_ok(fixture("mixed.xyz"));
  EXPECT_EQ(r.format, Format::kXyz);
  ASSERT_EQ(r.cloud.size(), 4U);
  EXPECT_EQ(r.cloud.points[0], Eigen::Vector3f(1.5F, 2.5F, 3.5F));
  EXPECT_EQ(r.cloud.points[1], Eigen::Vector3f(-1.0F, -2.0F, -3.0F));
  EXPECT_EQ(r.cloud.points[2], Eigen::Vector3f(4.0F, 5.0F, 6.0F));
  EXPECT_EQ(r.cloud.points[3], Eigen::Vector3f(7.0F, 8.0F, 9.0F));
  EXPECT_FALSE(r.cloud.has_intensity());
}

TEST(ReadFixture, Uos3dAxesUnitsNoReturnAndPose) {
  const ReadResult r = read_ok(fixture("tiny.3d"));
  EXPECT_EQ(r.format, Format::kUos3d);
  ASSERT_EQ(r.cloud.size(), 4U);
  EXPECT_EQ(r.no_return_dropped, 1U);
  // x right -> -y; y up -> z; z forward -> x; cm -> m
  EXPECT_TRUE(r.cloud.points[0].isApprox(Eigen::Vector3f(0.0F, -1.0F, 0.0F)));
  EXPECT_TRUE(r.cloud.points[1].isApprox(Eigen::Vector3f(0.0F, 0.0F, 2.0F)));
  EXPECT_TRUE(r.cloud.points[2].isApprox(Eigen::Vector3f(3.0F, 0.0F, 0.0F)));
  EXPECT_TRUE(r.cloud.points[3].isApprox(Eigen::Vector3f(0.3F, -0.1F, 0.2F)));
  ASSERT_EQ(r.cloud.no_return_directions.size(), 1U);
  EXPECT_TRUE(r.cloud.no_return_directions[0].isApprox(Eigen::Vector3f(0.0F, -1.0F, 0.0F)));
  // tiny.pose: t = (100, 200, 300) cm, ry = 90 deg (about 3DTK's up axis = lex3d's z)
  ASSERT_TRUE(r.cloud.has_world_pose);
  const Pose& T = r.cloud.T_world_cloud;
  EXPECT_TRUE(T.translation().isApprox(Eigen::Vector3d(3.0, -1.0, 2.0)));
  // 3DTK: Ry(90) maps forward (z) to right (x); in lex3d: x -> -y
  EXPECT_TRUE((T.linear() * Eigen::Vector3d::UnitX()).isApprox(-Eigen::Vector3d::UnitY(), 1e-12));
  EXPECT_TRUE((T.linear() * Eigen::Vector3d::UnitZ()).isApprox(Eigen::Vector3d::UnitZ(), 1e-12));
  // consistency with the raw 3DTK transform: p_w = R p + t in the 3DTK frame, p = (10, 20, 30)
  // Ry(90) * (10, 20, 30) = (30, 20, -10); + t = (130, 220, 290) -> lex3d (2.9, -1.3, 2.2)
  const Eigen::Vector3d pw = T * r.cloud.points[3].cast<double>();
  EXPECT_TRUE(pw.isApprox(Eigen::Vector3d(2.9, -1.3, 2.2), 1e-6)) << pw.transpose();
}

TEST(ReadFixture, FormatOverrideReadsTextAsUos) {
  ReadOptions o;
  o.format = Format::kUos3d;
  o.load_pose = false;
  const ReadResult r = read_ok(fixture("mixed.xyz"), o);
  EXPECT_EQ(r.format, Format::kUos3d);
  ASSERT_EQ(r.cloud.size(), 4U);
  EXPECT_TRUE(r.cloud.points[0].isApprox(Eigen::Vector3f(0.035F, -0.015F, 0.025F)));
}

// ------------------------------------------------------------------ text details

TEST(ReadText, FourColumnsAreIntensityAndHeaderNamesColumns) {
  const auto dir = temp_dir("read_text_cols");
  const std::string a = (dir / "a.txt").string();
  write_bytes(a, "1 2 3 0.5\n4 5 6 0.25\n");
  ReadResult r = read_ok(a);
  ASSERT_TRUE(r.cloud.has_intensity());
  EXPECT_EQ(r.cloud.intensity[1], 0.25F);

  const std::string b = (dir / "b.csv").string();
  write_bytes(b, "X,Y,Z,R,G,B,Intensity\n1,2,3,10,20,30,0.75\n");
  r = read_ok(b);
  ASSERT_EQ(r.cloud.size(), 1U);
  ASSERT_TRUE(r.cloud.has_intensity());
  EXPECT_EQ(r.cloud.intensity[0], 0.75F);

  const std::string c = (dir / "c.xyz").string();
  write_bytes(c, "1 2 3 4 5 6\n");
  r = read_ok(c);
  EXPECT_FALSE(r.cloud.has_intensity());
}

TEST(ReadText, NonFiniteValuesAreDroppedAndCounted) {
  const auto dir = temp_dir("read_text_nan");
  const std::string a = (dir / "a.xyz").string();
  write_bytes(a, "1 2 3\nnan 0 0\n0 inf 0\n0 0 -inf\n+4 5e0 .5\n1e39 0 0\n");
  const ReadResult r = read_ok(a);
  EXPECT_EQ(r.non_finite_dropped, 4U);  // 1e39 overflows a float
  ASSERT_EQ(r.cloud.size(), 2U);
  EXPECT_EQ(r.cloud.points[1], Eigen::Vector3f(4.0F, 5.0F, 0.5F));
}

TEST(ReadText, PointsBeyondAnyLidarAreDroppedAndCounted) {
  const auto dir = temp_dir("read_text_far");
  const std::string a = (dir / "a.xyz").string();
  std::string text;
  for (int i = 0; i < 200; ++i) text += std::to_string(i % 20) + " " + std::to_string(i / 20) + " 1 0." + std::to_string(i % 10) + "\n";
  text += "1e30 1e30 1e30 0.5\n20000 0 0 0.5\n";  // 1e30 m and 20 km: no lidar measures either
  write_bytes(a, text);
  const ReadResult r = read_ok(a);
  EXPECT_EQ(r.far_dropped, 2U);
  EXPECT_EQ(r.far_limit_m, 1e4);  // the cloud spans ~30 m: the 10 km floor applies
  ASSERT_EQ(r.cloud.size(), 200U);
  ASSERT_TRUE(r.cloud.has_intensity());
  EXPECT_EQ(r.cloud.intensity[199], 0.9F);  // channels stay in step
  ASSERT_EQ(r.notes.size(), 1U);
  EXPECT_NE(r.notes[0].find("2 points farther than 10000 m"), std::string::npos) << r.notes[0];
  // a PCD's time and named fields stay in step too
  const std::string p = (dir / "far.pcd").string();
  std::string pcd = "VERSION 0.7\nFIELDS x y z time label\nSIZE 4 4 4 8 2\nTYPE F F F F I\nCOUNT 1 1 1 1 1\n"
                    "WIDTH 101\nHEIGHT 1\nPOINTS 101\nDATA ascii\n";
  for (int i = 0; i < 100; ++i) pcd += std::to_string(i % 10) + " " + std::to_string(i / 10) + " 1 " + std::to_string(i) + " " + std::to_string(i) + "\n";
  pcd += "30000 0 0 100 100\n";
  write_bytes(p, pcd);
  const ReadResult f = read_ok(p);
  EXPECT_EQ(f.far_dropped, 1U);
  ASSERT_EQ(f.cloud.size(), 100U);
  ASSERT_TRUE(f.cloud.has_time());
  EXPECT_EQ(f.cloud.time[99], 99.0);
  ASSERT_EQ(f.cloud.fields.size(), 1U);
  ASSERT_EQ(f.cloud.fields[0].values.size(), 100U);
  EXPECT_EQ(f.cloud.fields[0].values[99], 99);
}

TEST(ReadBin, KittiRecordsForcedToBinXyzAreRefused) {
  const auto dir = temp_dir("read_bin_kitti_as_xyz");
  const std::string a = (dir / "a.bin").string();
  std::string bytes;
  for (int i = 0; i < 48; ++i) {  // 48 x 16 bytes: also a multiple of 12
    const float v[4] = {5.0F + static_cast<float>(i), -3.0F, 1.5F, 0.25F};
    bytes.append(reinterpret_cast<const char*>(v), sizeof v);
  }
  write_bytes(a, bytes);
  ReadOptions opt;
  opt.format = Format::kBinXyz;
  const auto r = read_cloud(a, opt);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), ErrorCode::kBadData);
  EXPECT_NE(r.status().message().find("--format kitti"), std::string::npos) << r.status().message();
  opt.format = Format::kKitti;
  EXPECT_TRUE(read_cloud(a, opt).ok());
}

TEST(ReadText, CommentsOnlyIsAnEmptyCloud) {
  const auto dir = temp_dir("read_text_comments");
  const std::string a = (dir / "a.xyz").string();
  write_bytes(a, "# nothing here\n\n");
  const ReadResult r = read_ok(a);
  EXPECT_TRUE(r.cloud.empty());
}

// ------------------------------------------------------------------ detection

TEST(DetectFormat, ByExtension) {
  const auto dir = temp_dir("detect_ext");
  const std::vector<std::pair<std::string, Format>> cases = {
      {"a.xyz", Format::kXyz}, {"a.TXT", Format::kXyz}, {"a.asc", Format::kXyz},
      {"a.csv", Format::kXyz}, {"a.3d", Format::kUos3d}};
  for (const auto& [name, expected] : cases) {
    const std::string p = (dir / name).string();
    write_bytes(p, "1 2 3\n");
    auto f = detect_format(p);
    ASSERT_TRUE(f.ok()) << name;
    EXPECT_EQ(f.value(), expected) << name;
  }
  EXPECT_EQ(detect_format(fixture("extra_fields.pcd")).value(), Format::kPcd);
  EXPECT_EQ(detect_format(fixture("big_endian.ply")).value(), Format::kPly);
}

TEST(DetectFormat, ByMagicWhateverTheExtension) {
  const auto dir = temp_dir("detect_magic");
  std::ifstream in(fixture("big_endian.ply"), std::ios::binary);
  const std::string ply((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  write_bytes((dir / "cloud.dat").string(), ply);
  EXPECT_EQ(detect_format((dir / "cloud.dat").string()).value(), Format::kPly);
  write_bytes((dir / "cloud.bin").string(), ply);
  EXPECT_EQ(detect_format((dir / "cloud.bin").string()).value(), Format::kPly);
  write_bytes((dir / "p.data").string(), "VERSION 0.7\nFIELDS x y z\n");
  EXPECT_EQ(detect_format((dir / "p.data").string()).value(), Format::kPcd);
  write_bytes((dir / "numbers").string(), "# header comment\n1.0, 2.0, 3.0\n");
  EXPECT_EQ(detect_format((dir / "numbers").string()).value(), Format::kXyz);
  write_bytes((dir / "junk.foo").string(), std::string("\x01\x02\x03garbage", 10));
  auto f = detect_format((dir / "junk.foo").string());
  ASSERT_FALSE(f.ok());
  EXPECT_EQ(f.status().code(), ErrorCode::kBadData);
  EXPECT_NE(f.status().message().find("junk.foo"), std::string::npos);
}

TEST(DetectFormat, BinSizeAndIntensityRule) {
  const auto dir = temp_dir("detect_bin");
  // 48 bytes: a multiple of 16 and 12. Fourth floats non-negative -> KITTI.
  const std::string k = (dir / "k.bin").string();
  write_bytes(k, floats_le({1, 2, 3, 0.5F, 4, 5, 6, 0.0F, 7, 8, 9, 1.0F}));
  EXPECT_EQ(detect_format(k).value(), Format::kKitti);
  // Same size, a negative fourth float -> x y z.
  const std::string x = (dir / "x.bin").string();
  write_bytes(x, floats_le({1, 2, 3, -4, 5, 6, 7, 8, 9, 10, 11, 12}));
  EXPECT_EQ(detect_format(x).value(), Format::kBinXyz);
  EXPECT_EQ(read_ok(x).cloud.size(), 4U);
  // A NaN fourth float -> x y z.
  const std::string n = (dir / "n.bin").string();
  write_bytes(n, floats_le({1, 2, 3, std::numeric_limits<float>::quiet_NaN(), 5, 6, 7, 8, 9, 10, 11, 12}));
  EXPECT_EQ(detect_format(n).value(), Format::kBinXyz);
  // 32 bytes: only a multiple of 16.
  const std::string k2 = (dir / "k2.bin").string();
  write_bytes(k2, floats_le({1, 2, 3, -4, 5, 6, 7, -8}));
  EXPECT_EQ(detect_format(k2).value(), Format::kKitti);
  // 36 bytes: only a multiple of 12.
  const std::string x2 = (dir / "x2.bin").string();
  write_bytes(x2, floats_le({1, 2, 3, 4, 5, 6, 7, 8, 9}));
  EXPECT_EQ(detect_format(x2).value(), Format::kBinXyz);
  // Forcing the format overrides detection.
  ReadOptions o;
  o.format = Format::kBinXyz;
  EXPECT_EQ(read_ok(k, o).cloud.size(), 4U);
}

TEST(DetectFormat, MissingFileIsIoError) {
  auto f = detect_format("/nonexistent/dir/cloud.pcd");
  ASSERT_FALSE(f.ok());
  EXPECT_EQ(f.status().code(), ErrorCode::kIoError);
}

TEST(FormatNames, RoundTripAndAliases) {
  for (Format f : {Format::kAuto, Format::kKitti, Format::kBinXyz, Format::kPcd, Format::kPly,
                   Format::kXyz, Format::kUos3d}) {
    auto p = parse_format(format_name(f));
    ASSERT_TRUE(p.has_value());
    EXPECT_EQ(*p, f);
  }
  EXPECT_EQ(parse_format("3D"), Format::kUos3d);
  EXPECT_EQ(parse_format("PCD"), Format::kPcd);
  EXPECT_EQ(parse_format("las"), Format::kLas);
  EXPECT_FALSE(parse_format("laz").has_value());
  EXPECT_EQ(format_name(Format::kUos3d), "uos");
}

// ------------------------------------------------------------------ lists

TEST(ReadLists, PoseListReorthonormalises) {
  const auto dir = temp_dir("pose_list");
  const std::string p = (dir / "poses.txt").string();
  // a slightly non-orthonormal rotation (1e-4) and a 90-degree yaw
  write_bytes(p,
              "1.0001 0 0 1 0 1 0 2 0 0 1 3\n"
              "0 -1 0 0 1 0 0 0 0 0 1 0\n");
  auto poses = read_pose_list(p);
  ASSERT_TRUE(poses.ok()) << poses.status().to_string();
  ASSERT_EQ(poses.value().size(), 2U);
  const Pose& a = poses.value()[0];
  EXPECT_TRUE((a.linear().transpose() * a.linear()).isApprox(Eigen::Matrix3d::Identity(), 1e-12));
  EXPECT_TRUE(a.translation().isApprox(Eigen::Vector3d(1, 2, 3)));
  EXPECT_TRUE((poses.value()[1].linear() * Eigen::Vector3d::UnitX()).isApprox(Eigen::Vector3d::UnitY()));
}

TEST(ReadLists, NumberListSkipsBlankLines) {
  const auto dir = temp_dir("number_list");
  const std::string p = (dir / "times.txt").string();
  write_bytes(p, "0\n1.5e-1\n\n  2 \n");
  auto v = read_number_list(p);
  ASSERT_TRUE(v.ok()) << v.status().to_string();
  EXPECT_EQ(v.value(), (std::vector<double>{0.0, 0.15, 2.0}));
}

TEST(ReadFile, ReadsWholeFileAndCapsSize) {
  const auto dir = temp_dir("read_file");
  const std::string p = (dir / "f.bin").string();
  write_bytes(p, std::string("abcdef"));
  auto b = read_file(p);
  ASSERT_TRUE(b.ok());
  EXPECT_EQ(b.value(), (std::vector<std::uint8_t>{'a', 'b', 'c', 'd', 'e', 'f'}));
  auto capped = read_file(p, 5);
  ASSERT_FALSE(capped.ok());
  EXPECT_NE(capped.status().message().find("f.bin"), std::string::npos);
  auto missing = read_file((dir / "nope").string());
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), ErrorCode::kIoError);
  auto directory = read_file(dir.string());
  ASSERT_FALSE(directory.ok());
  EXPECT_EQ(directory.status().code(), ErrorCode::kIoError);
}

}  // namespace
}  // namespace lex3d::io
