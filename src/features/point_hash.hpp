#pragma once
// A sparse voxel hash of 3D points for "is any point within d?" queries, used
// by the interest points' minimum distance and by the coverage points.

#include <cmath>
#include <cstdint>
#include <unordered_map>
#include <vector>

#include <Eigen/Core>

namespace lex3d::detail {

class PointHash {
 public:
  /// `radius`: the query distance; the cell side equals it, so 27 cells cover a query.
  explicit PointHash(float radius) : radius_(radius), inv_cell_(1.0F / radius) {}

  void insert(const Eigen::Vector3f& p) {
    const auto id = static_cast<std::uint32_t>(points_.size());
    points_.push_back(p);
    cells_[key(cell_of(p))].push_back(id);
  }

  /// True when a stored point lies within the radius of `p` (distance <= radius).
  [[nodiscard]] bool any_within(const Eigen::Vector3f& p) {
    const float r2 = radius_ * radius_;
    if (last_hit_ < points_.size() && (points_[last_hit_] - p).squaredNorm() <= r2) return true;
    const Eigen::Vector3i c = cell_of(p);
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const auto it = cells_.find(key(c + Eigen::Vector3i(dx, dy, dz)));
          if (it == cells_.end()) continue;
          for (const std::uint32_t id : it->second)
            if ((points_[id] - p).squaredNorm() <= r2) {
              last_hit_ = id;
              return true;
            }
        }
    return false;
  }

  [[nodiscard]] std::size_t size() const noexcept { return points_.size(); }

 private:
  [[nodiscard]] Eigen::Vector3i cell_of(const Eigen::Vector3f& p) const {
    return {static_cast<int>(std::floor(p.x() * inv_cell_)), static_cast<int>(std::floor(p.y() * inv_cell_)),
            static_cast<int>(std::floor(p.z() * inv_cell_))};
  }
  static std::uint64_t key(const Eigen::Vector3i& c) {
    // 21 bits a coordinate: +-1e6 cells, far beyond any lidar range at sane radii.
    const auto u = [](int v) { return static_cast<std::uint64_t>(static_cast<std::int64_t>(v) + (1 << 20)) & 0x1FFFFFULL; };
    return u(c.x()) | (u(c.y()) << 21) | (u(c.z()) << 42);
  }

  float radius_;
  float inv_cell_;
  std::vector<Eigen::Vector3f> points_;
  std::unordered_map<std::uint64_t, std::vector<std::uint32_t>> cells_;
  std::size_t last_hit_ = static_cast<std::size_t>(-1);
};

}  // namespace lex3d::detail
