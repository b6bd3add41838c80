#pragma once
// A static voxel grid over a point set for radius queries. Points are bucketed by cell
// in two linear passes (a counting sort, points of a cell in index order) and stored
// with their coordinates in cell order (x, y and z apart, each cell padded to a multiple
// of 8 with far points), so a query reads each cell it visits contiguously and tests its
// points eight at a time. The cells live in a compact open-addressing table (key and
// range in one 16-byte slot, sized by the number of cells, not of points). A query
// visits only the cells its ball touches and merges the cells' hits (each run in index
// order) into one sorted list. For the neighbourhoods of thousands of features this
// beats a kd-tree, because radii are a few cells at most.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

namespace lex3d::detail {

#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && !defined(__SANITIZE_ADDRESS__)
#define LEX3D_GRID_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define LEX3D_GRID_CLONES
#endif

// Writes to `out` the indices of the points of [0, n) (n a multiple of 8) within r2 of
// c, in order; returns how many. The test is that of a scalar loop, (dx² + dy²) + dz²
// <= r², done eight points at a time (no fused multiply-adds: the same bits).
LEX3D_GRID_CLONES static inline std::size_t grid_block_hits(const float* xs, const float* ys, const float* zs,
                                                              const std::uint32_t* idx, std::size_t n, float cx,
                                                              float cy, float cz, float r2, std::uint32_t* out) {
  std::size_t m = 0;
  for (std::size_t k = 0; k < n; k += 8) {
    std::int32_t in[8];
    for (std::size_t l = 0; l < 8; ++l) {
      const float dx = xs[k + l] - cx, dy = ys[k + l] - cy, dz = zs[k + l] - cz;
      in[l] = (dx * dx + dy * dy + dz * dz <= r2) ? 1 : 0;
    }
    for (std::size_t l = 0; l < 8; ++l) {  // branch-free: write every index, keep the hits
      out[m] = idx[k + l];
      m += static_cast<std::size_t>(in[l]);
    }
  }
  return m;
}

class PointGrid {
 public:
  PointGrid(const std::vector<Eigen::Vector3f>& points, float cell) : cell_(cell), inv_(1.0F / cell) {
    const std::size_t n = points.size();
    // Pass 1: the cell of every point and the size of every cell, in a table sized for
    // the worst case (one cell per point); the query table below is sized by the cells.
    std::size_t cap = 16;
    while (cap < 2 * n) cap <<= 1;
    std::vector<Slot> build(cap, Slot{kEmpty, 0, 0});
    const std::size_t build_mask = cap - 1;
    std::vector<std::uint32_t> slot_of(n);
    std::vector<std::uint32_t> first;  // build slots in the order their cells were first met
    for (std::size_t i = 0; i < n; ++i) {
      const std::uint64_t k = key(cell_of(points[i]));
      std::size_t s = hash(k) & build_mask;
      while (build[s].key != k && build[s].key != kEmpty) s = (s + 1) & build_mask;
      if (build[s].key == kEmpty) {
        build[s].key = k;
        first.push_back(static_cast<std::uint32_t>(s));
      }
      slot_of[i] = static_cast<std::uint32_t>(s);
      ++build[s].end;
    }
    // Cells in the order they were first met; each gets a contiguous range (begin, and
    // end as the fill cursor).
    // (Ranges padded to a multiple of 8 with far points, for tests eight at a time.)
    std::uint32_t at = 0;
    for (const std::uint32_t s : first) {
      const std::uint32_t count = build[s].end;
      build[s].begin = at;
      build[s].end = at;
      at += (count + 7U) & ~7U;
    }
    // Pass 2: scatter, in index order within each cell; the padding stays far away.
    xs_.assign(at, kFar);
    ys_.assign(at, kFar);
    zs_.assign(at, kFar);
    idx_.assign(at, 0);
    for (std::size_t i = 0; i < n; ++i) {
      const std::uint32_t k = build[slot_of[i]].end++;
      xs_[k] = points[i].x();
      ys_[k] = points[i].y();
      zs_[k] = points[i].z();
      idx_[k] = static_cast<std::uint32_t>(i);
    }
    for (const std::uint32_t s : first) build[s].end = (build[s].end + 7U) & ~7U;
    // The query table: at most a quarter full.
    std::size_t qcap = 16;
    while (qcap < 4 * first.size()) qcap <<= 1;
    slots_.assign(qcap, Slot{kEmpty, 0, 0});
    mask_ = qcap - 1;
    for (const std::uint32_t s : first) {
      std::size_t i = hash(build[s].key) & mask_;
      while (slots_[i].key != kEmpty) i = (i + 1) & mask_;
      slots_[i] = build[s];
    }
  }

  /// Appends to `out` the indices of the points within `radius` of `c`, sorted ascending.
  void radius(const Eigen::Vector3f& c, float radius, std::vector<std::uint32_t>& out) const {
    const std::size_t base = out.size();
    const Eigen::Vector3i lo = cell_of(c - Eigen::Vector3f::Constant(radius));
    const Eigen::Vector3i hi = cell_of(c + Eigen::Vector3f::Constant(radius));
    const float r2 = radius * radius;
    // Cells are skipped against a slightly larger ball: a point's cell comes from
    // rounded products, so it may sit a hair outside the cell's exact bounds.
    const float rc = radius + 1e-4F * cell_;
    const float rc2 = rc * rc;
    const float cx = c.x(), cy = c.y(), cz = c.z();
    // Each cell's hits come in index order: the query ends by merging these runs.
    thread_local std::vector<std::size_t> runs;
    runs.assign(1, base);
    // Distance along one axis from c to cell v's slab (0 inside).
    const auto gap = [&](int v, float cv) {
      const float a = static_cast<float>(v) * cell_;
      const float b = a + cell_;
      return cv < a ? a - cv : (cv > b ? cv - b : 0.0F);
    };
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
          const Slot* s = find(key({x, y, z}));
          if (s == nullptr) continue;
          // Room for the whole cell, then keep the hits.
          std::size_t n = out.size();
          out.resize(n + (s->end - s->begin));
          n += grid_block_hits(xs_.data() + s->begin, ys_.data() + s->begin, zs_.data() + s->begin,
                               idx_.data() + s->begin, s->end - s->begin, cx, cy, cz, r2, out.data() + n);
          out.resize(n);
          if (n > runs.back()) runs.push_back(n);
        }
      }
    }
    merge_runs(out, runs);
  }

 private:
  // Sorts out[runs.front(), runs.back()), made of the sorted runs [runs[i], runs[i + 1]),
  // by merging pairs of runs (branch-free) until one is left. Indices are distinct.
  static void merge_runs(std::vector<std::uint32_t>& out, std::vector<std::size_t>& runs) {
    if (runs.size() <= 2) return;
    const std::size_t base = runs.front();
    const std::size_t n = runs.back() - base;
    thread_local std::vector<std::uint32_t> scratch;
    scratch.resize(n);
    std::uint32_t* src = out.data() + base;
    std::uint32_t* dst = scratch.data();
    for (std::size_t& r : runs) r -= base;
    while (runs.size() > 2) {
      std::size_t w = 0;  // runs written so far (their ends overwrite runs[1..])
      std::size_t i = 0;
      for (; i + 2 < runs.size(); i += 2) {
        const std::uint32_t* a = src + runs[i];
        const std::uint32_t* a_end = src + runs[i + 1];
        const std::uint32_t* b = a_end;
        const std::uint32_t* b_end = src + runs[i + 2];
        std::uint32_t* d = dst + runs[i];
        while (a < a_end && b < b_end) {
          const bool take_b = *b < *a;
          *d++ = take_b ? *b : *a;
          b += take_b ? 1 : 0;
          a += take_b ? 0 : 1;
        }
        d = std::copy(a, a_end, d);
        std::copy(b, b_end, d);
        runs[++w] = runs[i + 2];
      }
      if (i + 1 < runs.size()) {  // an odd run left: copied as it is
        std::copy(src + runs[i], src + runs[i + 1], dst + runs[i]);
        runs[++w] = runs[i + 1];
      }
      runs.resize(w + 1);
      std::swap(src, dst);
    }
    if (src != out.data() + base) std::copy(src, src + n, out.data() + base);
  }

  struct Slot {
    std::uint64_t key;
    std::uint32_t begin, end;  // the cell's range in xs_/ys_/zs_/idx_ (padding included)
  };
  static constexpr std::uint64_t kEmpty = ~0ULL;
  static constexpr float kFar = 1e18F;  // padding: (1e18)² is finite and beyond any radius

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
  [[nodiscard]] const Slot* find(std::uint64_t k) const {
    for (std::size_t i = hash(k) & mask_;; i = (i + 1) & mask_) {
      if (slots_[i].key == k) return &slots_[i];
      if (slots_[i].key == kEmpty) return nullptr;
    }
  }

  float cell_;
  float inv_;
  std::size_t mask_ = 0;
  std::vector<Slot> slots_;
  std::vector<float> xs_, ys_, zs_;  // points in cell order (each cell padded to a multiple of 8)
  std::vector<std::uint32_t> idx_;   // their indices
};

}  // namespace lex3d::detail
