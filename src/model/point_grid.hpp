#pragma once
// A static voxel grid over a point set for radius queries: points are sorted by cell
// once (O(N log N)), and a query visits the cells its ball overlaps. For the
// neighbourhoods of thousands of features this is several times faster than a
// kd-tree, because radii are a few cells at most.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numeric>
#include <unordered_map>
#include <vector>

#include <Eigen/Core>

namespace lex3d::detail {

class PointGrid {
 public:
  PointGrid(const std::vector<Eigen::Vector3f>& points, float cell) : points_(points), inv_(1.0F / cell) {
    std::vector<std::uint64_t> keys(points.size());
    for (std::size_t i = 0; i < points.size(); ++i) keys[i] = key(cell_of(points[i]));
    order_.resize(points.size());
    std::iota(order_.begin(), order_.end(), 0U);
    std::stable_sort(order_.begin(), order_.end(), [&](std::uint32_t a, std::uint32_t b) { return keys[a] < keys[b]; });
    cells_.reserve(points.size() / 4 + 1);
    for (std::size_t i = 0; i < order_.size();) {
      std::size_t j = i;
      while (j < order_.size() && keys[order_[j]] == keys[order_[i]]) ++j;
      cells_.emplace(keys[order_[i]], std::make_pair(static_cast<std::uint32_t>(i), static_cast<std::uint32_t>(j)));
      i = j;
    }
  }

  /// Indices of the points within `radius` of `c`, sorted ascending.
  void radius(const Eigen::Vector3f& c, float radius, std::vector<std::uint32_t>& out) const {
    out.clear();
    const Eigen::Vector3i lo = cell_of(c - Eigen::Vector3f::Constant(radius));
    const Eigen::Vector3i hi = cell_of(c + Eigen::Vector3f::Constant(radius));
    const float r2 = radius * radius;
    for (int z = lo.z(); z <= hi.z(); ++z)
      for (int y = lo.y(); y <= hi.y(); ++y)
        for (int x = lo.x(); x <= hi.x(); ++x) {
          const auto it = cells_.find(key({x, y, z}));
          if (it == cells_.end()) continue;
          for (std::uint32_t k = it->second.first; k < it->second.second; ++k) {
            const std::uint32_t i = order_[k];
            if ((points_[i] - c).squaredNorm() <= r2) out.push_back(i);
          }
        }
    std::sort(out.begin(), out.end());
  }

 private:
  [[nodiscard]] Eigen::Vector3i cell_of(const Eigen::Vector3f& p) const {
    return {static_cast<int>(std::floor(p.x() * inv_)), static_cast<int>(std::floor(p.y() * inv_)),
            static_cast<int>(std::floor(p.z() * inv_))};
  }
  static std::uint64_t key(const Eigen::Vector3i& c) {
    const auto u = [](int v) { return static_cast<std::uint64_t>(static_cast<std::int64_t>(v) + (1 << 20)) & 0x1FFFFFULL; };
    return u(c.x()) | (u(c.y()) << 21) | (u(c.z()) << 42);
  }

  const std::vector<Eigen::Vector3f>& points_;
  float inv_;
  std::vector<std::uint32_t> order_;
  std::unordered_map<std::uint64_t, std::pair<std::uint32_t, std::uint32_t>> cells_;
};

}  // namespace lex3d::detail
