#pragma once
// A growing set of points answering "is any within the radius of p?" (the residual
// layer's thinning and keep decisions).

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

namespace lex3d::residual::detail {

/// A growing set of points answering "is any within the radius of p?": cells twice the
/// radius wide, so the ball around any point meets at most 2x2x2 cells, in an
/// open-addressing table, the points of a cell chained through `next_`.
class PointBallGrid {
 public:
  PointBallGrid(double radius, std::size_t expected) : radius_(radius), inv_cell_(1.0 / (2.0 * radius)) {
    std::size_t cap = 64;
    while (cap < 2 * expected) cap <<= 1;
    keys_.assign(cap, 0);
    heads_.assign(cap, kNone);
    mask_ = cap - 1;
    points_.reserve(expected);
    next_.reserve(expected);
    // ~32 filter bits a point (at most 2^23): an empty cell's bit is mostly clear.
    std::size_t bits = 4096;
    while (bits < 32 * expected && bits < (std::size_t{1} << 23)) bits <<= 1;
    filter_.assign(bits / 64, 0);
    filter_mask_ = bits - 1;
  }
  void insert(const Eigen::Vector3f& p) {
    if (2 * (used_ + 1) > keys_.size()) grow();
    const std::uint64_t k = key_of(cell(p.x()), cell(p.y()), cell(p.z()));
    const std::size_t b = (hash(k) >> 40) & filter_mask_;
    filter_[b >> 6] |= std::uint64_t{1} << (b & 63);
    const std::size_t s = slot(k, true);
    next_.push_back(heads_[s]);
    heads_[s] = static_cast<std::uint32_t>(points_.size());
    points_.push_back(p);
  }
  [[nodiscard]] bool any_within(const Eigen::Vector3d& p) const {
    const double r2 = radius_ * radius_;
    bool hit = false;
    visit_near(p, [&](std::uint32_t i) {
      hit = (points_[i].cast<double>() - p).squaredNorm() <= r2;
      return hit;
    });
    return hit;
  }
  /// The point nearest to `p` within the radius (its insertion index; ties: the lowest),
  /// or kNone when there is none.
  [[nodiscard]] std::uint32_t nearest_within(const Eigen::Vector3d& p) const {
    double best = radius_ * radius_;
    std::uint32_t found = kNone;
    visit_near(p, [&](std::uint32_t i) {
      const double d2 = (points_[i].cast<double>() - p).squaredNorm();
      if (d2 < best || (d2 == best && i < found)) {
        best = d2;
        found = i;
      }
      return false;
    });
    return found;
  }
  static constexpr std::uint32_t kNoPoint = 0xFFFFFFFFU;

 private:
  static constexpr std::uint32_t kNone = 0xFFFFFFFFU;
  /// Calls `f(i)` for each point i in the 2 x 2 x 2 cells nearest `p` (every point within
  /// a cell's half-width of it) until `f` returns true.
  template <typename F>
  void visit_near(const Eigen::Vector3d& p, F&& f) const {
    std::int64_t base[3], step[3];
    for (int a = 0; a < 3; ++a) {
      const double c = p[a] * inv_cell_;
      base[a] = static_cast<std::int64_t>(std::floor(c));
      step[a] = (c - static_cast<double>(base[a]) < 0.5) ? -1 : 1;
    }
    for (int dx = 0; dx < 2; ++dx)
      for (int dy = 0; dy < 2; ++dy)
        for (int dz = 0; dz < 2; ++dz) {
          const std::uint64_t k = key_of(base[0] + dx * step[0], base[1] + dy * step[1], base[2] + dz * step[2]);
          const std::uint64_t h = hash(k);
          const std::size_t b = (h >> 40) & filter_mask_;
          if (((filter_[b >> 6] >> (b & 63)) & 1U) == 0) continue;  // no point in that cell
          std::size_t s = h & mask_;
          while (heads_[s] != kNone && keys_[s] != k) s = (s + 1) & mask_;
          for (std::uint32_t i = heads_[s]; i != kNone; i = next_[i])
            if (f(i)) return;
        }
  }
  [[nodiscard]] std::int64_t cell(float v) const { return static_cast<std::int64_t>(std::floor(static_cast<double>(v) * inv_cell_)); }
  static std::uint64_t key_of(std::int64_t x, std::int64_t y, std::int64_t z) {
    const auto f = [](std::int64_t v) { return static_cast<std::uint64_t>(v) & 0x1FFFFFU; };
    return f(x) | (f(y) << 21) | (f(z) << 42);
  }
  static std::uint64_t hash(std::uint64_t k) {
    k ^= k >> 33;
    k *= 0xff51afd7ed558ccdULL;
    k ^= k >> 33;
    return k;
  }
  std::size_t slot(std::uint64_t k, bool create) {
    std::size_t s = hash(k) & mask_;
    while (heads_[s] != kNone && keys_[s] != k) s = (s + 1) & mask_;
    if (heads_[s] == kNone && create) {
      keys_[s] = k;
      ++used_;
    }
    return s;
  }
  void grow() {
    std::vector<std::uint64_t> keys = std::move(keys_);
    std::vector<std::uint32_t> heads = std::move(heads_);
    keys_.assign(keys.size() * 2, 0);
    heads_.assign(keys.size() * 2, kNone);
    mask_ = keys_.size() - 1;
    for (std::size_t i = 0; i < keys.size(); ++i) {
      if (heads[i] == kNone) continue;
      std::size_t s = hash(keys[i]) & mask_;
      while (heads_[s] != kNone) s = (s + 1) & mask_;
      keys_[s] = keys[i];
      heads_[s] = heads[i];
    }
  }

  double radius_;
  double inv_cell_;
  std::vector<std::uint64_t> keys_;
  std::vector<std::uint32_t> heads_;
  std::vector<std::uint32_t> next_;
  std::vector<Eigen::Vector3f> points_;
  std::vector<std::uint64_t> filter_;  // bit (hash >> 40) of every occupied cell's key
  std::size_t filter_mask_ = 0;
  std::size_t mask_ = 0;
  std::size_t used_ = 0;
};

}  // namespace lex3d::residual::detail
