// Point attributes in model files (formats/model.md §2.10): round trips of each field,
// lossless equality where the chunk promises it, bounds where it does not, bad input,
// corrupt and truncated chunks, determinism, a real KITTI scan, and the ring coded against
// the sensor-geometry layer's lasers (method 3) on synthetic, sample and Ouster scans, and
// intensities coded by a context tree on those lasers (method 4).

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <random>
#include <string>
#include <numeric>
#include <vector>

#include "lex3d/codec/codec.hpp"
#include "lex3d/io/io.hpp"
#include "lex3d/residual/attributes.hpp"
#include "lex3d/residual/residual.hpp"
#include "residual/residual_test_util.hpp"
#include "support/model_support.hpp"
#include "support/test_support.hpp"
#include "test_config.hpp"

namespace lex3d {
namespace {

using Bytes = std::vector<std::uint8_t>;
using residual_test::with_minor;
using residual_test::edit_chunk;

/// A spinning-lidar-like scan: `lasers` rings of `columns` points around a room, with
/// intensities in 0.01 steps, times in microseconds within the turn, ring and colour.
Cloud synthetic_scan(int lasers, int columns, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> jitter(-0.02, 0.02);
  std::uniform_int_distribution<int> noise(-3, 3);
  Cloud c;
  for (int col = 0; col < columns; ++col)
    for (int l = 0; l < lasers; ++l) {
      const double az = 2.0 * M_PI * col / columns;
      const double el = (-15.0 + 30.0 * l / std::max(1, lasers - 1)) * M_PI / 180.0;
      const double r = 8.0 + 3.0 * std::sin(3.0 * az) + jitter(rng);
      c.points.emplace_back(static_cast<float>(r * std::cos(el) * std::cos(az)),
                            static_cast<float>(r * std::cos(el) * std::sin(az)), static_cast<float>(r * std::sin(el)));
      const int k = std::clamp(40 + static_cast<int>(20 * std::sin(az * 5.0)) + noise(rng), 0, 99);
      c.intensity.push_back(static_cast<float>(k * 0.01));
      c.time.push_back(1.5e9 + 1e-6 * (col * 50 + l));
      c.ring.push_back(static_cast<std::uint16_t>(l));
      c.rgb.push_back({static_cast<std::uint8_t>(k * 2), static_cast<std::uint8_t>(255 - k), static_cast<std::uint8_t>(l * 8)});
    }
  return c;
}

struct Coded {
  Bytes file;
  std::vector<std::uint32_t> sources;
  std::vector<residual::AttributeField> fields;
};

/// A layer-only model of `input` with bound `e`, attributes kept as `ao`.
Coded code(const Cloud& input, double e, const residual::AttributeOptions& ao = {}, bool thin = false,
           bool wordless = false) {
  codec::ModelData d;
  d.input_points = input.size();
  // (with an instance of an empty word the file keeps the version its chunks need)
  if (wordless) d.alphabet = Alphabet{};
  else test::add_empty_word_instance(d);
  residual::LayerOptions lo;
  lo.thin = thin;
  lo.track_sources = true;
  lo.laser = false;
  residual::LayerStats st;
  const Cloud words = residual::decoder_word_cloud(d, *d.alphabet);
  d.residual = residual::encode_layer(input, words, d.T_cloud_sensor, e, &st, lo);
  Coded c;
  c.sources = st.sources;
  auto attrs = residual::encode_attributes(input, st.sources, ao, &c.fields);
  if (!attrs.empty()) d.attributes = std::move(attrs);
  c.file = codec::encode_model(d);
  return c;
}

/// The index of the point of `c` nearest to `p` (the first of equals).
std::size_t nearest_point(const Cloud& c, const Eigen::Vector3f& p) {
  std::size_t nearest = 0;
  float best = std::numeric_limits<float>::max();
  for (std::size_t i = 0; i < c.size(); ++i) {
    const float dd = (c.points[i] - p).squaredNorm();
    if (dd < best) {
      best = dd;
      nearest = i;
    }
  }
  return nearest;
}

StatusOr<Cloud> decode(const Bytes& file) {
  auto d = codec::decode_model(file);
  if (!d.ok()) return d.status();
  return residual::decode_cloud(d.value());
}

TEST(Attributes, EveryFieldRoundTripsLosslessly) {
  const Cloud in = synthetic_scan(16, 360, 1);
  const Coded c = code(in, 0.01);
  ASSERT_EQ(c.fields.size(), 4U);
  auto info = codec::inspect(c.file);
  ASSERT_TRUE(info.ok());
  EXPECT_EQ(info.value().minor, 6);
  auto out = decode(c.file);
  ASSERT_TRUE(out.ok()) << out.status().to_string();
  const Cloud& d = out.value();
  // thinning off, every point coded by the layer: one decoded point an input point
  ASSERT_EQ(d.size(), in.size());
  ASSERT_EQ(c.sources.size(), d.size());
  ASSERT_TRUE(d.has_intensity() && d.has_time() && d.has_rings() && d.has_rgb());
  std::vector<int> seen(in.size(), 0);
  for (std::size_t j = 0; j < d.size(); ++j) {
    const std::uint32_t i = c.sources[j];
    ++seen[i];
    EXPECT_EQ(d.intensity[j], in.intensity[i]) << j;
    EXPECT_EQ(d.time[j], in.time[i]) << j;
    EXPECT_EQ(d.ring[j], in.ring[i]) << j;
    EXPECT_EQ(d.rgb[j], in.rgb[i]) << j;
    EXPECT_LE((d.points[j] - in.points[i]).norm(), 0.01F);
  }
  for (const int s : seen) EXPECT_EQ(s, 1);  // a permutation of the input
  // the intensity's step was found in the data
  EXPECT_NEAR(c.fields[1].step, 0.01, 1e-12);
  EXPECT_EQ(c.fields[1].name, "intensity");
}

// A model without words (format 1.11: no alphabet, no instances) carries its layer and
// ATTR chunk as any other and decodes to the same cloud.
TEST(Attributes, ModelWithoutWordsCarriesTheChunk) {
  const Cloud in = synthetic_scan(16, 360, 1);
  const Coded with = code(in, 0.01);
  const Coded without = code(in, 0.01, {}, false, true);
  const auto info = codec::inspect(without.file);
  ASSERT_TRUE(info.ok());
  EXPECT_EQ(info.value().minor, 11);
  std::string types;
  for (const auto& ch : info.value().chunks) types += ch.type + " ";
  EXPECT_EQ(types, "MHDR RESD ATTR IEND ");
  EXPECT_LT(without.file.size(), with.file.size());
  const auto a = decode(with.file), b = decode(without.file);
  ASSERT_TRUE(a.ok() && b.ok()) << b.status().to_string();
  ASSERT_EQ(a.value().size(), b.value().size());
  EXPECT_EQ(a.value().points, b.value().points);
  EXPECT_EQ(a.value().intensity, b.value().intensity);
  EXPECT_EQ(a.value().time, b.value().time);
  EXPECT_EQ(a.value().ring, b.value().ring);
  EXPECT_EQ(a.value().rgb, b.value().rgb);
}

/// GPS times as a LAS file holds them (seconds of the week, no exact step) spanning more
/// than 2^31 of the default 1 ns steps: kept within half the finest step that fits them,
/// which the field reports, instead of refusing the scan.
TEST(Attributes, TimesSpanningSecondsWithoutAStepAreKeptWithinTheirReportedBound) {
  Cloud in = synthetic_scan(8, 200, 4);
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> jitter(0.0, 1e-4);
  for (std::size_t i = 0; i < in.size(); ++i) in.time[i] = 245379.398436825 + 6.5 * static_cast<double>(i) / static_cast<double>(in.size()) + jitter(rng);
  const Coded c = code(in, 0.01);
  const auto time = std::find_if(c.fields.begin(), c.fields.end(), [](const auto& f) { return f.name == "time"; });
  ASSERT_NE(time, c.fields.end());
  EXPECT_GT(time->max_error, 0.5e-9);  // wider than the default, as the span needs
  EXPECT_LT(time->max_error, 5e-9);
  auto out = decode(c.file);
  ASSERT_TRUE(out.ok()) << out.status().to_string();
  ASSERT_EQ(out.value().size(), in.size());
  for (std::size_t j = 0; j < out.value().size(); ++j)
    ASSERT_LE(std::abs(out.value().time[j] - in.time[c.sources[j]]), time->max_error) << j;
}

TEST(Attributes, FloatIntensitiesWithoutAStepKeepTheirBits) {
  Cloud in = synthetic_scan(8, 200, 2);
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(0.0F, 1000.0F);
  for (auto& v : in.intensity) v = u(rng);
  in.intensity[5] = -0.0F;
  in.intensity[6] = -17.25F;
  in.time.clear();
  in.rgb.clear();
  const Coded c = code(in, 0.01);
  auto out = decode(c.file);
  ASSERT_TRUE(out.ok()) << out.status().to_string();
  for (std::size_t j = 0; j < out.value().size(); ++j) {
    const float a = out.value().intensity[j], b = in.intensity[c.sources[j]];
    EXPECT_EQ(std::memcmp(&a, &b, 4), 0) << j;
  }
}

TEST(Attributes, BoundedIntensityStaysWithinItsBound) {
  Cloud in = synthetic_scan(8, 300, 4);
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(0.0F, 255.0F);
  for (auto& v : in.intensity) v = u(rng);
  residual::AttributeOptions ao;
  ao.intensity_error = 0.5;
  const Coded bounded = code(in, 0.01, ao);
  const Coded lossless = code(in, 0.01);
  auto out = decode(bounded.file);
  ASSERT_TRUE(out.ok());
  for (std::size_t j = 0; j < out.value().size(); ++j)
    EXPECT_LE(std::abs(out.value().intensity[j] - in.intensity[bounded.sources[j]]), 0.5F);
  EXPECT_LT(bounded.file.size(), lossless.file.size());
}

TEST(Attributes, ThinnedLayerAttachesEachDecodedPointToAnInputPointWithinTheBound) {
  const Cloud in = synthetic_scan(16, 720, 6);
  const double e = 0.05;
  const Coded c = code(in, e, {}, true);
  auto out = decode(c.file);
  ASSERT_TRUE(out.ok());
  const Cloud& d = out.value();
  EXPECT_LT(d.size(), in.size());
  for (std::size_t j = 0; j < d.size(); ++j) {
    const std::uint32_t i = c.sources[j];
    EXPECT_LE((d.points[j] - in.points[i]).cast<double>().norm(), e);
    EXPECT_EQ(d.intensity[j], in.intensity[i]);
    EXPECT_EQ(d.ring[j], in.ring[i]);
  }
}

TEST(Attributes, DeterministicBytes) {
  const Cloud in = synthetic_scan(16, 360, 7);
  EXPECT_EQ(code(in, 0.02).file, code(in, 0.02).file);
}

/// Expects encode_attributes to refuse `c` (every point its own source) with a message
/// holding `needle`.
void expect_refused(const Cloud& c, const std::string& needle) {
  std::vector<std::uint32_t> src(c.size());
  std::iota(src.begin(), src.end(), 0U);
  try {
    (void)residual::encode_attributes(c, src);
    ADD_FAILURE() << "no error for " << needle;
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
  }
}

TEST(Attributes, BadInputNamesTheField) {
  Cloud in = synthetic_scan(4, 50, 8);
  const auto expect_throw = expect_refused;
  Cloud nan = in;
  nan.intensity[3] = std::numeric_limits<float>::quiet_NaN();
  expect_throw(nan, "intensity");
  Cloud inf = in;
  inf.time[7] = std::numeric_limits<double>::infinity();
  expect_throw(inf, "time");
  Cloud short_rgb = in;
  short_rgb.rgb.pop_back();
  expect_throw(short_rgb, "rgb");
  Cloud short_ring = in;
  short_ring.ring.resize(3);
  expect_throw(short_ring, "ring");
  std::vector<std::uint32_t> far(in.size(), 0U);
  far[0] = static_cast<std::uint32_t>(in.size());
  EXPECT_THROW((void)residual::encode_attributes(in, far), std::invalid_argument);
}

TEST(Attributes, NoFieldsMeansNoChunkAndAnOlderVersion) {
  Cloud in = synthetic_scan(8, 100, 9);
  in.intensity.clear();
  in.time.clear();
  in.ring.clear();
  in.rgb.clear();
  const Coded c = code(in, 0.02);
  auto info = codec::inspect(c.file);
  ASSERT_TRUE(info.ok());
  EXPECT_LT(info.value().minor, 6);
}

/// The ATTR chunk's payload within a model file, and its offset.
std::pair<std::size_t, std::size_t> attr_payload(const Bytes& file) {
  auto info = codec::inspect(file);
  for (const auto& ch : info.value().chunks)
    if (ch.type == "ATTR") return {static_cast<std::size_t>(ch.offset) + 12, static_cast<std::size_t>(ch.length)};
  return {0, 0};
}

/// Every truncation of the ATTR payload of `m` fails with kBadData, and every byte flipped
/// either fails with kBadData or (inside a stream) decodes to a cloud of the same size.
void expect_damaged_payloads_fail(const codec::ModelData& m) {
  const Bytes payload = *m.attributes;
  auto base = residual::decode_cloud(m);
  ASSERT_TRUE(base.ok());
  for (std::size_t len = 0; len < payload.size(); ++len) {
    codec::ModelData t = m;
    t.attributes = Bytes(payload.begin(), payload.begin() + static_cast<std::ptrdiff_t>(len));
    auto r = residual::decode_cloud(t);
    EXPECT_FALSE(r.ok()) << "truncated at " << len;
    if (!r.ok()) {
      EXPECT_EQ(r.status().code(), ErrorCode::kBadData);
    }
  }
  for (std::size_t at = 0; at < payload.size(); ++at) {
    codec::ModelData t = m;
    (*t.attributes)[at] ^= 0x5A;
    auto r = residual::decode_cloud(t);
    if (r.ok()) {
      EXPECT_EQ(r.value().size(), base.value().size());
    } else {
      EXPECT_EQ(r.status().code(), ErrorCode::kBadData);
    }
  }
}

TEST(Attributes, CorruptOrTruncatedPayloadsAreRejectedWithoutCrashing) {
  const Cloud in = synthetic_scan(8, 120, 10);
  const Coded c = code(in, 0.02);
  auto m = codec::decode_model(c.file);
  ASSERT_TRUE(m.ok());
  expect_damaged_payloads_fail(m.value());
  // the point count
  codec::ModelData wrong = m.value();
  (*wrong.attributes)[0] ^= 1;
  auto r = residual::decode_cloud(wrong);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("points"), std::string::npos);
}

TEST(Attributes, ChunkNeedsFormatOneSix) {
  const Cloud in = synthetic_scan(8, 60, 11);
  Bytes file = code(in, 0.02).file;
  ASSERT_GE(file.size(), 20U);
  const Bytes fixed = with_minor(file, 5);
  auto d = codec::decode_model(fixed);
  ASSERT_FALSE(d.ok());
  EXPECT_NE(d.status().message().find("ATTR"), std::string::npos) << d.status().to_string();
}

TEST(Attributes, GoldenFileDecodes) {
  const std::string path = std::string(LEX3D_TEST_DATA_DIR) + "/../residual/golden/attributes_1_6.lex3dm";
  if (std::getenv("LEX3D_WRITE_GOLDEN") != nullptr) {
    ASSERT_TRUE(io::write_file_atomic(path, code(synthetic_scan(8, 64, 12), 0.02).file).ok());
  }
  ASSERT_TRUE(std::filesystem::exists(path)) << path;
  auto bytes = io::read_file(path);
  ASSERT_TRUE(bytes.ok());
  auto out = decode(bytes.value());
  ASSERT_TRUE(out.ok()) << out.status().to_string();
  // the golden file was made from synthetic_scan(8, 64, 12) at 0.02 m without thinning
  const Cloud in = synthetic_scan(8, 64, 12);
  ASSERT_EQ(out.value().size(), in.size());
  EXPECT_TRUE(out.value().has_intensity() && out.value().has_time() && out.value().has_rings() && out.value().has_rgb());
  // no thinning: the decoded points are a permutation of the input, attributes and all
  auto a = out.value().intensity, b = in.intensity;
  std::sort(a.begin(), a.end());
  std::sort(b.begin(), b.end());
  EXPECT_EQ(a, b);
  auto ta = out.value().time, tb = in.time;
  std::sort(ta.begin(), ta.end());
  std::sort(tb.begin(), tb.end());
  EXPECT_EQ(ta, tb);
}

/// The golden file `name` (tests/residual/golden), written first from `in` at 0.02 m without
/// thinning when LEX3D_WRITE_GOLDEN is set; empty (and a failure) when it cannot be read.
Bytes golden(const std::string& name, const Cloud& in) {
  const std::string path = std::string(LEX3D_TEST_DATA_DIR) + "/../residual/golden/" + name;
  if (std::getenv("LEX3D_WRITE_GOLDEN") != nullptr) EXPECT_TRUE(io::write_file_atomic(path, code(in, 0.02).file).ok());
  auto bytes = io::read_file(path);
  EXPECT_TRUE(bytes.ok()) << path;
  return bytes.ok() ? bytes.value() : Bytes{};
}

/// `c` with named integer fields as a LAS file's reader gives them: a classification that
/// follows the rings, a return number, a signed scan angle, a constant point source and a
/// field whose values lie far apart.
Cloud with_named_fields(Cloud c) {
  const std::size_t n = c.size();
  IntegerField cls{"classification", {}}, ret{"return_number", {}}, angle{"scan_angle_rank", {}},
      source{"point_source_id", {}}, wide{"wide_ids", {}};
  for (std::size_t i = 0; i < n; ++i) {
    cls.values.push_back(c.ring[i] < 3 ? 2 : 1 + static_cast<std::int32_t>(i % 5 == 0) * 4);
    ret.values.push_back(1 + static_cast<std::int32_t>(i % 3));
    angle.values.push_back(static_cast<std::int32_t>(i % 61) - 30);
    source.values.push_back(65535);
    wide.values.push_back(i % 2 == 0 ? -1000000000 : 1000000000 - static_cast<std::int32_t>(i));
  }
  c.fields = {cls, ret, angle, source, wide};
  return c;
}

TEST(Attributes, NamedFieldsRoundTripLosslesslyInFormatOneTen) {
  const Cloud in = with_named_fields(synthetic_scan(8, 120, 21));
  const Coded c = code(in, 0.01);
  ASSERT_EQ(c.fields.size(), 9U);  // ring, intensity, time, rgb, then the five named fields
  EXPECT_EQ(c.fields[4].name, "classification");
  EXPECT_EQ(c.fields[8].name, "wide_ids");
  auto info = codec::inspect(c.file);
  ASSERT_TRUE(info.ok());
  EXPECT_EQ(info.value().minor, 10);
  auto out = decode(c.file);
  ASSERT_TRUE(out.ok()) << out.status().to_string();
  const Cloud& d = out.value();
  ASSERT_EQ(d.size(), in.size());
  ASSERT_EQ(d.fields.size(), in.fields.size());
  for (std::size_t f = 0; f < in.fields.size(); ++f) {
    EXPECT_EQ(d.fields[f].name, in.fields[f].name);
    ASSERT_EQ(d.fields[f].values.size(), d.size());
    for (std::size_t j = 0; j < d.size(); ++j) EXPECT_EQ(d.fields[f].values[j], in.fields[f].values[c.sources[j]]) << in.fields[f].name << " " << j;
  }
  // a constant field costs next to nothing; the flag that follows the rings little
  EXPECT_LT(c.fields[7].bytes, 80U);
  EXPECT_LT(c.fields[4].bytes, 80U + in.size() / 8);
  // without named fields the file keeps format 1.6
  residual::AttributeOptions no_fields;
  no_fields.fields = false;
  const Coded plain = code(in, 0.01, no_fields);
  EXPECT_EQ(codec::inspect(plain.file).value().minor, 6);
  ASSERT_TRUE(decode(plain.file).ok());
  EXPECT_TRUE(decode(plain.file).value().fields.empty());
}

TEST(Attributes, NamedFieldsThatCannotBeKeptAreRefused) {
  const Cloud base = with_named_fields(synthetic_scan(4, 20, 22));
  const auto refused = expect_refused;
  Cloud c = base;
  c.fields[0].name = "class ification";
  refused(c, "class ification");
  c = base;
  c.fields[0].name = std::string(65, 'a');
  refused(c, "letters");
  c = base;
  c.fields[1].name = "classification";
  refused(c, "twice");
  c = base;
  c.fields[2].values.pop_back();
  refused(c, "scan_angle_rank");
  c = base;
  c.fields[4].values[0] = -2147483647 - 1;
  c.fields[4].values[1] = 2147483647;
  refused(c, "wide_ids");
}

TEST(Attributes, CorruptNamedFieldPayloadsAreRejectedWithoutCrashing) {
  const Cloud in = with_named_fields(synthetic_scan(4, 40, 23));
  const Coded c = code(in, 0.02);
  auto m = codec::decode_model(c.file);
  ASSERT_TRUE(m.ok());
  expect_damaged_payloads_fail(m.value());
  // a name repeated ("point_source_id" made "scan_angle_rank", as long), or a name that is
  // not plain, is refused
  codec::ModelData twice = m.value();
  Bytes& p = *twice.attributes;
  const std::string a = "classification", b = "point_source_id", b2 = "scan_angle_rank";
  const auto at_b = std::search(p.begin(), p.end(), b.begin(), b.end());
  ASSERT_NE(at_b, p.end());
  std::copy(b2.begin(), b2.end(), at_b);
  auto r2 = residual::decode_cloud(twice);
  ASSERT_FALSE(r2.ok());
  EXPECT_NE(r2.status().message().find("repeated"), std::string::npos) << r2.status().to_string();
  codec::ModelData bad = m.value();
  Bytes& q = *bad.attributes;
  *std::search(q.begin(), q.end(), a.begin(), a.end()) = ' ';
  auto r = residual::decode_cloud(bad);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), ErrorCode::kBadData);
}

TEST(Attributes, NamedFieldsNeedFormatOneTen) {
  const Cloud in = with_named_fields(synthetic_scan(4, 30, 24));
  const Bytes file = with_minor(code(in, 0.02).file, 9);
  auto d = codec::decode_model(file);
  ASSERT_FALSE(d.ok());
  EXPECT_NE(d.status().message().find("1.10"), std::string::npos) << d.status().to_string();
}

TEST(Attributes, NamedFieldsGoldenFileDecodes) {
  const Cloud in = with_named_fields(synthetic_scan(4, 48, 25));
  const Bytes bytes = golden("attributes_named_1_10.lex3dm", in);
  ASSERT_FALSE(bytes.empty());
  auto out = decode(bytes);
  ASSERT_TRUE(out.ok()) << out.status().to_string();
  ASSERT_EQ(out.value().size(), in.size());
  ASSERT_EQ(out.value().fields.size(), 5U);
  // no thinning: a permutation of the input, each field's values with it
  for (std::size_t f = 0; f < 5; ++f) {
    auto x = out.value().fields[f].values, y = in.fields[f].values;
    std::sort(x.begin(), x.end());
    std::sort(y.begin(), y.end());
    EXPECT_EQ(x, y) << in.fields[f].name;
  }
}

/// `c` with fields as a driver's PCD gives them, each with its type: an Ouster driver's
/// uint16 reflectivity and uint32 range, a uint8 label, an int8 flag, float32 normals (one
/// NaN, one -0), a float32 curvature on a 0.001 step and a float64 field that float32 holds.
Cloud with_typed_fields(Cloud c) {
  const std::size_t n = c.size();
  IntegerField refl{"reflectivity", {}, FieldType::kUint16}, range{"range", {}, FieldType::kUint32},
      label{"label", {}, FieldType::kUint8}, flag{"flag", {}, FieldType::kInt8}, normal{"normal_x", {}, FieldType::kFloat32},
      curv{"curvature", {}, FieldType::kFloat32}, wide{"offset", {}, FieldType::kFloat64};
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector3f& p = c.points[i];
    refl.values.push_back(static_cast<std::int32_t>((i * 7919) % 65536));
    range.values.push_back(static_cast<std::int32_t>(std::lround(p.norm() * 1000.0F)) + 2000000000);
    label.values.push_back(static_cast<std::int32_t>(c.ring[i] % 7) * 30 + 50);
    flag.values.push_back(static_cast<std::int32_t>(i % 5) - 2);
    normal.values.push_back(float_key(p.x() / p.norm()));
    curv.values.push_back(float_key(static_cast<float>(static_cast<double>(i % 997) * 0.001)));
    wide.values.push_back(float_key(static_cast<float>(i % 13) * 0.25F));
  }
  normal.values[3] = float_key(std::numeric_limits<float>::quiet_NaN());
  normal.values[4] = float_key(-0.0F);
  c.fields = {refl, range, label, flag, normal, curv, wide};
  return c;
}

TEST(Attributes, TypedFieldsKeepTheirTypeAndEveryBitInFormatOneFifteen) {
  const Cloud in = with_typed_fields(synthetic_scan(8, 120, 41));
  const Coded c = code(in, 0.01);
  ASSERT_EQ(c.fields.size(), 11U);  // ring, intensity, time, rgb, then the seven named fields
  EXPECT_EQ(codec::inspect(c.file).value().minor, 15);
  EXPECT_NE(c.fields[8].representation.find("float32 bit patterns"), std::string::npos) << c.fields[8].representation;
  EXPECT_NE(c.fields[9].representation.find("float32: step 0.001"), std::string::npos) << c.fields[9].representation;
  EXPECT_NE(c.fields[10].representation.find("float64: step 0.25"), std::string::npos) << c.fields[10].representation;
  EXPECT_NE(c.fields[4].representation.find("uint16"), std::string::npos) << c.fields[4].representation;
  auto out = decode(c.file);
  ASSERT_TRUE(out.ok()) << out.status().to_string();
  const Cloud& d = out.value();
  ASSERT_EQ(d.fields.size(), in.fields.size());
  for (std::size_t f = 0; f < in.fields.size(); ++f) {
    EXPECT_EQ(d.fields[f].name, in.fields[f].name);
    EXPECT_EQ(d.fields[f].type, in.fields[f].type) << in.fields[f].name;
    ASSERT_EQ(d.fields[f].values.size(), d.size());
    // (the keys are the float bits: equal keys, equal bits, NaN and -0 included)
    for (std::size_t j = 0; j < d.size(); ++j)
      ASSERT_EQ(d.fields[f].values[j], in.fields[f].values[c.sources[j]]) << in.fields[f].name << " " << j;
  }
  const auto nan_at = std::find(c.sources.begin(), c.sources.end(), 3U) - c.sources.begin();
  EXPECT_TRUE(std::isnan(d.fields[4].value(static_cast<std::size_t>(nan_at))));
  // a 1.14 reader's view: the type needs format 1.15
  auto old = codec::decode_model(with_minor(c.file, 14));
  ASSERT_FALSE(old.ok());
  EXPECT_NE(old.status().message().find("1.15"), std::string::npos) << old.status().to_string();
  // fields whose type is not recorded keep format 1.10
  EXPECT_EQ(codec::inspect(code(with_named_fields(synthetic_scan(4, 30, 42)), 0.01).file).value().minor, 10);
}

TEST(Attributes, TypedFieldsOutsideTheirTypeAreRefusedAndCorruptTypesRejected) {
  const Cloud base = with_typed_fields(synthetic_scan(4, 30, 43));
  Cloud c = base;
  c.fields[2].values[5] = 256;  // a uint8 label of 256
  expect_refused(c, "label");
  c = base;
  c.fields[3].values[1] = -129;  // an int8 flag
  expect_refused(c, "flag");
  c = base;
  c.fields[0].type = static_cast<FieldType>(9);
  expect_refused(c, "unknown type");
  // a descriptor whose type is unknown, or too narrow for its values, is bad data
  const Coded coded = code(base, 0.02);
  auto m = codec::decode_model(coded.file);
  ASSERT_TRUE(m.ok());
  expect_damaged_payloads_fail(m.value());
  const std::string name = "label";
  for (const std::uint8_t type : {std::uint8_t{9}, std::uint8_t{1}}) {  // unknown; int8 for 50..230
    codec::ModelData bad = m.value();
    Bytes& p = *bad.attributes;
    const auto at = std::search(p.begin(), p.end(), name.begin(), name.end());
    ASSERT_NE(at, p.end());
    // the name follows its 56-byte descriptor and a length byte; the type is the descriptor's byte 4
    const auto descriptor = at - 1 - 56;
    ASSERT_EQ(descriptor[0], 5);
    ASSERT_EQ(descriptor[4], static_cast<std::uint8_t>(FieldType::kUint8));
    descriptor[4] = type;
    auto r = residual::decode_cloud(bad);
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.status().code(), ErrorCode::kBadData);
    EXPECT_NE(r.status().message().find("label"), std::string::npos) << r.status().to_string();
  }
}

TEST(Attributes, TypedFieldsGoldenFileDecodes) {
  const Cloud in = with_typed_fields(synthetic_scan(4, 48, 44));
  const Bytes bytes = golden("attributes_typed_1_15.lex3dm", in);
  ASSERT_FALSE(bytes.empty());
  EXPECT_EQ(codec::inspect(bytes).value().minor, 15);
  auto out = decode(bytes);
  ASSERT_TRUE(out.ok()) << out.status().to_string();
  ASSERT_EQ(out.value().size(), in.size());
  ASSERT_EQ(out.value().fields.size(), in.fields.size());
  // no thinning: a permutation of the input, each field's values (float keys) with it
  for (std::size_t f = 0; f < in.fields.size(); ++f) {
    EXPECT_EQ(out.value().fields[f].type, in.fields[f].type);
    auto x = out.value().fields[f].values, y = in.fields[f].values;
    std::sort(x.begin(), x.end());
    std::sort(y.begin(), y.end());
    EXPECT_EQ(x, y) << in.fields[f].name;
  }
}

/// `c` as a driver's PCD gives it: its laser a uint8 `laser_id`, intensity a uint16 and time
/// a uint32 `t` in nanoseconds.
Cloud with_sources(Cloud c) {
  for (std::size_t i = 0; i < c.size(); ++i) {
    c.intensity[i] = static_cast<float>((i * 7) % 4000);
    c.time[i] = static_cast<double>(48828 * i + 17) * 1e-9;
  }
  c.ring_source = {"laser_id", FieldType::kUint8};
  c.intensity_source = {"intensity", FieldType::kUint16};
  c.time_source = {"t", FieldType::kUint32};
  return c;
}

TEST(Attributes, RingIntensityAndTimeKeepTheirSourceNamesAndTypesInFormatOneSixteen) {
  const Cloud in = with_sources(synthetic_scan(8, 120, 45));
  const Coded c = code(in, 0.01);
  ASSERT_GE(c.fields.size(), 3U);
  EXPECT_EQ(codec::inspect(c.file).value().minor, 16);
  EXPECT_NE(c.fields[0].representation.find("as laser_id uint8"), std::string::npos) << c.fields[0].representation;
  EXPECT_NE(c.fields[1].representation.find("as intensity uint16"), std::string::npos) << c.fields[1].representation;
  EXPECT_NE(c.fields[2].representation.find("as t uint32"), std::string::npos) << c.fields[2].representation;
  auto out = decode(c.file);
  ASSERT_TRUE(out.ok()) << out.status().to_string();
  const Cloud& d = out.value();
  EXPECT_EQ(d.ring_source.name, "laser_id");
  EXPECT_EQ(d.ring_source.type, FieldType::kUint8);
  EXPECT_EQ(d.intensity_source.name, "intensity");
  EXPECT_EQ(d.intensity_source.type, FieldType::kUint16);
  EXPECT_EQ(d.time_source.name, "t");
  EXPECT_EQ(d.time_source.type, FieldType::kUint32);
  for (std::size_t j = 0; j < d.size(); ++j) {
    ASSERT_EQ(std::llround(d.time[j] * 1e9), 48828 * static_cast<long>(c.sources[j]) + 17) << j;  // every nanosecond
    ASSERT_EQ(d.intensity[j], in.intensity[c.sources[j]]) << j;
  }
  // a 1.15 reader's view: the sources need format 1.16
  auto old = codec::decode_model(with_minor(c.file, 15));
  ASSERT_FALSE(old.ok());
  EXPECT_NE(old.status().message().find("1.16"), std::string::npos) << old.status().to_string();
  // sources that are the writers' own (ring uint16, intensity float32, time float64) are not
  // recorded: the file is the one without them
  Cloud plain = synthetic_scan(8, 120, 45), own = plain;
  own.ring_source = {"ring", FieldType::kUint16};
  own.intensity_source = {"intensity", FieldType::kFloat32};
  own.time_source = {"time", FieldType::kFloat64};
  EXPECT_EQ(code(own, 0.01).file, code(plain, 0.01).file);
  // damaged descriptors: bad data, never a crash
  auto m = codec::decode_model(c.file);
  ASSERT_TRUE(m.ok());
  expect_damaged_payloads_fail(m.value());
  for (const std::uint32_t transform : {0x109U, 0x004U, 0x307U}) {  // unknown type; no name bit; a reserved bit
    codec::ModelData bad = m.value();
    Bytes& p = *bad.attributes;
    const std::size_t ring_descriptor = 9;  // the first field
    ASSERT_EQ(p[ring_descriptor], 1);
    for (int b = 0; b < 4; ++b) p[ring_descriptor + 4 + b] = static_cast<std::uint8_t>(transform >> (8 * b));
    auto r = residual::decode_cloud(bad);
    ASSERT_FALSE(r.ok()) << transform;
    EXPECT_EQ(r.status().code(), ErrorCode::kBadData);
  }
}

TEST(Attributes, SourceNamesAndTypesGoldenFileDecodes) {
  const Cloud in = with_sources(synthetic_scan(4, 48, 46));
  const Bytes bytes = golden("attributes_sources_1_16.lex3dm", in);
  ASSERT_FALSE(bytes.empty());
  EXPECT_EQ(codec::inspect(bytes).value().minor, 16);
  auto out = decode(bytes);
  ASSERT_TRUE(out.ok()) << out.status().to_string();
  ASSERT_EQ(out.value().size(), in.size());
  EXPECT_EQ(out.value().ring_source.name, "laser_id");
  EXPECT_EQ(out.value().time_source.type, FieldType::kUint32);
  std::vector<long> got, want;
  for (std::size_t j = 0; j < in.size(); ++j) {
    got.push_back(std::llround(out.value().time[j] * 1e9));
    want.push_back(std::llround(in.time[j] * 1e9));
  }
  std::sort(got.begin(), got.end());
  std::sort(want.begin(), want.end());
  EXPECT_EQ(got, want);
}

/// `c` with colours whose channels move together (a grey ramp, red a little above green and
/// blue a little below, as a colourised map's are): coded as green and differences.
Cloud with_correlated_colours(Cloud c) {
  for (std::size_t i = 0; i < c.size(); ++i) {
    const int g = 20 + static_cast<int>((i * 37) % 200);
    c.rgb[i] = {static_cast<std::uint8_t>(g + 12 + static_cast<int>(i % 3)), static_cast<std::uint8_t>(g),
                static_cast<std::uint8_t>(g - 9 - static_cast<int>(i % 2))};
  }
  c.rgb[0] = {255, 0, 255};  // the extremes still decode
  c.rgb[1] = {0, 255, 0};
  return c;
}

TEST(Attributes, CorrelatedColoursAreCodedAsDifferencesLosslessly) {
  const Cloud in = with_correlated_colours(synthetic_scan(8, 120, 26));
  const Coded c = code(in, 0.01);
  ASSERT_EQ(c.fields.size(), 4U);
  EXPECT_EQ(c.fields[3].name, "rgb");
  EXPECT_NE(c.fields[3].representation.find("less green"), std::string::npos) << c.fields[3].representation;
  EXPECT_EQ(codec::inspect(c.file).value().minor, 10);
  auto out = decode(c.file);
  ASSERT_TRUE(out.ok()) << out.status().to_string();
  ASSERT_EQ(out.value().size(), in.size());
  for (std::size_t j = 0; j < in.size(); ++j) EXPECT_EQ(out.value().rgb[j], in.rgb[c.sources[j]]) << j;
  auto m = codec::decode_model(c.file);
  ASSERT_TRUE(m.ok());
  expect_damaged_payloads_fail(m.value());
  const Bytes old = with_minor(c.file, 9);
  auto refused = codec::decode_model(old);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.status().message().find("1.10"), std::string::npos) << refused.status().to_string();
}

TEST(Attributes, ColourDifferencesGoldenFileDecodes) {
  const Cloud in = with_correlated_colours(synthetic_scan(4, 48, 27));
  const Bytes bytes = golden("attributes_colour_1_10.lex3dm", in);
  ASSERT_FALSE(bytes.empty());
  auto info = residual::inspect_attributes(*codec::decode_model(bytes).value().attributes);
  ASSERT_TRUE(info.ok());
  EXPECT_NE(info.value().back().representation.find("less green"), std::string::npos);
  auto out = decode(bytes);
  ASSERT_TRUE(out.ok()) << out.status().to_string();
  ASSERT_EQ(out.value().size(), in.size());
  auto a = out.value().rgb, b = in.rgb;  // no thinning: a permutation of the input's colours
  std::sort(a.begin(), a.end());
  std::sort(b.begin(), b.end());
  EXPECT_EQ(a, b);
}

TEST(Attributes, KittiIntensityIsLosslessAndCostsFewBits) {
  const std::string path = std::string(LEX3D_SHARED_DATA_DIR) + "/kitti00/000000.bin";
  if (!std::filesystem::exists(path)) GTEST_SKIP() << "no KITTI data";
  auto r = io::read_cloud(path);
  ASSERT_TRUE(r.ok());
  const Cloud& in = r.value().cloud;
  ASSERT_TRUE(in.has_intensity());
  const Coded c = code(in, 0.02, {}, true);
  auto out = decode(c.file);
  ASSERT_TRUE(out.ok()) << out.status().to_string();
  for (std::size_t j = 0; j < out.value().size(); ++j) ASSERT_EQ(out.value().intensity[j], in.intensity[c.sources[j]]);
  ASSERT_EQ(c.fields.size(), 1U);
  const double bpp = 8.0 * static_cast<double>(c.fields[0].bytes) / static_cast<double>(out.value().size());
  std::printf("KITTI 000000 intensity: %.3f bits a decoded point (%zu points)\n", bpp, out.value().size());
  EXPECT_LT(bpp, 8.0);  // below a byte a point (raw: 32 bits)
}

/// Sensor-rate encoding (AttributeOptions::fast) on the KITTI sample: the methods compared on a
/// quarter of the points, the one coded in full still lossless, within 1 % of the default's
/// bytes, and the same bytes on two threads.
TEST(Attributes, FastComparesTheMethodsOnAQuarterOfThePoints) {
  const Cloud in = test::load_or_fail(test::sample("kitti00_000000.bin"));
  ASSERT_TRUE(in.has_intensity());
  residual::AttributeOptions fast;
  fast.fast = true;
  const Coded c = code(in, 0.02, fast, true);
  auto out = decode(c.file);
  ASSERT_TRUE(out.ok()) << out.status().to_string();
  for (std::size_t j = 0; j < out.value().size(); ++j) ASSERT_EQ(out.value().intensity[j], in.intensity[c.sources[j]]);
  const Coded full = code(in, 0.02, {}, true);
  EXPECT_LE(static_cast<double>(c.file.size()), 1.01 * static_cast<double>(full.file.size()));
  const Bytes one = residual::encode_attributes(in, c.sources, fast, nullptr, {}, 1);
  EXPECT_EQ(residual::encode_attributes(in, c.sources, fast, nullptr, {}, 2), one);
}

/// A model of `input` whose residual layer is the sensor-geometry coding (the laser table
/// from the input's geometry or rings), thinning as `thin`; also the ring field's bytes
/// when coded without the layer's lasers (methods 0-2 and 5).
struct LaserCoded {
  Coded c;
  residual::LayerStats stats;
  std::size_t ring_bytes_without_layer = 0;
};
LaserCoded code_laser(const Cloud& input, double e, bool thin) {
  codec::ModelData d;
  d.input_points = input.size();
  d.alphabet = Alphabet{};
  d.T_cloud_sensor = input.T_cloud_sensor;
  residual::LayerOptions lo;
  lo.thin = thin;
  lo.track_sources = true;
  lo.laser = true;
  LaserCoded out;
  const Cloud words = residual::decoder_word_cloud(d, *d.alphabet);
  d.residual = residual::encode_layer(input, words, d.T_cloud_sensor, e, &out.stats, lo);
  out.c.sources = out.stats.sources;
  auto attrs = residual::encode_attributes(input, out.stats.sources, {}, &out.c.fields, out.stats.layer);
  std::vector<residual::AttributeField> old_fields;
  (void)residual::encode_attributes(input, out.stats.sources, {}, &old_fields);
  for (const auto& f : old_fields)
    if (f.name == "ring") out.ring_bytes_without_layer = f.bytes;
  if (!attrs.empty()) d.attributes = std::move(attrs);
  out.c.file = codec::encode_model(d);
  return out;
}

constexpr std::size_t kDescriptorBytes = 56;  // of every field (formats/model.md §2.10)

/// A method 3 ring that is a function of the layer's laser: per laser one value (at most 16
/// bits through the integer model) and one flag, at most ~3 bytes, plus the range coder's
/// last bytes; the rest is the descriptor.
std::size_t free_ring_bound(std::size_t lasers) { return kDescriptorBytes + 3 * lasers + 16; }

const residual::AttributeField* field(const std::vector<residual::AttributeField>& fields, const std::string& name) {
  for (const auto& f : fields)
    if (f.name == name) return &f;
  return nullptr;
}

/// A scan whose ring is a permutation of its lasers (as an Ouster's channel order is of
/// the table's elevation order): the ring costs next to nothing against the layer's
/// lasers and comes back exactly.
TEST(Attributes, RingFollowsTheSensorGeometryLayersLasers) {
  Cloud in = synthetic_scan(16, 720, 21);
  for (auto& r : in.ring) r = static_cast<std::uint16_t>((r * 7 + 3) % 16);  // a permutation of 0..15
  const LaserCoded lc = code_laser(in, 0.01, false);
  ASSERT_TRUE(lc.stats.laser) << "the synthetic scan is not coded by the sensor geometry";
  ASSERT_EQ(lc.stats.layer.laser.size(), lc.c.sources.size());
  const auto* ring = field(lc.c.fields, "ring");
  ASSERT_NE(ring, nullptr);
  EXPECT_EQ(ring->method, 3);
  // a value and a flag a laser; this ring repeats exactly column after column, which the
  // mixed tree (method 5) also learns in the decoded order, so it is only no larger there
  EXPECT_LE(ring->bytes, lc.ring_bytes_without_layer);
  EXPECT_LE(ring->bytes, free_ring_bound(16));
  auto out = decode(lc.c.file);
  ASSERT_TRUE(out.ok()) << out.status().to_string();
  const Cloud& d = out.value();
  ASSERT_EQ(d.size(), lc.c.sources.size());
  ASSERT_TRUE(d.has_rings() && d.has_intensity() && d.has_time() && d.has_rgb());
  for (std::size_t j = 0; j < d.size(); ++j) {
    const std::uint32_t i = lc.c.sources[j];
    ASSERT_EQ(d.ring[j], in.ring[i]) << j;
    ASSERT_EQ(d.intensity[j], in.intensity[i]) << j;
    ASSERT_EQ(d.time[j], in.time[i]) << j;
    ASSERT_EQ(d.rgb[j], in.rgb[i]) << j;
  }
  // the same bytes again, and with the methods tried side by side on two threads
  EXPECT_EQ(code_laser(in, 0.01, false).c.file, lc.c.file);
  const Bytes one = residual::encode_attributes(in, lc.c.sources, {}, nullptr, lc.stats.layer, 1);
  ASSERT_FALSE(one.empty());
  EXPECT_EQ(residual::encode_attributes(in, lc.c.sources, {}, nullptr, lc.stats.layer, 2), one);
}

/// Method 3 outside a sensor-geometry layer: the descriptor's method byte set to 3 in a
/// file whose layer is the spherical coding is refused with a message, as is a method 3
/// payload given to decode_attributes alone.
TEST(Attributes, LayerLaserMethodNeedsASensorGeometryLayer) {
  const Cloud in = synthetic_scan(8, 120, 22);
  const Coded c = code(in, 0.02);  // spherical layer
  auto m = codec::decode_model(c.file);
  ASSERT_TRUE(m.ok());
  codec::ModelData t = m.value();
  ASSERT_EQ((*t.attributes)[9], 1);  // the first field is the ring
  (*t.attributes)[9 + 2] = 3;
  auto r = residual::decode_cloud(t);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), ErrorCode::kBadData);
  EXPECT_NE(r.status().message().find("sensor-geometry"), std::string::npos) << r.status().to_string();
  EXPECT_EQ(r.status().message().find('\n'), std::string::npos);

  Cloud ringed = synthetic_scan(16, 360, 23);
  const LaserCoded lc = code_laser(ringed, 0.01, false);
  ASSERT_TRUE(lc.stats.laser);
  auto lm = codec::decode_model(lc.c.file);
  ASSERT_TRUE(lm.ok());
  auto layer = residual::decode_layer(*lm.value().residual, Cloud{}, lm.value().T_cloud_sensor, ringed.size());
  ASSERT_TRUE(layer.ok());
  Cloud alone = layer.value();
  const Status s = residual::decode_attributes(*lm.value().attributes, alone);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("method 3"), std::string::npos) << s.to_string();
}

/// Every truncation and byte flip of a method 3 chunk fails cleanly or decodes to a cloud
/// of the right size.
TEST(Attributes, CorruptLayerLaserPayloadsAreRejectedWithoutCrashing) {
  const Cloud in = synthetic_scan(8, 96, 24);
  const LaserCoded lc = code_laser(in, 0.02, false);
  ASSERT_TRUE(lc.stats.laser);
  ASSERT_EQ(field(lc.c.fields, "ring")->method, 3);
  auto m = codec::decode_model(lc.c.file);
  ASSERT_TRUE(m.ok());
  expect_damaged_payloads_fail(m.value());
}

TEST(Attributes, LayerLaserGoldenFileDecodes) {
  const std::string path = std::string(LEX3D_TEST_DATA_DIR) + "/../residual/golden/attributes_layer_laser_1_6.lex3dm";
  Cloud in = synthetic_scan(8, 64, 25);
  for (auto& r : in.ring) r = static_cast<std::uint16_t>(7 - r);
  if (std::getenv("LEX3D_WRITE_GOLDEN") != nullptr) {
    ASSERT_TRUE(io::write_file_atomic(path, code_laser(in, 0.02, false).c.file).ok());
  }
  ASSERT_TRUE(std::filesystem::exists(path)) << path;
  auto bytes = io::read_file(path);
  ASSERT_TRUE(bytes.ok());
  auto fields = residual::inspect_attributes(
      [&] {
        auto m = codec::decode_model(bytes.value());
        return m.ok() && m.value().attributes ? *m.value().attributes : Bytes{};
      }());
  ASSERT_TRUE(fields.ok()) << fields.status().to_string();
  ASSERT_EQ(fields.value()[0].name, "ring");
  EXPECT_EQ(fields.value()[0].method, 3);
  auto out = decode(bytes.value());
  ASSERT_TRUE(out.ok()) << out.status().to_string();
  // made from that scan at 0.02 m without thinning: a permutation of its points
  ASSERT_EQ(out.value().size(), in.size());
  auto a = out.value().ring, b = in.ring;
  std::sort(a.begin(), a.end());
  std::sort(b.begin(), b.end());
  EXPECT_EQ(a, b);
  // each decoded point's ring is the one of the input point at its place
  for (std::size_t j = 0; j < out.value().size(); ++j)
    ASSERT_EQ(out.value().ring[j], in.ring[nearest_point(in, out.value().points[j])]) << j;
}

/// A real scan with rings: the ring comes back exactly, its stream is under a tenth of its
/// coding without the layer's lasers (measured here on the same decoded points) and the
/// field within free_ring_bound of the table's lasers.
void expect_free_ring(const std::string& path) {
  auto r = io::read_cloud(path);
  ASSERT_TRUE(r.ok()) << r.status().to_string();
  const Cloud& in = r.value().cloud;
  ASSERT_TRUE(in.has_rings());
  const LaserCoded lc = code_laser(in, 0.014, true);
  ASSERT_TRUE(lc.stats.laser) << path << ": not coded by the sensor geometry";
  const auto* ring = field(lc.c.fields, "ring");
  ASSERT_NE(ring, nullptr);
  auto out = decode(lc.c.file);
  ASSERT_TRUE(out.ok()) << out.status().to_string();
  const Cloud& d = out.value();
  ASSERT_EQ(d.size(), lc.c.sources.size());
  for (std::size_t j = 0; j < d.size(); ++j) ASSERT_EQ(d.ring[j], in.ring[lc.c.sources[j]]) << j;
  const double bpp = 8.0 * static_cast<double>(ring->bytes) / static_cast<double>(d.size());
  const double old_bpp = 8.0 * static_cast<double>(lc.ring_bytes_without_layer) / static_cast<double>(d.size());
  std::printf("%s: ring %zu bytes (%.4f bits a point, method %d), without the layer's lasers %zu bytes (%.4f)\n",
              path.c_str(), ring->bytes, bpp, ring->method, lc.ring_bytes_without_layer, old_bpp);
  EXPECT_EQ(ring->method, 3);
  EXPECT_LT((ring->bytes - kDescriptorBytes) * 10, lc.ring_bytes_without_layer - kDescriptorBytes);
  EXPECT_LE(ring->bytes, free_ring_bound(lc.stats.lasers));
}

TEST(Attributes, OusterRingIsNearlyFreeWithTheSensorGeometryLayer) {
  const std::string path = std::string(LEX3D_SHARED_DATA_DIR) + "/ouster/OS-2-128-U1_v2.3.0_1024x10.pcap";
  if (!std::filesystem::exists(path)) GTEST_SKIP() << "no Ouster data";
  expect_free_ring(path);
}

TEST(Attributes, Vlp16SampleRingIsNearlyFreeWithTheSensorGeometryLayer) {
  expect_free_ring(std::string(LEX3D_SAMPLES_DIR) + "/vlp16_velodyne_example.pcap");
}

/// A scan without a ring whose lasers each see two materials in turn, at levels of their
/// own (a per-laser calibration): mostly alternating along the scan line, so a value
/// follows from the same laser's previous one, while the differences differ from laser to
/// laser — what a context tree on the previous value of the same laser predicts and a
/// difference does not.
/// Levels 0..`top` in steps of `step`.
Cloud calibrated_scan(int lasers, int columns, std::uint32_t seed, int top = 99, double step = 0.01) {
  Cloud c = synthetic_scan(lasers, columns, seed);
  c.ring.clear();
  c.time.clear();
  c.rgb.clear();
  std::mt19937 rng(seed + 1);
  std::uniform_int_distribution<int> level(0, top), stay(0, 4);
  std::vector<std::array<int, 2>> levels(static_cast<std::size_t>(lasers));
  for (auto& lv : levels) lv = {level(rng), level(rng)};
  std::vector<int> state(static_cast<std::size_t>(lasers), 0);
  for (std::size_t i = 0; i < c.size(); ++i) {
    const std::size_t l = i % static_cast<std::size_t>(lasers);  // synthetic_scan: column by column
    if (stay(rng) != 0) state[l] = 1 - state[l];
    c.intensity[i] = static_cast<float>(levels[l][static_cast<std::size_t>(state[l])] * step);
  }
  return c;
}

/// Method 4 (the context tree over the layer's laser history): chosen where it codes
/// smallest, lossless, smaller than every older method on the same decoded points, and the
/// same bytes again.
TEST(Attributes, LayerTreeCodesCalibratedLasersLosslessly) {
  const Cloud in = calibrated_scan(16, 720, 31);
  const LaserCoded lc = code_laser(in, 0.01, false);
  ASSERT_TRUE(lc.stats.laser) << "the synthetic scan is not coded by the sensor geometry";
  const auto* it = field(lc.c.fields, "intensity");
  ASSERT_NE(it, nullptr);
  EXPECT_EQ(it->method, 4);
  // without the layer's lasers (methods 0-2 and 5 in the decoded order)
  std::vector<residual::AttributeField> old_fields;
  (void)residual::encode_attributes(in, lc.c.sources, {}, &old_fields);
  ASSERT_EQ(old_fields.size(), 1U);
  std::printf("calibrated lasers: intensity %zu bytes (method %d), without the layer's lasers %zu bytes\n", it->bytes,
              it->method,
              old_fields[0].bytes);
  EXPECT_LT(it->bytes, old_fields[0].bytes);
  auto out = decode(lc.c.file);
  ASSERT_TRUE(out.ok()) << out.status().to_string();
  ASSERT_EQ(out.value().size(), lc.c.sources.size());
  for (std::size_t j = 0; j < out.value().size(); ++j)
    ASSERT_EQ(out.value().intensity[j], in.intensity[lc.c.sources[j]]) << j;
  EXPECT_EQ(code_laser(in, 0.01, false).c.file, lc.c.file);
}

/// Every truncation and byte flip of `lc`'s attribute chunk (coded on a sensor-geometry
/// layer) fails cleanly or decodes to a cloud of the right size, and the chunk given to
/// decode_attributes without the layer's keys is refused naming `method`.
void expect_layer_method_checked(const LaserCoded& lc, std::size_t points, const std::string& method) {
  auto m = codec::decode_model(lc.c.file);
  ASSERT_TRUE(m.ok());
  expect_damaged_payloads_fail(m.value());
  auto layer = residual::decode_layer(*m.value().residual, Cloud{}, m.value().T_cloud_sensor, points);
  ASSERT_TRUE(layer.ok());
  Cloud alone = layer.value();
  const Status s = residual::decode_attributes(*m.value().attributes, alone);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.code(), ErrorCode::kBadData);
  EXPECT_NE(s.message().find(method), std::string::npos) << s.to_string();
}

/// Every truncation and byte flip of a method 4 chunk fails cleanly or decodes to a cloud
/// of the right size; method 4 in a file without a sensor-geometry layer, or given to
/// decode_attributes alone, is refused with a message naming it.
TEST(Attributes, CorruptLayerTreePayloadsAreRejectedWithoutCrashing) {
  const Cloud in = calibrated_scan(8, 96, 32);
  const LaserCoded lc = code_laser(in, 0.02, false);
  ASSERT_TRUE(lc.stats.laser);
  ASSERT_EQ(field(lc.c.fields, "intensity")->method, 4);
  expect_layer_method_checked(lc, in.size(), "method 4");

  const Coded sph = code(in, 0.02);  // spherical layer: its intensity field's method set to 4
  auto sm = codec::decode_model(sph.file);
  ASSERT_TRUE(sm.ok());
  codec::ModelData t = sm.value();
  ASSERT_EQ((*t.attributes)[9], 2);  // the only field is the intensity
  (*t.attributes)[9 + 2] = 4;
  auto r = residual::decode_cloud(t);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), ErrorCode::kBadData);
  EXPECT_NE(r.status().message().find("sensor-geometry"), std::string::npos) << r.status().to_string();
  (*t.attributes)[9 + 2] = 6;  // measurement columns: times and named fields only
  r = residual::decode_cloud(t);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("method 6, which codes times"), std::string::npos) << r.status().to_string();
  (*t.attributes)[9 + 2] = 7;  // no such method
  r = residual::decode_cloud(t);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("method 7 is unknown"), std::string::npos) << r.status().to_string();
}

/// Method 4 beyond the context tree's span of 255 (10-bit counts, as balm's): chosen,
/// lossless; a method 4 descriptor whose span exceeds 1023 is refused.
TEST(Attributes, LayerTreeCodesTenBitCounts) {
  const Cloud in = calibrated_scan(16, 360, 34, 999, 1.0);
  const LaserCoded lc = code_laser(in, 0.01, false);
  ASSERT_TRUE(lc.stats.laser);
  const auto* it = field(lc.c.fields, "intensity");
  ASSERT_NE(it, nullptr);
  EXPECT_EQ(it->method, 4);
  EXPECT_EQ(it->step, 1.0);
  auto out = decode(lc.c.file);
  ASSERT_TRUE(out.ok()) << out.status().to_string();
  for (std::size_t j = 0; j < out.value().size(); ++j)
    ASSERT_EQ(out.value().intensity[j], in.intensity[lc.c.sources[j]]) << j;

  auto m = codec::decode_model(lc.c.file);
  ASSERT_TRUE(m.ok());
  codec::ModelData t = m.value();
  ASSERT_EQ((*t.attributes)[9], 2);
  ASSERT_EQ((*t.attributes)[9 + 2], 4);
  const std::size_t span_at = 9 + 40;
  std::uint64_t span = 0;  // u64, little-endian
  for (int b = 7; b >= 0; --b) span = span << 8 | (*t.attributes)[span_at + static_cast<std::size_t>(b)];
  ASSERT_GT(span, 255U);
  ASSERT_LE(span, 1023U);
  (*t.attributes)[span_at] = 0x00;  // 1024
  (*t.attributes)[span_at + 1] = 0x04;
  auto r = residual::decode_cloud(t);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), ErrorCode::kBadData);
  EXPECT_NE(r.status().message().find("span above 1023"), std::string::npos) << r.status().to_string();
}

/// Golden file `path` holds one intensity field coded with `method`, made from `in` without
/// thinning: it decodes to a permutation of in's points, each with the intensity of the input
/// point at its place.
void expect_golden_intensity(const std::string& path, const Cloud& in, int method) {
  ASSERT_TRUE(std::filesystem::exists(path)) << path;
  auto bytes = io::read_file(path);
  ASSERT_TRUE(bytes.ok());
  auto m = codec::decode_model(bytes.value());
  ASSERT_TRUE(m.ok()) << m.status().to_string();
  ASSERT_TRUE(m.value().attributes.has_value());
  auto fields = residual::inspect_attributes(*m.value().attributes);
  ASSERT_TRUE(fields.ok()) << fields.status().to_string();
  ASSERT_EQ(fields.value().size(), 1U);
  ASSERT_EQ(fields.value()[0].name, "intensity");
  EXPECT_EQ(fields.value()[0].method, method);
  auto out = decode(bytes.value());
  ASSERT_TRUE(out.ok()) << out.status().to_string();
  ASSERT_EQ(out.value().size(), in.size());
  for (std::size_t j = 0; j < out.value().size(); ++j)
    ASSERT_EQ(out.value().intensity[j], in.intensity[nearest_point(in, out.value().points[j])]) << j;
}

TEST(Attributes, LayerTreeGoldenFileDecodes) {
  const std::string path = std::string(LEX3D_TEST_DATA_DIR) + "/../residual/golden/attributes_layer_tree_1_6.lex3dm";
  const Cloud in = calibrated_scan(16, 96, 33);
  if (std::getenv("LEX3D_WRITE_GOLDEN") != nullptr) {
    ASSERT_TRUE(io::write_file_atomic(path, code_laser(in, 0.02, false).c.file).ok());
  }
  expect_golden_intensity(path, in, 4);
}

/// `c` (synthetic_scan's column-by-column order, `lasers` a column) with the times of a
/// staggered lidar's firings, as an Ouster capture gives them (uint32 ns from the turn's
/// first): measurement column m fires at m·98 µs plus up to ±3 µs of jitter, and laser l's
/// point of column c belongs to measurement column c − shift(l), the shifts repeating
/// every four lasers (0, 6, 12, 18 columns).
Cloud with_staggered_times(Cloud c, int lasers, int columns, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> jitter(-3000, 3000);
  std::vector<std::int64_t> stamp(static_cast<std::size_t>(columns));
  for (int m = 0; m < columns; ++m) stamp[static_cast<std::size_t>(m)] = 3000 + 98000LL * m + jitter(rng);
  c.time.resize(c.size());
  for (std::size_t i = 0; i < c.size(); ++i) {
    const int l = static_cast<int>(i % static_cast<std::size_t>(lasers));
    const int col = static_cast<int>(i / static_cast<std::size_t>(lasers));
    const int m = ((col - 6 * (l % 4)) % columns + columns) % columns;
    c.time[i] = static_cast<double>(stamp[static_cast<std::size_t>(m)]) * 1e-9;
  }
  c.time_source = {"t", FieldType::kUint32};
  return c;
}

/// Method 6 (the layer's measurement columns) codes a staggered lidar's firing times: chosen,
/// lossless, about one value a measurement column (under 3 bytes each, where every older
/// method pays for the jitter at every point), and refused by a reader of format 1.16.
TEST(Attributes, LayerColumnCodesStaggeredFiringTimes) {
  constexpr int kLasers = 16, kColumns = 720;
  const Cloud in = with_staggered_times(calibrated_scan(kLasers, kColumns, 51), kLasers, kColumns, 52);
  const LaserCoded lc = code_laser(in, 0.01, false);
  ASSERT_TRUE(lc.stats.laser) << "the synthetic scan is not coded by the sensor geometry";
  ASSERT_EQ(lc.stats.layer.column.size(), lc.c.sources.size());
  EXPECT_EQ(lc.stats.layer.columns, static_cast<std::uint32_t>(kColumns));
  const auto* t = field(lc.c.fields, "time");
  ASSERT_NE(t, nullptr);
  EXPECT_EQ(t->method, 6);
  EXPECT_LT(t->bytes, kDescriptorBytes + 2 + 3 * kColumns);
  std::vector<residual::AttributeField> old_fields;
  (void)residual::encode_attributes(in, lc.c.sources, {}, &old_fields);
  const auto* old = field(old_fields, "time");
  ASSERT_NE(old, nullptr);
  std::printf("[ times ] %d lasers x %d columns: method 6 %zu bytes, without the layer's columns %zu bytes\n", kLasers,
              kColumns, t->bytes, old->bytes);
  EXPECT_LT(4 * t->bytes, old->bytes);
  // (method 6 needs 1.17; the layer's quick models 1.18)
  EXPECT_EQ(codec::inspect(lc.c.file).value().minor, 18);
  auto out = decode(lc.c.file);
  ASSERT_TRUE(out.ok()) << out.status().to_string();
  ASSERT_EQ(out.value().size(), in.size());
  EXPECT_EQ(out.value().time_source.name, "t");
  for (std::size_t j = 0; j < in.size(); ++j) ASSERT_EQ(out.value().time[j], in.time[lc.c.sources[j]]) << j;
  // the same bytes again
  EXPECT_EQ(code_laser(in, 0.01, false).c.file, lc.c.file);
  // method 6 in a file that says 1.16 (its layer's predictor field bits 9 and 10 cleared,
  // so that only the ATTR chunk needs more than 1.16)
  const Bytes v16 = with_minor(edit_chunk(lc.c.file, "RESL",
                                          [](std::uint8_t* p, std::uint64_t) { p[69] = static_cast<std::uint8_t>(p[69] & ~0x06U); }),
                               16);
  auto refused = codec::decode_model(v16);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.status().message().find("1.17"), std::string::npos) << refused.status().to_string();
}

/// A time its source holds in whole nanoseconds (uint32 `t`) on a 10 ns clock takes a
/// 10 ns step and comes back to the nanosecond; the same times without that source take
/// the exact 1 ns step, bit for bit.
TEST(Attributes, WholeNanosecondTimesTakeTheirCommonStep) {
  Cloud in = synthetic_scan(8, 120, 57);
  for (std::size_t i = 0; i < in.size(); ++i) in.time[i] = static_cast<double>(10 * ((i * 7919) % 9000)) * 1e-9;
  in.time_source = {"t", FieldType::kUint32};
  const Coded c = code(in, 0.01);
  const auto* t = field(c.fields, "time");
  ASSERT_NE(t, nullptr);
  EXPECT_NEAR(t->step, 1e-8, 1e-20);
  EXPECT_EQ(t->max_error, 0.0);
  auto out = decode(c.file);
  ASSERT_TRUE(out.ok()) << out.status().to_string();
  for (std::size_t j = 0; j < in.size(); ++j)
    ASSERT_EQ(std::llround(out.value().time[j] * 1e9), std::llround(in.time[c.sources[j]] * 1e9)) << j;
  in.time_source = {};
  const Coded plain = code(in, 0.01);
  EXPECT_NEAR(field(plain.fields, "time")->step, 1e-9, 1e-21);
  auto back = decode(plain.file);
  ASSERT_TRUE(back.ok());
  for (std::size_t j = 0; j < in.size(); ++j) ASSERT_EQ(back.value().time[j], in.time[plain.sources[j]]) << j;
  EXPECT_LT(t->bytes, field(plain.fields, "time")->bytes);
}

/// A driver's unorganised cloud (the VLP-16 sample without its columns, its times rounded
/// to float32 as the ROS driver's `time`): the columns come from the firing times, and the
/// times cost about what the capture's do (369 bytes), every float32 back bit for bit.
TEST(Attributes, DriverFloatTimesFollowTheirFirings) {
  auto r = io::read_cloud(std::string(LEX3D_SAMPLES_DIR) + "/vlp16_velodyne_example.pcap");
  ASSERT_TRUE(r.ok()) << r.status().to_string();
  Cloud in = r.value().cloud;
  const std::uint32_t firings = in.columns;
  in.geometry.reset();
  in.column.clear();
  in.rows = in.columns = 0;
  for (double& t : in.time) t = static_cast<double>(static_cast<float>(t));
  ASSERT_EQ(in.time_source.type, FieldType::kFloat32);
  const LaserCoded lc = code_laser(in, 0.014, false);
  ASSERT_TRUE(lc.stats.laser);
  EXPECT_NE(lc.stats.laser_table_source.find("columns by firing time"), std::string::npos) << lc.stats.laser_table_source;
  EXPECT_EQ(lc.stats.columns, firings);
  const auto* t = field(lc.c.fields, "time");
  ASSERT_NE(t, nullptr);
  EXPECT_EQ(t->method, 6);
  EXPECT_EQ(t->max_error, 0.0);
  EXPECT_LT(t->bytes, 600U);
  auto out = decode(lc.c.file);
  ASSERT_TRUE(out.ok()) << out.status().to_string();
  ASSERT_EQ(out.value().size(), in.size());
  for (std::size_t j = 0; j < in.size(); ++j)
    ASSERT_EQ(static_cast<float>(out.value().time[j]), static_cast<float>(in.time[lc.c.sources[j]])) << j;
}

/// Damaged method 6 streams and descriptors fail with kBadData, never a crash; without a
/// sensor-geometry layer a method 6 field is refused.
TEST(Attributes, CorruptLayerColumnPayloadsAreRejectedWithoutCrashing) {
  constexpr int kLasers = 8, kColumns = 96;
  Cloud in = with_staggered_times(calibrated_scan(kLasers, kColumns, 53), kLasers, kColumns, 54);
  in.intensity.clear();  // (the time alone)
  const LaserCoded lc = code_laser(in, 0.02, false);
  ASSERT_TRUE(lc.stats.laser);
  ASSERT_EQ(field(lc.c.fields, "time")->method, 6);
  expect_layer_method_checked(lc, in.size(), "method 6");
}

TEST(Attributes, LayerColumnGoldenFileDecodes) {
  constexpr int kLasers = 8, kColumns = 96;
  const std::string path = std::string(LEX3D_TEST_DATA_DIR) + "/../residual/golden/attributes_layer_column_1_17.lex3dm";
  const Cloud in = with_staggered_times(calibrated_scan(kLasers, kColumns, 55), kLasers, kColumns, 56);
  if (std::getenv("LEX3D_WRITE_GOLDEN") != nullptr) {
    ASSERT_TRUE(io::write_file_atomic(path, code_laser(in, 0.02, false).c.file).ok());
  }
  auto bytes = io::read_file(path);
  ASSERT_TRUE(bytes.ok()) << path;
  EXPECT_EQ(codec::inspect(bytes.value()).value().minor, 17);
  auto out = decode(bytes.value());
  ASSERT_TRUE(out.ok()) << out.status().to_string();
  ASSERT_EQ(out.value().size(), in.size());
  EXPECT_EQ(out.value().time_source.type, FieldType::kUint32);
  for (std::size_t j = 0; j < out.value().size(); ++j)
    ASSERT_EQ(out.value().time[j], in.time[nearest_point(in, out.value().points[j])]) << j;
}

/// The KITTI sample with the sensor-geometry layer (its lasers estimated from the points):
/// the intensity comes back exactly, and the field is no larger than its coding without
/// the layer's lasers on the same decoded points (the encoder keeps the smallest).
TEST(Attributes, KittiSampleIntensityFollowsTheLayersLasers) {
  const std::string path = std::string(LEX3D_SAMPLES_DIR) + "/kitti00_000000.bin";
  auto rd = io::read_cloud(path);
  ASSERT_TRUE(rd.ok()) << rd.status().to_string();
  const Cloud& in = rd.value().cloud;
  const LaserCoded lc = code_laser(in, 0.02, true);
  ASSERT_TRUE(lc.stats.laser) << "the KITTI sample is not coded by the sensor geometry";
  const auto* it = field(lc.c.fields, "intensity");
  ASSERT_NE(it, nullptr);
  auto out = decode(lc.c.file);
  ASSERT_TRUE(out.ok()) << out.status().to_string();
  const Cloud& d = out.value();
  ASSERT_EQ(d.size(), lc.c.sources.size());
  for (std::size_t j = 0; j < d.size(); ++j) ASSERT_EQ(d.intensity[j], in.intensity[lc.c.sources[j]]) << j;
  std::vector<residual::AttributeField> old_fields;
  (void)residual::encode_attributes(in, lc.c.sources, {}, &old_fields);
  std::printf("%s: intensity %zu bytes (%.3f bits a decoded point, method %d); without the layer's lasers: %zu bytes\n",
              path.c_str(),
              it->bytes, 8.0 * static_cast<double>(it->bytes) / static_cast<double>(d.size()), it->method,
              old_fields[0].bytes);
  EXPECT_LE(it->bytes, old_fields[0].bytes);
}

/// Method 5 (the mixed tree over the decoded order) on the KITTI sample with the
/// spherical layer, as `compress` codes it at 1 cm: chosen, lossless, and no larger than
/// the context tree alone was (65,769 bytes when method 0 was the best).
TEST(Attributes, KittiSampleIntensityTakesTheMixedTreeWithoutLasers) {
  const std::string path = std::string(LEX3D_SAMPLES_DIR) + "/kitti00_000000.bin";
  auto rd = io::read_cloud(path);
  ASSERT_TRUE(rd.ok()) << rd.status().to_string();
  const Cloud& in = rd.value().cloud;
  const Coded c = code(in, 0.01, {}, true);
  const auto* it = field(c.fields, "intensity");
  ASSERT_NE(it, nullptr);
  EXPECT_EQ(it->method, 5);
  auto out = decode(c.file);
  ASSERT_TRUE(out.ok()) << out.status().to_string();
  const Cloud& d = out.value();
  ASSERT_EQ(d.size(), c.sources.size());
  for (std::size_t j = 0; j < d.size(); ++j) ASSERT_EQ(d.intensity[j], in.intensity[c.sources[j]]) << j;
  std::printf("%s: intensity %zu bytes (%.3f bits a decoded point, method %d) with the spherical layer\n", path.c_str(),
              it->bytes, 8.0 * static_cast<double>(it->bytes) / static_cast<double>(d.size()), it->method);
  EXPECT_EQ(code(in, 0.01, {}, true).file, c.file);
}

/// Every truncation and byte flip of a method 5 chunk (every field of the synthetic scan,
/// spherical layer) fails cleanly or decodes to a cloud of the right size.
TEST(Attributes, CorruptMixedTreePayloadsAreRejectedWithoutCrashing) {
  const Cloud in = calibrated_scan(8, 64, 35);
  const Coded c = code(in, 0.02);
  const auto* it = field(c.fields, "intensity");
  ASSERT_NE(it, nullptr);
  ASSERT_EQ(it->method, 5);
  auto m = codec::decode_model(c.file);
  ASSERT_TRUE(m.ok());
  expect_damaged_payloads_fail(m.value());
}

TEST(Attributes, MixedTreeGoldenFileDecodes) {
  const std::string path = std::string(LEX3D_TEST_DATA_DIR) + "/../residual/golden/attributes_mixed_tree_1_6.lex3dm";
  const Cloud in = calibrated_scan(8, 64, 36);
  if (std::getenv("LEX3D_WRITE_GOLDEN") != nullptr) {
    ASSERT_TRUE(io::write_file_atomic(path, code(in, 0.02).file).ok());
  }
  expect_golden_intensity(path, in, 5);
}

/// A constant field (span 0) coded by the context tree costs nothing a point, so the
/// decoder does not bound the points by the stream's bytes there: a field of more points
/// than that bound would allow decodes.
TEST(Attributes, ConstantFieldOfManyPointsDecodes) {
  const std::size_t n = 800000;  // above (5 + 16) · 4096 · 8 points for a stream of a few bytes
  Cloud in;
  in.points.assign(n, Eigen::Vector3f(1.0F, 2.0F, 3.0F));
  in.intensity.assign(n, 0.25F);
  std::vector<std::uint32_t> sources(n);
  for (std::size_t j = 0; j < n; ++j) sources[j] = static_cast<std::uint32_t>(j);
  std::vector<residual::AttributeField> fields;
  const Bytes payload = residual::encode_attributes(in, sources, {}, &fields);
  ASSERT_EQ(fields.size(), 1U);
  EXPECT_EQ(fields[0].method, 0);
  Cloud out;
  out.points = in.points;
  const Status s = residual::decode_attributes(payload, out);
  ASSERT_TRUE(s.ok()) << s.to_string();
  ASSERT_EQ(out.intensity.size(), n);
  EXPECT_TRUE(std::all_of(out.intensity.begin(), out.intensity.end(), [](float v) { return v == 0.25F; }));
}

}  // namespace
}  // namespace lex3d
