#pragma once
// A sparse voxel hash of 3D points for "is any point within d?" queries, used
// by the interest points' minimum distance and by the coverage points.
//
// Cells are kept in an open-addressing table (linear probing, power-of-two size,
// at most half full) whose slots hold the newest point of the cell; each point
// links to the one inserted before it in the same cell. Most cells a query looks
// at are empty: a bit map of the occupied cells (a cell's bit may be shared with
// others; a clear bit proves the cell empty) answers those first. Its index is linear
// in the cell's x, so the three cells of a query along x are neighbouring bits.

#include <cmath>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

namespace lex3d::detail {

class PointHash {
 public:
  /// `radius`: the query distance; the cell side equals it, so 27 cells cover a query.
  explicit PointHash(float radius) : radius_(radius), inv_cell_(1.0F / radius), occupied_(kBitWords, 0) {
    rehash(64);
  }

  void insert(const Eigen::Vector3f& p) {
    const auto id = static_cast<std::uint32_t>(points_.size());
    points_.push_back(p);
    if (2 * (used_ + 1) > keys_.size()) rehash(2 * keys_.size());
    const std::uint64_t k = key(cell_of(p));
    std::size_t s = slot(k);
    while (keys_[s] != kFree && keys_[s] != k) s = (s + 1) & mask_;
    if (keys_[s] == kFree) {
      keys_[s] = k;
      heads_[s] = kNone;
      ++used_;
      const std::uint32_t b = bit_of(cell_of(p));
      occupied_[b >> 6] |= std::uint64_t{1} << (b & 63);
    }
    next_.push_back(heads_[s]);
    heads_[s] = id;
    last_hit_ = id;  // the next query is most likely near the newest point
  }

  /// True when a stored point lies within the radius of `p` (distance <= radius).
  [[nodiscard]] bool any_within(const Eigen::Vector3f& p) {
    const float r2 = radius_ * radius_;
    if (last_hit_ < points_.size() && (points_[last_hit_] - p).squaredNorm() <= r2) return true;
    const Eigen::Vector3i c = cell_of(p);
    // The cell itself first: the likeliest to hold a point within reach.
    if (maybe_occupied(bit_of(c)) && scan_cell(key(c), p, r2)) return true;
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy) {
        const std::uint32_t b = bit_of(c + Eigen::Vector3i(-1, dy, dz));
        for (int dx = -1; dx <= 1; ++dx) {
          if (dx == 0 && dy == 0 && dz == 0) continue;
          if (!maybe_occupied((b + static_cast<std::uint32_t>(dx + 1)) & kBitMask)) continue;
          if (scan_cell(key(c + Eigen::Vector3i(dx, dy, dz)), p, r2)) return true;
        }
      }
    return false;
  }

  [[nodiscard]] std::size_t size() const noexcept { return points_.size(); }

 private:
  static constexpr std::uint64_t kFree = ~std::uint64_t{0};  // keys use 63 bits
  static constexpr std::uint32_t kNone = ~std::uint32_t{0};
  static constexpr std::uint32_t kBits = 1U << 20;  // 128 KiB of bits
  static constexpr std::uint32_t kBitMask = kBits - 1;
  static constexpr std::size_t kBitWords = kBits / 64;

  // Bit of a cell: x + y·A + z·B modulo 2^20, with odd multipliers that spread
  // neighbouring rows and layers far apart.
  static std::uint32_t bit_of(const Eigen::Vector3i& c) {
    return (static_cast<std::uint32_t>(c.x()) + static_cast<std::uint32_t>(c.y()) * 0x9E3779B1U +
            static_cast<std::uint32_t>(c.z()) * 0x85EBCA77U) & kBitMask;
  }
  [[nodiscard]] bool maybe_occupied(std::uint32_t b) const {
    return ((occupied_[b >> 6] >> (b & 63)) & 1U) != 0;
  }

  // A cell index, clamped to the keys' 21 bits less one cell, so that neither the cast nor a
  // neighbour's index (+-1) overflows for a point far out (1e30 m, say). Clamped points share
  // the border cells; queries still compare exact distances, so answers stay right.
  [[nodiscard]] int cell_coord(float v) const {
    constexpr float kLimit = static_cast<float>((1 << 20) - 2);
    const float c = std::floor(v * inv_cell_);
    return static_cast<int>(!(c < kLimit) ? kLimit : c <= -kLimit ? -kLimit : c);  // NaN: kLimit
  }
  [[nodiscard]] Eigen::Vector3i cell_of(const Eigen::Vector3f& p) const {
    return {cell_coord(p.x()), cell_coord(p.y()), cell_coord(p.z())};
  }
  static std::uint64_t key(const Eigen::Vector3i& c) {
    // 21 bits a coordinate: +-1e6 cells, far beyond any lidar range at sane radii.
    const auto u = [](int v) { return static_cast<std::uint64_t>(static_cast<std::int64_t>(v) + (1 << 20)) & 0x1FFFFFULL; };
    return u(c.x()) | (u(c.y()) << 21) | (u(c.z()) << 42);
  }
  [[nodiscard]] std::size_t slot(std::uint64_t k) const {
    return static_cast<std::size_t>((k * 0x9E3779B97F4A7C15ULL) >> shift_);
  }

  bool scan_cell(std::uint64_t k, const Eigen::Vector3f& p, float r2) {
    std::size_t s = slot(k);
    while (keys_[s] != k) {
      if (keys_[s] == kFree) return false;
      s = (s + 1) & mask_;
    }
    for (std::uint32_t id = heads_[s]; id != kNone; id = next_[id])
      if ((points_[id] - p).squaredNorm() <= r2) {
        last_hit_ = id;
        return true;
      }
    return false;
  }

  void rehash(std::size_t n) {
    std::vector<std::uint64_t> old_keys(n, kFree);
    std::vector<std::uint32_t> old_heads(n, kNone);
    old_keys.swap(keys_);
    old_heads.swap(heads_);
    mask_ = n - 1;
    shift_ = 64;
    for (std::size_t m = n; m > 1; m >>= 1) --shift_;
    for (std::size_t i = 0; i < old_keys.size(); ++i) {
      if (old_keys[i] == kFree) continue;
      std::size_t s = slot(old_keys[i]);
      while (keys_[s] != kFree) s = (s + 1) & mask_;
      keys_[s] = old_keys[i];
      heads_[s] = old_heads[i];
    }
  }

  float radius_;
  float inv_cell_;
  std::vector<Eigen::Vector3f> points_;
  std::vector<std::uint32_t> next_;  // per point: the previous point of its cell
  std::vector<std::uint64_t> keys_;  // per slot: cell key or kFree
  std::vector<std::uint32_t> heads_; // per slot: newest point of the cell
  std::vector<std::uint64_t> occupied_;  // kBits bits, set for the cells that hold points
  std::size_t mask_ = 0;
  int shift_ = 64;
  std::size_t used_ = 0;
  std::size_t last_hit_ = static_cast<std::size_t>(-1);
};

}  // namespace lex3d::detail
