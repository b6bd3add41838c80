// The model file's georeference (formats/model.md §2.8): round trip, format version, one
// corruption test per reader check, truncation; and a georeferenced LAS scan through a
// residual layer back to its true coordinates within the bound.

#include <cmath>
#include <cstring>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <zlib.h>

#include "lex3d/codec/codec.hpp"
#include "lex3d/eval/metrics.hpp"
#include "lex3d/io/io.hpp"
#include "lex3d/residual/residual.hpp"
#include "support/model_support.hpp"
#include "support/test_support.hpp"

namespace lex3d::codec {
namespace {

using test::write_bytes;

using Bytes = std::vector<std::uint8_t>;

/// A georeference with two CRS records. Their bytes are `deflatable` (a WKT string, as LAS
/// files carry, which the writer deflates: format 1.12) or not (a third record of
/// pseudo-random bytes, which deflate cannot shrink: the records stay raw, format 1.5).
Georeference sample_georef(bool deflatable = false) {
  Georeference g;
  g.origin = Eigen::Vector3d(194032.632, 258842.256, 141.1224);
  g.unit_m = 0.3048;
  g.vertical_unit_m = 0.3048;
  g.unit_name = "international foot";
  g.crs_name = "NAD_1983_HARN_Lambert_Conformal_Conic";
  g.epsg = 2994;
  g.las_scale = Eigen::Vector3d(0.01, 0.01, 0.01);
  g.las_offset = Eigen::Vector3d(0.0, 0.0, 0.0);
  g.las_version_minor = 2;
  g.las_point_format = 3;
  g.las_global_encoding = 0;
  g.las_system_id = "PDAL";
  g.las_software = "PDAL 1.0.0";
  CrsRecord r;
  r.user_id = "LASF_Projection";
  r.record_id = 2112;
  r.description = "OGC Transformation Record";
  r.data = {'P', 'R', 'O', 'J', 'C', 'S', '[', ']', 0};
  g.crs_records.push_back(r);
  r.record_id = 34735;
  r.extended = true;
  r.data = {1, 0, 1, 0, 0, 0, 0, 0};
  g.crs_records.push_back(r);
  if (deflatable) {
    const std::string wkt =
        "PROJCS[\"NAD83(HARN) / Oregon GIC Lambert (ft)\",GEOGCS[\"NAD83(HARN)\",DATUM[\"NAD83_High_Accuracy_"
        "Reference_Network\",SPHEROID[\"GRS 1980\",6378137,298.257222101]],PRIMEM[\"Greenwich\",0],UNIT[\"degree\","
        "0.0174532925199433]],PROJECTION[\"Lambert_Conformal_Conic_2SP\"],UNIT[\"foot\",0.3048]]";
    g.crs_records[0].data.assign(wkt.begin(), wkt.end());
  } else {
    // every byte of the records pseudo-random (never NUL), their names to full length
    std::uint32_t x = 12345;
    const auto next = [&x] {
      x = x * 1664525U + 1013904223U;
      return static_cast<char>(1 + (x >> 24) % 255);
    };
    r.record_id = 7;
    r.extended = false;
    r.data.resize(300);
    g.crs_records.push_back(r);
    for (CrsRecord& rec : g.crs_records) {
      rec.user_id.clear();
      rec.description.clear();
      for (int i = 0; i < 16; ++i) rec.user_id.push_back(next());
      for (int i = 0; i < 32; ++i) rec.description.push_back(next());
      for (auto& byte : rec.data) byte = static_cast<std::uint8_t>(next());
    }
  }
  return g;
}

ModelData sample_model(bool deflatable = false) {
  ModelData d;
  d.input_points = 10;
  test::add_empty_word_instance(d);  // (so that the file is 1.5, not 1.11)
  d.georef = sample_georef(deflatable);
  return d;
}

std::uint64_t u64_at(const Bytes& b, std::size_t at) {
  std::uint64_t v = 0;
  for (int i = 7; i >= 0; --i) v = (v << 8) | b[at + static_cast<std::size_t>(i)];
  return v;
}

/// Offset of the GEOR chunk's header.
std::size_t geor_at(const Bytes& b) {
  for (std::size_t pos = 20; pos + 12 <= b.size();) {
    if (std::memcmp(&b[pos], "GEOR", 4) == 0) return pos;
    pos += 16 + u64_at(b, pos + 4);
  }
  return 0;
}

/// Recomputes the CRC of the chunk at `at`.
void fix_crc(Bytes& b, std::size_t at) {
  const std::uint64_t len = u64_at(b, at + 4);
  const auto k = static_cast<std::uint32_t>(crc32(0, b.data() + at, static_cast<uInt>(12 + len)));
  for (int i = 0; i < 4; ++i) b[at + 12 + len + static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(k >> (8 * i));
}

void fix_header_crc(Bytes& b) {
  const auto k = static_cast<std::uint32_t>(crc32(0, b.data(), 16));
  for (int i = 0; i < 4; ++i) b[16 + static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(k >> (8 * i));
}

TEST(Georef, RoundTripIsExactAndUsesMinorVersion5) {
  const ModelData d = sample_model();
  const Bytes b = encode_model(d);
  EXPECT_EQ(b[10] | (b[11] << 8), 5);
  auto back = decode_model(b);
  ASSERT_TRUE(back.ok()) << back.status().to_string();
  ASSERT_TRUE(back.value().georef);
  test::expect_same_georef(*back.value().georef, *d.georef);
  // without a georeference the file keeps its older version and has no GEOR chunk
  ModelData plain = d;
  plain.georef.reset();
  const Bytes p = encode_model(plain);
  EXPECT_EQ(p[10] | (p[11] << 8), 0);
  EXPECT_EQ(geor_at(p), 0U);
  EXPECT_FALSE(decode_model(p).value().georef);
}

TEST(Georef, EncoderRejectsInvalidGeoreferences) {
  auto rejects = [](void (*poke)(Georeference&)) {
    ModelData d = sample_model();
    poke(*d.georef);
    EXPECT_THROW((void)encode_model(d), std::invalid_argument);
  };
  rejects([](Georeference& g) { g.origin.x() = std::nan(""); });
  rejects([](Georeference& g) { g.origin.y() = 2e9; });
  rejects([](Georeference& g) { g.unit_m = 0.0; });
  rejects([](Georeference& g) { g.vertical_unit_m = 1e5; });
  rejects([](Georeference& g) { g.las_scale.z() = 0.0; });
  rejects([](Georeference& g) { g.las_point_format = 11; });
  rejects([](Georeference& g) { g.crs_records[0].data.assign((1U << 20) + 1, 0); });
}

/// A payload field overwritten: the reader names the problem.
void expect_geor_rejected(std::size_t field_offset, const Bytes& value, const std::string& needle) {
  Bytes b = encode_model(sample_model());
  const std::size_t at = geor_at(b);
  ASSERT_GT(at, 0U);
  std::memcpy(&b[at + 12 + field_offset], value.data(), value.size());
  fix_crc(b, at);
  auto r = decode_model(b);
  ASSERT_FALSE(r.ok()) << needle;
  EXPECT_EQ(r.status().code(), ErrorCode::kBadData);
  EXPECT_NE(r.status().message().find(needle), std::string::npos) << r.status().message();
}

Bytes f64_bytes(double v) {
  Bytes b(8);
  std::memcpy(b.data(), &v, 8);
  return b;
}
Bytes u32_bytes(std::uint32_t v) {
  Bytes b(4);
  std::memcpy(b.data(), &v, 4);
  return b;
}

TEST(GeorefCorrupt, EachFieldIsChecked) {
  expect_geor_rejected(0, f64_bytes(std::nan("")), "origin");
  expect_geor_rejected(16, f64_bytes(-5e9), "origin");
  expect_geor_rejected(24, f64_bytes(0.0), "unit");
  expect_geor_rejected(32, f64_bytes(std::numeric_limits<double>::infinity()), "unit");
  expect_geor_rejected(52, f64_bytes(-0.01), "LAS scale");
  expect_geor_rejected(84, f64_bytes(std::nan("")), "LAS offset");
  expect_geor_rejected(92, Bytes{7}, "minor version");
  expect_geor_rejected(93, Bytes{11}, "point format");
  expect_geor_rejected(96, Bytes{0xFF, 0xFF}, "string");
  // the record count and a record's length, after the four strings
  const Georeference g = sample_georef();
  const std::size_t records =
      96 + 8 + g.crs_name.size() + g.unit_name.size() + g.las_system_id.size() + g.las_software.size();
  expect_geor_rejected(records, u32_bytes(100000), "record count");
  expect_geor_rejected(records + 4 + 51, u32_bytes(0x7FFFFFFF), "record 0 length");
  expect_geor_rejected(records + 4 + 18, Bytes{2}, "extended flag");
}

TEST(Georef, CompressibleRecordsAreDeflatedInFormat1_12) {
  const ModelData d = sample_model(true);
  const Bytes b = encode_model(d);
  EXPECT_EQ(b[10] | (b[11] << 8), 12);
  const Bytes raw = encode_model(sample_model(false));
  const std::size_t at = geor_at(b);
  ASSERT_GT(at, 0U);
  const auto back = decode_model(b);
  ASSERT_TRUE(back.ok()) << back.status().to_string();
  const Georeference& g = *back.value().georef;
  ASSERT_EQ(g.crs_records.size(), 2U);
  for (std::size_t i = 0; i < 2; ++i) {
    EXPECT_EQ(g.crs_records[i].data, d.georef->crs_records[i].data) << i;
    EXPECT_EQ(g.crs_records[i].user_id, d.georef->crs_records[i].user_id) << i;
    EXPECT_EQ(g.crs_records[i].description, d.georef->crs_records[i].description) << i;
    EXPECT_EQ(g.crs_records[i].record_id, d.georef->crs_records[i].record_id) << i;
  }
  EXPECT_EQ(g.crs_name, d.georef->crs_name);
  // the records' bytes and heads take less room deflated than raw
  std::uint64_t raw_records = 0;
  for (const auto& r : d.georef->crs_records) raw_records += 55 + r.data.size();
  const std::size_t records = 96 + 8 + d.georef->crs_name.size() + d.georef->unit_name.size() +
                              d.georef->las_system_id.size() + d.georef->las_software.size();
  EXPECT_LT(u64_at(b, at + 4), records + 4 + raw_records);
  EXPECT_EQ(b[at + 12 + records + 3] & 0x80, 0x80) << "bit 31 of the record count";
  // claimed as 1.11: refused
  Bytes old = b;
  old[10] = 11;
  fix_header_crc(old);
  auto r = decode_model(old);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("need format version 1.12"), std::string::npos) << r.status().message();
  // its size and stream corrupted, its payload cut: refused, never a crash
  const auto corrupt = [&](std::size_t offset, std::uint8_t mask) {
    Bytes c = b;
    c[at + 12 + offset] ^= mask;
    fix_crc(c, at);
    return decode_model(c);
  };
  EXPECT_FALSE(corrupt(records + 4, 0xFF).ok()) << "raw size";
  EXPECT_FALSE(corrupt(records + 7, 0x7F).ok()) << "raw size";
  const std::uint64_t len = u64_at(b, at + 4);
  for (std::size_t k = records + 8; k < len; ++k) {
    const auto c = corrupt(k, 0x24);
    if (c.ok()) EXPECT_EQ(c.value().georef->crs_records.size(), 2U) << k;  // (zlib's check makes this rare)
  }
  (void)raw;
}

TEST(GeorefCorrupt, NeedsMinorVersion5) {
  Bytes b = encode_model(sample_model());
  b[10] = 4;
  fix_header_crc(b);
  auto r = decode_model(b);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("needs format version 1.5"), std::string::npos) << r.status().message();
}

TEST(GeorefCorrupt, TrailingBytesAndTruncatedPayload) {
  const Bytes good = encode_model(sample_model());
  const std::size_t at = geor_at(good);
  const std::uint64_t len = u64_at(good, at + 4);
  // the payload cut at every length (the chunk reframed, CRC fixed): an error, never a crash
  for (std::uint64_t n = 0; n < len; ++n) {
    Bytes b(good.begin(), good.begin() + static_cast<std::ptrdiff_t>(at + 12 + n));
    for (int i = 0; i < 8; ++i) b[at + 4 + static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(n >> (8 * i));
    b.resize(b.size() + 4);
    fix_crc(b, at);
    b.insert(b.end(), good.begin() + static_cast<std::ptrdiff_t>(at + 16 + len), good.end());
    auto r = decode_model(b);
    EXPECT_FALSE(r.ok()) << "payload of " << n << " bytes";
  }
  // and the whole file cut at every byte
  for (std::size_t n = 0; n < good.size(); ++n) {
    auto r = decode_model(Bytes(good.begin(), good.begin() + static_cast<std::ptrdiff_t>(n)));
    EXPECT_FALSE(r.ok()) << n;
  }
}

TEST(GeorefGolden, Format15FileDecodes) {
  // tests/codec/golden/tiny_model_georef_1.5.lex3dm, built by tests/fuzz/make_corpus.py from
  // the specification (model.md §2.8) independently of this encoder: decoded forever
  auto bytes = io::read_file(std::string(LEX3D_TEST_DATA_DIR) + "/../codec/golden/tiny_model_georef_1.5.lex3dm");
  ASSERT_TRUE(bytes.ok());
  auto d = decode_model(bytes.value());
  ASSERT_TRUE(d.ok()) << d.status().to_string();
  ASSERT_TRUE(d.value().georef);
  const Georeference& g = *d.value().georef;
  EXPECT_EQ(g.origin, Eigen::Vector3d(393925.823061, 3689171.943122, 3158.8627));
  EXPECT_EQ(g.unit_m, 1.0);
  EXPECT_EQ(g.epsg, 32642U);
  EXPECT_EQ(g.las_scale, Eigen::Vector3d(0.001, 0.001, 1e-5));
  EXPECT_EQ(g.las_point_format, 1);
  EXPECT_EQ(g.crs_name, "WGS 84 / UTM zone 42N");
  EXPECT_EQ(g.las_system_id, "ALIRT");
  ASSERT_EQ(g.crs_records.size(), 1U);
  EXPECT_EQ(g.crs_records[0].record_id, 2112);
  EXPECT_EQ(g.crs_records[0].description, "OGC Transformation Record");
  // our encoder writes the same GEOR payload for the same georeference
  ModelData again = d.value();
  const Bytes ours = encode_model(again, Quantization{});
  const Bytes& theirs = bytes.value();
  const std::size_t a = geor_at(ours), b = geor_at(theirs);
  ASSERT_GT(a, 0U);
  ASSERT_GT(b, 0U);
  EXPECT_EQ(Bytes(ours.begin() + static_cast<std::ptrdiff_t>(a), ours.begin() + static_cast<std::ptrdiff_t>(a + 16 + u64_at(ours, a + 4))),
            Bytes(theirs.begin() + static_cast<std::ptrdiff_t>(b), theirs.begin() + static_cast<std::ptrdiff_t>(b + 16 + u64_at(theirs, b + 4))));
}

// ------------------------------------------------------------------ end to end on real LAS

TEST(GeorefModel, LasScanComesBackInItsTrueCoordinatesWithinTheBound) {
  LEX3D_REQUIRE_SHARED("las/autzen_trim.las");
  auto read = io::read_cloud(test::shared_data("las/autzen_trim.las"));
  ASSERT_TRUE(read.ok());
  const Cloud& input = read.value().cloud;
  ASSERT_TRUE(input.georef);
  const double E = 0.05;  // metres
  ModelData d;
  d.input_points = input.size();
  d.alphabet = Alphabet{};
  d.georef = input.georef;
  d.residual = residual::encode_layer(input, Cloud{}, d.T_cloud_sensor, E);
  const Bytes file = encode_model(d);
  auto decoded = decode_model(file);
  ASSERT_TRUE(decoded.ok()) << decoded.status().to_string();
  auto cloud = residual::decode_cloud(decoded.value());
  ASSERT_TRUE(cloud.ok());
  Cloud out = cloud.value();
  out.georef = decoded.value().georef;
  // written as LAS in feet, read back: the true coordinates within E + half the file's step
  const std::string las = (test::temp_dir("georef_model") / "back.las").string();
  ASSERT_TRUE(io::write_cloud(las, out).ok());
  auto back = io::read_cloud(las);
  ASSERT_TRUE(back.ok());
  ASSERT_TRUE(back.value().cloud.georef);
  // both clouds in metres about the input's origin
  Cloud a = input, b = back.value().cloud;
  const Eigen::Vector3d shift = b.georef->origin - a.georef->origin;
  for (auto& p : b.points) p = (p.cast<double>() + shift).cast<float>();
  const eval::DistanceResult dist = eval::compare_clouds(a, b);
  const double quantum = 0.5 * std::sqrt(3.0) * 0.01 * 0.3048;  // half a 0.01 ft step on each axis
  EXPECT_LE(dist.hausdorff, E + quantum + 1e-6);
  EXPECT_GT(dist.hausdorff, 0.0);
  // and the file says feet and the same CRS records
  EXPECT_DOUBLE_EQ(back.value().cloud.georef->unit_m, 0.3048);
  EXPECT_EQ(back.value().cloud.georef->crs_records.size(), input.georef->crs_records.size());
}

/// A binary PLY of double x y z (no viewpoint) at `path`.
void write_double_ply(const std::string& path, const std::vector<Eigen::Vector3d>& pts) {
  const std::string head = "ply\nformat binary_little_endian 1.0\nelement vertex " + std::to_string(pts.size()) +
                           "\nproperty double x\nproperty double y\nproperty double z\nend_header\n";
  Bytes b(head.begin(), head.end());
  for (const auto& p : pts)
    for (int a = 0; a < 3; ++a) {
      const std::size_t at = b.size();
      b.resize(at + 8);
      std::memcpy(b.data() + at, &p[a], 8);
    }
  write_bytes(path, b);
}

TEST(GeorefModel, UtmPlyWithoutViewpointCodesWithAFineBound) {
  // Rolling ground 60 m across at UTM coordinates, in a PLY of doubles with no sensor pose:
  // read relative to a round origin, the sensor left at that origin (not at the CRS's, 5,400 km
  // off, where float32 steps are 0.5 m), so a 2 cm bound codes and holds in true coordinates.
  std::vector<Eigen::Vector3d> pts;
  for (int i = 0; i < 120; ++i)
    for (int j = 0; j < 120; ++j) {
      const double x = 0.5 * i + 0.013 * j, y = 0.5 * j;
      pts.emplace_back(512345.678 + x, 5403850.25 + y, 121.5 + 2.0 * std::sin(x / 9.0) + std::cos(y / 7.0));
    }
  const std::string path = (test::temp_dir("georef_utm_ply") / "utm.ply").string();
  write_double_ply(path, pts);
  auto read = io::read_cloud(path);
  ASSERT_TRUE(read.ok()) << read.status().to_string();
  const Cloud& input = read.value().cloud;
  ASSERT_TRUE(input.georef);
  EXPECT_TRUE(input.T_cloud_sensor.matrix().isIdentity(0.0));  // at the local origin
  const double E = 0.02;
  ModelData d;
  d.input_points = input.size();
  d.alphabet = Alphabet{};
  d.georef = input.georef;
  d.T_cloud_sensor = input.T_cloud_sensor;
  d.residual = residual::encode_layer(input, Cloud{}, d.T_cloud_sensor, E);
  auto decoded = decode_model(encode_model(d));
  ASSERT_TRUE(decoded.ok()) << decoded.status().to_string();
  ASSERT_TRUE(decoded.value().georef);
  auto cloud = residual::decode_cloud(decoded.value());
  ASSERT_TRUE(cloud.ok());
  // every input point within E of a decoded one and back, in true (double) coordinates
  Cloud a, b;
  for (const auto& p : pts) a.points.push_back((p - input.georef->origin).cast<float>());
  for (const auto& p : cloud.value().points)
    b.points.push_back((decoded.value().georef->to_crs(p) - input.georef->origin).cast<float>());
  const eval::DistanceResult dist = eval::compare_clouds(a, b);
  EXPECT_LE(dist.hausdorff, E + 1e-5);
  EXPECT_GT(dist.hausdorff, 0.0);
}

}  // namespace
}  // namespace lex3d::codec
