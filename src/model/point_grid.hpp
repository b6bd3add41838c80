#pragma once
// A static voxel grid over a point set for radius queries. Points are bucketed by cell
// in two linear passes (a counting sort, points of a cell in index order) and stored
// with their coordinates in cell order, so a query reads each cell it visits
// contiguously; cells live in a flat open-addressing table. A query visits only the
// cells its ball touches. For the neighbourhoods of thousands of features this beats
// a kd-tree, because radii are a few cells at most.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

namespace lex3d::detail {

class PointGrid {
 public:
  PointGrid(const std::vector<Eigen::Vector3f>& points, float cell) : cell_(cell), inv_(1.0F / cell) {
    const std::size_t n = points.size();
    std::size_t cap = 16;
    while (cap < 2 * n) cap <<= 1;
    keys_.assign(cap, kEmpty);
    begin_.assign(cap, 0);
    end_.assign(cap, 0);
    mask_ = cap - 1;
    // Pass 1: the cell of every point and the size of every cell.
    std::vector<std::uint32_t> slot_of(n);
    for (std::size_t i = 0; i < n; ++i) {
      const std::size_t s = insert(key(cell_of(points[i])));
      slot_of[i] = static_cast<std::uint32_t>(s);
      ++end_[s];
    }
    // Cells in the order they were first met; each gets a contiguous range.
    std::uint32_t at = 0;
    for (std::size_t i = 0; i < n; ++i) {
      const std::size_t s = slot_of[i];
      if (begin_[s] != 0 || end_[s] == 0) continue;  // placed already (begin is stored + 1)
      const std::uint32_t count = end_[s];
      begin_[s] = at + 1;
      end_[s] = at;  // fill cursor
      at += count;
    }
    // Pass 2: scatter, in index order within each cell.
    pts_.resize(n);
    idx_.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
      const std::size_t s = slot_of[i];
      const std::uint32_t k = end_[s]++;
      pts_[k] = points[i];
      idx_[k] = static_cast<std::uint32_t>(i);
    }
    for (std::size_t s = 0; s < cap; ++s)
      if (keys_[s] != kEmpty) --begin_[s];
  }

  /// Indices of the points within `radius` of `c`, sorted ascending.
  void radius(const Eigen::Vector3f& c, float radius, std::vector<std::uint32_t>& out) const {
    out.clear();
    const Eigen::Vector3i lo = cell_of(c - Eigen::Vector3f::Constant(radius));
    const Eigen::Vector3i hi = cell_of(c + Eigen::Vector3f::Constant(radius));
    const float r2 = radius * radius;
    // Cells are skipped against a slightly larger ball: a point's cell comes from
    // rounded products, so it may sit a hair outside the cell's exact bounds.
    const float rc = radius + 1e-4F * cell_;
    const float rc2 = rc * rc;
    // Distance along one axis from c to cell v's slab (0 inside).
    const auto gap = [&](int v, float cv) {
      const float a = static_cast<float>(v) * cell_;
      const float b = a + cell_;
      return cv < a ? a - cv : (cv > b ? cv - b : 0.0F);
    };
    for (int z = lo.z(); z <= hi.z(); ++z) {
      const float gz = gap(z, c.z());
      const float gz2 = gz * gz;
      if (gz2 > rc2) continue;
      for (int y = lo.y(); y <= hi.y(); ++y) {
        const float gy = gap(y, c.y());
        const float gyz2 = gz2 + gy * gy;
        if (gyz2 > rc2) continue;
        for (int x = lo.x(); x <= hi.x(); ++x) {
          const float gx = gap(x, c.x());
          if (gyz2 + gx * gx > rc2) continue;  // the cell lies outside the ball
          const std::size_t s = find(key({x, y, z}));
          if (s == kNone) continue;
          for (std::uint32_t k = begin_[s]; k < end_[s]; ++k)
            if ((pts_[k] - c).squaredNorm() <= r2) out.push_back(idx_[k]);
        }
      }
    }
    std::sort(out.begin(), out.end());
  }

 private:
  static constexpr std::uint64_t kEmpty = ~0ULL;
  static constexpr std::size_t kNone = ~static_cast<std::size_t>(0);

  [[nodiscard]] Eigen::Vector3i cell_of(const Eigen::Vector3f& p) const {
    return {static_cast<int>(std::floor(p.x() * inv_)), static_cast<int>(std::floor(p.y() * inv_)),
            static_cast<int>(std::floor(p.z() * inv_))};
  }
  static std::uint64_t key(const Eigen::Vector3i& c) {
    const auto u = [](int v) { return static_cast<std::uint64_t>(static_cast<std::int64_t>(v) + (1 << 20)) & 0x1FFFFFULL; };
    return u(c.x()) | (u(c.y()) << 21) | (u(c.z()) << 42);
  }
  static std::size_t hash(std::uint64_t k) {
    k ^= k >> 33;
    k *= 0xff51afd7ed558ccdULL;
    k ^= k >> 33;
    return static_cast<std::size_t>(k);
  }
  std::size_t insert(std::uint64_t k) {
    for (std::size_t i = hash(k) & mask_;; i = (i + 1) & mask_) {
      if (keys_[i] == k) return i;
      if (keys_[i] == kEmpty) {
        keys_[i] = k;
        return i;
      }
    }
  }
  [[nodiscard]] std::size_t find(std::uint64_t k) const {
    for (std::size_t i = hash(k) & mask_;; i = (i + 1) & mask_) {
      if (keys_[i] == k) return i;
      if (keys_[i] == kEmpty) return kNone;
    }
  }

  float cell_;
  float inv_;
  std::size_t mask_ = 0;
  std::vector<std::uint64_t> keys_;
  std::vector<std::uint32_t> begin_, end_;  // per table slot: the cell's range in pts_/idx_
  std::vector<Eigen::Vector3f> pts_;        // points in cell order
  std::vector<std::uint32_t> idx_;          // their indices
};

}  // namespace lex3d::detail
