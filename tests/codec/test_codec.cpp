// Tests of the model file and alphabet file (formats/model.md, formats/alphabet.md):
// round trips within the documented error bounds, determinism, one corruption test per
// reader check (each overwrites exactly one field and, where the check is not the CRC,
// fixes the CRCs so that the check under test is the one that fires), truncation at
// every byte, and golden files of format 1.0 decoded forever.

#include <array>
#include <cmath>
#include <limits>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <iterator>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include <functional>
#include <zlib.h>

#include "lex3d/codec/codec.hpp"
#include "lex3d/model/model.hpp"
#include "support/test_support.hpp"

using namespace lex3d;
using namespace lex3d::codec;

namespace {

using Bytes = std::vector<std::uint8_t>;

// ---------------------------------------------------------------------------------------
// Synthetic data
// ---------------------------------------------------------------------------------------

Alphabet synthetic_alphabet(std::uint32_t seed, std::size_t words, int dim, double radius = 0.35) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::uniform_int_distribution<int> n_points(0, 40);
  Alphabet a;
  a.word_radius = radius;
  a.point_spacing = radius / 10.0;
  a.descriptor_dim = dim;
  for (std::size_t w = 0; w < words; ++w) {
    Word word;
    const int n = n_points(rng);
    while (static_cast<int>(word.points.size()) < n) {
      const Eigen::Vector3d p(u(rng), u(rng), u(rng));
      if (p.norm() <= 1.0) word.points.push_back((p * radius).cast<float>());
    }
    for (int j = 0; j < dim; ++j) {
      const int kind = j % 7;
      word.descriptor.push_back(kind == 0 ? -1.0F : kind == 1 ? 1.0F : kind == 2 ? 0.0F : static_cast<float>(u(rng)));
    }
    a.words.push_back(std::move(word));
  }
  return a;
}

Pose random_pose(std::mt19937_64& rng, double extent) {
  std::normal_distribution<double> g(0.0, 1.0);
  std::uniform_real_distribution<double> u(-extent, extent);
  Eigen::Quaterniond q(g(rng), g(rng), g(rng), g(rng));
  q.normalize();
  Pose T = Pose::Identity();
  T.linear() = q.toRotationMatrix();
  T.translation() = Eigen::Vector3d(u(rng), u(rng), u(rng));
  return T;
}

Model synthetic_model(std::uint32_t seed, std::size_t n, std::size_t words) {
  std::mt19937_64 rng(seed);
  std::uniform_int_distribution<std::uint32_t> word(0, static_cast<std::uint32_t>(words - 1));
  Model m;
  for (std::size_t i = 0; i < n; ++i) {
    Instance inst;
    inst.word = word(rng);
    inst.T_cloud_word = random_pose(rng, 60.0);
    m.instances.push_back(inst);
  }
  // Edge rotations: identity, half turns (angle exactly pi) and one just below.
  const Eigen::Vector3d axes[] = {Eigen::Vector3d::UnitX(), Eigen::Vector3d(1, 1, 0).normalized(),
                                  Eigen::Vector3d(-1, 2, 3).normalized()};
  for (const auto& axis : axes) {
    for (const double angle : {0.0, M_PI, M_PI - 1e-5, 1e-7}) {
      Instance inst;
      inst.word = word(rng);
      inst.T_cloud_word = Pose::Identity();
      inst.T_cloud_word.linear() = Eigen::AngleAxisd(angle, axis).toRotationMatrix();
      inst.T_cloud_word.translation() = Eigen::Vector3d(-0.00025, 0.00025, 1e4);
      m.instances.push_back(inst);
    }
  }
  return m;
}

ModelData synthetic_data(std::uint32_t seed, std::size_t n_instances = 300, std::size_t words = 20) {
  ModelData d;
  d.alphabet = synthetic_alphabet(seed, words, 100);
  d.model = synthetic_model(seed + 1, n_instances, words);
  d.input_points = 123456789012ULL;
  std::mt19937_64 rng(seed + 2);
  d.T_cloud_sensor = random_pose(rng, 5.0);
  return d;
}

// ---------------------------------------------------------------------------------------
// Byte surgery (an independent reading of the container in formats/alphabet.md §2)
// ---------------------------------------------------------------------------------------

std::uint32_t crc(const std::uint8_t* p, std::size_t n) {
  return static_cast<std::uint32_t>(crc32(0, p, static_cast<uInt>(n)));
}
std::uint64_t get_u64(const Bytes& b, std::size_t at) {
  std::uint64_t v = 0;
  for (int i = 7; i >= 0; --i) v = (v << 8) | b[at + static_cast<std::size_t>(i)];
  return v;
}
void poke(Bytes& b, std::size_t at, std::uint64_t v, int bytes) {
  for (int i = 0; i < bytes; ++i) b[at + static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(v >> (8 * i));
}
void poke_f64(Bytes& b, std::size_t at, double d) {
  std::uint64_t v = 0;
  std::memcpy(&v, &d, 8);
  poke(b, at, v, 8);
}
void append_u64(Bytes& b, std::uint64_t v) {
  for (int i = 0; i < 8; ++i) b.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
}

struct File {
  Bytes head;  // 20 bytes
  struct Chunk {
    std::string type;
    Bytes payload;
  };
  std::vector<Chunk> chunks;

  static File parse(const Bytes& b) {
    File f;
    f.head.assign(b.begin(), b.begin() + 20);
    for (std::size_t pos = 20; pos < b.size();) {
      const std::uint64_t len = get_u64(b, pos + 4);
      Chunk c;
      c.type.assign(reinterpret_cast<const char*>(&b[pos]), 4);
      c.payload.assign(b.begin() + static_cast<std::ptrdiff_t>(pos + 12),
                       b.begin() + static_cast<std::ptrdiff_t>(pos + 12 + len));
      f.chunks.push_back(std::move(c));
      pos += 16 + len;
    }
    return f;
  }
  /// Reassembles with correct header and chunk CRCs.
  [[nodiscard]] Bytes build() const {
    Bytes b = head;
    poke(b, 16, crc(b.data(), 16), 4);
    for (const auto& c : chunks) {
      const std::size_t start = b.size();
      b.insert(b.end(), c.type.begin(), c.type.end());
      append_u64(b, c.payload.size());
      b.insert(b.end(), c.payload.begin(), c.payload.end());
      const std::uint32_t k = crc(b.data() + start, b.size() - start);
      for (int i = 0; i < 4; ++i) b.push_back(static_cast<std::uint8_t>(k >> (8 * i)));
    }
    return b;
  }
  Chunk& chunk(const std::string& type) {
    for (auto& c : chunks)
      if (c.type == type) return c;
    throw std::runtime_error("no chunk " + type);
  }
  /// Offset of a chunk's header in build().
  [[nodiscard]] std::size_t offset(const std::string& type) const {
    std::size_t pos = 20;
    for (const auto& c : chunks) {
      if (c.type == type) return pos;
      pos += 16 + c.payload.size();
    }
    throw std::runtime_error("no chunk " + type);
  }
};

Bytes deflate_bytes(const Bytes& raw) {
  uLongf n = compressBound(static_cast<uLong>(raw.size()));
  Bytes z(n);
  EXPECT_EQ(compress2(z.data(), &n, raw.data(), static_cast<uLong>(raw.size()), 9), Z_OK);
  z.resize(n);
  return z;
}
/// The raw data of an INST or WORD payload (count u64, raw_size u64, zlib stream).
Bytes inflate_payload(const Bytes& payload) {
  uLongf n = static_cast<uLongf>(get_u64(payload, 8));
  Bytes raw(std::max<std::size_t>(n, 1));
  EXPECT_EQ(uncompress(raw.data(), &n, payload.data() + 16, static_cast<uLong>(payload.size() - 16)), Z_OK);
  raw.resize(n);
  return raw;
}
Bytes make_payload(std::uint64_t count, std::uint64_t raw_size, const Bytes& raw) {
  Bytes p;
  append_u64(p, count);
  append_u64(p, raw_size);
  const Bytes z = deflate_bytes(raw);
  p.insert(p.end(), z.begin(), z.end());
  return p;
}
/// Column k of a planes() block of n u32 values at `at`: set element i.
void poke_plane(Bytes& raw, std::size_t at, std::size_t n, std::size_t i, std::uint32_t v) {
  for (std::size_t k = 0; k < 4; ++k) raw[at + k * n + i] = static_cast<std::uint8_t>(v >> (8 * k));
}

// ---------------------------------------------------------------------------------------
// Checks
// ---------------------------------------------------------------------------------------

template <typename T>
::testing::AssertionResult is_bad(const StatusOr<T>& r, const std::string& needle,
                                  std::optional<std::uint64_t> offset = std::nullopt,
                                  ErrorCode code = ErrorCode::kBadData) {
  if (r.ok()) return ::testing::AssertionFailure() << "decoded, expected an error containing \"" << needle << "\"";
  const Status& s = r.status();
  if (s.code() != code) return ::testing::AssertionFailure() << "wrong code: " << s.to_string();
  if (s.message().find(needle) == std::string::npos)
    return ::testing::AssertionFailure() << "message \"" << s.message() << "\" lacks \"" << needle << "\"";
  if (s.to_string().find('\n') != std::string::npos) return ::testing::AssertionFailure() << "message is not one line";
  if (!s.offset()) return ::testing::AssertionFailure() << "no offset: " << s.to_string();
  if (offset && *s.offset() != *offset)
    return ::testing::AssertionFailure() << "offset " << *s.offset() << ", expected " << *offset << ": "
                                         << s.to_string();
  return ::testing::AssertionSuccess() << s.to_string();
}

double rotation_angle(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
  return Eigen::AngleAxisd(a.transpose() * b).angle();
}

double max_point_norm(const Alphabet& a) {
  double r = a.word_radius;
  for (const auto& w : a.words)
    for (const auto& p : w.points) r = std::max(r, static_cast<double>(p.norm()));
  return r;
}

void expect_alphabet_within_bounds(const Alphabet& original, const Alphabet& decoded, double word_point_m) {
  ASSERT_EQ(decoded.size(), original.size());
  EXPECT_EQ(decoded.word_radius, original.word_radius);
  EXPECT_EQ(decoded.point_spacing, original.point_spacing);
  EXPECT_EQ(decoded.descriptor_dim, original.descriptor_dim);
  for (std::size_t w = 0; w < original.size(); ++w) {
    const Word& a = original.words[w];
    const Word& b = decoded.words[w];
    ASSERT_EQ(b.points.size(), a.points.size()) << "word " << w;
    for (std::size_t i = 0; i < a.points.size(); ++i)
      for (int k = 0; k < 3; ++k)
        EXPECT_LE(std::abs(static_cast<double>(b.points[i](k)) - a.points[i](k)), word_point_m / 2 + 1e-7)
            << "word " << w << " point " << i;
    ASSERT_EQ(b.descriptor.size(), a.descriptor.size());
    for (std::size_t j = 0; j < a.descriptor.size(); ++j)
      EXPECT_LE(std::abs(b.descriptor[j] - a.descriptor[j]), 1.0 / 254 + 1e-6) << "word " << w << " value " << j;
  }
}

/// Decoded instances against the originals within the bounds of formats/model.md §3.
void expect_model_within_bounds(const ModelData& original, const ModelData& decoded, const Quantization& q) {
  EXPECT_EQ(decoded.input_points, original.input_points);
  EXPECT_TRUE(decoded.T_cloud_sensor.matrix() == original.T_cloud_sensor.matrix());  // exact
  ASSERT_TRUE(decoded.alphabet.has_value());
  const double rho = max_point_norm(*original.alphabet);
  const double half_sqrt3 = std::sqrt(3.0) / 2.0;
  const double point_bound = half_sqrt3 * (q.translation_m + q.rotation_rad * rho + q.word_point_m);
  ASSERT_EQ(decoded.model.instances.size(), original.model.instances.size());
  for (std::size_t i = 0; i < original.model.instances.size(); ++i) {
    const Instance& a = original.model.instances[i];
    const Instance& b = decoded.model.instances[i];
    ASSERT_EQ(b.word, a.word) << "instance " << i;
    for (int k = 0; k < 3; ++k)
      EXPECT_LE(std::abs(b.T_cloud_word.translation()(k) - a.T_cloud_word.translation()(k)),
                q.translation_m / 2 * (1 + 1e-9))
          << "instance " << i;
    EXPECT_LE(rotation_angle(a.T_cloud_word.linear(), b.T_cloud_word.linear()), half_sqrt3 * q.rotation_rad + 1e-9)
        << "instance " << i;
    // Every point of the word, placed in double precision.
    const Word& wa = original.alphabet->words[a.word];
    const Word& wb = decoded.alphabet->words[b.word];
    for (std::size_t j = 0; j < wa.points.size(); ++j) {
      const Eigen::Vector3d pa = a.T_cloud_word * wa.points[j].cast<double>();
      const Eigen::Vector3d pb = b.T_cloud_word * wb.points[j].cast<double>();
      EXPECT_LE((pa - pb).norm(), point_bound + 1e-7 * (1.0 + pa.norm())) << "instance " << i << " point " << j;
    }
  }
}

}  // namespace

// ---------------------------------------------------------------------------------------
// Round trips
// ---------------------------------------------------------------------------------------

TEST(CodecRoundTrip, SyntheticAlphabetWithinBounds) {
  const Alphabet a = synthetic_alphabet(7, 30, 100);
  for (const double step : {0.0005, 0.01, 1e-6}) {
    Quantization q;
    q.word_point_m = step;
    const auto r = decode_alphabet(encode_alphabet(a, q));
    ASSERT_TRUE(r.ok()) << r.status().to_string();
    expect_alphabet_within_bounds(a, r.value(), step);
  }
}

TEST(CodecRoundTrip, SyntheticModelWithinBounds) {
  const ModelData d = synthetic_data(11);
  for (const Quantization q : {Quantization{}, Quantization{0.01, 0.005, 0.002}, Quantization{1e-5, 1e-6, 1e-5}}) {
    const Bytes file = encode_model(d, q);
    const auto r = decode_model(file);
    ASSERT_TRUE(r.ok()) << r.status().to_string();
    expect_model_within_bounds(d, r.value(), q);
    expect_alphabet_within_bounds(*d.alphabet, *r.value().alphabet, q.word_point_m);
    EXPECT_FALSE(r.value().alphabet_hash.has_value());
    for (const auto& inst : r.value().model.instances) EXPECT_EQ(inst.feature, 0U);
  }
}

TEST(CodecQuantization, StepsScaleWithTheWordRadius) {
  const Quantization q = quantization_for_word_radius(0.32);
  EXPECT_DOUBLE_EQ(q.translation_m, 0.01);
  EXPECT_DOUBLE_EQ(q.rotation_rad, 1.0 / 32.0);
  EXPECT_DOUBLE_EQ(q.word_point_m, 0.0005);
  EXPECT_NO_THROW(q.validate());
  // Capped to what the format allows; no words: fine fixed steps.
  EXPECT_DOUBLE_EQ(quantization_for_word_radius(8.0).translation_m, 0.1);
  for (const double r : {0.0, -1.0, std::numeric_limits<double>::quiet_NaN()}) {
    const Quantization f = quantization_for_word_radius(r);
    EXPECT_DOUBLE_EQ(f.translation_m, 0.002);
    EXPECT_DOUBLE_EQ(f.rotation_rad, 0.001);
  }
  // The bound of formats/model.md §3 for a point at the word radius: under 0.06 δ.
  const double bound = std::sqrt(3.0) / 2.0 * (q.translation_m + q.rotation_rad * 0.32 + q.word_point_m);
  EXPECT_LT(bound, 0.06 * 0.32);
}

TEST(CodecRoundTrip, RealModelOfNewerCollegeWithinBounds) {
  const Cloud cloud = test::load_or_fail(test::sample("newer_college_00.bin"));
  ASSERT_FALSE(cloud.empty());
  LearnParams p;
  p.max_iterations = 40;
  p.model.threads = 2;
  const LearnResult learned = learn_alphabet({cloud}, p);
  ASSERT_GT(learned.alphabet.size(), 0U);
  ASSERT_GT(learned.models[0].instances.size(), 100U);

  ModelData d;
  d.input_points = cloud.size();
  d.T_cloud_sensor = cloud.T_cloud_sensor;
  d.model = learned.models[0];
  d.alphabet = learned.alphabet;
  const Quantization q;
  const Bytes model_file = encode_model(d, q);
  const auto r = decode_model(model_file);
  ASSERT_TRUE(r.ok()) << r.status().to_string();
  expect_model_within_bounds(d, r.value(), q);
  expect_alphabet_within_bounds(learned.alphabet, *r.value().alphabet, q.word_point_m);

  // Reconstruction (unthinned, so points pair up one to one) point by point.
  const Reconstruction a = reconstruct(d.model, *d.alphabet, 0.0);
  const Reconstruction b = reconstruct(r.value().model, *r.value().alphabet, 0.0);
  ASSERT_EQ(a.cloud.size(), b.cloud.size());
  ASSERT_GT(a.cloud.size(), 0U);
  const double bound =
      std::sqrt(3.0) / 2.0 * (q.translation_m + q.rotation_rad * max_point_norm(*d.alphabet) + q.word_point_m);
  double worst = 0.0;
  for (std::size_t i = 0; i < a.cloud.size(); ++i) {
    ASSERT_EQ(a.word_of_point[i], b.word_of_point[i]);
    const double e = (a.cloud.points[i] - b.cloud.points[i]).cast<double>().norm();
    const double slack = 1e-6 * (1.0 + a.cloud.points[i].cast<double>().norm());  // f32 arithmetic
    EXPECT_LE(e, bound + slack) << "point " << i;
    worst = std::max(worst, e);
  }

  // Sizes: embedded, and referenced + separate alphabet file.
  const Bytes alphabet_file = encode_alphabet(*d.alphabet, q);
  ModelData ref = d;
  ref.alphabet.reset();
  ref.alphabet_hash = alphabet_hash(alphabet_file);
  const Bytes ref_file = encode_model(ref, q);
  const auto rr = decode_model(ref_file, &alphabet_file);
  ASSERT_TRUE(rr.ok()) << rr.status().to_string();
  expect_model_within_bounds(d, rr.value(), q);
  const auto info = inspect(ref_file);
  ASSERT_TRUE(info.ok());
  std::uint64_t inst_bytes = 0;
  for (const auto& c : info.value().chunks)
    if (c.type == "INST") inst_bytes = c.length + 16;
  const double n = static_cast<double>(d.model.instances.size());
  std::printf("[ sizes    ] newer_college_00: %zu points, %zu instances, %zu words (%zu points)\n", cloud.size(),
              d.model.instances.size(), d.alphabet->size(), d.alphabet->total_points());
  std::printf("[ sizes    ] model file (embedded alphabet) %zu B; referencing model %zu B + alphabet file %zu B\n",
              model_file.size(), ref_file.size(), alphabet_file.size());
  std::printf("[ sizes    ] INST chunk %llu B = %.2f B/instance; whole embedded file %.2f B/instance; "
              "input as float32 xyz %zu B\n",
              static_cast<unsigned long long>(inst_bytes), static_cast<double>(inst_bytes) / n,
              static_cast<double>(model_file.size()) / n, cloud.size() * 12);
  std::printf("[ sizes    ] worst reconstructed point error %.3g m, bound %.3g m\n", worst, bound);
  RecordProperty("model_file_bytes", static_cast<int>(model_file.size()));
  RecordProperty("instances", static_cast<int>(d.model.instances.size()));
}

TEST(CodecRoundTrip, EmptyModelAndEmptyAlphabet) {
  for (const int dim : {0, 100}) {
    Alphabet empty;
    empty.descriptor_dim = dim;
    empty.word_radius = 0.0;
    const Bytes af = encode_alphabet(empty);
    const auto a = decode_alphabet(af);
    ASSERT_TRUE(a.ok()) << a.status().to_string();
    EXPECT_EQ(a.value().size(), 0U);
    EXPECT_EQ(a.value().descriptor_dim, dim);

    ModelData d;
    d.alphabet = empty;
    const auto m = decode_model(encode_model(d));
    ASSERT_TRUE(m.ok()) << m.status().to_string();
    EXPECT_TRUE(m.value().model.instances.empty());
    EXPECT_EQ(m.value().alphabet->size(), 0U);
    EXPECT_EQ(m.value().input_points, 0U);
  }
  // No instances, a non-empty alphabet.
  ModelData d = synthetic_data(3, 0, 4);
  d.model.instances.clear();
  const auto m = decode_model(encode_model(d));
  ASSERT_TRUE(m.ok()) << m.status().to_string();
  EXPECT_TRUE(m.value().model.instances.empty());
  EXPECT_EQ(m.value().alphabet->size(), 4U);
  // A word without points.
  Alphabet one = synthetic_alphabet(5, 3, 8);
  one.words[1].points.clear();
  const auto a = decode_alphabet(encode_alphabet(one));
  ASSERT_TRUE(a.ok()) << a.status().to_string();
  EXPECT_TRUE(a.value().words[1].points.empty());
}

TEST(CodecRoundTrip, DeterministicBytes) {
  const ModelData d = synthetic_data(21);
  EXPECT_EQ(encode_model(d), encode_model(d));
  EXPECT_EQ(encode_alphabet(*d.alphabet), encode_alphabet(*d.alphabet));
  const ModelData copy = d;  // a fresh copy encodes the same
  EXPECT_EQ(encode_model(copy), encode_model(d));
  Quantization q;
  q.translation_m = 0.001;
  EXPECT_NE(encode_model(d, q), encode_model(d));
}

TEST(CodecRoundTrip, EmbeddedAndReferencedAlphabetsDecodeAlike) {
  const ModelData d = synthetic_data(31);
  const Bytes alphabet_file = encode_alphabet(*d.alphabet);
  ModelData ref = d;
  ref.alphabet.reset();
  ref.alphabet_hash = alphabet_hash(alphabet_file);
  const Bytes embedded = encode_model(d);
  const Bytes referenced = encode_model(ref);
  EXPECT_LT(referenced.size() + alphabet_file.size() - 16, embedded.size() + 16);
  EXPECT_LT(referenced.size(), embedded.size());

  const auto e = decode_model(embedded);
  const auto r = decode_model(referenced, &alphabet_file);
  ASSERT_TRUE(e.ok()) << e.status().to_string();
  ASSERT_TRUE(r.ok()) << r.status().to_string();
  EXPECT_EQ(r.value().alphabet_hash, ref.alphabet_hash);
  ASSERT_EQ(e.value().model.instances.size(), r.value().model.instances.size());
  for (std::size_t i = 0; i < e.value().model.instances.size(); ++i) {
    EXPECT_EQ(e.value().model.instances[i].word, r.value().model.instances[i].word);
    EXPECT_TRUE(e.value().model.instances[i].T_cloud_word.matrix() == r.value().model.instances[i].T_cloud_word.matrix());
  }
  EXPECT_EQ(encode_alphabet(*e.value().alphabet), encode_alphabet(*r.value().alphabet));
  // The embedded alphabet is the alphabet file byte for byte.
  EXPECT_EQ(File::parse(embedded).chunk("ALPH").payload, alphabet_file);

  // Referencing model without its alphabet: the caller must supply it.
  EXPECT_TRUE(is_bad(decode_model(referenced), "supply it", std::nullopt, ErrorCode::kInvalidArgument));
  // An embedding model ignores an external alphabet.
  const Bytes other = encode_alphabet(synthetic_alphabet(99, 2, 100));
  EXPECT_TRUE(decode_model(embedded, &other).ok());
}

/// The chunk types of a model file, in order, and its MHDR's length.
std::string chunk_list(const Bytes& b) {
  std::string types;
  for (const auto& c : File::parse(b).chunks) types += c.type + " ";
  return types;
}

TEST(CodecRoundTrip, ModelWithoutWordsHasNoAlphabetNoInstancesAndTheShortHeader) {
  ModelData d;
  d.input_points = 123456;
  d.alphabet = Alphabet{};
  d.residual = Bytes{1, 2, 3, 4, 5, 6, 7, 8, 9};  // (a previous-point layer as far as the codec sees)
  const Bytes b = encode_model(d);
  EXPECT_EQ(b[10] | (b[11] << 8), 11);
  EXPECT_EQ(b[12] | b[13] | b[14] | b[15], 0) << "flags: neither alphabet bit";
  EXPECT_EQ(chunk_list(b), "MHDR RESD IEND ");
  EXPECT_EQ(File::parse(b).chunk("MHDR").payload.size(), 8U);
  // header, then MHDR, RESD and IEND each with 16 bytes of framing
  EXPECT_EQ(b.size(), 20U + (16 + 8) + (16 + 9) + 16);
  const auto back = decode_model(b);
  ASSERT_TRUE(back.ok()) << back.status().to_string();
  EXPECT_EQ(back.value().input_points, d.input_points);
  ASSERT_TRUE(back.value().alphabet.has_value());
  EXPECT_EQ(back.value().alphabet->size(), 0U);
  EXPECT_FALSE(back.value().alphabet_hash.has_value());
  EXPECT_TRUE(back.value().model.instances.empty());
  EXPECT_TRUE(back.value().T_cloud_sensor.matrix() == Pose::Identity().matrix());
  EXPECT_EQ(*back.value().residual, *d.residual);
  EXPECT_EQ(encode_model(back.value()), b) << "decode then encode gives the same bytes";

  // A sensor pose other than the identity is kept exactly: MHDR of 104 bytes.
  ModelData posed = d;
  posed.T_cloud_sensor = Pose::Identity();
  posed.T_cloud_sensor.linear() = Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  posed.T_cloud_sensor.translation() = Eigen::Vector3d(5403850.25, -0.125, 1e-9);
  const Bytes p = encode_model(posed);
  EXPECT_EQ(File::parse(p).chunk("MHDR").payload.size(), 104U);
  const auto pb = decode_model(p);
  ASSERT_TRUE(pb.ok()) << pb.status().to_string();
  EXPECT_TRUE(pb.value().T_cloud_sensor.matrix() == posed.T_cloud_sensor.matrix());
  EXPECT_EQ(encode_model(pb.value()), p);
}

TEST(CodecRoundTrip, ModelWithoutInstancesKeepsItsAlphabetReference) {
  const ModelData words = synthetic_data(43);
  const Bytes alphabet_file = encode_alphabet(*words.alphabet);
  ModelData d;
  d.input_points = 77;
  d.alphabet_hash = alphabet_hash(alphabet_file);
  const Bytes b = encode_model(d);
  EXPECT_EQ(b[10] | (b[11] << 8), 11);
  EXPECT_EQ(chunk_list(b), "MHDR AREF IEND ");
  const auto back = decode_model(b, &alphabet_file);
  ASSERT_TRUE(back.ok()) << back.status().to_string();
  EXPECT_EQ(back.value().alphabet->size(), words.alphabet->size());
  EXPECT_TRUE(back.value().model.instances.empty());
  EXPECT_EQ(back.value().input_points, 77U);
  // An embedded alphabet with words, no instances: the alphabet stays, INST goes.
  ModelData e = words;
  e.model.instances.clear();
  const Bytes eb = encode_model(e);
  EXPECT_EQ(chunk_list(eb), "MHDR ALPH IEND ");
  ASSERT_TRUE(decode_model(eb).ok());
  EXPECT_EQ(decode_model(eb).value().alphabet->size(), words.alphabet->size());
  // With instances nothing changes: format 1.0, the 120-byte MHDR, an INST chunk.
  const Bytes w = encode_model(words);
  EXPECT_EQ(w[10] | (w[11] << 8), 0);
  EXPECT_EQ(chunk_list(w), "MHDR ALPH INST IEND ");
  EXPECT_EQ(File::parse(w).chunk("MHDR").payload.size(), 120U);
}

TEST(CodecCorruptWordless, LayoutRulesAreChecked) {
  ModelData d;
  d.input_points = 10;
  d.alphabet = Alphabet{};
  const Bytes b = encode_model(d);
  ASSERT_TRUE(decode_model(b).ok());
  // Before format 1.11 a model names its alphabet.
  File old = File::parse(b);
  poke(old.head, 10, 10, 2);
  EXPECT_TRUE(is_bad(decode_model(old.build()), "before format version 1.11, the header says 1.10", 12));
  // The short MHDR is 8 or 104 bytes; 120 only beside an INST chunk.
  for (const std::size_t n : {0, 7, 9, 103, 120}) {
    File f = File::parse(b);
    f.chunks[0].payload.resize(n, 0);
    EXPECT_TRUE(is_bad(decode_model(f.build()), "expected 8 or 104 in a model file without instances", 24)) << n;
  }
  // No INST without an alphabet.
  const ModelData word_data = synthetic_data(44);
  const Bytes words = encode_model(word_data);
  const Bytes alphabet_file = encode_alphabet(*word_data.alphabet);
  File with_inst = File::parse(b);
  with_inst.chunks.insert(with_inst.chunks.begin() + 1, File::parse(words).chunk("INST"));
  EXPECT_TRUE(is_bad(decode_model(with_inst.build()), "chunk 'INST' does not belong", 44));
  // An alphabet reference without instances in a file that claims 1.10: the short MHDR is
  // out of place, and so is the missing INST.
  ModelData ref;
  ref.input_points = 10;
  ref.alphabet_hash = alphabet_hash(alphabet_file);
  File r = File::parse(encode_model(ref));
  ASSERT_TRUE(decode_model(r.build(), &alphabet_file).ok());
  poke(r.head, 10, 10, 2);
  EXPECT_TRUE(is_bad(decode_model(r.build(), &alphabet_file), "chunk 'MHDR' payload is 8 bytes, expected 120", 24));
  r.chunks[0].payload = File::parse(words).chunk("MHDR").payload;
  EXPECT_TRUE(is_bad(decode_model(r.build(), &alphabet_file), "comes before the required chunk 'INST'"));
  // A sensor-geometry layer without its head pose (marker 0xFFFFFFFE) needs 1.11 whatever the
  // file holds besides (the codec reads the marker and the predictor field, not the rest).
  {
    ModelData l = word_data;
    Bytes layer = {3, 0, 0, 0, 0xFE, 0xFF, 0xFF, 0xFF};
    layer.resize(120, 0);
    layer[68] = 5;  // predictor 5, no table predictors
    l.residual = layer;
    File lf = File::parse(encode_model(l));
    EXPECT_EQ(lf.head[10], 11);
    poke(lf.head, 10, 10, 2);
    EXPECT_TRUE(is_bad(decode_model(lf.build()), "without T_sensor_head (marker 0xFFFFFFFE) needs format version 1.11"));
    // and the predictor field's bit 8 (the table's fields pick their predictors) too
    layer[4] = 0xFF;
    layer[69] = 1;
    l.residual = layer;
    File tf = File::parse(encode_model(l));
    EXPECT_EQ(tf.head[10], 11);
    poke(tf.head, 10, 9, 2);
    EXPECT_TRUE(is_bad(decode_model(tf.build()), "picks its predictors (predictor field bit 8) needs format version 1.11"));
  }
  // A non-identity pose in the short MHDR must still be a rigid transform.
  File bent = File::parse(b);
  bent.chunks[0].payload.resize(104, 0);
  EXPECT_TRUE(is_bad(decode_model(bent.build()), "rotation is not orthonormal"));
}

TEST(CodecRoundTrip, AlphabetHashMismatchIsAnError) {
  const ModelData d = synthetic_data(41);
  const Bytes alphabet_file = encode_alphabet(*d.alphabet);
  ModelData ref = d;
  ref.alphabet.reset();
  ref.alphabet_hash = alphabet_hash(alphabet_file);
  const Bytes referenced = encode_model(ref);
  const std::size_t aref = File::parse(referenced).offset("AREF");
  // Another alphabet.
  const Bytes other = encode_alphabet(synthetic_alphabet(42, 20, 100));
  EXPECT_TRUE(is_bad(decode_model(referenced, &other), "does not match the model's alphabet_hash", aref + 12));
  // The same alphabet quantised differently.
  Quantization q;
  q.word_point_m = 0.001;
  const Bytes requantised = encode_alphabet(*d.alphabet, q);
  EXPECT_TRUE(is_bad(decode_model(referenced, &requantised), "does not match", aref + 12));
  // The right file with one byte changed.
  Bytes changed = alphabet_file;
  changed[changed.size() / 2] ^= 0x01;
  EXPECT_TRUE(is_bad(decode_model(referenced, &changed), "does not match", aref + 12));
  EXPECT_EQ(alphabet_hash({}), 0xcbf29ce484222325ULL);           // FNV-1a 64 offset basis
  EXPECT_EQ(alphabet_hash({'a'}), 0xaf63dc4c8601ec8cULL);        // published FNV-1a 64 test vector
}

TEST(CodecRoundTrip, EncoderRejectsCallerMistakes) {
  ModelData d = synthetic_data(51, 10, 5);
  Quantization bad;
  bad.translation_m = 0.0;
  EXPECT_THROW((void)encode_model(d, bad), std::invalid_argument);
  bad = Quantization{};
  bad.rotation_rad = 0.2;
  EXPECT_THROW((void)encode_model(d, bad), std::invalid_argument);
  bad = Quantization{};
  bad.word_point_m = std::nan("");
  EXPECT_THROW((void)encode_alphabet(*d.alphabet, bad), std::invalid_argument);

  ModelData no_alphabet = d;
  no_alphabet.alphabet.reset();
  EXPECT_THROW((void)encode_model(no_alphabet), std::invalid_argument);
  ModelData bad_word = d;
  bad_word.model.instances[3].word = 5;
  EXPECT_THROW((void)encode_model(bad_word), std::invalid_argument);
  ModelData far = d;
  far.model.instances[0].T_cloud_word.translation().x() = 2e6;  // > 2^31 steps of 0.5 mm
  EXPECT_THROW((void)encode_model(far), std::invalid_argument);
  ModelData nan_pose = d;
  nan_pose.model.instances[0].T_cloud_word.translation().y() = std::nan("");
  EXPECT_THROW((void)encode_model(nan_pose), std::invalid_argument);
  ModelData scaled = d;
  scaled.T_cloud_sensor.linear() *= 1.01;
  EXPECT_THROW((void)encode_model(scaled), std::invalid_argument);

  Alphabet a = *d.alphabet;
  a.words[0].descriptor[0] = 1.5F;
  EXPECT_THROW((void)encode_alphabet(a), std::invalid_argument);
  a = *d.alphabet;
  a.words[1].descriptor.pop_back();
  EXPECT_THROW((void)encode_alphabet(a), std::invalid_argument);
  a = *d.alphabet;
  a.words[0].points.push_back(Eigen::Vector3f(std::nanf(""), 0, 0));
  EXPECT_THROW((void)encode_alphabet(a), std::invalid_argument);
  a = *d.alphabet;
  a.word_radius = -1.0;
  EXPECT_THROW((void)encode_alphabet(a), std::invalid_argument);
}

// ---------------------------------------------------------------------------------------
// Reader checks: header
// ---------------------------------------------------------------------------------------

class CodecCorrupt : public ::testing::Test {
 protected:
  void SetUp() override {
    data_ = synthetic_data(61, 40, 6);
    model_ = encode_model(data_);
    alphabet_ = encode_alphabet(*data_.alphabet);
    ASSERT_TRUE(decode_model(model_).ok());
    ASSERT_TRUE(decode_alphabet(alphabet_).ok());
  }
  /// Decodes a model rebuilt (CRCs fixed) from `f`.
  static StatusOr<ModelData> model_of(const File& f) { return decode_model(f.build()); }
  static StatusOr<Alphabet> alphabet_of(const File& f) { return decode_alphabet(f.build()); }

  ModelData data_;
  Bytes model_;
  Bytes alphabet_;
};

TEST_F(CodecCorrupt, WrongMagic) {
  Bytes b = model_;
  b[3] = 'Z';
  EXPECT_TRUE(is_bad(decode_model(b), "bad magic", 0));
  b = alphabet_;
  b[7] = 'Q';
  EXPECT_TRUE(is_bad(decode_alphabet(b), "bad magic", 0));
  EXPECT_TRUE(is_bad(decode_model(alphabet_), "this is a lex3d alphabet file", 0));
  EXPECT_TRUE(is_bad(decode_alphabet(model_), "this is a lex3d model file", 0));
  EXPECT_TRUE(is_bad(decode_model(Bytes{'P', 'K', 3, 4}), "bad magic", 0));
  EXPECT_TRUE(is_bad(inspect(Bytes(40, 0)), "bad magic", 0));
}

TEST_F(CodecCorrupt, NewerMajorVersionIsRejected) {
  File f = File::parse(model_);
  poke(f.head, 8, 2, 2);
  EXPECT_TRUE(is_bad(model_of(f), "unsupported format version 2.0", 8));
  Bytes raw = model_;  // checked before the header CRC, which a new major may not have
  poke(raw, 8, 0x1234, 2);
  EXPECT_TRUE(is_bad(decode_model(raw), "unsupported format version 4660.0", 8));
  File a = File::parse(alphabet_);
  poke(a.head, 8, 0, 2);
  EXPECT_TRUE(is_bad(alphabet_of(a), "unsupported format version 0.0", 8));
  EXPECT_TRUE(is_bad(inspect(a.build()), "unsupported format version", 8));
}

TEST_F(CodecCorrupt, NewerMinorVersionIsAccepted) {
  File f = File::parse(model_);
  poke(f.head, 10, 3, 2);
  // What a 1.3 writer may add: optional chunks, here one of each kind of position.
  f.chunks.insert(f.chunks.begin() + 1, {"mtim", Bytes{1, 2, 3}});
  f.chunks.insert(f.chunks.end() - 1, {"resd", Bytes(100, 7)});
  const auto r = model_of(f);
  ASSERT_TRUE(r.ok()) << r.status().to_string();
  expect_model_within_bounds(data_, r.value(), Quantization{});
  const auto info = inspect(f.build());
  ASSERT_TRUE(info.ok());
  EXPECT_EQ(info.value().minor, 3);
  File a = File::parse(alphabet_);
  poke(a.head, 10, 65535, 2);
  EXPECT_TRUE(alphabet_of(a).ok());
}

TEST_F(CodecCorrupt, HeaderCrcMismatch) {
  Bytes b = model_;
  b[17] ^= 0x40;
  EXPECT_TRUE(is_bad(decode_model(b), "header CRC mismatch", 16));
  b = model_;
  b[12] ^= 0x03;  // flags changed without fixing the header CRC
  EXPECT_TRUE(is_bad(decode_model(b), "header CRC mismatch", 16));
  b = alphabet_;
  b[10] = 1;  // minor changed without fixing the CRC
  EXPECT_TRUE(is_bad(decode_alphabet(b), "header CRC mismatch", 16));
  const auto info = inspect(b);  // inspect reports it instead
  ASSERT_TRUE(info.ok()) << info.status().to_string();
  EXPECT_FALSE(info.value().header_crc_ok);
}

TEST_F(CodecCorrupt, ReservedFlagBits) {
  File f = File::parse(model_);
  poke(f.head, 12, 1U | (1U << 7), 4);
  EXPECT_TRUE(is_bad(model_of(f), "reserved flag bits 0x00000080 set", 12));
  poke(f.head, 12, 1U | (1U << 31), 4);
  EXPECT_TRUE(is_bad(model_of(f), "reserved flag bits 0x80000000 set", 12));
  File a = File::parse(alphabet_);
  poke(a.head, 12, 1, 4);
  EXPECT_TRUE(is_bad(alphabet_of(a), "reserved flag bits 0x00000001 set", 12));
}

TEST_F(CodecCorrupt, AlphabetFlagsMustNameExactlyOneSource) {
  File f = File::parse(model_);
  poke(f.head, 12, 3, 4);
  EXPECT_TRUE(is_bad(model_of(f), "set both bit 0 (alphabet embedded) and bit 1", 12));
  // Neither (a model without words) only from format 1.11.
  poke(f.head, 12, 0, 4);
  EXPECT_TRUE(is_bad(model_of(f), "must set one of bit 0 (alphabet embedded) and bit 1 (alphabet referenced) before "
                                  "format version 1.11, the header says 1.0", 12));
  // Flags say referenced, the file embeds: the ALPH chunk does not belong.
  poke(f.head, 12, 2, 4);
  EXPECT_TRUE(is_bad(model_of(f), "chunk 'ALPH' does not belong", f.offset("ALPH")));
}

// ---------------------------------------------------------------------------------------
// Reader checks: chunk framing
// ---------------------------------------------------------------------------------------

TEST_F(CodecCorrupt, ChunkCrcMismatch) {
  const File f = File::parse(model_);
  const std::size_t inst = f.offset("INST");
  const std::size_t len = File::parse(model_).chunk("INST").payload.size();
  Bytes b = model_;
  b[inst + 12 + len / 2] ^= 0x10;  // payload byte
  EXPECT_TRUE(is_bad(decode_model(b), "chunk 'INST' CRC mismatch", inst + 12 + len));
  b = model_;
  b[inst + 12 + len + 2] ^= 0x01;  // the crc field itself
  EXPECT_TRUE(is_bad(decode_model(b), "chunk 'INST' CRC mismatch", inst + 12 + len));
  b = model_;
  b[inst + 1] = 'M';  // type: 'IMST' with the old CRC
  EXPECT_TRUE(is_bad(decode_model(b), "chunk 'IMST' CRC mismatch", inst + 12 + len));
  // inspect reports the bad chunk and carries on.
  b = model_;
  b[inst + 12 + len / 2] ^= 0x10;
  const auto info = inspect(b);
  ASSERT_TRUE(info.ok()) << info.status().to_string();
  ASSERT_EQ(info.value().chunks.size(), 4U);
  EXPECT_TRUE(info.value().header_crc_ok);
  EXPECT_TRUE(info.value().chunks[0].crc_ok);
  EXPECT_TRUE(info.value().chunks[1].crc_ok);
  EXPECT_FALSE(info.value().chunks[2].crc_ok);
  EXPECT_TRUE(info.value().chunks[3].crc_ok);
  // Alphabet file, WORD chunk.
  const File a = File::parse(alphabet_);
  Bytes c = alphabet_;
  const std::size_t word = a.offset("WORD");
  c[word + 20] ^= 0xFF;
  EXPECT_TRUE(is_bad(decode_alphabet(c), "chunk 'WORD' CRC mismatch"));
}

TEST_F(CodecCorrupt, AbsurdChunkLength) {
  const File f = File::parse(model_);
  const std::size_t inst = f.offset("INST");
  for (const std::uint64_t len : {std::uint64_t{1} << 63, ~std::uint64_t{0}, std::uint64_t{1} << 40,
                                  static_cast<std::uint64_t>(model_.size() - inst - 16 + 1)}) {
    Bytes b = model_;
    poke(b, inst + 4, len, 8);
    EXPECT_TRUE(is_bad(decode_model(b), "chunk 'INST' length " + std::to_string(len) + " exceeds", inst + 4));
    EXPECT_TRUE(is_bad(inspect(b), "exceeds", inst + 4));
  }
  Bytes b = alphabet_;
  poke(b, 20 + 4, std::uint64_t{1} << 50, 8);  // AHDR
  EXPECT_TRUE(is_bad(decode_alphabet(b), "chunk 'AHDR' length", 24));
}

TEST_F(CodecCorrupt, InvalidChunkType) {
  File f = File::parse(model_);
  f.chunk("INST").type = std::string("IN\x01T", 4);
  EXPECT_TRUE(is_bad(model_of(f), "invalid chunk type 'IN\\x01T'", f.offset(std::string("IN\x01T", 4))));
  f = File::parse(model_);
  f.chunk("INST").type = "IN T";
  EXPECT_TRUE(is_bad(model_of(f), "invalid chunk type 'IN T'"));
}

TEST_F(CodecCorrupt, UnknownOptionalChunkIsSkipped) {
  File f = File::parse(model_);
  f.chunks.insert(f.chunks.begin() + 2, {"xtra", Bytes(33, 0xAB)});
  f.chunks.insert(f.chunks.begin() + 1, {"zERO", Bytes{}});
  const auto r = model_of(f);
  ASSERT_TRUE(r.ok()) << r.status().to_string();
  expect_model_within_bounds(data_, r.value(), Quantization{});
  // In the alphabet file and inside an embedded alphabet too.
  File a = File::parse(alphabet_);
  a.chunks.insert(a.chunks.begin() + 2, {"note", Bytes{'h', 'i'}});
  EXPECT_TRUE(alphabet_of(a).ok());
  File m = File::parse(model_);
  m.chunk("ALPH").payload = a.build();
  EXPECT_TRUE(model_of(m).ok());
  // Still CRC-checked.
  Bytes b = f.build();
  b[f.offset("xtra") + 12 + 5] ^= 1;
  EXPECT_TRUE(is_bad(decode_model(b), "chunk 'xtra' CRC mismatch"));
}

TEST_F(CodecCorrupt, ScanStampRoundTripsAndItsChunkIsChecked) {
  ModelData d = data_;
  d.stamp = ScanStamp{ScanStamp::Source::kCapture, 1525347606, 362040000, "velodyne"};
  const Bytes bytes = encode_model(d);
  EXPECT_EQ(bytes.size(), model_.size() + 12 + 15 + 8 + 4);  // chunk head, fields, frame, CRC
  EXPECT_EQ(bytes[10], model_[10]);                          // no format version of its own
  auto r = decode_model(bytes);
  ASSERT_TRUE(r.ok()) << r.status().to_string();
  ASSERT_TRUE(r.value().stamp.has_value());
  EXPECT_EQ(r.value().stamp->source, ScanStamp::Source::kCapture);
  EXPECT_EQ(r.value().stamp->sec, 1525347606U);
  EXPECT_EQ(r.value().stamp->nsec, 362040000U);
  EXPECT_EQ(r.value().stamp->frame_id, "velodyne");
  EXPECT_FALSE(decode_model(model_).value().stamp.has_value());
  // Anywhere between MHDR and IEND (an optional chunk), at most once.
  File f = File::parse(bytes);
  const auto scan = std::find_if(f.chunks.begin(), f.chunks.end(), [](const auto& c) { return c.type == "scan"; });
  ASSERT_NE(scan, f.chunks.end());
  auto moved = *scan;
  f.chunks.erase(scan);
  f.chunks.insert(f.chunks.begin() + 1, moved);
  auto m = model_of(f);
  ASSERT_TRUE(m.ok()) << m.status().to_string();
  EXPECT_EQ(m.value().stamp->frame_id, "velodyne");
  f.chunks.insert(f.chunks.begin() + 2, moved);
  EXPECT_TRUE(is_bad(model_of(f), "chunk 'scan' is repeated"));
  // Its fields.
  const auto with = [&](const std::function<void(Bytes&)>& edit) {
    File g = File::parse(bytes);
    edit(g.chunk("scan").payload);
    return model_of(g);
  };
  EXPECT_TRUE(is_bad(with([](Bytes& p) { p[0] = 3; }), "scan stamp source 3 is neither 1"));
  EXPECT_TRUE(is_bad(with([](Bytes& p) { p[12] = 0x3C; }), "scan stamp nanoseconds"));
  EXPECT_TRUE(is_bad(with([](Bytes& p) { p[13] = 9; }), "scan frame_id of 9 bytes does not fill"));
  EXPECT_TRUE(is_bad(with([](Bytes& p) { p.resize(10); }), "chunk 'scan' payload is 10 bytes, at least 15"));
  EXPECT_TRUE(is_bad(with([](Bytes& p) { p[16] = 0; }), "scan frame_id holds a NUL byte"));
  // And the encoder refuses what it could not store.
  ModelData bad = data_;
  bad.stamp = ScanStamp{ScanStamp::Source::kMessage, 1, 1000000000, ""};
  EXPECT_THROW((void)encode_model(bad), std::invalid_argument);
  bad.stamp = ScanStamp{ScanStamp::Source::kMessage, 1, 0, std::string(1025, 'f')};
  EXPECT_THROW((void)encode_model(bad), std::invalid_argument);
}

TEST_F(CodecCorrupt, UnknownRequiredChunkIsRejected) {
  File f = File::parse(model_);
  f.chunks.insert(f.chunks.begin() + 2, {"XTRA", Bytes(5, 1)});
  EXPECT_TRUE(is_bad(model_of(f), "unknown required chunk 'XTRA'", f.offset("XTRA")));
  File a = File::parse(alphabet_);
  a.chunks.insert(a.chunks.begin() + 1, {"Note", Bytes{}});
  EXPECT_TRUE(is_bad(alphabet_of(a), "unknown required chunk 'Note'", a.offset("Note")));
  // A chunk of the other format is unknown here.
  File m = File::parse(model_);
  m.chunks.insert(m.chunks.begin() + 1, {"AHDR", Bytes(32, 0)});
  EXPECT_TRUE(is_bad(model_of(m), "unknown required chunk 'AHDR'"));
}

TEST_F(CodecCorrupt, ChunkOrder) {
  // Repeated.
  File f = File::parse(model_);
  f.chunks.insert(f.chunks.begin() + 3, f.chunks[2]);
  EXPECT_TRUE(is_bad(model_of(f), "chunk 'INST' is repeated or out of order"));
  // Missing.
  f = File::parse(model_);
  f.chunks.erase(f.chunks.begin() + 2);
  EXPECT_TRUE(is_bad(model_of(f), "chunk 'IEND' comes before the required chunk 'INST'", f.offset("IEND")));
  f = File::parse(model_);
  f.chunks.erase(f.chunks.begin() + 1);
  EXPECT_TRUE(is_bad(model_of(f), "chunk 'INST' comes before the required chunk 'ALPH'"));
  // Swapped.
  f = File::parse(model_);
  std::swap(f.chunks[1], f.chunks[2]);
  EXPECT_TRUE(is_bad(model_of(f), "comes before the required chunk 'ALPH'"));
  // Not first.
  f = File::parse(model_);
  f.chunks.insert(f.chunks.begin(), {"note", Bytes{}});
  EXPECT_TRUE(is_bad(model_of(f), "the first chunk must be 'MHDR', found 'note'", 20));
  // AREF in an embedding model.
  f = File::parse(model_);
  Bytes aref;
  append_u64(aref, 42);
  f.chunks.insert(f.chunks.begin() + 2, {"AREF", aref});
  EXPECT_TRUE(is_bad(model_of(f), "chunk 'AREF' does not belong"));
  // Alphabet file.
  File a = File::parse(alphabet_);
  std::swap(a.chunks[0], a.chunks[1]);
  EXPECT_TRUE(is_bad(alphabet_of(a), "the first chunk must be 'AHDR', found 'WORD'", 20));
  a = File::parse(alphabet_);
  a.chunks.erase(a.chunks.begin() + 1);
  EXPECT_TRUE(is_bad(alphabet_of(a), "chunk 'AEND' comes before the required chunk 'WORD'"));
}

TEST_F(CodecCorrupt, EndChunk) {
  Bytes b = model_;
  b.push_back(0);
  EXPECT_TRUE(is_bad(decode_model(b), "1 bytes after the end chunk 'IEND'", model_.size()));
  b = alphabet_;
  b.insert(b.end(), {1, 2, 3});
  EXPECT_TRUE(is_bad(decode_alphabet(b), "3 bytes after the end chunk 'AEND'", alphabet_.size()));
  File f = File::parse(model_);
  f.chunk("IEND").payload = {0};
  EXPECT_TRUE(is_bad(model_of(f), "end chunk 'IEND' must be empty", f.offset("IEND") + 4));
  f = File::parse(model_);
  f.chunks.pop_back();
  EXPECT_TRUE(is_bad(model_of(f), "file ends before the 'IEND' chunk"));
}

TEST_F(CodecCorrupt, TruncationAtEveryByte) {
  ModelData small = synthetic_data(71, 5, 3);
  const Bytes files[] = {encode_model(small), encode_alphabet(*small.alphabet)};
  for (const Bytes& file : files) {
    const bool is_model = &file == &files[0];
    for (std::size_t n = 0; n < file.size(); ++n) {
      const Bytes prefix(file.begin(), file.begin() + static_cast<std::ptrdiff_t>(n));
      const Status s = is_model ? decode_model(prefix).status() : decode_alphabet(prefix).status();
      ASSERT_EQ(s.code(), ErrorCode::kBadData) << "prefix " << n << ": " << s.to_string();
      ASSERT_TRUE(s.offset().has_value()) << n;
      ASSERT_LE(*s.offset(), n) << s.to_string();
      ASSERT_EQ(s.to_string().find('\n'), std::string::npos);
      (void)inspect(prefix);  // must not crash; may succeed on a chunk boundary
    }
  }
  // A referencing model, with its alphabet file supplied.
  const Bytes af = files[1];
  ModelData ref = small;
  ref.alphabet.reset();
  ref.alphabet_hash = alphabet_hash(af);
  const Bytes file = encode_model(ref);
  for (std::size_t n = 0; n < file.size(); ++n) {
    const Bytes prefix(file.begin(), file.begin() + static_cast<std::ptrdiff_t>(n));
    const Status s = decode_model(prefix, &af).status();
    ASSERT_EQ(s.code(), ErrorCode::kBadData) << "prefix " << n << ": " << s.to_string();
    ASSERT_LE(*s.offset(), n);
  }
  // A truncated external alphabet file (its hash recorded as is).
  for (std::size_t n = 0; n < af.size(); n += 7) {
    const Bytes cut(af.begin(), af.begin() + static_cast<std::ptrdiff_t>(n));
    ModelData r2 = small;
    r2.alphabet.reset();
    r2.alphabet_hash = alphabet_hash(cut);
    EXPECT_TRUE(is_bad(decode_model(encode_model(r2), &cut), "external alphabet file: "));
  }
}

// ---------------------------------------------------------------------------------------
// Reader checks: payloads
// ---------------------------------------------------------------------------------------

TEST_F(CodecCorrupt, MhdrFields) {
  File f = File::parse(model_);
  const std::size_t p = f.offset("MHDR") + 12;
  f.chunk("MHDR").payload.pop_back();
  EXPECT_TRUE(is_bad(model_of(f), "chunk 'MHDR' payload is 119 bytes, expected 120", p - 8));
  for (const double v : {std::nan(""), HUGE_VAL, -HUGE_VAL}) {
    f = File::parse(model_);
    poke_f64(f.chunk("MHDR").payload, 8 + 8 * 10, v);  // T_cloud_sensor t1
    EXPECT_TRUE(is_bad(model_of(f), "MHDR T_cloud_sensor value 10 is not finite", p + 88));
  }
  f = File::parse(model_);
  poke_f64(f.chunk("MHDR").payload, 8 + 8 * 4, 1.1);  // r11
  EXPECT_TRUE(is_bad(model_of(f), "rotation is not orthonormal", p + 8));
  f = File::parse(model_);  // a reflection: orthogonal but det -1
  for (int k = 0; k < 3; ++k) {
    auto& pl = f.chunk("MHDR").payload;
    const std::size_t at = 8 + 8 * static_cast<std::size_t>(k);
    double v = 0.0;
    const std::uint64_t u = get_u64(pl, at);
    std::memcpy(&v, &u, 8);
    poke_f64(pl, at, -v);
  }
  EXPECT_TRUE(is_bad(model_of(f), "rotation is not orthonormal", p + 8));
  for (const double v : {0.0, -0.001, 0.5, std::nan(""), HUGE_VAL}) {
    f = File::parse(model_);
    poke_f64(f.chunk("MHDR").payload, 104, v);
    EXPECT_TRUE(is_bad(model_of(f), "MHDR translation_m", p + 104));
    f = File::parse(model_);
    poke_f64(f.chunk("MHDR").payload, 112, v);
    EXPECT_TRUE(is_bad(model_of(f), "MHDR rotation_rad", p + 112));
  }
}

TEST_F(CodecCorrupt, ArefLength) {
  const Bytes af = alphabet_;
  ModelData ref = data_;
  ref.alphabet.reset();
  ref.alphabet_hash = alphabet_hash(af);
  File f = File::parse(encode_model(ref));
  f.chunk("AREF").payload.push_back(0);
  EXPECT_TRUE(is_bad(decode_model(f.build(), &af), "chunk 'AREF' payload is 9 bytes, expected 8"));
}

TEST_F(CodecCorrupt, AhdrFields) {
  File a = File::parse(alphabet_);
  const std::size_t p = a.offset("AHDR") + 12;
  a.chunk("AHDR").payload.push_back(0);
  EXPECT_TRUE(is_bad(alphabet_of(a), "chunk 'AHDR' payload is 33 bytes, expected 32", p - 8));
  for (const double v : {-0.1, std::nan(""), HUGE_VAL}) {
    a = File::parse(alphabet_);
    poke_f64(a.chunk("AHDR").payload, 0, v);
    EXPECT_TRUE(is_bad(alphabet_of(a), "AHDR word_radius", p));
    a = File::parse(alphabet_);
    poke_f64(a.chunk("AHDR").payload, 8, v);
    EXPECT_TRUE(is_bad(alphabet_of(a), "AHDR point_spacing", p + 8));
  }
  a = File::parse(alphabet_);
  poke(a.chunk("AHDR").payload, 16, 65536, 4);
  EXPECT_TRUE(is_bad(alphabet_of(a), "AHDR descriptor_dim 65536 exceeds 65535", p + 16));
  for (const double v : {0.0, 0.2, -HUGE_VAL, std::nan("")}) {
    a = File::parse(alphabet_);
    poke_f64(a.chunk("AHDR").payload, 24, v);
    EXPECT_TRUE(is_bad(alphabet_of(a), "AHDR word_point_m", p + 24));
  }
  // A count that disagrees with the WORD data (raw_size no longer matches).
  a = File::parse(alphabet_);
  poke(a.chunk("AHDR").payload, 20, 0xFFFFFFFFU, 4);
  EXPECT_TRUE(is_bad(alphabet_of(a), "WORD raw_size", a.offset("WORD") + 12 + 8));
  a = File::parse(alphabet_);
  poke(a.chunk("AHDR").payload, 16, 99, 4);
  EXPECT_TRUE(is_bad(alphabet_of(a), "WORD raw_size", a.offset("WORD") + 12 + 8));
}

TEST_F(CodecCorrupt, WordCountsAndRawSize) {
  const File base = File::parse(alphabet_);
  const std::size_t p = base.offset("WORD") + 12;
  const Bytes raw = inflate_payload(File(base).chunk("WORD").payload);
  const std::uint64_t total = get_u64(File(base).chunk("WORD").payload, 0);
  const std::size_t W = data_.alphabet->size();

  File a = base;
  a.chunk("WORD").payload.resize(15);
  EXPECT_TRUE(is_bad(alphabet_of(a), "chunk 'WORD' payload is 15 bytes, at least 16 expected", p - 8));
  // total_points: absurd, then merely wrong.
  a = base;
  poke(a.chunk("WORD").payload, 0, std::uint64_t{1} << 62, 8);
  EXPECT_TRUE(is_bad(alphabet_of(a), "WORD total_points 4611686018427387904 is absurd", p));
  a = base;
  poke(a.chunk("WORD").payload, 0, total + 1, 8);
  EXPECT_TRUE(is_bad(alphabet_of(a), "WORD raw_size", p + 8));
  // raw_size that disagrees with the counts.
  a = base;
  poke(a.chunk("WORD").payload, 8, raw.size() + 1, 8);
  EXPECT_TRUE(is_bad(alphabet_of(a), "WORD raw_size " + std::to_string(raw.size() + 1) + " is not", p + 8));
  // Counts that claim more than the stored bytes can inflate to (no allocation happens).
  a = base;
  const std::uint64_t huge_points = std::uint64_t{1} << 40;
  poke(a.chunk("WORD").payload, 0, huge_points, 8);
  poke(a.chunk("WORD").payload, 8, 4 * W + 12 * huge_points + W * 100, 8);
  EXPECT_TRUE(is_bad(alphabet_of(a), "cannot come from", p + 8));
}

TEST_F(CodecCorrupt, WordPointCountsMustAddUp) {
  const File base = File::parse(alphabet_);
  const std::size_t p = base.offset("WORD") + 12;
  const Bytes raw = inflate_payload(File(base).chunk("WORD").payload);
  const std::uint64_t total = get_u64(File(base).chunk("WORD").payload, 0);
  const std::size_t W = data_.alphabet->size();
  Bytes r2 = raw;  // raw_size kept, one count raised
  poke_plane(r2, 0, W, 0, static_cast<std::uint32_t>(r2[0]) + 1U);
  File a = base;
  a.chunk("WORD").payload = make_payload(total, raw.size(), r2);
  EXPECT_TRUE(is_bad(alphabet_of(a), "WORD point counts add up to " + std::to_string(total + 1), p));
}

TEST_F(CodecCorrupt, DescriptorValueMinus128) {
  const File base = File::parse(alphabet_);
  const std::size_t p = base.offset("WORD") + 12;
  const Bytes raw = inflate_payload(File(base).chunk("WORD").payload);
  const std::uint64_t total = get_u64(File(base).chunk("WORD").payload, 0);
  File a = base;
  Bytes r2 = raw;
  r2[r2.size() - 3] = 0x80;
  a = base;
  a.chunk("WORD").payload = make_payload(total, raw.size(), r2);
  EXPECT_TRUE(is_bad(alphabet_of(a), "WORD descriptor value -128", p + 16));
}

TEST_F(CodecCorrupt, DeflateStreams) {
  // Each case rewrites the INST payload (CRC fixed) so that only the deflate stream is wrong.
  const File base = File::parse(model_);
  const std::size_t p = base.offset("INST") + 12;
  const Bytes payload = File(base).chunk("INST").payload;
  const std::uint64_t n = get_u64(payload, 0);
  const Bytes raw = inflate_payload(payload);
  ASSERT_EQ(raw.size(), 28 * n);

  File f = base;  // corrupt stream
  f.chunk("INST").payload[16] ^= 0xFF;  // the zlib header
  EXPECT_TRUE(is_bad(model_of(f), "chunk 'INST' deflate stream is corrupt (incorrect header check)"));
  f = base;  // not a zlib stream at all
  std::fill(f.chunk("INST").payload.begin() + 16, f.chunk("INST").payload.end(), 0xFF);
  EXPECT_TRUE(is_bad(model_of(f), "chunk 'INST' deflate stream is corrupt"));
  f = base;  // stream cut short
  f.chunk("INST").payload.resize(payload.size() - 9);
  EXPECT_TRUE(is_bad(model_of(f), "chunk 'INST' deflate stream is truncated"));
  f = base;  // bytes after the stream
  f.chunk("INST").payload.insert(f.chunk("INST").payload.end(), {0, 0, 0});
  EXPECT_TRUE(is_bad(model_of(f), "3 bytes after the deflate stream in chunk 'INST'", p + payload.size()));
  f = base;  // inflates to more than raw_size
  Bytes longer = raw;
  longer.push_back(0);
  f.chunk("INST").payload = make_payload(n, raw.size(), longer);
  EXPECT_TRUE(is_bad(model_of(f), "chunk 'INST' inflates to more than its raw_size of " + std::to_string(raw.size())));
  f = base;  // inflates to fewer
  Bytes shorter(raw.begin(), raw.end() - 1);
  f.chunk("INST").payload = make_payload(n, raw.size(), shorter);
  EXPECT_TRUE(is_bad(model_of(f), "chunk 'INST' inflates to " + std::to_string(raw.size() - 1) + " bytes", p + 16));
  f = base;  // empty stream (for one instance, which 0 stored bytes may still claim)
  f.chunk("INST").payload.resize(16);
  poke(f.chunk("INST").payload, 0, 1, 8);
  poke(f.chunk("INST").payload, 8, 28, 8);
  EXPECT_TRUE(is_bad(model_of(f), "deflate stream is truncated"));
  // The same for WORD.
  File a = File::parse(alphabet_);
  const Bytes wraw = inflate_payload(a.chunk("WORD").payload);
  const std::uint64_t total = get_u64(a.chunk("WORD").payload, 0);
  Bytes wlonger = wraw;
  wlonger.insert(wlonger.end(), 1000, 0);
  a.chunk("WORD").payload = make_payload(total, wraw.size(), wlonger);
  EXPECT_TRUE(is_bad(alphabet_of(a), "chunk 'WORD' inflates to more than its raw_size"));
}

TEST_F(CodecCorrupt, InstCountsAndRawSize) {
  const File base = File::parse(model_);
  const std::size_t p = base.offset("INST") + 12;
  const Bytes payload = File(base).chunk("INST").payload;
  const std::uint64_t n = get_u64(payload, 0);

  File f = base;
  f.chunk("INST").payload.resize(8);
  EXPECT_TRUE(is_bad(model_of(f), "chunk 'INST' payload is 8 bytes, at least 16 expected", p - 8));
  // Absurd counts are refused before anything is allocated.
  for (const std::uint64_t count : {std::uint64_t{1} << 60, ~std::uint64_t{0}, std::uint64_t{1} << 33}) {
    f = base;
    poke(f.chunk("INST").payload, 0, count, 8);
    EXPECT_TRUE(is_bad(model_of(f), "INST instance_count " + std::to_string(count) + " cannot come from", p));
  }
  f = base;
  poke(f.chunk("INST").payload, 0, n + 1, 8);
  EXPECT_TRUE(is_bad(model_of(f), "INST raw_size " + std::to_string(28 * n) + " is not 28*instance_count", p + 8));
  f = base;
  poke(f.chunk("INST").payload, 8, 28 * n - 1, 8);
  EXPECT_TRUE(is_bad(model_of(f), "is not 28*instance_count", p + 8));
}

TEST_F(CodecCorrupt, InstanceWordIdBeyondTheAlphabet) {
  const File base = File::parse(model_);
  const std::size_t p = base.offset("INST") + 12;
  const Bytes payload = File(base).chunk("INST").payload;
  const std::uint64_t n = get_u64(payload, 0);
  const Bytes raw = inflate_payload(payload);
  const auto un = static_cast<std::size_t>(n);
  Bytes r2 = raw;
  File f = base;
  poke_plane(r2, 0, un, un - 1, static_cast<std::uint32_t>(data_.alphabet->size()));
  f.chunk("INST").payload = make_payload(n, raw.size(), r2);
  EXPECT_TRUE(is_bad(model_of(f),
                     "instance " + std::to_string(n - 1) + " has word id 6 but the alphabet has 6 words", p + 16));
  r2 = raw;
  poke_plane(r2, 0, un, 0, 0xFFFFFFFFU);
  f.chunk("INST").payload = make_payload(n, raw.size(), r2);
  EXPECT_TRUE(is_bad(model_of(f), "instance 0 has word id 4294967295", p + 16));
  // The same through a referencing model and its external alphabet.
  ModelData ref = data_;
  ref.alphabet.reset();
  ref.alphabet_hash = alphabet_hash(alphabet_);
  File g = File::parse(encode_model(ref));
  g.chunk("INST").payload = make_payload(n, raw.size(), r2);
  EXPECT_TRUE(is_bad(decode_model(g.build(), &alphabet_), "instance 0 has word id 4294967295"));
}

TEST_F(CodecCorrupt, InstanceRotationVectorLongerThanPi) {
  const File base = File::parse(model_);
  const std::size_t p = base.offset("INST") + 12;
  const Bytes payload = File(base).chunk("INST").payload;
  const std::uint64_t n = get_u64(payload, 0);
  const Bytes raw = inflate_payload(payload);
  const auto un = static_cast<std::size_t>(n);
  File f = base;
  Bytes r2 = raw;  // rx of instance 2 = 16000 steps of 0.0002 rad = 3.2 rad
  poke_plane(r2, 4 * 4 * un, un, 2, 32000U);  // zigzag(16000)
  f.chunk("INST").payload = make_payload(n, raw.size(), r2);
  EXPECT_TRUE(is_bad(model_of(f), "instance 2 rotation vector is longer than pi", p + 16));
}

TEST_F(CodecCorrupt, EmbeddedAlphabetErrorsCarryModelOffsets) {
  File f = File::parse(model_);
  File inner = File::parse(f.chunk("ALPH").payload);
  poke_f64(inner.chunk("AHDR").payload, 24, 0.0);  // word_point_m
  f.chunk("ALPH").payload = inner.build();
  const std::size_t at = f.offset("ALPH") + 12 + inner.offset("AHDR") + 12 + 24;
  EXPECT_TRUE(is_bad(model_of(f), "model file: embedded alphabet (ALPH): AHDR word_point_m", at));
  // An inner CRC error with a correct outer CRC.
  f = File::parse(model_);
  f.chunk("ALPH").payload[40] ^= 1;  // inside the AHDR payload
  EXPECT_TRUE(is_bad(model_of(f), "embedded alphabet (ALPH): chunk 'AHDR' CRC mismatch"));
  // An empty ALPH.
  f = File::parse(model_);
  f.chunk("ALPH").payload.clear();
  EXPECT_TRUE(is_bad(model_of(f), "embedded alphabet (ALPH): truncated header", f.offset("ALPH") + 12));
}

TEST_F(CodecCorrupt, SeededRandomCorruptionNeverCrashes) {
  // Random byte changes (with and without fixed CRCs): decoders return ok or kBadData.
  std::mt19937_64 rng(2024);
  const Bytes files[] = {model_, alphabet_};
  int errors = 0;
  for (int round = 0; round < 3000; ++round) {
    const bool is_model = round % 2 == 0;
    Bytes b = files[round % 2];
    const int edits = 1 + static_cast<int>(rng() % 4);
    for (int e = 0; e < edits; ++e) b[rng() % b.size()] = static_cast<std::uint8_t>(rng());
    if (round % 3 == 0) {  // fix CRCs when the framing survived, to reach the payload checks
      const auto info = inspect(b);
      if (info.ok()) b = File::parse(b).build();
    }
    const Status s = is_model ? decode_model(b).status() : decode_alphabet(b).status();
    if (!s.ok()) {
      ++errors;
      ASSERT_TRUE(s.code() == ErrorCode::kBadData) << s.to_string();
      ASSERT_EQ(s.to_string().find('\n'), std::string::npos);
    }
  }
  EXPECT_GT(errors, 1500);
}

// ---------------------------------------------------------------------------------------
// Golden files of format 1.0 (tests/codec/golden/): decoded forever, values hard-coded.
// ---------------------------------------------------------------------------------------

namespace {

std::string golden_path(const std::string& name) { return std::string(LEX3D_TEST_DATA_DIR) + "/../codec/golden/" + name; }

Bytes read_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return Bytes(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

// The generator of the golden files (run DISABLED_WriteGoldenFiles to regenerate; the
// decode test below does not call it: it checks the values recorded when the files were
// made, so a change here cannot silently change what "format 1.0" means).
Alphabet golden_alphabet() {
  Alphabet a;
  a.word_radius = 0.25;
  a.point_spacing = 0.025;
  a.descriptor_dim = 4;
  a.words.resize(3);
  a.words[0].points = {{0.0F, 0.0F, 0.0F}, {0.1F, 0.0F, 0.0F}, {0.0F, 0.1F, 0.0F}, {0.0F, 0.0F, -0.1F}};
  a.words[0].descriptor = {1.0F, -1.0F, 0.0F, 0.5F};
  a.words[1].points = {{0.05F, 0.05F, 0.05F}, {-0.2F, 0.0125F, 0.1F}, {0.0003F, -0.0003F, 0.2485F}};
  a.words[1].descriptor = {0.25F, -0.25F, 0.75F, -0.75F};
  a.words[2].points = {};  // a word without points
  a.words[2].descriptor = {0.0F, 0.001F, -0.999F, 0.3F};
  return a;
}
ModelData golden_model() {
  ModelData d;
  d.input_points = 1234;
  d.T_cloud_sensor = Pose::Identity();
  d.T_cloud_sensor.linear() << 0, -1, 0, 1, 0, 0, 0, 0, 1;
  d.T_cloud_sensor.translation() = Eigen::Vector3d(1.0, 2.0, 0.5);
  const auto pose = [](double tx, double ty, double tz, const Eigen::Vector3d& r) {
    Pose T = Pose::Identity();
    if (r.norm() > 0) T.linear() = Eigen::AngleAxisd(r.norm(), r.normalized()).toRotationMatrix();
    T.translation() = Eigen::Vector3d(tx, ty, tz);
    return T;
  };
  d.model.instances = {
      {0, pose(0, 0, 0, Eigen::Vector3d::Zero()), 0},
      {1, pose(1.5, -2.25, 0.75, Eigen::Vector3d(0, 0, M_PI / 2)), 0},
      {0, pose(10.0005, 0.0002, -3.0, Eigen::Vector3d(M_PI, 0, 0)), 0},
      {2, pose(-50.0, 25.5, 0.1, Eigen::Vector3d(0.1, -0.2, 0.3)), 0},
      {1, pose(0.00025, -0.00025, 0.0, Eigen::Vector3d(0, 0, -0.00011)), 0},
  };
  d.alphabet = golden_alphabet();
  return d;
}

// What the golden files hold (quantised values, from the generator above at format 1.0
// with the default Quantization: translation_m 0.0005, rotation_rad 0.0002, word_point_m 0.0005).
constexpr double kGoldenStepT = 0.0005, kGoldenStepR = 0.0002, kGoldenStepW = 0.0005;
constexpr std::uint64_t kGoldenAlphabetHash = 0x6739b02118403a99ULL;  // FNV-1a 64 of tiny_alphabet_1.0.lex3da
const std::vector<std::vector<std::array<int, 3>>> kGoldenPoints = {
    {{0, 0, 0}, {200, 0, 0}, {0, 200, 0}, {0, 0, -200}},
    {{100, 100, 100}, {-400, 25, 200}, {1, -1, 497}},
    {},
};
const std::vector<std::vector<int>> kGoldenDescriptors = {{127, -127, 0, 64}, {32, -32, 95, -95}, {0, 0, -127, 38}};
struct GoldenInstance {
  std::uint32_t word;
  std::array<int, 3> tq;
  std::array<int, 3> rq;
};
const std::vector<GoldenInstance> kGoldenInstances = {
    {0, {0, 0, 0}, {0, 0, 0}},
    {1, {3000, -4500, 1500}, {0, 0, 7854}},
    {0, {20001, 0, -6000}, {15708, 0, 0}},
    {2, {-100000, 51000, 200}, {500, -1000, 1500}},
    {1, {1, -1, 0}, {0, 0, -1}},
};

void expect_golden_alphabet(const Alphabet& a) {
  EXPECT_EQ(a.word_radius, 0.25);
  EXPECT_EQ(a.point_spacing, 0.025);
  EXPECT_EQ(a.descriptor_dim, 4);
  ASSERT_EQ(a.size(), 3U);
  for (std::size_t w = 0; w < 3; ++w) {
    ASSERT_EQ(a.words[w].points.size(), kGoldenPoints[w].size()) << w;
    for (std::size_t i = 0; i < kGoldenPoints[w].size(); ++i)
      for (int k = 0; k < 3; ++k)
        EXPECT_EQ(a.words[w].points[i](k), static_cast<float>(kGoldenPoints[w][i][static_cast<std::size_t>(k)] * kGoldenStepW))
            << w << " " << i;
    ASSERT_EQ(a.words[w].descriptor.size(), 4U);
    for (std::size_t j = 0; j < 4; ++j)
      EXPECT_EQ(a.words[w].descriptor[j], static_cast<float>(kGoldenDescriptors[w][j] / 127.0)) << w << " " << j;
  }
}

void expect_golden_model(const ModelData& d) {
  EXPECT_EQ(d.input_points, 1234U);
  Eigen::Matrix4d T;
  T << 0, -1, 0, 1, 1, 0, 0, 2, 0, 0, 1, 0.5, 0, 0, 0, 1;
  EXPECT_TRUE(d.T_cloud_sensor.matrix() == T);
  ASSERT_EQ(d.model.instances.size(), kGoldenInstances.size());
  for (std::size_t i = 0; i < kGoldenInstances.size(); ++i) {
    const auto& g = kGoldenInstances[i];
    const Instance& inst = d.model.instances[i];
    EXPECT_EQ(inst.word, g.word) << i;
    for (int k = 0; k < 3; ++k)
      EXPECT_EQ(inst.T_cloud_word.translation()(k), g.tq[static_cast<std::size_t>(k)] * kGoldenStepT) << i;
    const Eigen::Vector3d r(g.rq[0] * kGoldenStepR, g.rq[1] * kGoldenStepR, g.rq[2] * kGoldenStepR);
    Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
    if (r.norm() > 0) R = Eigen::AngleAxisd(r.norm(), r / r.norm()).toRotationMatrix();
    EXPECT_LT((inst.T_cloud_word.linear() - R).cwiseAbs().maxCoeff(), 1e-12) << i;
  }
}

}  // namespace

TEST(CodecGolden, DISABLED_WriteGoldenFiles) {
  // Regenerates the golden files in the source tree. Only for a new format version:
  // files of an existing version must never change (add new ones instead).
  const ModelData d = golden_model();
  const Bytes alphabet_file = encode_alphabet(*d.alphabet);
  ModelData ref = d;
  ref.alphabet.reset();
  ref.alphabet_hash = alphabet_hash(alphabet_file);
  const std::pair<std::string, Bytes> files[] = {{"tiny_alphabet_1.0.lex3da", alphabet_file},
                                                 {"tiny_model_1.0.lex3dm", encode_model(d)},
                                                 {"tiny_model_ref_1.0.lex3dm", encode_model(ref)}};
  for (const auto& [name, bytes] : files) {
    std::ofstream out(golden_path(name), std::ios::binary);
    out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
    ASSERT_TRUE(out.good()) << name;
  }
}

TEST(CodecGolden, Format1_0FilesDecodeToTheRecordedValues) {
  const Bytes alphabet_file = read_bytes(golden_path("tiny_alphabet_1.0.lex3da"));
  const Bytes model_file = read_bytes(golden_path("tiny_model_1.0.lex3dm"));
  const Bytes ref_file = read_bytes(golden_path("tiny_model_ref_1.0.lex3dm"));
  ASSERT_FALSE(alphabet_file.empty());
  ASSERT_FALSE(model_file.empty());
  ASSERT_FALSE(ref_file.empty());

  const auto a = decode_alphabet(alphabet_file);
  ASSERT_TRUE(a.ok()) << a.status().to_string();
  expect_golden_alphabet(a.value());

  const auto m = decode_model(model_file);
  ASSERT_TRUE(m.ok()) << m.status().to_string();
  expect_golden_model(m.value());
  expect_golden_alphabet(*m.value().alphabet);
  EXPECT_FALSE(m.value().alphabet_hash.has_value());

  EXPECT_EQ(alphabet_hash(alphabet_file), kGoldenAlphabetHash);
  const auto r = decode_model(ref_file, &alphabet_file);
  ASSERT_TRUE(r.ok()) << r.status().to_string();
  expect_golden_model(r.value());
  expect_golden_alphabet(*r.value().alphabet);
  EXPECT_EQ(r.value().alphabet_hash, std::optional<std::uint64_t>(kGoldenAlphabetHash));

  // The chunk layout of format 1.0.
  const auto info = inspect(model_file);
  ASSERT_TRUE(info.ok());
  EXPECT_EQ(info.value().kind, "model");
  EXPECT_EQ(info.value().major, 1);
  EXPECT_EQ(info.value().minor, 0);
  EXPECT_EQ(info.value().flags, 1U);
  EXPECT_TRUE(info.value().header_crc_ok);
  std::string types;
  for (const auto& c : info.value().chunks) {
    types += c.type + " ";
    EXPECT_TRUE(c.crc_ok) << c.type;
  }
  EXPECT_EQ(types, "MHDR ALPH INST IEND ");
  EXPECT_EQ(info.value().chunks[0].offset, 20U);
  EXPECT_EQ(info.value().chunks[0].length, 120U);
  EXPECT_EQ(info.value().chunks[1].length, alphabet_file.size());
  const auto ainfo = inspect(alphabet_file);
  ASSERT_TRUE(ainfo.ok());
  EXPECT_EQ(ainfo.value().kind, "alphabet");
  EXPECT_EQ(ainfo.value().flags, 0U);
  ASSERT_EQ(ainfo.value().chunks.size(), 3U);
  EXPECT_EQ(ainfo.value().chunks[1].type, "WORD");
  const auto rinfo = inspect(ref_file);
  ASSERT_TRUE(rinfo.ok());
  EXPECT_EQ(rinfo.value().flags, 2U);
  EXPECT_EQ(rinfo.value().chunks[1].type, "AREF");
}
