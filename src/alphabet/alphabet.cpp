#include "lex3d/alphabet/alphabet.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>
#include <unordered_set>

#include "lex3d/core/parallel.hpp"

namespace lex3d {

std::size_t Alphabet::total_points() const noexcept {
  std::size_t n = 0;
  for (const auto& w : words) n += w.points.size();
  return n;
}

Word cut_word(const std::vector<Eigen::Vector3f>& points_sensor, const std::vector<std::uint32_t>& nearby,
              const Eigen::Isometry3f& T_sensor_feature, const float* descriptor, int descriptor_dim, double radius,
              double spacing) {
  Word w;
  w.descriptor.assign(descriptor, descriptor + descriptor_dim);
  const Eigen::Isometry3f T_feature_sensor = T_sensor_feature.inverse();
  const float r2 = static_cast<float>(radius * radius);
  const float inv = spacing > 0.0 ? static_cast<float>(1.0 / spacing) : 0.0F;
  // Thinning on a grid of `spacing`: the first point of a cell (in input order) wins,
  // which keeps the result deterministic and its points at least ~spacing apart.
  std::unordered_set<std::uint64_t> taken;
  for (const std::uint32_t i : nearby) {
    const Eigen::Vector3f q = T_feature_sensor * points_sensor[i];
    if (q.squaredNorm() > r2) continue;
    if (inv > 0.0F) {
      const auto cell = [&](float v) {
        return static_cast<std::uint64_t>(static_cast<std::int64_t>(std::floor(v * inv)) + (1 << 20)) & 0x1FFFFFULL;
      };
      const std::uint64_t key = cell(q.x()) | (cell(q.y()) << 21) | (cell(q.z()) << 42);
      if (!taken.insert(key).second) continue;
    }
    w.points.push_back(q);
  }
  return w;
}

WordIndex::WordIndex(const Alphabet& alphabet) : alphabet_(alphabet) {
  packed_.reserve(alphabet.words.size() * static_cast<std::size_t>(alphabet.descriptor_dim));
  for (const auto& w : alphabet.words) packed_.insert(packed_.end(), w.descriptor.begin(), w.descriptor.end());
}

WordIndex::~WordIndex() = default;

std::vector<WordIndex::Match> WordIndex::nearest(const float* descriptors, std::size_t count, int threads) const {
  std::vector<Match> out;
  const std::size_t words = alphabet_.words.size();
  if (words == 0) return out;
  const int dim = alphabet_.descriptor_dim;
  out.resize(count);
  // Exact search: with 100-dimensional descriptors and alphabets of hundreds of words a
  // vectorised linear scan beats tree search and keeps ties deterministic (lowest id).
  parallel_for(count, threads, [&](std::size_t i) {
    const float* q = descriptors + i * static_cast<std::size_t>(dim);
    Match best{0, std::numeric_limits<float>::infinity()};
    for (std::size_t w = 0; w < words; ++w) {
      const float d = descriptor_distance_sq(q, packed_.data() + w * static_cast<std::size_t>(dim), dim);
      if (d < best.distance_sq) best = {static_cast<std::uint32_t>(w), d};
    }
    out[i] = best;
  }, 64);
  return out;
}

namespace {

constexpr char kMagic[4] = {'L', '3', 'D', 'A'};
constexpr std::uint32_t kVersion = 0;
constexpr std::uint32_t kMaxWords = 1U << 24;
constexpr std::uint32_t kMaxDim = 4096;

void put_u32(std::vector<std::uint8_t>& b, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) b.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
}
void put_f32(std::vector<std::uint8_t>& b, float f) {
  std::uint32_t v;
  std::memcpy(&v, &f, 4);
  put_u32(b, v);
}
void put_f64(std::vector<std::uint8_t>& b, double d) {
  std::uint64_t v;
  std::memcpy(&v, &d, 8);
  put_u32(b, static_cast<std::uint32_t>(v));
  put_u32(b, static_cast<std::uint32_t>(v >> 32));
}

struct Reader {
  const std::vector<std::uint8_t>& b;
  std::size_t pos = 0;
  [[nodiscard]] std::size_t left() const { return b.size() - pos; }
  bool u32(std::uint32_t& v) {
    if (left() < 4) return false;
    v = 0;
    for (int i = 0; i < 4; ++i) v |= static_cast<std::uint32_t>(b[pos + static_cast<std::size_t>(i)]) << (8 * i);
    pos += 4;
    return true;
  }
  bool f32(float& f) {
    std::uint32_t v;
    if (!u32(v)) return false;
    std::memcpy(&f, &v, 4);
    return true;
  }
  bool f64(double& d) {
    std::uint32_t lo, hi;
    if (!u32(lo) || !u32(hi)) return false;
    const std::uint64_t v = lo | (static_cast<std::uint64_t>(hi) << 32);
    std::memcpy(&d, &v, 8);
    return true;
  }
};

}  // namespace

std::vector<std::uint8_t> serialize_alphabet(const Alphabet& a) {
  std::vector<std::uint8_t> b(kMagic, kMagic + 4);
  put_u32(b, kVersion);
  put_f64(b, a.word_radius);
  put_f64(b, a.point_spacing);
  put_u32(b, static_cast<std::uint32_t>(a.descriptor_dim));
  put_u32(b, static_cast<std::uint32_t>(a.words.size()));
  for (const auto& w : a.words) {
    put_u32(b, static_cast<std::uint32_t>(w.points.size()));
    for (const auto& p : w.points) {
      put_f32(b, p.x());
      put_f32(b, p.y());
      put_f32(b, p.z());
    }
    for (const float d : w.descriptor) put_f32(b, d);
  }
  return b;
}

StatusOr<Alphabet> deserialize_alphabet(const std::vector<std::uint8_t>& bytes) {
  if (bytes.size() < 4 || std::memcmp(bytes.data(), kMagic, 4) != 0)
    return bad_data("not a lex3d alphabet (bad magic)", 0);
  Reader r{bytes, 4};
  std::uint32_t version = 0, dim = 0, n = 0;
  Alphabet a;
  if (!r.u32(version)) return bad_data("alphabet truncated in the header", r.pos);
  if (version != kVersion) return bad_data("unsupported alphabet version " + std::to_string(version), 4);
  if (!r.f64(a.word_radius) || !r.f64(a.point_spacing) || !r.u32(dim) || !r.u32(n))
    return bad_data("alphabet truncated in the header", r.pos);
  if (!(a.word_radius > 0.0 && a.word_radius < 1e3) || !(a.point_spacing >= 0.0 && a.point_spacing < 1e3))
    return bad_data("alphabet header has an invalid word radius or spacing", 8);
  if (dim == 0 || dim > kMaxDim) return bad_data("alphabet descriptor size " + std::to_string(dim) + " is invalid", 24);
  if (n > kMaxWords || static_cast<std::uint64_t>(n) * (4 + 4ULL * dim) > r.left())
    return bad_data("alphabet word count " + std::to_string(n) + " does not fit the file", 28);
  a.descriptor_dim = static_cast<int>(dim);
  a.words.resize(n);
  for (auto& w : a.words) {
    std::uint32_t np = 0;
    if (!r.u32(np)) return bad_data("alphabet truncated in a word", r.pos);
    if (static_cast<std::uint64_t>(np) * 12 + 4ULL * dim > r.left())
      return bad_data("alphabet word of " + std::to_string(np) + " points does not fit the file", r.pos - 4);
    w.points.resize(np);
    for (auto& p : w.points) {
      float x, y, z;
      r.f32(x);
      r.f32(y);
      r.f32(z);
      p = {x, y, z};
      if (!p.allFinite()) return bad_data("alphabet word point is not finite", r.pos - 12);
    }
    w.descriptor.resize(dim);
    for (auto& d : w.descriptor) r.f32(d);
  }
  if (r.left() != 0) return bad_data("alphabet has " + std::to_string(r.left()) + " trailing bytes", r.pos);
  return a;
}

}  // namespace lex3d
