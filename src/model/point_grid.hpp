#pragma once
// The points of a scan within each of many balls (the neighbourhoods of the features),
// found point by point instead of ball by ball. Balls are registered in the cells of a
// voxel grid they may reach; then every point, in index order, tests the balls of its
// own cell, four at a time. A point's hits go to the end of each hit ball's list, so
// every list comes out in index order with no sorting or merging. (Ball by ball, each
// query looked up ~27 cells and merged their runs of hits, which cost more than the
// distance tests themselves.)
//
// Cells are grouped in blocks of 4x4x4 kept in a hash table: a ball's cells mostly lie
// in one or two blocks, and consecutive points mostly in one, so few hash look-ups.
//
// The result is exactly that of testing, for every ball, the points of every cell of
// its bounding box that is not farther from the centre than the radius (plus a margin
// for rounding): the cells, their keys (21 bits an axis) and the test, (dx² + dy²) + dz²
// <= r² in float, are those of a query ball by ball.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <vector>

#include <Eigen/Core>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "core/huge_pages.hpp"
#include "lex3d/core/parallel.hpp"

namespace lex3d::detail {

class BallGrid {
 public:
  explicit BallGrid(float cell) : cell_(cell), inv_(1.0F / cell) {}

  /// For each ball b (centre[b], radius[b]), the indices of the points within it, in
  /// ascending order: index[offset[b], offset[b + 1]).
  void points_in_balls(const std::vector<Eigen::Vector3f>& points, const std::vector<Eigen::Vector3f>& centre,
                       const std::vector<float>& radius, int threads, std::vector<std::size_t>& offset,
                       std::vector<std::uint32_t>& index) {
    const std::size_t n = points.size();
    const std::size_t nb = centre.size();
    offset.assign(nb + 1, 0);
    index.clear();
    if (n == 0 || nb == 0) return;
    // The cell of every point (blocks numbered in the order they are first met).
    std::vector<std::uint32_t> cell_of_point(n);
    {
      std::uint64_t last = kEmpty;
      std::uint32_t last_block = 0;
      for (std::size_t i = 0; i < n; ++i) {
        const Eigen::Vector3i c = cell_of(points[i]);
        const std::uint64_t b = block_key(c.x(), c.y(), c.z());
        if (b != last) {  // points in scan order mostly stay in a block
          last = b;
          last_block = insert(b);
        }
        cell_of_point[i] = 64 * last_block + local(c.x(), c.y(), c.z());
      }
    }
    const std::size_t cells = 64 * count_;
    std::vector<std::uint8_t> occupied(cells, 0);
    for (const std::uint32_t c : cell_of_point) occupied[c] = 1;
    // The cells holding points each ball may reach, as (cell, ball) pairs, then the
    // balls of each cell gathered by a counting sort: centre, r² and id apart, each
    // cell padded to a multiple of 4 with far balls of r² = -1.
    std::vector<std::uint32_t> cell_balls(cells + 1, 0);
    struct Reg {
      std::uint32_t c, b;
    };
    std::size_t cap = 16 * nb, nreg = 0;
    std::unique_ptr<Reg[]> reg(new Reg[cap]);  // not zeroed: each pair is written before it is read
    for (std::size_t b = 0; b < nb; ++b)
      for_cells(centre[b], radius[b], [&](std::uint32_t c) {
        // Written always, kept when the cell holds points (no branch on that: most do
        // not, in no pattern a predictor learns).
        if (nreg == cap) {
          std::unique_ptr<Reg[]> more(new Reg[2 * cap]);
          std::copy(reg.get(), reg.get() + nreg, more.get());
          reg.swap(more);
          cap *= 2;
        }
        reg[nreg] = {c, static_cast<std::uint32_t>(b)};
        const std::uint32_t o = occupied[c];
        cell_balls[c + 1] += o;
        nreg += o;
      });
    for (std::size_t c = 0; c < cells; ++c) cell_balls[c + 1] = cell_balls[c] + ((cell_balls[c + 1] + 3U) & ~3U);
    const std::size_t slots = cell_balls[cells];
    std::vector<float> bx(slots, kFar), by(slots, kFar), bz(slots, kFar), br2(slots, -1.0F);
    std::vector<std::uint32_t> bid(slots, 0);
    {
      std::vector<std::uint32_t> fill(cell_balls.begin(), cell_balls.end() - 1);
      for (std::size_t r = 0; r < nreg; ++r) {
        const std::uint32_t c = reg[r].c, b = reg[r].b;
        const std::uint32_t k = fill[c]++;
        bx[k] = centre[b].x();
        by[k] = centre[b].y();
        bz[k] = centre[b].z();
        br2[k] = radius[b] * radius[b];
        bid[k] = b;
      }
    }
    // Every point tests the balls of its cell once, keeping which of them hold it as a
    // bit mask over the cell's slots (cells of up to 64; a point of a larger cell is
    // tested again instead); each ball's points are counted, then placed, in index
    // order, at the ball's cursor. With several threads, each block of points has its
    // own counts and cursors, blocks in index order.
    const std::size_t blocks = threads > 1 ? 4 * static_cast<std::size_t>(threads) : 1;
    const std::size_t per_block = (n + blocks - 1) / blocks;
    std::vector<std::size_t> at(blocks * nb, 0);
    std::vector<std::uint64_t> mask(n);
    const auto test = [&](std::size_t i, auto&& fn) {
      const std::uint32_t c = cell_of_point[i];
      const std::uint32_t s0 = cell_balls[c], s1 = cell_balls[c + 1];
      ball_hits(bx.data() + s0, by.data() + s0, bz.data() + s0, br2.data() + s0, bid.data() + s0, s1 - s0,
                points[i], fn);
    };
    // fn(ball) for each ball holding point i, from its mask when it has one.
    const auto each_hit = [&](std::size_t i, auto&& fn) {
      const std::uint32_t c = cell_of_point[i];
      const std::uint32_t s0 = cell_balls[c], s1 = cell_balls[c + 1];
      if (s1 - s0 > 64) return test(i, fn);
      for (std::uint64_t m = mask[i]; m != 0; m &= m - 1) fn(bid[s0 + static_cast<std::uint32_t>(__builtin_ctzll(m))]);
    };
    parallel_for(blocks, threads, [&](std::size_t blk) {
      std::size_t* const count = at.data() + blk * nb;
      const std::size_t i0 = std::min(n, blk * per_block), i1 = std::min(n, i0 + per_block);
      for (std::size_t i = i0; i < i1; ++i) {
        const std::uint32_t c = cell_of_point[i];
        const std::uint32_t s0 = cell_balls[c], s1 = cell_balls[c + 1];
        if (s1 - s0 <= 64)
          mask[i] = ball_mask(bx.data() + s0, by.data() + s0, bz.data() + s0, br2.data() + s0, s1 - s0, points[i]);
        each_hit(i, [&](std::uint32_t b) { ++count[b]; });
      }
    }, 1);
    std::size_t total = 0;
    for (std::size_t b = 0; b < nb; ++b) {
      offset[b] = total;
      for (std::size_t blk = 0; blk < blocks; ++blk) {
        const std::size_t c = at[blk * nb + b];
        at[blk * nb + b] = total;
        total += c;
      }
    }
    offset[nb] = total;
    // The lists are megabytes of fresh memory, filled once: on huge pages where the kernel
    // allows, so that the first touch costs a fault per 2 MiB rather than per 4 KiB.
    if (index.capacity() < total) {
      std::vector<std::uint32_t> fresh;
      reserve_on_huge_pages(fresh, total);
      index.swap(fresh);
    }
    index.resize(total);
    std::uint32_t* const out = index.data();
    parallel_for(blocks, threads, [&](std::size_t blk) {
      std::size_t* const cursor = at.data() + blk * nb;
      const std::size_t i0 = std::min(n, blk * per_block), i1 = std::min(n, i0 + per_block);
      for (std::size_t i = i0; i < i1; ++i)
        each_hit(i, [&](std::uint32_t b) { out[cursor[b]++] = static_cast<std::uint32_t>(i); });
    }, 1);
  }

 private:
  // Bit k set when ball k of [0, n) (n a multiple of 4, at most 64) holds p; the test
  // is that of ball_hits.
  static std::uint64_t ball_mask(const float* cx, const float* cy, const float* cz, const float* r2, std::size_t n,
                                 const Eigen::Vector3f& p) {
    std::uint64_t m = 0;
#if defined(__SSE2__)
    const __m128 px = _mm_set1_ps(p.x()), py = _mm_set1_ps(p.y()), pz = _mm_set1_ps(p.z());
    for (std::size_t k = 0; k < n; k += 4) {
      const __m128 dx = _mm_sub_ps(px, _mm_loadu_ps(cx + k));
      const __m128 dy = _mm_sub_ps(py, _mm_loadu_ps(cy + k));
      const __m128 dz = _mm_sub_ps(pz, _mm_loadu_ps(cz + k));
      const __m128 d2 = _mm_add_ps(_mm_add_ps(_mm_mul_ps(dx, dx), _mm_mul_ps(dy, dy)), _mm_mul_ps(dz, dz));
      m |= static_cast<std::uint64_t>(_mm_movemask_ps(_mm_cmple_ps(d2, _mm_loadu_ps(r2 + k)))) << k;
    }
#else
    for (std::size_t k = 0; k < n; ++k) {
      const float dx = p.x() - cx[k], dy = p.y() - cy[k], dz = p.z() - cz[k];
      m |= static_cast<std::uint64_t>(dx * dx + dy * dy + dz * dz <= r2[k] ? 1 : 0) << k;
    }
#endif
    return m;
  }

  // Calls hit(id) for each ball of [0, n) (n a multiple of 4) that holds p, in order.
  // The test is that of a scalar loop, (dx² + dy²) + dz² <= r², done four balls at a
  // time (the same bits). The hits of up to 64 balls are gathered without branches
  // first: a branch on each test would be mispredicted about as often as it is taken.
  template <typename Hit>
  static void ball_hits(const float* cx, const float* cy, const float* cz, const float* r2, const std::uint32_t* id,
                        std::size_t n, const Eigen::Vector3f& p, Hit&& hit) {
    std::uint32_t buf[64];
#if defined(__SSE2__)
    const __m128 px = _mm_set1_ps(p.x()), py = _mm_set1_ps(p.y()), pz = _mm_set1_ps(p.z());
#endif
    for (std::size_t k = 0; k < n;) {
      const std::size_t k1 = std::min(n, k + 64);
      std::size_t m = 0;
#if defined(__SSE2__)
      for (; k < k1; k += 4) {
        const __m128 dx = _mm_sub_ps(px, _mm_loadu_ps(cx + k));
        const __m128 dy = _mm_sub_ps(py, _mm_loadu_ps(cy + k));
        const __m128 dz = _mm_sub_ps(pz, _mm_loadu_ps(cz + k));
        const __m128 d2 = _mm_add_ps(_mm_add_ps(_mm_mul_ps(dx, dx), _mm_mul_ps(dy, dy)), _mm_mul_ps(dz, dz));
        const int in = _mm_movemask_ps(_mm_cmple_ps(d2, _mm_loadu_ps(r2 + k)));
        for (std::size_t l = 0; l < 4; ++l) {  // write every id, keep the hits
          buf[m] = id[k + l];
          m += static_cast<std::size_t>((in >> l) & 1);
        }
      }
#else
      for (; k < k1; ++k) {
        const float dx = p.x() - cx[k], dy = p.y() - cy[k], dz = p.z() - cz[k];
        buf[m] = id[k];
        m += (dx * dx + dy * dy + dz * dz <= r2[k]) ? 1 : 0;
      }
#endif
      for (std::size_t j = 0; j < m; ++j) hit(buf[j]);
    }
  }

  // Calls fn(cell) for each cell a ball may reach, in a block that holds points: those
  // of its bounding box not farther from c than the radius.
  template <typename Fn>
  void for_cells(const Eigen::Vector3f& c, float radius, Fn&& fn) const {
    const Eigen::Vector3i lo = cell_of(c - Eigen::Vector3f::Constant(radius));
    const Eigen::Vector3i hi = cell_of(c + Eigen::Vector3f::Constant(radius));
    if (small_box(lo, hi)) {
      for_cells_small(c, radius, lo, hi, fn);
      return;
    }
    // Cells are skipped against a slightly larger ball: a point's cell comes from
    // rounded products, so it may sit a hair outside the cell's exact bounds.
    const float rc = radius + 1e-4F * cell_;
    const float rc2 = rc * rc;
    const float cx = c.x(), cy = c.y(), cz = c.z();
    const auto gap = [&](int v, float cv) { return slab_gap(v, cv); };
    std::uint64_t last = kEmpty;
    std::uint32_t last_block = kNone;
    for (int z = lo.z(); z <= hi.z(); ++z) {
      const float gz = gap(z, cz);
      const float gz2 = gz * gz;
      if (gz2 > rc2) continue;
      for (int y = lo.y(); y <= hi.y(); ++y) {
        const float gy = gap(y, cy);
        const float gyz2 = gz2 + gy * gy;
        if (gyz2 > rc2) continue;
        for (int x = lo.x(); x <= hi.x(); ++x) {
          const float gx = gap(x, cx);
          if (gyz2 + gx * gx > rc2) continue;  // the cell lies outside the ball
          const std::uint64_t b = block_key(x, y, z);
          if (b != last) {
            last = b;
            last_block = find(b);
          }
          if (last_block != kNone) fn(64 * last_block + local(x, y, z));
        }
      }
    }
  }

  static constexpr int kSmall = 16;  // cells an axis for_cells_small takes
  // Whether the cells [lo, hi] span at most kSmall an axis, their blocks in increasing
  // order (no wrap of the 21-bit keys inside).
  [[nodiscard]] static bool small_box(const Eigen::Vector3i& lo, const Eigen::Vector3i& hi) {
    for (int a = 0; a < 3; ++a)
      if (hi[a] - lo[a] >= kSmall || (wrap(hi[a]) >> 2) < (wrap(lo[a]) >> 2)) return false;
    return true;
  }
  // for_cells over a small box: the same cells in the same order, tested with the same
  // float values, the per-axis gaps squared once per axis instead of once per cell, and
  // each block looked up once (the general loop looks a block up again on every row).
  template <typename Fn>
  void for_cells_small(const Eigen::Vector3f& c, float radius, const Eigen::Vector3i& lo, const Eigen::Vector3i& hi,
                       Fn&& fn) const {
    const float rc = radius + 1e-4F * cell_;
    const float rc2 = rc * rc;
    // Per axis and cell: the gap squared, the block (from the box's first) and the place in it.
    float g2[3][kSmall];
    std::uint32_t blk[3][kSmall], loc[3][kSmall];
    int n[3];
    std::uint32_t first[3];
    for (int a = 0; a < 3; ++a) {
      n[a] = hi[a] - lo[a] + 1;
      first[a] = wrap(lo[a]) >> 2;
      for (int i = 0; i < n[a]; ++i) {
        const int v = lo[a] + i;
        const float g = slab_gap(v, c[a]);
        g2[a][i] = g * g;
        blk[a][i] = (wrap(v) >> 2) - first[a];
        loc[a][i] = wrap(v) & 3;
      }
    }
    // Block numbers by (z, y, x) block offset, looked up when first needed.
    constexpr std::uint32_t kUnknown = kNone - 1;
    const std::uint32_t nbx = blk[0][n[0] - 1] + 1, nby = blk[1][n[1] - 1] + 1, nbz = blk[2][n[2] - 1] + 1;
    std::uint32_t block[125];  // 16 cells an axis span at most 5 blocks
    std::fill(block, block + nbx * nby * nbz, kUnknown);
    for (int z = 0; z < n[2]; ++z) {
      const float gz2 = g2[2][z];
      if (gz2 > rc2) continue;
      for (int y = 0; y < n[1]; ++y) {
        const float gyz2 = gz2 + g2[1][y];
        if (gyz2 > rc2) continue;
        for (int x = 0; x < n[0]; ++x) {
          if (gyz2 + g2[0][x] > rc2) continue;  // the cell lies outside the ball
          std::uint32_t& id = block[(blk[2][z] * nby + blk[1][y]) * nbx + blk[0][x]];
          if (id == kUnknown)
            id = find(static_cast<std::uint64_t>(first[0] + blk[0][x]) |
                      (static_cast<std::uint64_t>(first[1] + blk[1][y]) << 19) |
                      (static_cast<std::uint64_t>(first[2] + blk[2][z]) << 38));
          if (id != kNone) fn(64 * id + (loc[0][x] | loc[1][y] << 2 | loc[2][z] << 4));
        }
      }
    }
  }

  static constexpr std::uint64_t kEmpty = ~0ULL;
  static constexpr std::uint32_t kNone = ~0U;
  static constexpr float kFar = 1e18F;  // padding: (1e18)² is finite and beyond any radius

  // Clamped to +-2^30 (NaN to the upper end) so that the cast, and a query's neighbouring
  // cells, never overflow an int for a point far out; keys wrap at 21 bits anyway, the two
  // border cells reach to infinity (slab_gap) and distances are compared exactly.
  static constexpr int kCellLimit = 1 << 30;
  [[nodiscard]] int cell_coord(float v) const {
    constexpr auto kLimit = static_cast<float>(kCellLimit);
    const float c = std::floor(v * inv_);
    return static_cast<int>(!(c < kLimit) ? kLimit : c <= -kLimit ? -kLimit : c);
  }
  // Distance along one axis from cv to cell v's slab (0 inside); a border cell's slab is
  // unbounded outwards, as it holds every point beyond it.
  [[nodiscard]] float slab_gap(int v, float cv) const {
    const float a = v <= -kCellLimit ? -std::numeric_limits<float>::infinity() : static_cast<float>(v) * cell_;
    const float b = v >= kCellLimit ? std::numeric_limits<float>::infinity() : static_cast<float>(v) * cell_ + cell_;
    return cv < a ? a - cv : (cv > b ? cv - b : 0.0F);
  }
  [[nodiscard]] Eigen::Vector3i cell_of(const Eigen::Vector3f& p) const {
    return {cell_coord(p.x()), cell_coord(p.y()), cell_coord(p.z())};
  }
  // A cell's key is its coordinates, 21 bits each (wrapping): the upper 19 name its
  // block, the lower 2 its place in the block.
  static std::uint32_t wrap(int v) {
    return static_cast<std::uint32_t>((static_cast<std::int64_t>(v) + (1 << 20)) & 0x1FFFFF);
  }
  static std::uint64_t block_key(int x, int y, int z) {
    return static_cast<std::uint64_t>(wrap(x) >> 2) | (static_cast<std::uint64_t>(wrap(y) >> 2) << 19) |
           (static_cast<std::uint64_t>(wrap(z) >> 2) << 38);
  }
  static std::uint32_t local(int x, int y, int z) { return (wrap(x) & 3) | (wrap(y) & 3) << 2 | (wrap(z) & 3) << 4; }
  static std::size_t hash(std::uint64_t k) {
    k ^= k >> 33;
    k *= 0xff51afd7ed558ccdULL;
    k ^= k >> 33;
    return static_cast<std::size_t>(k);
  }
  // Block numbers by key, open addressing, at most half full (grown by doubling).
  std::uint32_t insert(std::uint64_t k) {
    if (2 * (count_ + 1) > keys_.size()) grow();
    std::size_t i = hash(k) & mask_;
    for (; keys_[i] != kEmpty; i = (i + 1) & mask_)
      if (keys_[i] == k) return ids_[i];
    keys_[i] = k;
    ids_[i] = static_cast<std::uint32_t>(count_);
    return static_cast<std::uint32_t>(count_++);
  }
  [[nodiscard]] std::uint32_t find(std::uint64_t k) const {
    for (std::size_t i = hash(k) & mask_;; i = (i + 1) & mask_) {
      if (keys_[i] == k) return ids_[i];
      if (keys_[i] == kEmpty) return kNone;
    }
  }
  void grow() {
    const std::size_t cap = keys_.empty() ? 1024 : 2 * keys_.size();
    std::vector<std::uint64_t> keys(cap, kEmpty);
    std::vector<std::uint32_t> ids(cap);
    const std::size_t mask = cap - 1;
    for (std::size_t j = 0; j < keys_.size(); ++j) {
      if (keys_[j] == kEmpty) continue;
      std::size_t i = hash(keys_[j]) & mask;
      while (keys[i] != kEmpty) i = (i + 1) & mask;
      keys[i] = keys_[j];
      ids[i] = ids_[j];
    }
    keys_.swap(keys);
    ids_.swap(ids);
    mask_ = cap - 1;
  }

  float cell_;
  float inv_;
  std::vector<std::uint64_t> keys_;
  std::vector<std::uint32_t> ids_;
  std::size_t mask_ = 0;
  std::size_t count_ = 0;
};

}  // namespace lex3d::detail
