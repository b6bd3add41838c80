// ScanState::choose_by_fit: word choice by descriptor distance and by how well a word fits
// the points.

#include "model/scan_state.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <numeric>

#include <Eigen/Eigenvalues>
#include <Eigen/SVD>

#include "lex3d/core/parallel.hpp"
#include "model/scan_state_simd.hpp"

namespace lex3d::detail {

namespace {

// v where m is all ones, +0 where it is zero (a select on bits: loops using it vectorise).
inline float mask(float v, std::uint32_t m) {
  std::uint32_t b;
  std::memcpy(&b, &v, sizeof b);
  b &= m;
  std::memcpy(&v, &b, sizeof v);
  return v;
}

// 1 when an entry at (x, y, z) with σ² s2 may be within its σ of the box with centre c and
// half sizes h, else 0. The margin (0.2 % of σ² and 1e-8 m²) exceeds the rounding of the
// box's centre and half sizes, so no entry that could pass the fit test with a point in
// the box gets 0.
inline std::int32_t near_box(float x, float y, float z, float s2, const float* c, const float* h) {
  float ox = std::fabs(x - c[0]) - h[0];
  float oy = std::fabs(y - c[1]) - h[1];
  float oz = std::fabs(z - c[2]) - h[2];
  // max(o, 0) as bits, so that the loops using this vectorise.
  ox = mask(ox, static_cast<std::uint32_t>(-static_cast<std::int32_t>(ox > 0.0F)));
  oy = mask(oy, static_cast<std::uint32_t>(-static_cast<std::int32_t>(oy > 0.0F)));
  oz = mask(oz, static_cast<std::uint32_t>(-static_cast<std::int32_t>(oz > 0.0F)));
  return (ox * ox + oy * oy + oz * oz <= s2 * 1.002F + 1e-8F) ? 1 : 0;
}
inline void box_centre(const float* blo, const float* bhi, float* c, float* h) {
  for (int a = 0; a < 3; ++a) {
    c[a] = 0.5F * (blo[a] + bhi[a]);
    h[a] = 0.5F * (bhi[a] - blo[a]);
  }
}

// keep[k] = near_box of entry k, with σ² s2[k] = r2[k] / 9 (written), and the box
// [blo, bhi]; lo and hi: the least and greatest x of the entries kept, smax their largest
// σ² (all three unset when none is kept), reduced eight lanes at a time (the least and
// greatest of a set do not depend on the order they are taken in).
LEX3D_CLONES void box_keep(const float* lx, const float* ly, const float* lz, const float* r2, std::size_t n,
                           const float* blo, const float* bhi, float* s2, std::int32_t* keep, float& lo, float& hi,
                           float& smax) {
  float c[3], h[3];
  box_centre(blo, bhi, c, h);
  for (std::size_t k = 0; k < n; ++k) {
    s2[k] = r2[k] / 9.0F;
    keep[k] = near_box(lx[k], ly[k], lz[k], s2[k], c, h);
  }
  const float inf = std::numeric_limits<float>::infinity();
  V8f lo8 = splat8(inf), hi8 = splat8(-inf), s8 = hi8;
  std::size_t k = 0;
  for (; k + 8 <= n; k += 8) {
    V8i kept;
    std::memcpy(&kept, keep + k, sizeof kept);
    kept = kept != 0;
    const V8f x = load8(lx + k), s = load8(s2 + k);
    lo8 = (kept & (x < lo8)) != 0 ? x : lo8;
    hi8 = (kept & (x > hi8)) != 0 ? x : hi8;
    s8 = (kept & (s > s8)) != 0 ? s : s8;
  }
  lo = inf;
  hi = smax = -inf;
  for (int l = 0; l < 8; ++l) {
    lo = std::min(lo, lo8[l]);
    hi = std::max(hi, hi8[l]);
    smax = std::max(smax, s8[l]);
  }
  for (; k < n; ++k)
    if (keep[k] != 0) {
      lo = std::min(lo, lx[k]);
      hi = std::max(hi, lx[k]);
      smax = std::max(smax, s2[k]);
    }
}

// How many of the n entries near_box finds near the box [blo, bhi].
LEX3D_CLONES std::size_t box_count(const float* lx, const float* ly, const float* lz, const float* s2, std::size_t n,
                                   const float* blo, const float* bhi) {
  float c[3], h[3];
  box_centre(blo, bhi, c, h);
  std::int32_t count = 0;
  for (std::size_t k = 0; k < n; ++k) count += near_box(lx[k], ly[k], lz[k], s2[k], c, h);
  return static_cast<std::size_t>(count);
}

// The entries of one feature that can be within their σ of a box (the union of the
// candidate words' bounding boxes), bucketed into slabs along x at least as wide as the
// largest σ among them (a counting sort), for the fit test of several words: an entry
// within its σ of a word point lies in the point's slab or one next to it, and those
// three slabs are one contiguous run. Entries left out are farther than σ from every
// point of those words.
struct Slabs {
  std::vector<float> x, y, z, sig2;  // kept entries in slab order, padded to a multiple of 8 (the first `padded`)
  std::vector<std::uint32_t> start;  // slab b holds [start[b], start[b + 1])
  float x0 = 0.0F, inv = 0.0F;
  int count = 0;
  std::size_t size = 0;    // entries kept
  std::size_t padded = 0;  // size rounded up to a multiple of 8

  // r2: (3σ)² of each entry (σ² is taken as (3σ)² / 9).
  void build(const float* lx, const float* ly, const float* lz, const float* r2, std::size_t n, const float* blo,
             const float* bhi) {
    constexpr int kMaxSlabs = 64;
    grow(s2_, n);
    grow(keep_, n);
    float lo = 0.0F, hi = 0.0F, smax = 0.0F;
    box_keep(lx, ly, lz, r2, n, blo, bhi, s2_.data(), keep_.data(), lo, hi, smax);
    const float* const s2 = s2_.data();
    grow(kept_, n);
    std::size_t m = 0;
    for (std::size_t k = 0; k < n; ++k) {
      kept_[m] = static_cast<std::uint32_t>(k);
      m += static_cast<std::size_t>(keep_[k]);
    }
    size = m;
    const std::size_t npad = (size + 7) / 8 * 8;
    // Padded with entries nothing reaches (tests run in blocks of 8). The arrays only
    // grow: the first `size` are all written below, the padding here.
    padded = npad;
    grow(x, npad);
    grow(y, npad);
    grow(z, npad);
    grow(sig2, npad);
    for (std::size_t i = size; i < npad; ++i) {
      x[i] = y[i] = z[i] = 1e9F;
      sig2[i] = -1.0F;
    }
    if (size == 0) {
      count = 0;
      start.assign(1, 0);
      return;
    }
    // 0.1 % wider than the largest σ: floors of the scaled coordinates of an entry and a
    // word point within σ of it then differ by at most one despite rounding.
    float width = std::sqrt(smax) * 1.001F + 1e-6F;
    if ((hi - lo) / width > static_cast<float>(kMaxSlabs - 1)) width = (hi - lo) / static_cast<float>(kMaxSlabs - 1);
    x0 = lo;
    inv = 1.0F / width;
    count = std::min(kMaxSlabs, static_cast<int>((hi - lo) * inv) + 1);
    start.assign(static_cast<std::size_t>(count) + 1, 0);
    grow(slab_, size);
    for (std::size_t i = 0; i < size; ++i) {
      const int b = std::min(count - 1, std::max(0, static_cast<int>((lx[kept_[i]] - x0) * inv)));
      slab_[i] = static_cast<std::uint32_t>(b);
      ++start[static_cast<std::size_t>(b) + 1];
    }
    for (int b = 0; b < count; ++b) start[static_cast<std::size_t>(b) + 1] += start[static_cast<std::size_t>(b)];
    cursor_.assign(start.begin(), start.end() - 1);
    for (std::size_t i = 0; i < size; ++i) {
      const std::uint32_t k = kept_[i];
      const std::uint32_t at = cursor_[slab_[i]]++;
      x[at] = lx[k];
      y[at] = ly[k];
      z[at] = lz[k];
      sig2[at] = s2[k];
    }
  }
  // The run of entries that can be within σ of a point at x = px is [run_lo, run_hi):
  // the point's slab and the ones either side, clamped to the slabs there are (empty for
  // a point two slabs or more outside them; a NaN gives every entry). Both ends only grow
  // with px, so for x-sorted points a..d, [run_lo(a), run_hi(d)) holds all their runs.
  std::uint32_t run_lo(float px) const { return start[static_cast<std::size_t>(std::max(slab(px, -2) - 1, 0))]; }
  std::uint32_t run_hi(float px) const {
    return start[static_cast<std::size_t>(std::min(slab(px, count + 1) + 2, count))];
  }

 private:
  // floor((px - x0) / width), clamped to [-2, count + 1] (as far out as makes a
  // difference to the runs); `nan` for a NaN.
  int slab(float px, int nan) const {
    const float g = (px - x0) * inv;
    if (g > -2.0F && g < static_cast<float>(count) + 1.0F) return static_cast<int>(std::floor(g));
    if (g <= -2.0F) return -2;
    return g >= static_cast<float>(count) + 1.0F ? count + 1 : nan;
  }

  std::vector<std::uint32_t> kept_, slab_, cursor_;
  std::vector<std::int32_t> keep_;
  std::vector<float> s2_;
};

// Word choice by fit with slabs: the counts of fit_counts (entries with a word point
// within their σ, and the word points with no entry within σ). Each word point needs
// testing only against its three slabs, widened to whole blocks of 8 entries; the points
// go by in fours (the word's points sorted by x, so their runs mostly overlap), each four
// testing the run holding all their runs (Slabs::run_lo, run_hi): the entry loads, the
// update of the hits and the loop with its hard-to-predict exit are shared by the four.
// Every pair tested is compared as in fit_counts, and an entry outside a point's own run
// is farther than σ from it along x, so testing it as well changes no count. The np
// points are read padded to a multiple of 4 with far points (PackedWord::xp), which hit
// nothing and are not counted.
// Gives up (returns false, the counts unset) once `max_lonely` word points have no entry
// within σ (the count only grows, so that is the same as its final value reaching it).
LEX3D_CLONES bool fit_counts_slabs(const Slabs& s, const float* wx, const float* wy, const float* wz, std::size_t np,
                                   std::size_t max_lonely, std::int32_t* hit, std::size_t& explained,
                                   std::size_t& unsupported) {
  const std::size_t npad = s.padded;
  const float* lx = s.x.data();
  const float* ly = s.y.data();
  const float* lz = s.z.data();
  const float* sig2 = s.sig2.data();
  for (std::size_t k = 0; k < npad; ++k) hit[k] = 0;
  std::size_t lonely = 0;
  for (std::size_t p = 0; p < np; p += 4) {
    const std::size_t real = std::min<std::size_t>(4, np - p);  // the rest are padding
    const std::uint32_t lo = s.run_lo(wx[p]), hi = s.run_hi(wx[p + real - 1]);
    const V8f ax = splat8(wx[p]), ay = splat8(wy[p]), az = splat8(wz[p]);
    const V8f bx = splat8(wx[p + 1]), by = splat8(wy[p + 1]), bz = splat8(wz[p + 1]);
    const V8f cx = splat8(wx[p + 2]), cy = splat8(wy[p + 2]), cz = splat8(wz[p + 2]);
    const V8f dx = splat8(wx[p + 3]), dy = splat8(wy[p + 3]), dz = splat8(wz[p + 3]);
    V8i anya = {0, 0, 0, 0, 0, 0, 0, 0}, anyb = anya, anyc = anya, anyd = anya;
    for (std::size_t k = lo & ~7U; k < hi; k += 8) {
      const V8f ex = load8(lx + k), ey = load8(ly + k), ez = load8(lz + k), es = load8(sig2 + k);
      const V8f a0 = ax - ex, a1 = ay - ey, a2 = az - ez;
      const V8f b0 = bx - ex, b1 = by - ey, b2 = bz - ez;
      const V8f c0 = cx - ex, c1 = cy - ey, c2 = cz - ez;
      const V8f d0 = dx - ex, d1 = dy - ey, d2 = dz - ez;
      // The masks as they come (all ones or zero): hit[k] is nonzero when entry k is hit.
      const V8i ma = a0 * a0 + a1 * a1 + a2 * a2 <= es;
      const V8i mb = b0 * b0 + b1 * b1 + b2 * b2 <= es;
      const V8i mc = c0 * c0 + c1 * c1 + c2 * c2 <= es;
      const V8i md = d0 * d0 + d1 * d1 + d2 * d2 <= es;
      V8i h;
      std::memcpy(&h, hit + k, sizeof h);
      h |= (ma | mb) | (mc | md);
      std::memcpy(hit + k, &h, sizeof h);
      anya |= ma;
      anyb |= mb;
      anyc |= mc;
      anyd |= md;
    }
    lonely += (any8(anya) ? 0 : 1) + (any8(anyb) ? 0 : 1) + (any8(anyc) ? 0 : 1) + (any8(anyd) ? 0 : 1) - (4 - real);
    if (lonely >= max_lonely) return false;
  }
  std::size_t e = 0;
  for (std::size_t k = 0; k < s.size; ++k) e += hit[k] != 0 ? 1 : 0;
  explained = e;
  unsupported = lonely;
  return true;
}

}  // namespace

namespace {

// descriptor_distances_sq of q to every word, eight words at a time: the descriptors
// are stored transposed (value i of words w..w+7 side by side, nw8 words a row, the extra
// ones zero), a lane per word. Each lane does what descriptor_distances_sq does for its
// word, in the same order (value i into running sum i % 8, the values past the last
// block of 8 after the blocks, the eight sums added pairwise), so the distances have
// the same bits; there is no horizontal sum and no chain of dependent adds to wait on.
LEX3D_CLONES void distances_to_words(const float* q, const float* rows_t, std::size_t nw8, int dim, float* out) {
  const int blocks = dim / 8;
  for (std::size_t w = 0; w < nw8; w += 8) {
    V8f acc[8];
    for (int l = 0; l < 8; ++l) acc[l] = splat8(0.0F);
    for (int k = 0; k < blocks; ++k)
      for (int l = 0; l < 8; ++l) {
        const int i = 8 * k + l;
        const V8f d = splat8(q[i]) - load8(rows_t + static_cast<std::size_t>(i) * nw8 + w);
        acc[l] += d * d;
      }
    for (int l = 0; l < 8; ++l) {  // fixed indices keep acc in registers
      const int i = 8 * blocks + l;
      if (i >= dim) break;
      const V8f d = splat8(q[i]) - load8(rows_t + static_cast<std::size_t>(i) * nw8 + w);
      acc[l] += d * d;
    }
    const V8f sum = ((acc[0] + acc[1]) + (acc[2] + acc[3])) + ((acc[4] + acc[5]) + (acc[6] + acc[7]));
    std::memcpy(out + w, &sum, sizeof sum);
  }
}

// Word choice by fit for one feature: among the kk words `near` (nearest descriptor
// first), the one that best fits the feature's n entries (lx, ly, lz; r2: (3σ)² of each),
// as ScanState::choose_by_fit describes. Compiled for AVX2 too, with the slab loops.
LEX3D_CLONES std::uint32_t best_fit(const std::pair<float, std::uint32_t>* near, std::size_t kk,
                                    const std::vector<PackedWord>& packed, const float* lx, const float* ly,
                                    const float* lz, const float* r2, std::size_t n) {
  thread_local std::vector<std::int32_t> hits;
  thread_local Slabs slabs;
  float lo[3], hi[3];
  for (int a = 0; a < 3; ++a) {
    lo[a] = packed[near[0].second].lo[a];
    hi[a] = packed[near[0].second].hi[a];
    for (std::size_t c = 1; c < kk; ++c) {
      lo[a] = std::min(lo[a], packed[near[c].second].lo[a]);
      hi[a] = std::max(hi[a], packed[near[c].second].hi[a]);
    }
  }
  slabs.build(lx, ly, lz, r2, n, lo, hi);
  grow(hits, slabs.padded);
  if (slabs.size == 0) {  // nothing explained: the first word with the fewest points
    std::size_t pick = 0;
    for (std::size_t c = 1; c < kk; ++c)
      if (packed[near[c].second].size() < packed[near[pick].second].size()) pick = c;
    return near[pick].second;
  }
  // The word with the highest score (explained - unsupported), the first in the list
  // on ties. A word explains at most the entries near its bounding box (`most`), so
  // the words are tried by decreasing `most`, and one is passed over, or given up
  // once enough of its points are found unsupported, when it can no longer win.
  thread_local std::vector<std::pair<std::int64_t, std::uint32_t>> order;  // (-most, position)
  order.clear();
  for (std::size_t c = 0; c < kk; ++c) {
    const PackedWord& w = packed[near[c].second];
    const float wlo[3] = {w.lo.x(), w.lo.y(), w.lo.z()}, whi[3] = {w.hi.x(), w.hi.y(), w.hi.z()};
    const std::size_t most =
        box_count(slabs.x.data(), slabs.y.data(), slabs.z.data(), slabs.sig2.data(), slabs.padded, wlo, whi);
    order.emplace_back(-static_cast<std::int64_t>(most), static_cast<std::uint32_t>(c));
  }
  std::sort(order.begin(), order.end());
  std::int64_t best = 0;
  std::size_t best_c = kk;  // none yet
  for (const auto& [minus_most, c] : order) {
    const PackedWord& w = packed[near[c].second];
    // It must reach best, or best + 1 when it comes after the best word in the list.
    std::size_t max_lonely = std::numeric_limits<std::size_t>::max();
    if (best_c < kk) {
      const std::int64_t slack = -minus_most - best - (c > best_c ? 1 : 0);
      if (slack < 0) continue;
      max_lonely = static_cast<std::size_t>(slack) + 1;
    }
    std::size_t explained = 0, unsupported = 0;
    if (!fit_counts_slabs(slabs, w.xp.data(), w.yp.data(), w.zp.data(), w.size(), max_lonely, hits.data(), explained,
                          unsupported))
      continue;
    const std::int64_t score = static_cast<std::int64_t>(explained) - static_cast<std::int64_t>(unsupported);
    if (best_c == kk || score > best || (score == best && c < best_c)) {
      best = score;
      best_c = c;
    }
  }
  return near[best_c].second;
}

}  // namespace

std::size_t ScanState::choose_by_fit(const Alphabet& alphabet, int k, int threads, bool all_features) {
  if (alphabet.size() == 0) return 0;
  if (!all_features && (k <= 1 || alphabet.size() < 2)) return 0;
  const int dim = alphabet.descriptor_dim;
  const std::size_t nw = alphabet.size();
  // The words' points sorted by x (the fit counts do not depend on the order of the
  // points; fit_counts_slabs takes them four by four, and neighbours in x share most of
  // their slabs).
  std::vector<PackedWord> packed;
  packed.reserve(nw);
  for (const auto& w : alphabet.words) {
    Word sorted = w;
    std::stable_sort(sorted.points.begin(), sorted.points.end(),
                     [](const Eigen::Vector3f& a, const Eigen::Vector3f& b) { return a.x() < b.x(); });
    packed.emplace_back(sorted);
  }
  // The words' descriptors transposed (distances_to_words).
  const std::size_t nw8 = (nw + 7) / 8 * 8;
  std::vector<float> descriptors_t(nw8 * static_cast<std::size_t>(dim), 0.0F);
  for (std::size_t w = 0; w < nw; ++w)
    for (int i = 0; i < dim; ++i)
      descriptors_t[static_cast<std::size_t>(i) * nw8 + w] = alphabet.words[w].descriptor[static_cast<std::size_t>(i)];
  std::vector<std::size_t> active;
  for (std::size_t f = 0; f < word_.size(); ++f)
    if (all_features || word_[f] >= 0) active.push_back(f);
  std::vector<std::int32_t> choice(active.size(), -1);
  const auto kk = std::min<std::size_t>(static_cast<std::size_t>(std::max(k, 1)), nw);
  parallel_for(active.size(), threads, [&](std::size_t i) {
    const std::size_t f = active[i];
    thread_local std::vector<float> dist;
    thread_local std::vector<std::pair<float, std::uint32_t>> near;
    // The kk nearest words by descriptor (ties: lower id), in order: words come by
    // increasing id, so one enters the list when strictly nearer than its last.
    dist.resize(nw8);
    distances_to_words(scan_.features.descriptor(f), descriptors_t.data(), nw8, dim, dist.data());
    near.clear();
    for (std::size_t w = 0; w < nw; ++w) {
      const float d = dist[w];
      if (near.size() == kk) {
        if (!(d < near.back().first)) continue;
        near.pop_back();
      }
      auto at = near.end();
      while (at != near.begin() && d < (at - 1)->first) --at;
      near.insert(at, {d, static_cast<std::uint32_t>(w)});
    }
    if (kk == 1) {
      choice[i] = static_cast<std::int32_t>(near[0].second);
      return;
    }
    const std::size_t b = begin_of(f), e = end_of(f);
    choice[i] = static_cast<std::int32_t>(best_fit(near.data(), kk, packed, lx_.data() + b, ly_.data() + b,
                                                   lz_.data() + b, reach2_e_.data() + b, e - b));
  }, 8);
  std::size_t changed = 0;
  for (std::size_t i = 0; i < active.size(); ++i) {
    const std::size_t f = active[i];
    if (choice[i] < 0 || choice[i] == word_[f]) continue;
    word_[f] = choice[i];
    word_points_[f] = static_cast<std::uint32_t>(alphabet.words[static_cast<std::size_t>(choice[i])].points.size());
    ++changed;
  }
  if (changed > 0) stale_ = true;
  return changed;
}


}  // namespace lex3d::detail
