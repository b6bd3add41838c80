// Writing: bit-exact round trips in every writable format, colours,
// determinism, atomicity, edge-case clouds and the PNG writer.

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "lex3d/io/io.hpp"
#include "support/test_support.hpp"

namespace lex3d::io {
namespace {

namespace fs = std::filesystem;
using test::has_shared_data;
using test::shared_data;
using test::temp_dir;
using Rgb = std::array<std::uint8_t, 3>;

std::vector<std::uint8_t> slurp(const std::string& path) {
  auto r = read_file(path);
  EXPECT_TRUE(r.ok()) << r.status().to_string();
  return r.ok() ? r.value() : std::vector<std::uint8_t>{};
}

std::uint32_t bits(float f) {
  std::uint32_t u = 0;
  std::memcpy(&u, &f, 4);
  return u;
}

/// Floats that stress text round trips: tiny, huge, subnormal, negative zero, 0.1.
Cloud tricky_cloud(bool with_intensity) {
  Cloud c;
  const float vals[] = {0.1F,         -0.0F,       1.0F / 3.0F, 123456.789F, -9.87654e-30F,
                        1e-40F /*subnormal*/,      3.4e38F,     -2.5F,       1e-7F,
                        16777217.0F,  0.30000001F, 7.0F};
  const std::size_t n = sizeof(vals) / sizeof(vals[0]);
  for (std::size_t i = 0; i < 40; ++i) {
    c.points.emplace_back(vals[i % n], vals[(i * 7 + 3) % n], vals[(i * 5 + 1) % n] + static_cast<float>(i));
    if (with_intensity) c.intensity.push_back(static_cast<float>(i) * 0.037F);
  }
  return c;
}

std::vector<Rgb> colours_for(std::size_t n) {
  std::vector<Rgb> c(n);
  for (std::size_t i = 0; i < n; ++i) {
    c[i] = {static_cast<std::uint8_t>(i * 37), static_cast<std::uint8_t>(255 - i),
            static_cast<std::uint8_t>(i * i)};
  }
  return c;
}

void expect_same_points(const Cloud& a, const Cloud& b) {
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    for (int k = 0; k < 3; ++k) {
      ASSERT_EQ(bits(a.points[i][k]), bits(b.points[i][k])) << "point " << i << " coord " << k;
    }
  }
}

void expect_same_intensity(const Cloud& a, const Cloud& b) {
  ASSERT_EQ(a.intensity.size(), b.intensity.size());
  for (std::size_t i = 0; i < a.intensity.size(); ++i) {
    ASSERT_EQ(bits(a.intensity[i]), bits(b.intensity[i])) << "intensity " << i;
  }
}

struct Case {
  const char* name;
  const char* file;
  WriteOptions options;
  bool keeps_intensity;
  bool keeps_colour;
};

std::vector<Case> all_cases() {
  std::vector<Case> cs;
  WriteOptions o;
  o.pcd_encoding = PcdEncoding::kAscii;
  cs.push_back({"pcd_ascii", "c.pcd", o, true, true});
  o.pcd_encoding = PcdEncoding::kBinary;
  cs.push_back({"pcd_binary", "c.pcd", o, true, true});
  o.pcd_encoding = PcdEncoding::kBinaryCompressed;
  cs.push_back({"pcd_binary_compressed", "c.pcd", o, true, true});
  WriteOptions p;
  p.ply_binary = true;
  cs.push_back({"ply_binary", "c.ply", p, true, true});
  p.ply_binary = false;
  cs.push_back({"ply_ascii", "c.ply", p, true, true});
  cs.push_back({"kitti", "c.bin", WriteOptions{}, true, false});
  cs.push_back({"xyz", "c.xyz", WriteOptions{}, true, false});
  cs.push_back({"txt", "c.txt", WriteOptions{}, true, false});
  WriteOptions b;
  b.format = Format::kBinXyz;
  cs.push_back({"binxyz", "c.bin", b, false, false});
  return cs;
}

/// Writes `cloud` as case `c` into a fresh directory `<prefix><c.name>` (its path in `path`)
/// and reads it back into `out` (a binxyz case told its format); `out` stays empty when the
/// write or the read fails.
void write_and_read(const Cloud& cloud, const Case& c, const std::string& prefix, std::optional<ReadResult>& out,
                    std::string* path = nullptr) {
  const auto dir = temp_dir(prefix + c.name);
  const std::string file = (dir / c.file).string();
  if (path != nullptr) *path = file;
  ASSERT_TRUE(write_cloud(file, cloud, c.options).ok());
  ReadOptions ro;
  if (c.options.format == Format::kBinXyz) ro.format = Format::kBinXyz;
  auto r = read_cloud(file, ro);
  ASSERT_TRUE(r.ok()) << r.status().to_string();
  out = std::move(r).value();
}

/// write_and_read, then checks the points and intensities bit for bit.
void round_trip(const Cloud& cloud, const Case& c, const std::string& prefix,
                std::optional<ReadResult>& out) {
  write_and_read(cloud, c, prefix, out);
  if (!out) return;
  expect_same_points(cloud, out->cloud);
  expect_same_intensity(cloud, out->cloud);
}

TEST(WriteRoundTrip, BitExactInEveryFormat) {
  for (bool with_i : {false, true}) {
    const Cloud cloud = tricky_cloud(with_i);
    for (const Case& c : all_cases()) {
      SCOPED_TRACE(std::string(c.name) + (with_i ? " with intensity" : ""));
      std::optional<ReadResult> r;
      write_and_read(cloud, c, "rt_", r);
      ASSERT_TRUE(r.has_value());
      EXPECT_EQ(r.value().non_finite_dropped, 0U);
      expect_same_points(cloud, r.value().cloud);
      if (with_i && c.keeps_intensity) {
        expect_same_intensity(cloud, r.value().cloud);
      } else if (std::string(c.name) == "kitti") {
        // KITTI always has 4 floats: intensity 0 when the cloud has none
        ASSERT_EQ(r.value().cloud.intensity.size(), cloud.size());
        for (float i : r.value().cloud.intensity) EXPECT_EQ(i, 0.0F);
      } else {
        EXPECT_FALSE(r.value().cloud.has_intensity());
      }
    }
  }
}

// Every attribute a point carries (intensity, laser, time, colour) comes back from PCD (each
// encoding) and PLY (binary and ascii); the formats that cannot hold one say so
// (fields_not_written), and LAS keeps the time as GPS time.
TEST(WriteRoundTrip, RingAndTimeAreKeptWhereTheFormatHoldsThem) {
  Cloud cloud = tricky_cloud(true);
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    cloud.ring.push_back(static_cast<std::uint16_t>((i * 13) % 70));
    cloud.time.push_back(1.7e9 + 0.1 * static_cast<double>(i) + 1e-7);  // needs double precision
  }
  cloud.rgb = colours_for(cloud.size());
  // named integer fields (a LAS classification and scan angle), negative values too
  IntegerField cls{"classification", {}}, angle{"scan_angle", {}};
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    cls.values.push_back(static_cast<std::int32_t>((i * 3) % 32));
    angle.values.push_back((static_cast<std::int32_t>(i % 11) - 5) * 500);  // 0.006° units: 3° steps
  }
  cloud.fields = {cls, angle};
  for (const Case& c : all_cases()) {
    SCOPED_TRACE(c.name);
    std::optional<ReadResult> r;
    std::string path;
    write_and_read(cloud, c, "rt_attr_", r, &path);
    ASSERT_TRUE(r.has_value());
    const Cloud& back = r.value().cloud;
    const std::vector<std::string> missing = fields_not_written(path, cloud, c.options);
    const bool pcd_or_ply = std::string(c.file) != "c.bin" && std::string(c.file) != "c.xyz" &&
                            std::string(c.file) != "c.txt";
    if (pcd_or_ply) {
      EXPECT_TRUE(missing.empty());
      ASSERT_TRUE(back.has_rings());
      ASSERT_TRUE(back.has_time());
      EXPECT_EQ(back.ring, cloud.ring);
      for (std::size_t i = 0; i < cloud.size(); ++i) ASSERT_EQ(back.time[i], cloud.time[i]) << i;
      EXPECT_EQ(r.value().colors, cloud.rgb);
      ASSERT_EQ(back.fields.size(), 2U);
      EXPECT_EQ(back.fields[0].name, "classification");
      EXPECT_EQ(back.fields[0].values, cls.values);
      EXPECT_EQ(back.fields[1].name, "scan_angle");
      EXPECT_EQ(back.fields[1].values, angle.values);
      EXPECT_TRUE(r.value().dropped_fields.empty());
    } else {
      // each attribute the file did not get is named, and none is read back
      EXPECT_EQ(std::count(missing.begin(), missing.end(), "ring"), 1);
      EXPECT_EQ(std::count(missing.begin(), missing.end(), "time"), 1);
      EXPECT_EQ(std::count(missing.begin(), missing.end(), "rgb"), 1);
      EXPECT_EQ(std::count(missing.begin(), missing.end(), "intensity"), c.keeps_intensity ? 0 : 1);
      EXPECT_EQ(std::count(missing.begin(), missing.end(), "classification"), 1);
      EXPECT_EQ(std::count(missing.begin(), missing.end(), "scan_angle"), 1);
      EXPECT_TRUE(back.fields.empty());
      EXPECT_FALSE(back.has_rings());
      EXPECT_FALSE(back.has_time());
    }
  }
  // LAS: GPS time (format 3 with colours), the ring as extra bytes (the file then LAS 1.4).
  const std::string las = (temp_dir("rt_attr_las") / "c.las").string();
  Cloud small = cloud;
  for (std::size_t i = 0; i < small.size(); ++i)
    small.points[i] = Eigen::Vector3f(0.25F * static_cast<float>(i), 3.0F - 0.5F * static_cast<float>(i % 7), 1.5F);
  ASSERT_TRUE(write_cloud(las, small).ok());
  EXPECT_TRUE(fields_not_written(las, small).empty());
  auto r = read_cloud(las);
  ASSERT_TRUE(r.ok()) << r.status().to_string();
  EXPECT_NE(r.value().encoding.find("LAS 1.4, point format 3"), std::string::npos) << r.value().encoding;
  EXPECT_EQ(r.value().cloud.ring, small.ring);
  ASSERT_TRUE(r.value().cloud.has_time());
  for (std::size_t i = 0; i < small.size(); ++i) ASSERT_EQ(r.value().cloud.time[i], small.time[i]) << i;
  EXPECT_TRUE(r.value().dropped_fields.empty());
  // format 3 holds the classification in its place and the scan angle as a rank in degrees
  const IntegerField* cls_back = r.value().cloud.field("classification");
  ASSERT_NE(cls_back, nullptr);
  EXPECT_EQ(cls_back->values, cls.values);
  const IntegerField* rank = r.value().cloud.field("scan_angle_rank");
  ASSERT_NE(rank, nullptr);
  for (std::size_t i = 0; i < small.size(); ++i) EXPECT_EQ(rank->values[i], angle.values[i] / 500 * 3) << i;
}

// A PCD or PLY field lex3d cannot keep as a named field (several values a point, a list,
// 64-bit integers, doubles that float32 does not hold) is named as not kept; PCL's "_"
// padding is not. Float fields are kept with their type.
TEST(ReadFields, FieldsNotKeptAreNamed) {
  const auto dir = temp_dir("read_fields");
  const std::string pcd = (dir / "f.pcd").string();
  std::ofstream(pcd) << "VERSION 0.7\nFIELDS x y z label normal_x _ hist wide\nSIZE 4 4 4 2 4 1 4 8\nTYPE F F F U F U F F\n"
                        "COUNT 1 1 1 1 1 1 2 1\nWIDTH 2\nHEIGHT 1\nPOINTS 2\nDATA ascii\n"
                        "1 2 3 7 0.5 0 1 2 0.1\n4 5 6 9 0.25 0 3 4 2\n";
  auto r = read_cloud(pcd);
  ASSERT_TRUE(r.ok()) << r.status().to_string();
  ASSERT_EQ(r.value().cloud.fields.size(), 2U);
  EXPECT_EQ(r.value().cloud.fields[0].name, "label");
  EXPECT_EQ(r.value().cloud.fields[0].type, FieldType::kUint16);
  EXPECT_EQ(r.value().cloud.fields[0].values, (std::vector<std::int32_t>{7, 9}));
  EXPECT_EQ(r.value().cloud.fields[1].name, "normal_x");
  EXPECT_EQ(r.value().cloud.fields[1].type, FieldType::kFloat32);
  EXPECT_EQ(r.value().cloud.fields[1].value(0), 0.5);
  EXPECT_EQ(r.value().cloud.fields[1].value(1), 0.25);
  EXPECT_EQ(r.value().dropped_fields, (std::vector<std::string>{"hist (2 values a point)",
                                                                "wide (double-precision values that float32 does not hold)"}));
  const std::string ply = (dir / "f.ply").string();
  std::ofstream(ply) << "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
                        "property float z\nproperty short segment\nproperty float nx\nproperty list uchar int idx\nend_header\n"
                        "1 2 3 -4 0.5 1 7\n4 5 6 12 0.25 1 8\n";
  auto p = read_cloud(ply);
  ASSERT_TRUE(p.ok()) << p.status().to_string();
  ASSERT_EQ(p.value().cloud.fields.size(), 2U);
  EXPECT_EQ(p.value().cloud.fields[0].type, FieldType::kInt16);
  EXPECT_EQ(p.value().cloud.fields[0].values, (std::vector<std::int32_t>{-4, 12}));
  EXPECT_EQ(p.value().cloud.fields[1].type, FieldType::kFloat32);
  EXPECT_EQ(p.value().cloud.fields[1].value(1), 0.25);
  EXPECT_EQ(p.value().dropped_fields, std::vector<std::string>{"idx (a list)"});
}

// Named fields keep their type and every bit through PCD (ascii, binary, compressed) and
// PLY (binary, ascii): integers of 8-32 bits, float32 with NaN and -0, float64 that float32
// holds; an integer outside its type is refused.
TEST(WriteRoundTrip, NamedFieldsKeepTheirTypes) {
  Cloud c;
  IntegerField i8{"flag", {}, FieldType::kInt8}, u8{"label", {}, FieldType::kUint8}, i16{"segment", {}, FieldType::kInt16},
      u16{"reflectivity", {}, FieldType::kUint16}, u32{"range", {}, FieldType::kUint32}, i32{"id", {}, FieldType::kInt32},
      f32{"normal_x", {}, FieldType::kFloat32}, f64{"offset", {}, FieldType::kFloat64};
  for (int i = 0; i < 40; ++i) {
    c.points.emplace_back(0.1F * static_cast<float>(i), 2.0F, -1.0F);
    i8.values.push_back(i % 2 == 0 ? -128 : 127);
    u8.values.push_back(i * 6);
    i16.values.push_back(i % 2 == 0 ? -32768 : 32767);
    u16.values.push_back(65535 - i);
    u32.values.push_back(2147483647 - i);
    i32.values.push_back(-2147483647 - 1 + i);
    f32.values.push_back(float_key(static_cast<float>(i) / 3.0F));
    f64.values.push_back(float_key(1e-7F * static_cast<float>(i * i)));
  }
  f32.values[1] = float_key(std::numeric_limits<float>::quiet_NaN());
  f32.values[2] = float_key(-0.0F);
  f32.values[3] = float_key(-std::numeric_limits<float>::infinity());
  c.fields = {i8, u8, i16, u16, u32, i32, f32, f64};
  for (const Case& k : all_cases()) {
    if (std::string(k.file) != "c.pcd" && std::string(k.file) != "c.ply") continue;
    std::optional<ReadResult> out;
    write_and_read(c, k, "typed_", out);
    ASSERT_TRUE(out.has_value()) << k.name;
    EXPECT_TRUE(out->dropped_fields.empty()) << k.name;
    ASSERT_EQ(out->cloud.fields.size(), c.fields.size()) << k.name;
    for (std::size_t f = 0; f < c.fields.size(); ++f) {
      EXPECT_EQ(out->cloud.fields[f].name, c.fields[f].name) << k.name;
      EXPECT_EQ(out->cloud.fields[f].type, c.fields[f].type) << k.name << " " << c.fields[f].name;
      EXPECT_EQ(out->cloud.fields[f].values, c.fields[f].values) << k.name << " " << c.fields[f].name;
    }
  }
  Cloud bad = c;
  bad.fields[1].values[0] = 256;
  const auto dir = temp_dir("typed_bad");
  const Status st = write_cloud((dir / "bad.pcd").string(), bad);
  EXPECT_EQ(st.code(), ErrorCode::kInvalidArgument);
  EXPECT_NE(st.message().find("label"), std::string::npos) << st.to_string();
  EXPECT_FALSE(std::filesystem::exists(dir / "bad.pcd"));
}

// The ring, intensity and time come back in the names and types their source gave them (a
// driver's uint8 laser_id, uint16 intensity and uint32 nanosecond `t`), in every PCD and PLY
// encoding; a value the source's type cannot hold falls back to the writers' own column.
TEST(WriteRoundTrip, RingIntensityAndTimeKeepTheirSourceNamesAndTypes) {
  Cloud c;
  for (int i = 0; i < 40; ++i) {
    c.points.emplace_back(0.1F * static_cast<float>(i), 2.0F, -1.0F);
    c.ring.push_back(static_cast<std::uint16_t>(i % 32 == 0 ? 255 : i % 32));
    c.intensity.push_back(static_cast<float>(65535 - 1000 * i));
    c.time.push_back(static_cast<double>(48828 * i + 17) * 1e-9);
  }
  c.ring_source = {"laser_id", FieldType::kUint8};
  c.intensity_source = {"intensity", FieldType::kUint16};
  c.time_source = {"t", FieldType::kUint32};
  for (const Case& k : all_cases()) {
    if (std::string(k.file) != "c.pcd" && std::string(k.file) != "c.ply") continue;
    std::optional<ReadResult> out;
    write_and_read(c, k, "sourced_", out);
    ASSERT_TRUE(out.has_value()) << k.name;
    const Cloud& d = out->cloud;
    EXPECT_EQ(d.ring_source.name, "laser_id") << k.name;
    EXPECT_EQ(d.ring_source.type, FieldType::kUint8) << k.name;
    EXPECT_EQ(d.intensity_source.type, FieldType::kUint16) << k.name;
    EXPECT_EQ(d.time_source.name, "t") << k.name;
    EXPECT_EQ(d.time_source.type, FieldType::kUint32) << k.name;
    EXPECT_TRUE(d.fields.empty()) << k.name;
    EXPECT_EQ(d.ring, c.ring) << k.name;
    EXPECT_EQ(d.intensity, c.intensity) << k.name;
    ASSERT_EQ(d.time.size(), c.time.size()) << k.name;
    for (std::size_t i = 0; i < c.size(); ++i) EXPECT_EQ(std::llround(d.time[i] * 1e9), 48828 * static_cast<long>(i) + 17);
  }
  // a ring of 300 in a uint8 source, a fractional intensity in a uint16 one: written as the
  // writers' own ring (uint16) and intensity (float32), values kept
  Cloud wide = c;
  wide.ring[3] = 300;
  wide.intensity[4] = 0.5F;
  const auto dir = temp_dir("sourced_fallback");
  const std::string path = (dir / "wide.pcd").string();
  ASSERT_TRUE(write_cloud(path, wide).ok());
  auto back = read_cloud(path);
  ASSERT_TRUE(back.ok()) << back.status().to_string();
  EXPECT_EQ(back.value().cloud.ring_source.name, "ring");
  EXPECT_EQ(back.value().cloud.ring_source.type, FieldType::kUint16);
  EXPECT_EQ(back.value().cloud.intensity_source.type, FieldType::kFloat32);
  EXPECT_EQ(back.value().cloud.ring, wide.ring);
  EXPECT_EQ(back.value().cloud.intensity, wide.intensity);
  EXPECT_EQ(back.value().cloud.time_source.name, "t");
}

// An organised cloud written as an organised PCD keeps each point's laser and time; the
// no-return pixels are not points when it is read back.
TEST(WriteRoundTrip, OrganisedPcdKeepsRingAndTime) {
  Cloud c;
  c.rows = 3;
  c.columns = 4;
  for (std::uint32_t r = 0; r < 3; ++r)
    for (std::uint32_t col = 0; col < 4; ++col) {
      if ((r + col) % 3 == 0) continue;  // a no-return
      c.points.emplace_back(1.0F + static_cast<float>(col), 0.5F * static_cast<float>(r), 2.0F);
      c.ring.push_back(static_cast<std::uint16_t>(r));
      c.column.push_back(col);
      c.time.push_back(0.001 * (4 * r + col));
    }
  const std::string path = (temp_dir("rt_organised") / "o.pcd").string();
  ASSERT_TRUE(write_cloud(path, c).ok());
  auto r = read_cloud(path);
  ASSERT_TRUE(r.ok()) << r.status().to_string();
  EXPECT_EQ(r.value().cloud.rows, 3U);
  EXPECT_EQ(r.value().cloud.size(), c.size());
  EXPECT_EQ(r.value().no_return_dropped, 12U - c.size());
  EXPECT_EQ(r.value().cloud.ring, c.ring);
  EXPECT_EQ(r.value().cloud.column, c.column);
  EXPECT_EQ(r.value().cloud.time, c.time);
  // with a driver's ring (uint8) and time (`t`, uint32 ns): the organised file keeps them so
  Cloud d = c;
  for (std::size_t i = 0; i < d.size(); ++i) d.time[i] = static_cast<double>(1000 * i + 7) * 1e-9;
  d.ring_source = {"ring", FieldType::kUint8};
  d.time_source = {"t", FieldType::kUint32};
  ASSERT_TRUE(write_cloud(path, d).ok());
  auto s = read_cloud(path);
  ASSERT_TRUE(s.ok()) << s.status().to_string();
  EXPECT_EQ(s.value().cloud.rows, 3U);
  EXPECT_EQ(s.value().cloud.ring_source.type, FieldType::kUint8);
  EXPECT_EQ(s.value().cloud.time_source.name, "t");
  EXPECT_EQ(s.value().cloud.time_source.type, FieldType::kUint32);
  EXPECT_EQ(s.value().cloud.ring, d.ring);
  ASSERT_EQ(s.value().cloud.time.size(), d.size());
  for (std::size_t i = 0; i < d.size(); ++i) EXPECT_EQ(std::llround(s.value().cloud.time[i] * 1e9), 1000 * static_cast<long>(i) + 7);
}

TEST(WriteRoundTrip, ColoursArePreserved) {
  const Cloud cloud = tricky_cloud(true);
  for (Case c : all_cases()) {
    if (!c.keeps_colour) continue;
    SCOPED_TRACE(c.name);
    c.options.colors = colours_for(cloud.size());
    std::optional<ReadResult> r;
    round_trip(cloud, c, "colour_", r);
    if (!r) return;  // round_trip has recorded the failure
    EXPECT_EQ(r->colors, c.options.colors);
  }
}

TEST(WriteRoundTrip, PcdRgbFieldIsPackedLikePcl) {
  Cloud cloud;
  cloud.points.emplace_back(1.0F, 2.0F, 3.0F);
  WriteOptions o;
  o.colors = {Rgb{0x12, 0x34, 0x56}};
  o.pcd_encoding = PcdEncoding::kBinary;
  const auto dir = temp_dir("pcd_rgb");
  const std::string path = (dir / "c.pcd").string();
  ASSERT_TRUE(write_cloud(path, cloud, o).ok());
  const auto bytes = slurp(path);
  const std::string text(bytes.begin(), bytes.end());
  EXPECT_NE(text.find("FIELDS x y z rgb\nSIZE 4 4 4 4\nTYPE F F F F\n"), std::string::npos);
  ASSERT_GE(bytes.size(), 4U);
  std::uint32_t packed = 0;
  std::memcpy(&packed, bytes.data() + bytes.size() - 4, 4);
  EXPECT_EQ(packed, 0xFF123456U);

  o.pcd_encoding = PcdEncoding::kAscii;
  ASSERT_TRUE(write_cloud(path, cloud, o).ok());
  const auto ascii = slurp(path);
  const std::string ascii_text(ascii.begin(), ascii.end());
  EXPECT_NE(ascii_text.find("TYPE F F F U\n"), std::string::npos);  // as PCL writes ascii rgb
  EXPECT_NE(ascii_text.find("1 2 3 4279383126\n"), std::string::npos);
}

TEST(WriteRoundTrip, RealKittiScanThroughEveryFormat) {
  LEX3D_REQUIRE_SHARED("kitti00/000000.bin");
  auto src = read_cloud(shared_data("kitti00/000000.bin"));
  ASSERT_TRUE(src.ok());
  const Cloud& cloud = src.value().cloud;
  for (const Case& c : all_cases()) {
    if (c.options.format == Format::kBinXyz) continue;
    SCOPED_TRACE(c.name);
    std::optional<ReadResult> r;
    round_trip(cloud, c, "real_", r);
    if (!r) return;  // round_trip has recorded the failure
  }
  // KITTI in, KITTI out: the same bytes
  const auto dir = temp_dir("real_kitti_bytes");
  ASSERT_TRUE(write_cloud((dir / "k.bin").string(), cloud).ok());
  EXPECT_EQ(slurp((dir / "k.bin").string()), slurp(shared_data("kitti00/000000.bin")));
}

TEST(WriteDeterminism, SameBytesTwice) {
  const Cloud cloud = tricky_cloud(true);
  for (Case c : all_cases()) {
    SCOPED_TRACE(c.name);
    if (c.keeps_colour) c.options.colors = colours_for(cloud.size());
    const auto dir = temp_dir(std::string("det_") + c.name);
    const std::string a = (dir / (std::string("a_") + c.file)).string();
    const std::string b = (dir / (std::string("b_") + c.file)).string();
    ASSERT_TRUE(write_cloud(a, cloud, c.options).ok());
    ASSERT_TRUE(write_cloud(b, cloud, c.options).ok());
    const auto ba = slurp(a);
    EXPECT_FALSE(ba.empty());
    EXPECT_EQ(ba, slurp(b));
  }
}

TEST(WriteEdgeCases, EmptyCloudInEachFormat) {
  const Cloud empty;
  for (const Case& c : all_cases()) {
    SCOPED_TRACE(c.name);
    const auto dir = temp_dir(std::string("empty_") + c.name);
    const std::string path = (dir / c.file).string();
    ASSERT_TRUE(write_cloud(path, empty, c.options).ok());
    auto r = read_cloud(path);
    const std::string name = c.name;
    if (name.rfind("pcd", 0) == 0 || name.rfind("ply", 0) == 0) {
      // a well-formed header with zero points reads as an empty cloud
      ASSERT_TRUE(r.ok()) << r.status().to_string();
      EXPECT_TRUE(r.value().cloud.empty());
    } else {
      // headerless formats give a 0-byte file, which is an error to read
      ASSERT_FALSE(r.ok());
      EXPECT_EQ(r.status().code(), ErrorCode::kBadData);
      EXPECT_NE(r.status().message().find("file is empty"), std::string::npos);
    }
  }
}

TEST(WriteEdgeCases, SinglePointInEachFormat) {
  Cloud one;
  one.points.emplace_back(-1.25F, 0.5F, 1e-3F);
  one.intensity.push_back(0.75F);
  for (const Case& c : all_cases()) {
    SCOPED_TRACE(c.name);
    const auto dir = temp_dir(std::string("one_") + c.name);
    const std::string path = (dir / c.file).string();
    ASSERT_TRUE(write_cloud(path, one, c.options).ok());
    ReadOptions ro;
    ro.format = c.options.format;  // kAuto, or kBinXyz which 12 bytes would not reveal
    auto r = read_cloud(path, ro);
    ASSERT_TRUE(r.ok()) << r.status().to_string();
    expect_same_points(one, r.value().cloud);
  }
}

TEST(WriteEdgeCases, NonFinitePointsAreDroppedAndCountedOnRead) {
  Cloud cloud;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  cloud.points = {{1, 2, 3}, {nan, 0, 0}, {4, 5, 6}, {0, inf, 0}, {0, 0, -inf}, {7, 8, 9}};
  cloud.intensity = {0.1F, 0.2F, 0.3F, 0.4F, 0.5F, 0.6F};
  for (Case c : all_cases()) {
    SCOPED_TRACE(c.name);
    if (c.keeps_colour) c.options.colors = colours_for(cloud.size());
    const auto dir = temp_dir(std::string("nan_") + c.name);
    const std::string path = (dir / c.file).string();
    ASSERT_TRUE(write_cloud(path, cloud, c.options).ok());
    ReadOptions ro;
    ro.format = c.options.format;
    auto r = read_cloud(path, ro);
    ASSERT_TRUE(r.ok()) << r.status().to_string();
    const ReadResult& rr = r.value();
    EXPECT_EQ(rr.non_finite_dropped, 3U);
    ASSERT_EQ(rr.cloud.size(), 3U);
    EXPECT_EQ(rr.cloud.points[1], Eigen::Vector3f(4, 5, 6));
    if (c.keeps_intensity) {
      ASSERT_TRUE(rr.cloud.has_intensity());
      EXPECT_EQ(rr.cloud.intensity[2], 0.6F);  // stays aligned with its point
    }
    if (c.keeps_colour) {
      ASSERT_EQ(rr.colors.size(), 3U);
      EXPECT_EQ(rr.colors[2], c.options.colors[5]);
    }
  }
}

TEST(WriteEdgeCases, OverwritesAnExistingFile) {
  const auto dir = temp_dir("overwrite");
  const std::string path = (dir / "c.pcd").string();
  ASSERT_TRUE(write_cloud(path, tricky_cloud(false)).ok());
  Cloud one;
  one.points.emplace_back(1.0F, 2.0F, 3.0F);
  ASSERT_TRUE(write_cloud(path, one).ok());
  EXPECT_EQ(read_cloud(path).value().cloud.size(), 1U);
  std::size_t files = 0;
  for ([[maybe_unused]] const auto& e : fs::directory_iterator(dir)) ++files;
  EXPECT_EQ(files, 1U);  // no temporary left behind
}

TEST(WriteErrors, MissingDirectoryIsIoErrorAndLeavesNoTemp) {
  const auto dir = temp_dir("write_missing_dir");
  const std::string path = (dir / "no" / "such" / "dir" / "c.pcd").string();
  const Status s = write_cloud(path, tricky_cloud(false));
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.code(), ErrorCode::kIoError);
  EXPECT_NE(s.message().find("c.pcd"), std::string::npos);
  EXPECT_EQ(s.message().find('\n'), std::string::npos);
  EXPECT_TRUE(fs::is_empty(dir));

  const Status f = write_file_atomic((dir / "nope" / "x.bin").string(), {1, 2, 3});
  EXPECT_EQ(f.code(), ErrorCode::kIoError);
  EXPECT_TRUE(fs::is_empty(dir));
}

TEST(WriteErrors, RenameFailureRemovesTheTemporary) {
  const auto dir = temp_dir("write_rename_fail");
  // the target is a non-empty directory: the temp file is written, rename fails
  fs::create_directories(dir / "target.pcd" / "child");
  const Status s = write_cloud((dir / "target.pcd").string(), tricky_cloud(false));
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.code(), ErrorCode::kIoError);
  std::size_t files = 0;
  for ([[maybe_unused]] const auto& e : fs::directory_iterator(dir)) ++files;
  EXPECT_EQ(files, 1U);  // only target.pcd/
}

TEST(WriteErrors, BadArgumentsAreInvalidArgument) {
  const auto dir = temp_dir("write_bad_args");
  const Cloud cloud = tricky_cloud(true);
  WriteOptions o;
  o.colors = colours_for(3);
  EXPECT_EQ(write_cloud((dir / "a.pcd").string(), cloud, o).code(), ErrorCode::kInvalidArgument);
  EXPECT_EQ(write_cloud((dir / "a.laz").string(), cloud).code(), ErrorCode::kInvalidArgument);
  EXPECT_EQ(write_cloud((dir / "a.e57").string(), cloud).code(), ErrorCode::kInvalidArgument);
  WriteOptions u;
  u.format = Format::kUos3d;
  EXPECT_EQ(write_cloud((dir / "a.3d").string(), cloud, u).code(), ErrorCode::kInvalidArgument);
  Cloud bad = cloud;
  bad.intensity.pop_back();
  EXPECT_EQ(write_cloud((dir / "b.pcd").string(), bad).code(), ErrorCode::kInvalidArgument);
  EXPECT_TRUE(fs::is_empty(dir));
}

TEST(WriteFile, AtomicWriteThenRead) {
  const auto dir = temp_dir("write_file");
  const std::string path = (dir / "blob.bin").string();
  const std::vector<std::uint8_t> bytes = {0, 1, 2, 255, 254};
  ASSERT_TRUE(write_file_atomic(path, bytes).ok());
  EXPECT_EQ(slurp(path), bytes);
  ASSERT_TRUE(write_file_atomic(path, {}).ok());
  EXPECT_TRUE(slurp(path).empty());
}

// ------------------------------------------------------------------ PNG

std::uint32_t be32(const std::vector<std::uint8_t>& b, std::size_t at) {
  return (static_cast<std::uint32_t>(b[at]) << 24) | (static_cast<std::uint32_t>(b[at + 1]) << 16) |
         (static_cast<std::uint32_t>(b[at + 2]) << 8) | static_cast<std::uint32_t>(b[at + 3]);
}

TEST(WritePng, SignatureAndHeader) {
  const auto dir = temp_dir("png");
  const std::string path = (dir / "img.png").string();
  const int w = 7, h = 5;
  std::vector<std::uint8_t> rgb(static_cast<std::size_t>(w * h * 3));
  for (std::size_t i = 0; i < rgb.size(); ++i) rgb[i] = static_cast<std::uint8_t>(i * 13);
  ASSERT_TRUE(write_png_rgb(path, w, h, rgb).ok());
  const auto png = slurp(path);
  ASSERT_GE(png.size(), 8U + 25U + 12U);
  const std::uint8_t sig[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n'};
  EXPECT_EQ(std::memcmp(png.data(), sig, 8), 0);
  EXPECT_EQ(be32(png, 8), 13U);  // IHDR length
  EXPECT_EQ(std::string(png.begin() + 12, png.begin() + 16), "IHDR");
  EXPECT_EQ(be32(png, 16), static_cast<std::uint32_t>(w));
  EXPECT_EQ(be32(png, 20), static_cast<std::uint32_t>(h));
  EXPECT_EQ(png[24], 8);  // bit depth
  EXPECT_EQ(png[25], 2);  // RGB
  EXPECT_EQ(std::string(png.end() - 8, png.end() - 4), "IEND");
  // deterministic
  const std::string again = (dir / "again.png").string();
  ASSERT_TRUE(write_png_rgb(again, w, h, rgb).ok());
  EXPECT_EQ(slurp(again), png);
}

TEST(WritePng, BadParametersAreInvalidArgument) {
  const auto dir = temp_dir("png_bad");
  const std::string path = (dir / "img.png").string();
  EXPECT_EQ(write_png_rgb(path, 0, 5, {}).code(), ErrorCode::kInvalidArgument);
  EXPECT_EQ(write_png_rgb(path, 4, -1, {}).code(), ErrorCode::kInvalidArgument);
  EXPECT_EQ(write_png_rgb(path, 2, 2, std::vector<std::uint8_t>(11)).code(), ErrorCode::kInvalidArgument);
  EXPECT_EQ(write_png_rgb(path, 100000, 100000, {}).code(), ErrorCode::kInvalidArgument);
  EXPECT_TRUE(fs::is_empty(dir));
  EXPECT_EQ(write_png_rgb((dir / "no" / "img.png").string(), 1, 1, {1, 2, 3}).code(),
            ErrorCode::kIoError);
}

}  // namespace
}  // namespace lex3d::io
