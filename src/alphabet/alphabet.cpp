#include "lex3d/alphabet/alphabet.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
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
    thread_local std::vector<float> dist;
    dist.resize(words);
    descriptor_distances_sq(descriptors + i * static_cast<std::size_t>(dim), packed_.data(), words, dim, dist.data());
    Match best{0, std::numeric_limits<float>::infinity()};
    for (std::size_t w = 0; w < words; ++w)
      if (dist[w] < best.distance_sq) best = {static_cast<std::uint32_t>(w), dist[w]};
    out[i] = best;
  }, 64);
  return out;
}

}  // namespace lex3d
