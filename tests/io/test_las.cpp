// LAS reading and writing, georeferenced clouds (a double origin, the CRS's units), and
// double-precision PCD/PLY/text in projected coordinates.

#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "lex3d/io/io.hpp"
#include "support/test_support.hpp"

namespace lex3d::io {
namespace {

using test::write_bytes;

using test::shared_data;
using test::temp_dir;
using Bytes = std::vector<std::uint8_t>;

ReadResult read_ok(const std::string& path) {
  auto r = read_cloud(path);
  EXPECT_TRUE(r.ok()) << path << ": " << r.status().to_string();
  if (!r.ok()) return {};
  return std::move(r).value();
}

Bytes file_bytes(const std::string& path) {
  auto b = read_file(path);
  EXPECT_TRUE(b.ok());
  return b.ok() ? b.value() : Bytes{};
}

template <typename T>
T get(const Bytes& b, std::size_t at) {
  T v;
  std::memcpy(&v, b.data() + at, sizeof(T));  // the test machine is little-endian
  return v;
}
template <typename T>
void put(Bytes& b, std::size_t at, T v) {
  std::memcpy(b.data() + at, &v, sizeof(T));
}

/// The header's fields a test checks the reader against, read straight from the bytes.
struct RawHeader {
  std::uint16_t header_size;
  std::uint32_t point_offset;
  std::uint8_t format;
  std::uint16_t record_len;
  std::uint64_t count;
  double scale[3], offset[3], max[3], min[3];
};
RawHeader raw_header(const Bytes& b) {
  RawHeader h{};
  h.header_size = get<std::uint16_t>(b, 94);
  h.point_offset = get<std::uint32_t>(b, 96);
  h.format = b[104];
  h.record_len = get<std::uint16_t>(b, 105);
  h.count = get<std::uint32_t>(b, 107);
  if (b[25] >= 4 && get<std::uint64_t>(b, 247) != 0) h.count = get<std::uint64_t>(b, 247);
  for (int a = 0; a < 3; ++a) {
    h.scale[a] = get<double>(b, 131 + 8 * a);
    h.offset[a] = get<double>(b, 155 + 8 * a);
    h.max[a] = get<double>(b, 179 + 16 * a);
    h.min[a] = get<double>(b, 187 + 16 * a);
  }
  return h;
}

/// The true coordinates (CRS units) of the cloud's points: origin + point, per axis unit.
std::vector<Eigen::Vector3d> true_points(const Cloud& c) {
  std::vector<Eigen::Vector3d> out;
  for (const auto& p : c.points) out.push_back(c.georef->to_crs(p));
  return out;
}

/// Every point, mapped back to the file's integer grid, is the record's integer exactly,
/// and the points lie within the header's bounds.
void expect_matches_records(const std::string& path, const ReadResult& r) {
  const Bytes b = file_bytes(path);
  const RawHeader h = raw_header(b);
  ASSERT_EQ(r.cloud.size(), h.count);
  ASSERT_TRUE(r.cloud.georef.has_value());
  const Georeference& g = *r.cloud.georef;
  for (int a = 0; a < 3; ++a) {
    EXPECT_DOUBLE_EQ(g.las_scale[a], h.scale[a]);
    EXPECT_DOUBLE_EQ(g.las_offset[a], h.offset[a]);
  }
  EXPECT_EQ(g.las_point_format, h.format);
  std::size_t mismatches = 0;
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e300), hi = -lo;
  for (std::size_t i = 0; i < r.cloud.size(); ++i) {
    const Eigen::Vector3d t = g.to_crs(r.cloud.points[i]);
    lo = lo.cwiseMin(t);
    hi = hi.cwiseMax(t);
    for (int a = 0; a < 3; ++a) {
      const auto rec = get<std::int32_t>(b, h.point_offset + i * h.record_len + 4 * static_cast<std::size_t>(a));
      if (std::llround((t[a] - h.offset[a]) / h.scale[a]) != rec) ++mismatches;
    }
  }
  EXPECT_EQ(mismatches, 0U);
  for (int a = 0; a < 3; ++a) {
    EXPECT_GE(lo[a], h.min[a] - h.scale[a]) << "axis " << a;
    EXPECT_LE(hi[a], h.max[a] + h.scale[a]) << "axis " << a;
    EXPECT_NEAR(lo[a], h.min[a], h.scale[a]) << "axis " << a;  // the header's bounds are tight here
    EXPECT_NEAR(hi[a], h.max[a], h.scale[a]) << "axis " << a;
  }
  // float32 about the origin keeps the file's resolution
  EXPECT_LT(g.representation_error_m, 0.5 * h.scale[0] * g.unit_m);
}

bool has_field(const ReadResult& r, const std::string& name) {
  for (const auto& f : r.dropped_fields)
    if (f == name) return true;
  return false;
}

// ------------------------------------------------------------------ shared files

TEST(LasRead, AutzenIsInInternationalFeet) {
  LEX3D_REQUIRE_SHARED("las/autzen_trim.las");
  const std::string path = shared_data("las/autzen_trim.las");
  const ReadResult r = read_ok(path);
  EXPECT_EQ(r.format, Format::kLas);
  EXPECT_EQ(r.cloud.size(), 110000U);
  ASSERT_TRUE(r.cloud.georef);
  const Georeference& g = *r.cloud.georef;
  EXPECT_DOUBLE_EQ(g.unit_m, 0.3048);  // GeoTIFF ProjLinearUnitsGeoKey 9002 and the WKT UNIT agree
  EXPECT_DOUBLE_EQ(g.vertical_unit_m, 0.3048);
  EXPECT_NE(g.crs_name.find("Lambert_Conformal_Conic"), std::string::npos) << g.crs_name;
  EXPECT_EQ(g.crs_records.size(), 5U);  // GeoTIFF keys, doubles, ASCII, two WKT records
  EXPECT_EQ(g.las_version_minor, 2);
  EXPECT_EQ(g.las_system_id, "PDAL");
  expect_matches_records(path, r);
  // metres: the file spans 1177 ft = 359 m in x
  const Bounds b = compute_bounds(r.cloud);
  EXPECT_NEAR(b.max.x() - b.min.x(), (637179.22 - 636001.76) * 0.3048, 0.01);
  EXPECT_FALSE(has_field(r, "GPS time"));  // kept as each point's time
  ASSERT_TRUE(r.cloud.has_time());
  EXPECT_NE(*std::min_element(r.cloud.time.begin(), r.cloud.time.end()),
            *std::max_element(r.cloud.time.begin(), r.cloud.time.end()));
  // the record's other fields, kept by name (formats/model.md §2.10): Autzen has ground
  // (class 2) and unclassified (1) points, first to third returns
  EXPECT_FALSE(has_field(r, "classification"));
  const IntegerField* cls = r.cloud.field("classification");
  ASSERT_NE(cls, nullptr);
  ASSERT_EQ(cls->values.size(), r.cloud.size());
  EXPECT_EQ(*std::min_element(cls->values.begin(), cls->values.end()), 1);
  EXPECT_EQ(*std::max_element(cls->values.begin(), cls->values.end()), 2);
  const IntegerField* ret = r.cloud.field("return_number");
  ASSERT_NE(ret, nullptr);
  EXPECT_EQ(*std::max_element(ret->values.begin(), ret->values.end()), 4);
  for (const char* name : {"number_of_returns", "scan_direction_flag", "scan_angle_rank", "user_data", "point_source_id"})
    EXPECT_NE(r.cloud.field(name), nullptr) << name;
  EXPECT_EQ(r.cloud.field("edge_of_flight_line"), nullptr);  // all 0, as a writer puts it
  EXPECT_TRUE(r.dropped_fields.empty());
  EXPECT_EQ(r.colors.size(), r.cloud.size());  // PDRF 3 has RGB
  ASSERT_TRUE(r.cloud.has_intensity());
}

TEST(LasRead, Autzen14HoldsTheSamePointsAs12) {
  LEX3D_REQUIRE_SHARED("las/autzen_trim_7.las");
  LEX3D_REQUIRE_SHARED("las/autzen_trim.las");
  const std::string path = shared_data("las/autzen_trim_7.las");
  const ReadResult r14 = read_ok(path);
  const ReadResult r12 = read_ok(shared_data("las/autzen_trim.las"));
  ASSERT_TRUE(r14.cloud.georef);
  EXPECT_EQ(r14.cloud.georef->las_version_minor, 4);
  EXPECT_EQ(r14.cloud.georef->las_point_format, 7);
  EXPECT_DOUBLE_EQ(r14.cloud.georef->unit_m, 0.3048);  // from the WKT alone
  expect_matches_records(path, r14);
  ASSERT_EQ(r14.cloud.size(), r12.cloud.size());
  const auto a = true_points(r14.cloud), b = true_points(r12.cloud);
  double worst = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i) worst = std::max(worst, (a[i] - b[i]).cwiseAbs().maxCoeff());
  EXPECT_LT(worst, 1e-6);  // feet
}

TEST(LasRead, HexbinIsUtmInMetres) {
  LEX3D_REQUIRE_SHARED("las/hexbin-crop.las");
  const std::string path = shared_data("las/hexbin-crop.las");
  const ReadResult r = read_ok(path);
  EXPECT_EQ(r.cloud.size(), 38367U);
  ASSERT_TRUE(r.cloud.georef);
  const Georeference& g = *r.cloud.georef;
  EXPECT_EQ(g.epsg, 32642U);
  EXPECT_DOUBLE_EQ(g.unit_m, 1.0);
  EXPECT_EQ(g.crs_name, "WGS 84 / UTM zone 42N");
  EXPECT_EQ(g.las_system_id, "ALIRT");
  expect_matches_records(path, r);
  // the local coordinates are small: the origin sits within the cloud's box
  const Bounds b = compute_bounds(r.cloud);
  EXPECT_LT(b.max.cwiseAbs().maxCoeff(), 300.0F);
  EXPECT_LT(b.min.cwiseAbs().maxCoeff(), 300.0F);
  EXPECT_TRUE(r.colors.empty());  // PDRF 1: no RGB
}

TEST(LasWrite, SharedFilesRoundTripExactly) {
  for (const char* name : {"las/autzen_trim.las", "las/autzen_trim_7.las", "las/hexbin-crop.las"}) {
    if (!test::has_shared_data(name)) GTEST_SKIP() << "shared data not available: " << name;
    const ReadResult r = read_ok(shared_data(name));
    const std::string out = (temp_dir("las_write") / "back.las").string();
    WriteOptions wo;
    wo.colors = r.colors;
    ASSERT_TRUE(write_cloud(out, r.cloud, wo).ok()) << name;
    const ReadResult back = read_ok(out);
    ASSERT_EQ(back.cloud.size(), r.cloud.size()) << name;
    ASSERT_TRUE(back.cloud.georef);
    EXPECT_EQ(back.cloud.georef->las_version_minor, r.cloud.georef->las_version_minor);
    EXPECT_EQ(back.cloud.georef->las_point_format, r.cloud.georef->las_point_format);
    EXPECT_EQ(back.cloud.georef->las_scale, r.cloud.georef->las_scale);
    EXPECT_EQ(back.cloud.georef->unit_m, r.cloud.georef->unit_m);
    // the CRS records, byte for byte
    ASSERT_EQ(back.cloud.georef->crs_records.size(), r.cloud.georef->crs_records.size());
    for (std::size_t k = 0; k < r.cloud.georef->crs_records.size(); ++k)
      EXPECT_EQ(back.cloud.georef->crs_records[k].data, r.cloud.georef->crs_records[k].data);
    // the same integers at the same scale and offset, and every other field of the record
    // (returns, flags, classification, scan angle, user data, point source, GPS time, RGB)
    const Bytes a = file_bytes(shared_data(name)), b = file_bytes(out);
    const RawHeader ha = raw_header(a), hb = raw_header(b);
    ASSERT_EQ(ha.record_len, hb.record_len) << name;
    // (colours are kept as 8 bits and written back as v·257: compared as colours below)
    const int rgb = ha.format == 3 ? 28 : ha.format == 7 ? 30 : -1;
    std::size_t differ = 0;
    for (std::size_t i = 0; i < r.cloud.size(); ++i)
      for (std::size_t k = 0; k < ha.record_len; ++k) {
        const bool colour = rgb >= 0 && k >= static_cast<std::size_t>(rgb) && k < static_cast<std::size_t>(rgb) + 6;
        if (!colour) differ += a[ha.point_offset + i * ha.record_len + k] != b[hb.point_offset + i * hb.record_len + k];
      }
    EXPECT_EQ(differ, 0U) << name;
    // the header's points by return number (LAS 1.4: the 64-bit counts)
    for (std::size_t k = 0; k < 5; ++k) {
      if (a[25] >= 4) EXPECT_EQ(get<std::uint64_t>(a, 255 + 8 * k), get<std::uint64_t>(b, 255 + 8 * k)) << name << " " << k;
      else EXPECT_EQ(get<std::uint32_t>(a, 111 + 4 * k), get<std::uint32_t>(b, 111 + 4 * k)) << name << " " << k;
    }
    EXPECT_EQ(back.colors, r.colors) << name;
    for (int ax = 0; ax < 3; ++ax) {  // the written bounds are the points' (hexbin's header is 0.4 mm loose)
      EXPECT_NEAR(hb.min[ax], ha.min[ax], ha.scale[ax]) << name;
      EXPECT_NEAR(hb.max[ax], ha.max[ax], ha.scale[ax]) << name;
    }
  }
}

// ------------------------------------------------------------------ a small fixture made here

/// A small LAS 1.4 format-6 file in UTM with a WKT EVLR: written by the writer from a cloud
/// whose georeference says so.
Cloud fixture_cloud() {
  Cloud c;
  Georeference g;
  g.las_scale = Eigen::Vector3d(0.001, 0.001, 0.001);
  g.las_offset = Eigen::Vector3d(500000.0, 5403000.0, 0.0);
  g.las_version_minor = 4;
  g.las_point_format = 6;
  g.las_global_encoding = 0x10;
  g.origin = Eigen::Vector3d(500100.0, 5403850.0, 100.0);
  CrsRecord wkt;
  wkt.user_id = "LASF_Projection";
  wkt.record_id = 2112;
  wkt.extended = true;
  const std::string text =
      "PROJCS[\"WGS 84 / UTM zone 33N\",GEOGCS[\"WGS 84\",UNIT[\"degree\",0.0174532925199433]],"
      "PROJECTION[\"Transverse_Mercator\"],UNIT[\"metre\",1,AUTHORITY[\"EPSG\",\"9001\"]],AUTHORITY[\"EPSG\",\"32633\"]]";
  wkt.data.assign(text.begin(), text.end());
  wkt.data.push_back(0);
  g.crs_records.push_back(wkt);
  c.georef = g;
  for (int i = 0; i < 200; ++i) {
    c.points.emplace_back(static_cast<float>(0.25 * (i % 20)) - 2.5F, static_cast<float>(0.5 * (i / 20)) - 2.0F,
                          static_cast<float>(0.001 * i));
    c.intensity.push_back(static_cast<float>(i * 7));
  }
  return c;
}

std::string write_fixture(const std::string& dir, const std::string& name = "fixture.las") {
  const std::string path = (temp_dir(dir) / name).string();
  const Status s = write_cloud(path, fixture_cloud(), {});
  EXPECT_TRUE(s.ok()) << s.to_string();
  return path;
}

TEST(LasFixture, Las14Format6WithWktEvlrRoundTrips) {
  const std::string path = write_fixture("las_fixture");
  const Bytes b = file_bytes(path);
  EXPECT_EQ(b[25], 4);
  EXPECT_EQ(get<std::uint16_t>(b, 94), 375);
  EXPECT_EQ(get<std::uint32_t>(b, 107), 0U);       // legacy count is 0 for format 6
  EXPECT_EQ(get<std::uint64_t>(b, 247), 200U);     // the 64-bit count
  EXPECT_EQ(get<std::uint32_t>(b, 243), 1U);       // one EVLR
  const ReadResult r = read_ok(path);
  ASSERT_EQ(r.cloud.size(), 200U);
  ASSERT_TRUE(r.cloud.georef);
  EXPECT_EQ(r.cloud.georef->epsg, 32633U);
  EXPECT_EQ(r.cloud.georef->crs_name, "WGS 84 / UTM zone 33N");
  ASSERT_EQ(r.cloud.georef->crs_records.size(), 1U);
  EXPECT_TRUE(r.cloud.georef->crs_records[0].extended);
  const Cloud c = fixture_cloud();
  for (std::size_t i = 0; i < c.size(); ++i) {
    const Eigen::Vector3d want = c.georef->to_crs(c.points[i]);
    const Eigen::Vector3d got = r.cloud.georef->to_crs(r.cloud.points[i]);
    EXPECT_LE((want - got).cwiseAbs().maxCoeff(), 0.0005 + 1e-9) << i;  // half the 1 mm step
    EXPECT_EQ(r.cloud.intensity[i], c.intensity[i]);
  }
}

TEST(LasFixture, NamedFieldsGoBackIntoTheirPlaces) {
  // Format 6 (LAS 1.4) fields from the cloud, written and read back; one the format has no
  // place for goes into extra bytes, and a value that does not fit a place is refused.
  Cloud c = fixture_cloud();
  const std::size_t n = c.size();
  const auto field = [n](const char* name, auto value) {
    IntegerField f{name, std::vector<std::int32_t>(n)};
    for (std::size_t i = 0; i < n; ++i) f.values[i] = static_cast<std::int32_t>(value(static_cast<int>(i)));
    return f;
  };
  c.fields = {field("classification", [](int i) { return i % 7 == 0 ? 200 : 2; }),
              field("return_number", [](int i) { return 1 + i % 3; }),
              field("number_of_returns", [](int) { return 3; }),
              field("scan_angle", [](int i) { return i * 50 - 5000; }),
              field("scanner_channel", [](int i) { return i % 4; }),
              field("user_data", [](int i) { return i % 256; }),
              field("point_source_id", [](int i) { return 60000 + i; }),
              field("not_a_las_field", [](int i) { return i; })};
  const std::string path = (temp_dir("las_named") / "named.las").string();
  EXPECT_TRUE(fields_not_written(path, c, {}).empty());
  ASSERT_TRUE(write_cloud(path, c, {}).ok());
  const ReadResult r = read_ok(path);
  ASSERT_EQ(r.cloud.size(), n);
  for (const IntegerField& f : c.fields) {
    const IntegerField* back = r.cloud.field(f.name);
    ASSERT_NE(back, nullptr) << f.name;
    EXPECT_EQ(back->values, f.values) << f.name;
  }
  EXPECT_EQ(r.cloud.field("not_a_las_field")->type, FieldType::kInt32);  // an extra long
  const Bytes b = file_bytes(path);
  EXPECT_EQ(get<std::uint64_t>(b, 255), 67U);  // points by return: 1, 2, 3 (a third each)
  EXPECT_EQ(get<std::uint64_t>(b, 263), 67U);
  EXPECT_EQ(get<std::uint64_t>(b, 271), 66U);
  // format 1 (LAS 1.2): scan_angle goes back as the rank in degrees; classification 200 does not fit 5 bits
  c.georef->las_version_minor = 2;
  c.georef->las_point_format = 1;
  c.georef->crs_records.clear();
  EXPECT_FALSE(write_cloud(path, c, {}).ok());
  c.fields[0] = field("classification", [](int i) { return i % 32; });
  ASSERT_TRUE(write_cloud(path, c, {}).ok());
  const ReadResult r12 = read_ok(path);
  const IntegerField* rank = r12.cloud.field("scan_angle_rank");
  ASSERT_NE(rank, nullptr);
  for (std::size_t i = 0; i < n; ++i) EXPECT_EQ(rank->values[i], std::lround((static_cast<double>(i) * 50 - 5000) * 0.006)) << i;
  EXPECT_EQ(r12.cloud.field("classification")->values, c.fields[0].values);
  // format 1 has no scanner channel: an extra byte value (the file then LAS 1.4, format 1)
  ASSERT_NE(r12.cloud.field("scanner_channel"), nullptr);
  EXPECT_EQ(r12.cloud.field("scanner_channel")->values, c.fields[4].values);
  EXPECT_EQ(r12.cloud.georef->las_point_format, 1);
  EXPECT_EQ(r12.cloud.georef->las_version_minor, 4);
}

// Every field the record has no place for, and the ring, go into extra bytes in their own
// types (LAS 1.4 R15 §2.5.2: one 192-byte descriptor each in a "LASF_Spec" record 4) and come
// back; a descriptor with a scale and offset is read as float32 values with them applied; what
// a field cannot hold (a 64-bit value beyond 31 bits, undocumented bytes) is named as dropped.
TEST(LasFixture, ExtraBytesOfEveryTypeRoundTrip) {
  Cloud c = fixture_cloud();
  c.georef->las_version_minor = 2;
  c.georef->las_point_format = 1;
  c.georef->las_global_encoding = 0;
  c.georef->crs_records.clear();
  const std::size_t n = c.size();
  const auto field = [n](const char* name, FieldType type, auto value) {
    IntegerField f{name, std::vector<std::int32_t>(n), type};
    for (std::size_t i = 0; i < n; ++i) f.values[i] = value(static_cast<int>(i));
    return f;
  };
  const auto as_float = [](float v) { return float_key(v); };
  c.fields = {field("u8", FieldType::kUint8, [](int i) { return i % 256; }),
              field("i8", FieldType::kInt8, [](int i) { return i % 200 - 100; }),
              field("u16", FieldType::kUint16, [](int i) { return i * 300; }),
              field("i16", FieldType::kInt16, [](int i) { return i * 150 - 30000; }),
              field("u32", FieldType::kUint32, [](int i) { return i * 10000000; }),
              field("i32", FieldType::kInt32, [](int i) { return -i * 10000000; }),
              field("f32", FieldType::kFloat32, [&](int i) { return as_float(0.1F * static_cast<float>(i) - 3.0F); }),
              field("f64", FieldType::kFloat64, [&](int i) { return as_float(static_cast<float>(i) * 0.5F); })};
  c.ring.resize(n);
  for (std::size_t i = 0; i < n; ++i) c.ring[i] = static_cast<std::uint16_t>(i % 64);
  const std::string path = (temp_dir("las_extra") / "extra.las").string();
  EXPECT_TRUE(fields_not_written(path, c, {}).empty());
  ASSERT_TRUE(write_cloud(path, c, {}).ok());
  Bytes b = file_bytes(path);
  EXPECT_EQ(b[25], 4);                                                      // LAS 1.4
  EXPECT_EQ(b[104], 1);                                                     // point format 1 kept
  EXPECT_EQ(get<std::uint16_t>(b, 105), 28 + 2 + 1 + 1 + 2 + 2 + 4 + 4 + 4 + 8);  // the record and its extra bytes
  EXPECT_EQ(get<std::uint32_t>(b, 100), 1U);                                // one VLR
  const std::size_t vlr = get<std::uint16_t>(b, 94);
  EXPECT_EQ(std::string(reinterpret_cast<const char*>(b.data() + vlr + 2)), "LASF_Spec");
  EXPECT_EQ(get<std::uint16_t>(b, vlr + 18), 4);
  EXPECT_EQ(get<std::uint16_t>(b, vlr + 20), 9 * 192);
  const std::size_t desc = vlr + 54;
  EXPECT_EQ(b[desc + 2], 3);  // the ring: unsigned short
  EXPECT_EQ(std::string(reinterpret_cast<const char*>(b.data() + desc + 4)), "ring");
  const std::uint8_t types[] = {3, 1, 2, 3, 4, 5, 6, 9, 10};
  for (std::size_t k = 0; k < 9; ++k) EXPECT_EQ(b[desc + 192 * k + 2], types[k]) << k;

  const ReadResult r = read_ok(path);
  ASSERT_EQ(r.cloud.size(), n);
  EXPECT_EQ(r.cloud.ring, c.ring);
  for (const IntegerField& f : c.fields) {
    const IntegerField* back = r.cloud.field(f.name);
    ASSERT_NE(back, nullptr) << f.name;
    EXPECT_EQ(back->type, f.type) << f.name;
    EXPECT_EQ(back->values, f.values) << f.name;
  }
  EXPECT_TRUE(r.dropped_fields.empty());

  // the u16 descriptor given a scale of 0.01 and an offset of 5: float32 raw · 0.01 + 5
  const std::size_t u16 = desc + 192 * 3;
  b[u16 + 3] = 0x18;
  put<double>(b, u16 + 112, 0.01);
  put<double>(b, u16 + 136, 5.0);
  // the first point's u32 value 2^32 - 1 (beyond the 31 bits a field holds)
  put<std::uint32_t>(b, get<std::uint32_t>(b, 96) + 28 + 2 + 1 + 1 + 2 + 2, 0xFFFFFFFFU);
  // the i32 descriptor undocumented bytes (type 0, its 4 bytes in `options`)
  b[desc + 192 * 6 + 2] = 0;
  b[desc + 192 * 6 + 3] = 4;
  // the ring a short, the first point's -1: no laser number, a field "extra_ring" of its own
  b[desc + 2] = 4;
  put<std::int16_t>(b, get<std::uint32_t>(b, 96) + 28, -1);
  const std::string edited = (temp_dir("las_extra") / "edited.las").string();
  write_bytes(edited, std::string(b.begin(), b.end()));
  const ReadResult e = read_ok(edited);
  const IntegerField* scaled = e.cloud.field("u16");
  ASSERT_NE(scaled, nullptr);
  EXPECT_EQ(scaled->type, FieldType::kFloat32);
  for (std::size_t i = 0; i < n; ++i)
    EXPECT_EQ(key_float(scaled->values[i]), static_cast<float>(static_cast<double>(i * 300) * 0.01 + 5.0)) << i;
  EXPECT_EQ(e.cloud.field("u32"), nullptr);
  EXPECT_EQ(e.cloud.field("i32"), nullptr);
  ASSERT_NE(e.cloud.field("f64"), nullptr);  // the values after them still in their places
  EXPECT_EQ(e.cloud.field("f64")->values, c.fields[7].values);
  const auto said = [&](const std::vector<std::string>& lines, const std::string& what) {
    return std::any_of(lines.begin(), lines.end(), [&](const std::string& l) { return l.find(what) != std::string::npos; });
  };
  EXPECT_TRUE(said(e.dropped_fields, "extra bytes \"u32\" (a value beyond 31 bits)"));
  EXPECT_TRUE(said(e.dropped_fields, "extra bytes \"i32\" (undocumented bytes)"));
  EXPECT_TRUE(said(e.notes, "extra bytes \"u16\" read as float32 values"));
  EXPECT_FALSE(e.cloud.has_rings());
  const IntegerField* extra_ring = e.cloud.field("extra_ring");
  ASSERT_NE(extra_ring, nullptr);
  EXPECT_EQ(extra_ring->type, FieldType::kInt16);
  EXPECT_EQ(extra_ring->values[0], -1);
  EXPECT_EQ(extra_ring->values[5], 5);
  // written as PCD, every field reads back (a field named "ring" would be read as the lasers)
  const std::string pcd = (temp_dir("las_extra") / "back.pcd").string();
  ASSERT_TRUE(write_cloud(pcd, e.cloud).ok());
  const ReadResult back = read_ok(pcd);
  ASSERT_NE(back.cloud.field("extra_ring"), nullptr);
  EXPECT_EQ(back.cloud.field("extra_ring")->values, extra_ring->values);
}

TEST(LasFixture, FeetFromGeoKeysAreReadIntoMetres) {
  Cloud c = fixture_cloud();
  c.georef->las_version_minor = 2;
  c.georef->las_point_format = 1;
  c.georef->las_global_encoding = 0;
  c.georef->unit_m = 1.0;  // the writer takes the points as they are; the reader applies the keys' unit
  c.georef->crs_records.clear();
  CrsRecord keys;
  keys.user_id = "LASF_Projection";
  keys.record_id = 34735;
  const std::vector<std::uint16_t> k = {1, 1, 0, 2, 3072, 0, 1, 2994, 3076, 0, 1, 9002};
  keys.data.resize(k.size() * 2);
  std::memcpy(keys.data.data(), k.data(), keys.data.size());
  c.georef->crs_records.push_back(keys);
  const auto dir = temp_dir("las_feet");  // (each call empties the directory)
  const std::string path = (dir / "feet.las").string();
  ASSERT_TRUE(write_cloud(path, c, {}).ok());
  const ReadResult r = read_ok(path);
  ASSERT_TRUE(r.cloud.georef);
  EXPECT_DOUBLE_EQ(r.cloud.georef->unit_m, 0.3048);
  EXPECT_EQ(r.cloud.georef->epsg, 2994U);
  // the same file coordinates, now metres: the cloud's extent shrinks by 0.3048
  const Bounds a = compute_bounds(c), b = compute_bounds(r.cloud);
  EXPECT_NEAR(b.max.x() - b.min.x(), (a.max.x() - a.min.x()) * 0.3048, 1e-3);
  // and written back in feet
  const std::string again = (dir / "again.las").string();
  ASSERT_TRUE(write_cloud(again, r.cloud, {}).ok());
  const Bytes x = file_bytes(path), y = file_bytes(again);
  const RawHeader hx = raw_header(x), hy = raw_header(y);
  for (std::size_t i = 0; i < 200; ++i)
    for (std::size_t k2 = 0; k2 < 12; ++k2)
      ASSERT_EQ(x[hx.point_offset + i * hx.record_len + k2], y[hy.point_offset + i * hy.record_len + k2]) << i;
}

TEST(LasFixture, LazIsRefused) {
  const std::string path = write_fixture("las_laz");
  Bytes b = file_bytes(path);
  const std::string laz = (temp_dir("las_laz") / "points.laz").string();
  write_bytes(laz, b);
  auto r = read_cloud(laz);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("LAZ"), std::string::npos) << r.status().message();
  // a compressed point format byte in a file named .las
  b[104] |= 0x80;
  const std::string hidden = (temp_dir("las_laz") / "hidden.las").string();
  write_bytes(hidden, b);
  r = read_cloud(hidden);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("LAZ"), std::string::npos) << r.status().message();
  EXPECT_FALSE(write_cloud((temp_dir("las_laz") / "out.laz").string(), fixture_cloud(), {}).ok());
}

TEST(LasCorrupt, TruncationAtEveryOffsetIsAnError) {
  const std::string path = write_fixture("las_trunc");
  const Bytes b = file_bytes(path);
  const std::string cut = (temp_dir("las_trunc") / "cut.las").string();
  // every byte of the header, the records' start and the EVLR, and a stride through the points
  for (std::size_t n = 1; n < b.size(); n += (n < 500 || n > b.size() - 300) ? 1 : 7) {
    write_bytes(cut, Bytes(b.begin(), b.begin() + static_cast<std::ptrdiff_t>(n)));
    auto r = read_cloud(cut);
    ASSERT_FALSE(r.ok()) << "cut at " << n;
    EXPECT_EQ(r.status().code(), ErrorCode::kBadData) << n;
    EXPECT_EQ(r.status().message().rfind(cut, 0), 0U) << r.status().message();
    EXPECT_EQ(r.status().message().find('\n'), std::string::npos);
  }
}

TEST(LasCorrupt, EachHeaderFieldIsChecked) {
  const std::string path = write_fixture("las_fields");
  const Bytes good = file_bytes(path);
  const std::string bad = (temp_dir("las_fields") / "bad.las").string();
  struct Case {
    const char* what;
    void (*poke)(Bytes&);
    const char* expect;
  };
  const Case cases[] = {
      {"signature", [](Bytes& b) { b[0] = 'X'; }, "LASF"},
      {"version", [](Bytes& b) { b[25] = 9; }, "version"},
      {"header size", [](Bytes& b) { put<std::uint16_t>(b, 94, 300); }, "header size"},
      {"header size past the end", [](Bytes& b) { put<std::uint16_t>(b, 94, 65000); }, "header size"},
      {"offset to points", [](Bytes& b) { put<std::uint32_t>(b, 96, 0xFFFFFF00U); }, "offset to point data"},
      {"VLR count", [](Bytes& b) { put<std::uint32_t>(b, 100, 1000000U); }, "VLRs"},
      {"point format", [](Bytes& b) { b[104] = 11; }, "format"},
      {"record length", [](Bytes& b) { put<std::uint16_t>(b, 105, 20); }, "record length"},
      {"64-bit count", [](Bytes& b) { put<std::uint64_t>(b, 247, 1ULL << 40); }, "truncated point data"},
      {"legacy count disagrees", [](Bytes& b) { put<std::uint32_t>(b, 107, 7U); }, "differ"},
      {"scale zero", [](Bytes& b) { put<double>(b, 139, 0.0); }, "scale"},
      {"offset NaN", [](Bytes& b) { put<double>(b, 171, std::nan("")); }, "offset"},
      {"EVLR start", [](Bytes& b) { put<std::uint64_t>(b, 235, 100); }, "EVLR"},
      {"EVLR count", [](Bytes& b) { put<std::uint32_t>(b, 243, 1000U); }, "EVLR"},
      {"EVLR length", [](Bytes& b) { put<std::uint64_t>(b, get<std::uint64_t>(b, 235) + 20, 1ULL << 50); }, "EVLR 0 length"},
  };
  for (const Case& c : cases) {
    Bytes b = good;
    c.poke(b);
    write_bytes(bad, b);
    auto r = read_cloud(bad, {Format::kLas});
    ASSERT_FALSE(r.ok()) << c.what;
    EXPECT_NE(r.status().message().find(c.expect), std::string::npos) << c.what << ": " << r.status().message();
    EXPECT_EQ(r.status().message().rfind(bad, 0), 0U) << c.what;
  }
}

TEST(LasCorrupt, VlrLengthIsChecked) {
  Cloud c = fixture_cloud();
  c.georef->las_version_minor = 2;
  c.georef->las_point_format = 0;
  c.georef->crs_records[0].extended = false;  // a VLR in a 1.2 file
  const std::string path = (temp_dir("las_vlr") / "vlr.las").string();
  ASSERT_TRUE(write_cloud(path, c, {}).ok());
  Bytes b = file_bytes(path);
  ASSERT_EQ(get<std::uint32_t>(b, 100), 1U);
  put<std::uint16_t>(b, 227 + 20, 60000);  // the VLR's length runs into the points and past them
  write_bytes(path, b);
  auto r = read_cloud(path);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("VLR 0 length"), std::string::npos) << r.status().message();
  // a garbled WKT is reported, not fatal
  b = file_bytes(path);
  put<std::uint16_t>(b, 227 + 20, static_cast<std::uint16_t>(c.georef->crs_records[0].data.size()));
  b[227 + 54] = '@';
  write_bytes(path, b);
  const ReadResult ok = read_ok(path);
  EXPECT_EQ(ok.cloud.size(), 200U);
  EXPECT_DOUBLE_EQ(ok.cloud.georef->unit_m, 1.0);
  EXPECT_FALSE(ok.notes.empty());
}

TEST(LasCorrupt, ExtentBeyondFloat32ResolutionIsRefused) {
  // 1 µm steps over 1000 km: float32 about one origin cannot keep them
  Cloud c = fixture_cloud();
  c.georef->las_scale = Eigen::Vector3d(1e-6, 1e-6, 1e-6);
  c.georef->las_offset = c.georef->origin;
  c.points[0].x() = -500000.0F;  // the writer needs 32-bit steps: it coarsens the scale
  const std::string path = (temp_dir("las_extent") / "wide.las").string();
  ASSERT_TRUE(write_cloud(path, c, {}).ok());
  Bytes b = file_bytes(path);
  // put the fine scale back by hand with integers that span 2^31 steps of 1 µm (2147 m)
  const RawHeader h = raw_header(b);
  put<double>(b, 131, 1e-6);
  put<double>(b, 155, 500000.0);
  put<std::int32_t>(b, h.point_offset, -2000000000);
  put<std::int32_t>(b, h.point_offset + h.record_len, 2000000000);
  write_bytes(path, b);
  auto r = read_cloud(path);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("float32"), std::string::npos) << r.status().message();
}

// ------------------------------------------------------------------ doubles in other formats

/// A binary PCD of double x y z with the VIEWPOINT `viewpoint` (tx ty tz qw qx qy qz).
Bytes double_pcd(const std::vector<Eigen::Vector3d>& pts, const std::string& viewpoint) {
  const std::string n = std::to_string(pts.size());
  const std::string text = "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 8 8 8\nTYPE F F F\nCOUNT 1 1 1\nWIDTH " + n +
                           "\nHEIGHT 1\nVIEWPOINT " + viewpoint + "\nPOINTS " + n + "\nDATA binary\n";
  Bytes b(text.begin(), text.end());
  for (const auto& p : pts)
    for (int a = 0; a < 3; ++a) {
      const std::size_t at = b.size();
      b.resize(at + 8);
      std::memcpy(b.data() + at, &p[a], 8);
    }
  return b;
}

TEST(Georeference, PcdWithDoubleUtmCoordinates) {
  const std::string dir = temp_dir("pcd_utm").string();
  std::vector<Eigen::Vector3d> pts;
  for (int i = 0; i < 500; ++i)
    pts.emplace_back(393775.823 + 0.137 * i, 5403850.001 + 0.071 * (i % 37), 3107.8627 + 0.00013 * i);
  const std::string path = dir + "/utm.pcd";
  write_bytes(path, double_pcd(pts, "0 0 0 1 0 0 0"));
  const ReadResult r = read_ok(path);
  ASSERT_EQ(r.cloud.size(), 500U);
  ASSERT_TRUE(r.cloud.georef);
  const Georeference& g = *r.cloud.georef;
  EXPECT_EQ(g.origin, g.origin.array().round().matrix());  // a rounded centre
  double worst = 0.0;
  for (std::size_t i = 0; i < pts.size(); ++i) worst = std::max(worst, (g.to_crs(r.cloud.points[i]) - pts[i]).norm());
  EXPECT_LT(worst, 1e-5);  // float32 straight away would lose 0.25 m at 5,403,850 m
  EXPECT_NEAR(g.representation_error_m, worst, 1e-9);
  // written back as doubles in true coordinates
  const std::string out = dir + "/back.pcd";
  ASSERT_TRUE(write_cloud(out, r.cloud, {}).ok());
  const ReadResult back = read_ok(out);
  ASSERT_TRUE(back.cloud.georef);
  double back_worst = 0.0;
  for (std::size_t i = 0; i < pts.size(); ++i)
    back_worst = std::max(back_worst, (back.cloud.georef->to_crs(back.cloud.points[i]) - pts[i]).norm());
  EXPECT_LT(back_worst, 1e-5);
  // and a PLY and a text file the same way
  for (const char* ext : {".ply", ".xyz"}) {
    const std::string o2 = dir + "/back" + ext;
    ASSERT_TRUE(write_cloud(o2, r.cloud, {}).ok());
    const ReadResult b2 = read_ok(o2);
    ASSERT_TRUE(b2.cloud.georef) << ext;
    double w2 = 0.0;
    for (std::size_t i = 0; i < pts.size(); ++i) w2 = std::max(w2, (b2.cloud.georef->to_crs(b2.cloud.points[i]) - pts[i]).norm());
    EXPECT_LT(w2, 1e-5) << ext;
  }
}

TEST(Georeference, ViewpointGivenMovesWithThePoints) {
  // A PCD whose VIEWPOINT stands among its UTM points: the pose moves by the same origin (with
  // the identity, no pose, the sensor stays at the local origin: test_georef's UTM PLY).
  std::vector<Eigen::Vector3d> pts;
  for (int i = 0; i < 300; ++i) pts.emplace_back(393775.8 + 0.21 * i, 5403850.0 + 0.13 * (i % 29), 310.0 + 0.01 * i);
  const std::string path = (temp_dir("pcd_viewpoint") / "vp.pcd").string();
  write_bytes(path, double_pcd(pts, "393800 5403851 312 1 0 0 0"));
  const ReadResult r = read_ok(path);
  ASSERT_TRUE(r.cloud.georef);
  const Eigen::Vector3d sensor = r.cloud.georef->origin + r.cloud.T_cloud_sensor.translation();
  EXPECT_NEAR((sensor - Eigen::Vector3d(393800, 5403851, 312)).norm(), 0.0, 1e-6);
  EXPECT_LT(r.cloud.T_cloud_sensor.translation().norm(), 100.0);
}

TEST(Georeference, SmallCoordinatesStayAsTheyAre) {
  const std::string path = (temp_dir("xyz_small") / "small.xyz").string();
  write_bytes(path, Bytes{'1', ' ', '2', ' ', '3', '\n', '4', '.', '5', ' ', '-', '6', ' ', '7', '\n'});
  const ReadResult r = read_ok(path);
  ASSERT_EQ(r.cloud.size(), 2U);
  EXPECT_FALSE(r.cloud.georef);
  EXPECT_EQ(r.cloud.points[1], Eigen::Vector3f(4.5F, -6.0F, 7.0F));
}

}  // namespace
}  // namespace lex3d::io
