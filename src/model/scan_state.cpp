#include "model/scan_state.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <numeric>

#include <Eigen/SVD>

#include "lex3d/core/parallel.hpp"

namespace lex3d::detail {

PackedWord::PackedWord(const Word& word) {
  const std::size_t n = word.points.size();
  x.resize(n);
  y.resize(n);
  z.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    x[i] = word.points[i].x();
    y[i] = word.points[i].y();
    z[i] = word.points[i].z();
  }
  // Padding: far points that no loop counts (padded() of them are read).
  const std::size_t npad = (n + 7) / 8 * 8;
  xp.assign(npad, 1e9F);
  yp.assign(npad, 1e9F);
  zp.assign(npad, 1e9F);
  std::copy(x.begin(), x.end(), xp.begin());
  std::copy(y.begin(), y.end(), yp.begin());
  std::copy(z.begin(), z.end(), zp.begin());
  if (n > 0) {
    lo = hi = word.points.front();
    for (const auto& p : word.points) {
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
    }
  }
}

namespace {

std::vector<PackedWord> pack(const Alphabet& alphabet) {
  std::vector<PackedWord> out;
  out.reserve(alphabet.size());
  for (const auto& w : alphabet.words) out.emplace_back(w);
  return out;
}

// The hot loops below are compiled twice, for AVX2 and the baseline, and picked at load
// time; neither uses fused multiply-adds, so both give the same bits.
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && !defined(__SANITIZE_ADDRESS__)
#define LEX3D_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define LEX3D_CLONES
#endif

// e^x for x in [-87, 0] (Cody-Waite reduction, the Cephes polynomial; relative error
// about 2e-7), branch-free so that the loops calling it vectorise (the caller keeps x
// in range: a clamp here would be a branch to the compiler).
inline float exp_neg(float x) {
  const float kRound = 12582912.0F;  // 1.5 · 2^23: adding and subtracting it rounds to an integer
  const float n = (x * 1.44269504088896341F + kRound) - kRound;
  const float r = (x - n * 0.693359375F) - n * -2.12194440e-4F;
  float y = 1.9875691500E-4F;
  y = y * r + 1.3981999507E-3F;
  y = y * r + 8.3334519073E-3F;
  y = y * r + 4.1665795894E-2F;
  y = y * r + 1.6666665459E-1F;
  y = y * r + 5.0000001201E-1F;
  y = y * (r * r) + r + 1.0F;
  const std::uint32_t bits = (static_cast<std::uint32_t>(static_cast<std::int32_t>(n)) + 127U) << 23;
  float scale;
  std::memcpy(&scale, &bits, sizeof scale);
  return y * scale;
}

inline float mask(float v, std::uint32_t m) {
  std::uint32_t b;
  std::memcpy(&b, &v, sizeof b);
  b &= m;
  std::memcpy(&v, &b, sizeof v);
  return v;
}

// Σ_p exp(-d²·a) over the word points within reach of each entry (0 when none), for
// the n entries of a feature. Word arrays are padded to a multiple of 8 with far
// points; the sum keeps eight lanes (point p in lane p % 8), added pairwise, so the
// SSE and AVX2 builds give the same bits.
LEX3D_CLONES void gaussian_sums(const float* lx, const float* ly, const float* lz, const float* reach2,
                                const float* a, std::size_t n, const float* wx, const float* wy, const float* wz,
                                std::size_t npad, const float* lo, const float* hi, float* out) {
  for (std::size_t k = 0; k < n; ++k) {
    const float qx = lx[k], qy = ly[k], qz = lz[k];
    const float r2 = reach2[k];
    out[k] = 0.0F;
    // A point farther than 3σ from the word's bounding box gets nothing.
    const float ox = std::max(std::max(lo[0] - qx, qx - hi[0]), 0.0F);
    const float oy = std::max(std::max(lo[1] - qy, qy - hi[1]), 0.0F);
    const float oz = std::max(std::max(lo[2] - qz, qz - hi[2]), 0.0F);
    if (ox * ox + oy * oy + oz * oz > r2) continue;
    const float ak = a[k];
    float acc[8] = {0.0F, 0.0F, 0.0F, 0.0F, 0.0F, 0.0F, 0.0F, 0.0F};
    for (std::size_t p = 0; p < npad; p += 8)
      for (std::size_t l = 0; l < 8; ++l) {
        const float dx = wx[p + l] - qx, dy = wy[p + l] - qy, dz = wz[p + l] - qz;
        const float d2 = dx * dx + dy * dy + dz * dz;
        // Points beyond reach: d² and the result masked to 0 (as bits, no branch).
        const std::uint32_t m = static_cast<std::uint32_t>(-static_cast<std::int32_t>(d2 <= r2));
        acc[l] += mask(exp_neg(-mask(d2, m) * ak), m);
      }
    out[k] = ((acc[0] + acc[1]) + (acc[2] + acc[3])) + ((acc[4] + acc[5]) + (acc[6] + acc[7]));
  }
}

// For each of the npad word points (mx, my, mz), the first target strictly nearest
// within reach (match -1 when none). Targets in the outer loop, word points inner, with
// selects done on bits: the inner loop vectorises.
LEX3D_CLONES void nearest_targets(const float* tx, const float* ty, const float* tz, std::size_t nt, const float* mx,
                                  const float* my, const float* mz, std::size_t npad, float reach2, float* best,
                                  std::int32_t* match) {
  for (std::size_t p = 0; p < npad; ++p) {
    best[p] = reach2;
    match[p] = -1;
  }
  for (std::size_t t = 0; t < nt; ++t) {
    const float x = tx[t], y = ty[t], z = tz[t];
    const auto ti = static_cast<std::int32_t>(t);
    for (std::size_t p = 0; p < npad; ++p) {
      const float dx = x - mx[p], dy = y - my[p], dz = z - mz[p];
      const float d2 = dx * dx + dy * dy + dz * dz;
      const std::int32_t m = -static_cast<std::int32_t>(d2 < best[p]);
      std::int32_t bb, db;
      std::memcpy(&bb, &best[p], sizeof bb);
      std::memcpy(&db, &d2, sizeof db);
      bb = (bb & ~m) | (db & m);
      std::memcpy(&best[p], &bb, sizeof bb);
      match[p] = (match[p] & ~m) | (ti & m);
    }
  }
}

// Word choice by fit: sets sup[p] when word point p is within σ of some entry and
// returns how many entries have a word point within σ (sig2: σ² of each entry). Word
// points outside, entries inside, so the inner loop runs over many entries and vectorises.
LEX3D_CLONES std::size_t fit_counts(const float* lx, const float* ly, const float* lz, const float* sig2, std::size_t n,
                                    const float* wx, const float* wy, const float* wz, std::size_t np,
                                    std::int32_t* hit, std::int32_t* sup) {
  for (std::size_t k = 0; k < n; ++k) hit[k] = 0;
  for (std::size_t p = 0; p < np; ++p) {
    const float px = wx[p], py = wy[p], pz = wz[p];
    std::int32_t any = 0;
    for (std::size_t k = 0; k < n; ++k) {
      const float dx = px - lx[k], dy = py - ly[k], dz = pz - lz[k];
      const std::int32_t m = (dx * dx + dy * dy + dz * dz <= sig2[k]) ? 1 : 0;
      hit[k] |= m;
      any |= m;
    }
    sup[p] = any;
  }
  std::size_t explained = 0;
  for (std::size_t k = 0; k < n; ++k) explained += static_cast<std::size_t>(hit[k]);
  return explained;
}

// Squared descriptor distances from q to each of `count` descriptors stored one after
// another: the arithmetic of descriptor_distance_sq (eight running sums, element i in
// sum i % 8, added pairwise), so the same bits, with one dispatch for all words.
LEX3D_CLONES void descriptor_distances(const float* q, const float* words, std::size_t count, int dim, float* out) {
  const int blocks = dim / 8;
  for (std::size_t w = 0; w < count; ++w) {
    const float* b = words + w * static_cast<std::size_t>(dim);
    float acc[8] = {0.0F, 0.0F, 0.0F, 0.0F, 0.0F, 0.0F, 0.0F, 0.0F};
    for (int k = 0; k < blocks; ++k)
      for (int l = 0; l < 8; ++l) {
        const float d = q[8 * k + l] - b[8 * k + l];
        acc[l] += d * d;
      }
    for (int i = 8 * blocks; i < dim; ++i) {
      const float d = q[i] - b[i];
      acc[i - 8 * blocks] += d * d;
    }
    out[w] = ((acc[0] + acc[1]) + (acc[2] + acc[3])) + ((acc[4] + acc[5]) + (acc[6] + acc[7]));
  }
}

// keep[k] = 1 when entry k may be within its σ of the box [blo, bhi], else 0. The margin
// (0.2 % of σ² and 1e-8 m²) exceeds the rounding of the box's centre and half sizes, so
// no entry that could pass the fit test is dropped.
LEX3D_CLONES void box_keep(const float* lx, const float* ly, const float* lz, const float* s2, std::size_t n,
                           const float* blo, const float* bhi, std::int32_t* keep) {
  const float cx = 0.5F * (blo[0] + bhi[0]), cy = 0.5F * (blo[1] + bhi[1]), cz = 0.5F * (blo[2] + bhi[2]);
  const float hx = 0.5F * (bhi[0] - blo[0]), hy = 0.5F * (bhi[1] - blo[1]), hz = 0.5F * (bhi[2] - blo[2]);
  for (std::size_t k = 0; k < n; ++k) {
    float ox = std::fabs(lx[k] - cx) - hx;
    float oy = std::fabs(ly[k] - cy) - hy;
    float oz = std::fabs(lz[k] - cz) - hz;
    // max(o, 0) as bits, so that the loop vectorises.
    ox = mask(ox, static_cast<std::uint32_t>(-static_cast<std::int32_t>(ox > 0.0F)));
    oy = mask(oy, static_cast<std::uint32_t>(-static_cast<std::int32_t>(oy > 0.0F)));
    oz = mask(oz, static_cast<std::uint32_t>(-static_cast<std::int32_t>(oz > 0.0F)));
    keep[k] = (ox * ox + oy * oy + oz * oz <= s2[k] * 1.002F + 1e-8F) ? 1 : 0;
  }
}

// The entries of one feature that can be within their σ of a box (the union of the
// candidate words' bounding boxes), bucketed into slabs along x at least as wide as the
// largest σ among them (a counting sort), for the fit test of several words: an entry
// within its σ of a word point lies in the point's slab or one next to it, and those
// three slabs are one contiguous run. Entries left out are farther than σ from every
// point of those words.
struct Slabs {
  std::vector<float> x, y, z, sig2;  // kept entries in slab order, padded to a multiple of 8
  std::vector<std::uint32_t> start;  // slab b holds [start[b], start[b + 1])
  float x0 = 0.0F, inv = 0.0F;
  int count = 0;
  std::size_t size = 0;  // entries kept

  void build(const float* lx, const float* ly, const float* lz, const float* s2, std::size_t n, const float* blo,
             const float* bhi) {
    constexpr int kMaxSlabs = 64;
    keep_.resize(n);
    box_keep(lx, ly, lz, s2, n, blo, bhi, keep_.data());
    kept_.resize(n);
    std::size_t m = 0;
    for (std::size_t k = 0; k < n; ++k) {
      kept_[m] = static_cast<std::uint32_t>(k);
      m += static_cast<std::size_t>(keep_[k]);
    }
    kept_.resize(m);
    float lo = 0.0F, hi = 0.0F, smax = 0.0F;
    if (m > 0) {
      lo = hi = lx[kept_[0]];
      smax = s2[kept_[0]];
    }
    for (std::size_t i = 1; i < m; ++i) {
      const float v = lx[kept_[i]];
      lo = std::min(lo, v);
      hi = std::max(hi, v);
      smax = std::max(smax, s2[kept_[i]]);
    }
    size = kept_.size();
    const std::size_t npad = (size + 7) / 8 * 8;
    // Padded with entries nothing reaches (tests run in blocks of 8).
    x.assign(npad, 1e9F);
    y.assign(npad, 1e9F);
    z.assign(npad, 1e9F);
    sig2.assign(npad, -1.0F);
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
    slab_.resize(size);
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
  // The run of entries that can be within σ of a point at x = px ([lo, hi), maybe empty).
  void window(float px, std::uint32_t& lo, std::uint32_t& hi) const {
    const float g = (px - x0) * inv;
    if (!(g > -2.0F && g < static_cast<float>(count) + 1.0F)) {
      lo = hi = 0;
      return;
    }
    const int b = static_cast<int>(std::floor(g));
    lo = start[static_cast<std::size_t>(std::max(b - 1, 0))];
    hi = start[static_cast<std::size_t>(std::min(b + 2, count))];
    if (hi < lo) hi = lo;
  }

 private:
  std::vector<std::uint32_t> kept_, slab_, cursor_;
  std::vector<std::int32_t> keep_;
};

// Word choice by fit with slabs: the counts of fit_counts (entries with a word point
// within their σ, and the word points with no entry within σ), testing each word point
// against its three slabs only, widened to whole blocks of 8 entries. Every pair tested
// is compared as in fit_counts; the pairs skipped are farther than σ apart along x.
LEX3D_CLONES void fit_counts_slabs(const Slabs& s, const float* wx, const float* wy, const float* wz, std::size_t np,
                                   std::int32_t* hit, std::size_t& explained, std::size_t& unsupported) {
  const std::size_t npad = s.x.size();
  const float* lx = s.x.data();
  const float* ly = s.y.data();
  const float* lz = s.z.data();
  const float* sig2 = s.sig2.data();
  for (std::size_t k = 0; k < npad; ++k) hit[k] = 0;
  std::size_t lonely = 0;
  for (std::size_t p = 0; p < np; ++p) {
    const float px = wx[p], py = wy[p], pz = wz[p];
    std::uint32_t lo = 0, hi = 0;
    s.window(px, lo, hi);
    std::int32_t any[8] = {0, 0, 0, 0, 0, 0, 0, 0};
    for (std::size_t k = lo & ~7U; k < hi; k += 8)
      for (std::size_t l = 0; l < 8; ++l) {
        const float dx = px - lx[k + l], dy = py - ly[k + l], dz = pz - lz[k + l];
        const std::int32_t m = (dx * dx + dy * dy + dz * dz <= sig2[k + l]) ? 1 : 0;
        hit[k + l] |= m;
        any[l] |= m;
      }
    const std::int32_t a = (any[0] | any[1] | any[2] | any[3]) | (any[4] | any[5] | any[6] | any[7]);
    lonely += a ? 0 : 1;
  }
  std::size_t e = 0;
  for (std::size_t k = 0; k < s.size; ++k) e += static_cast<std::size_t>(hit[k]);
  explained = e;
  unsupported = lonely;
}

// Squared distance from q to the box [lo, hi] (0 inside).
inline float box_distance_sq(const PackedWord& w, float qx, float qy, float qz) {
  const float ox = std::max(std::max(w.lo.x() - qx, qx - w.hi.x()), 0.0F);
  const float oy = std::max(std::max(w.lo.y() - qy, qy - w.hi.y()), 0.0F);
  const float oz = std::max(std::max(w.lo.z() - qz, qz - w.hi.z()), 0.0F);
  return ox * ox + oy * oy + oz * oz;
}

}  // namespace

ScanState::ScanState(const PreparedScan& scan, int threads) : scan_(scan) {
  const std::size_t n = scan.cloud.size();
  const std::size_t nf = scan.features.size();
  inv_two_sigma2_.resize(n);
  norm_.resize(n);
  log_floor_.resize(n);
  std::vector<float> reach2(n);
  const double log_n = std::log(static_cast<double>(std::max<std::size_t>(n, 1)));
  for (std::size_t j = 0; j < n; ++j) {
    const double s = std::max(1e-4, static_cast<double>(scan.sigma[j]));
    inv_two_sigma2_[j] = static_cast<float>(1.0 / (2.0 * s * s));
    reach2[j] = static_cast<float>(9.0 * s * s);
    const double c = 2.0 * M_PI * s * s;
    norm_[j] = 1.0 / (c * std::sqrt(c));  // c^(-3/2)
    log_floor_[j] = -1.5 * std::log(c) - 4.5 - log_n;
  }
  S_.assign(n, 0.0);
  delta_.assign(n, 0.0);
  word_.assign(nf, -1);
  word_points_.assign(nf, 0);
  pose_.resize(nf);
  off_.assign(scan.nearby_offset.begin(), scan.nearby_offset.end());
  const std::size_t entries = off_[nf];
  idx_.resize(entries);
  lx_.resize(entries);
  ly_.resize(entries);
  lz_.resize(entries);
  reach2_e_.resize(entries);
  a_e_.resize(entries);
  sig2_e_.resize(entries);
  cache_.assign(entries, 0.0F);
  const std::uint32_t* near = scan.nearby_index.data();
  parallel_for(nf, threads, [&](std::size_t f) {
    pose_[f] = scan.features.features[f].T_cloud_feature.cast<float>();
    const Eigen::Isometry3f T_feature_cloud = pose_[f].inverse();
    for (std::size_t k = off_[f]; k < off_[f + 1]; ++k) {
      const std::uint32_t j = near[k];
      const Eigen::Vector3f q = T_feature_cloud * scan.cloud.points[j];
      idx_[k] = j;
      lx_[k] = q.x();
      ly_[k] = q.y();
      lz_[k] = q.z();
      reach2_e_[k] = reach2[j];
      a_e_[k] = inv_two_sigma2_[j];
      sig2_e_[k] = reach2[j] / 9.0F;
    }
  }, 64);
  recompute();
}

void ScanState::recompute() {
  const double lm = log_m(M_);
  log_l_ = 0.0;
  above_ = 0;
  for (std::size_t j = 0; j < S_.size(); ++j) {
    if (!(S_[j] > 0.0)) {
      log_l_ += log_floor_[j];
      continue;
    }
    const double v = std::log(S_[j]) - lm;
    if (v > log_floor_[j]) {
      log_l_ += v;
      ++above_;
    } else {
      log_l_ += log_floor_[j];
    }
  }
}

void ScanState::contribution(std::size_t f, const PackedWord& word, std::vector<float>& out) const {
  const std::size_t b = begin_of(f), e = end_of(f);
  out.assign(e - b, 0.0F);
  if (word.size() == 0) return;
  const float lo[3] = {word.lo.x(), word.lo.y(), word.lo.z()};
  const float hi[3] = {word.hi.x(), word.hi.y(), word.hi.z()};
  gaussian_sums(lx_.data() + b, ly_.data() + b, lz_.data() + b, reach2_e_.data() + b, a_e_.data() + b, e - b,
                word.xp.data(), word.yp.data(), word.zp.data(), word.xp.size(), lo, hi, out.data());
  for (std::size_t k = b; k < e; ++k)
    if (out[k - b] != 0.0F) out[k - b] = static_cast<float>(static_cast<double>(out[k - b]) * norm_[idx_[k]]);
}

std::int64_t ScanState::stage(const std::vector<Change>& changes) {
  std::int64_t dm = 0;
  for (const auto& c : changes) {
    const std::size_t b = begin_of(c.feature), e = end_of(c.feature);
    const bool has_after = !c.contrib.empty();
    for (std::size_t k = b; k < e; ++k) {
      const double before = cache_[k];
      const double after = has_after ? c.contrib[k - b] : 0.0;
      if (before == 0.0 && after == 0.0) continue;
      const std::uint32_t j = idx_[k];
      if (delta_[j] == 0.0) touched_.push_back(j);
      delta_[j] += after - before;
      if (delta_[j] == 0.0) delta_[j] = 1e-300;  // keep it marked as touched
    }
    dm += static_cast<std::int64_t>(c.word_points) - static_cast<std::int64_t>(word_points_[c.feature]);
  }
  return dm;
}

double ScanState::staged_delta(std::uint64_t m_new) const {
  const double lm_old = log_m(M_);
  const double lm_new = log_m(m_new);
  double d = 0.0;
  std::size_t touched_above = 0;
  for (const std::uint32_t j : touched_) {
    const double s_new = std::max(0.0, S_[j] + delta_[j]);
    d += log_term(j, s_new, lm_new) - log_term(j, S_[j], lm_old);
    touched_above += above(j, S_[j], lm_old) ? 1 : 0;
  }
  // The untouched points above the background only see M change.
  return d - static_cast<double>(above_ - touched_above) * (lm_new - lm_old);
}

void ScanState::unstage() {
  for (const std::uint32_t j : touched_) delta_[j] = 0.0;
  touched_.clear();
}

double ScanState::delta_log_likelihood(const std::vector<Change>& changes) {
  const std::int64_t dm = stage(changes);
  const double d = staged_delta(static_cast<std::uint64_t>(static_cast<std::int64_t>(M_) + dm));
  unstage();
  return d;
}

void ScanState::apply(const std::vector<Change>& changes) {
  const std::int64_t dm = stage(changes);
  const auto m_new = static_cast<std::uint64_t>(static_cast<std::int64_t>(M_) + dm);
  log_l_ += staged_delta(m_new);
  const double lm_old = log_m(M_);
  const double lm_new = log_m(m_new);
  for (const std::uint32_t j : touched_) {
    const bool was = above(j, S_[j], lm_old);
    S_[j] = std::max(0.0, S_[j] + delta_[j]);
    above_ = above_ + (above(j, S_[j], lm_new) ? 1 : 0) - (was ? 1 : 0);
  }
  unstage();
  for (const auto& c : changes) {
    word_[c.feature] = c.word;
    word_points_[c.feature] = c.word_points;
    const std::size_t b = begin_of(c.feature), e = end_of(c.feature);
    if (c.contrib.empty()) std::fill(cache_.begin() + static_cast<std::ptrdiff_t>(b), cache_.begin() + static_cast<std::ptrdiff_t>(e), 0.0F);
    else std::copy(c.contrib.begin(), c.contrib.begin() + static_cast<std::ptrdiff_t>(e - b), cache_.begin() + static_cast<std::ptrdiff_t>(b));
  }
  M_ = m_new;
}

void ScanState::assign_words(const std::vector<std::int32_t>& words, const Alphabet& alphabet) {
  for (std::size_t f = 0; f < word_.size() && f < words.size(); ++f) {
    word_[f] = words[f];
    word_points_[f] = words[f] >= 0 ? static_cast<std::uint32_t>(alphabet.words[static_cast<std::size_t>(words[f])].points.size()) : 0U;
  }
  stale_ = true;
}

void ScanState::rescore(const Alphabet& alphabet, int threads) {
  if (!stale_) return;
  const std::vector<PackedWord> packed = pack(alphabet);
  parallel_for(word_.size(), threads, [&](std::size_t f) {
    const std::size_t b = begin_of(f), e = end_of(f);
    if (word_[f] < 0) {
      std::fill(cache_.begin() + static_cast<std::ptrdiff_t>(b), cache_.begin() + static_cast<std::ptrdiff_t>(e), 0.0F);
      return;
    }
    thread_local std::vector<float> out;
    contribution(f, packed[static_cast<std::size_t>(word_[f])], out);
    std::copy(out.begin(), out.end(), cache_.begin() + static_cast<std::ptrdiff_t>(b));
  }, 16);
  // Sums in feature order: the same S whatever the thread count.
  std::fill(S_.begin(), S_.end(), 0.0);
  M_ = 0;
  for (std::size_t f = 0; f < word_.size(); ++f) {
    if (word_[f] < 0) continue;
    M_ += word_points_[f];
    for (std::size_t k = begin_of(f); k < end_of(f); ++k) S_[idx_[k]] += static_cast<double>(cache_[k]);
  }
  stale_ = false;
  recompute();
}

std::size_t ScanState::prune(const Alphabet& alphabet, int threads, bool keep_sole_cover) {
  rescore(alphabet, threads);
  std::vector<std::size_t> count(alphabet.size(), 0);
  for (const auto w : word_)
    if (w >= 0) ++count[static_cast<std::size_t>(w)];
  std::vector<std::uint32_t> order(alphabet.size());
  std::iota(order.begin(), order.end(), 0U);
  std::stable_sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t b) { return count[a] > count[b]; });
  // The features of each word, in feature order.
  std::vector<std::vector<std::uint32_t>> of_word(alphabet.size());
  for (std::size_t f = 0; f < word_.size(); ++f)
    if (word_[f] >= 0) of_word[static_cast<std::size_t>(word_[f])].push_back(static_cast<std::uint32_t>(f));
  // With keep_sole_cover: which entries (instance, nearby scan point) have a word point
  // within the point's σ, and how many instances cover each scan point so.
  std::vector<std::uint8_t> covers;
  std::vector<std::uint32_t> cover_count;
  if (keep_sole_cover) {
    covers.assign(cache_.size(), 0);
    cover_count.assign(S_.size(), 0);
    const std::vector<PackedWord> packed = pack(alphabet);
    parallel_for(word_.size(), threads, [&](std::size_t f) {
      if (word_[f] < 0) return;
      const std::size_t b = begin_of(f), e = end_of(f);
      const PackedWord& w = packed[static_cast<std::size_t>(word_[f])];
      thread_local std::vector<std::int32_t> hits, sup;
      hits.resize(e - b);
      sup.resize(w.size());
      fit_counts(lx_.data() + b, ly_.data() + b, lz_.data() + b, sig2_e_.data() + b, e - b, w.x.data(), w.y.data(),
                 w.z.data(), w.size(), hits.data(), sup.data());
      for (std::size_t k = b; k < e; ++k) covers[k] = hits[k - b] != 0 ? 1 : 0;
    }, 16);
    for (std::size_t f = 0; f < word_.size(); ++f)
      if (word_[f] >= 0)
        for (std::size_t k = begin_of(f); k < end_of(f); ++k) cover_count[idx_[k]] += covers[k];
  }
  std::size_t dropped = 0;
  std::vector<Change> one(1);
  for (const std::uint32_t w : order) {
    for (const std::uint32_t f : of_word[w]) {
      one[0].feature = f;
      one[0].word = -1;
      one[0].word_points = 0;
      one[0].contrib.clear();
      if (delta_log_likelihood(one) < 0.0) continue;
      if (keep_sole_cover) {
        bool sole = false;
        for (std::size_t k = begin_of(f); k < end_of(f) && !sole; ++k) sole = covers[k] != 0 && cover_count[idx_[k]] == 1;
        if (sole) continue;
        for (std::size_t k = begin_of(f); k < end_of(f); ++k) cover_count[idx_[k]] -= covers[k];
      }
      apply(one);
      ++dropped;
    }
  }
  recompute();
  return dropped;
}

namespace {

// One rigid correction D (q ≈ D p) from word points to their nearest targets, in the
// instance's frame; identity when fewer than 3 pairs fall within reach. `match[i]` is the
// target of word point i or -1.
Eigen::Isometry3f fit_pairs(const std::vector<Eigen::Vector3f>& word, const std::vector<Eigen::Vector3f>& targets,
                            const std::vector<std::int32_t>& match) {
  Eigen::Vector3d ca = Eigen::Vector3d::Zero(), cb = Eigen::Vector3d::Zero();
  std::size_t pairs = 0;
  for (std::size_t i = 0; i < word.size(); ++i) {
    if (match[i] < 0) continue;
    ca += word[i].cast<double>();
    cb += targets[static_cast<std::size_t>(match[i])].cast<double>();
    ++pairs;
  }
  Eigen::Isometry3f D = Eigen::Isometry3f::Identity();
  if (pairs < 3) return D;
  ca /= static_cast<double>(pairs);
  cb /= static_cast<double>(pairs);
  Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
  for (std::size_t i = 0; i < word.size(); ++i) {
    if (match[i] < 0) continue;
    H += (word[i].cast<double>() - ca) * (targets[static_cast<std::size_t>(match[i])].cast<double>() - cb).transpose();
  }
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(H, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d V = svd.matrixV();
  Eigen::Matrix3d R = V * svd.matrixU().transpose();
  if (R.determinant() < 0.0) {
    V.col(2) *= -1.0;
    R = V * svd.matrixU().transpose();
  }
  const Eigen::Vector3d t = cb - R * ca;
  if (!R.allFinite() || !t.allFinite()) return D;
  D.linear() = R.cast<float>();
  D.translation() = t.cast<float>();
  return D;
}

}  // namespace

void ScanState::refine(const Alphabet& alphabet, int iterations, double max_distance, int threads) {
  if (iterations <= 0) return;
  const float reach2 = static_cast<float>(max_distance * max_distance);
  const std::vector<PackedWord> packed = pack(alphabet);
  std::vector<std::size_t> active;
  for (std::size_t f = 0; f < word_.size(); ++f)
    if (word_[f] >= 0) active.push_back(f);
  std::vector<Eigen::Isometry3f> correction(active.size(), Eigen::Isometry3f::Identity());
  parallel_for(active.size(), threads, [&](std::size_t i) {
    const std::size_t f = active[i];
    // ICP in the instance's frame: D moves the word onto the nearby scan points;
    // the new pose is pose · D.
    const Word& word = alphabet.words[static_cast<std::size_t>(word_[f])];
    const PackedWord& pw = packed[static_cast<std::size_t>(word_[f])];
    Eigen::Isometry3f& total = correction[i];
    const std::size_t np = word.points.size();
    if (np == 0) return;
    // Only scan points near the word's bounding box can pair up (twice the reach
    // leaves room for the word to move).
    const float margin = 2.0F * static_cast<float>(max_distance);
    thread_local std::vector<Eigen::Vector3f> targets, moved;
    thread_local std::vector<float> tx, ty, tz, mx, my, mz, best;
    thread_local std::vector<std::int32_t> match;
    targets.clear();
    tx.clear();
    ty.clear();
    tz.clear();
    for (std::size_t k = begin_of(f); k < end_of(f); ++k) {
      const float qx = lx_[k], qy = ly_[k], qz = lz_[k];
      if (pw.lo.x() - qx <= margin && qx - pw.hi.x() <= margin && pw.lo.y() - qy <= margin &&
          qy - pw.hi.y() <= margin && pw.lo.z() - qz <= margin && qz - pw.hi.z() <= margin) {
        targets.emplace_back(qx, qy, qz);
        tx.push_back(qx);
        ty.push_back(qy);
        tz.push_back(qz);
      }
    }
    const std::size_t nt = targets.size();
    const std::size_t npad = pw.xp.size();
    mx.assign(pw.xp.begin(), pw.xp.end());
    my.assign(pw.yp.begin(), pw.yp.end());
    mz.assign(pw.zp.begin(), pw.zp.end());
    best.resize(npad);
    match.resize(npad);
    moved.assign(word.points.begin(), word.points.end());
    for (int it = 0; it < iterations; ++it) {
      nearest_targets(tx.data(), ty.data(), tz.data(), nt, mx.data(), my.data(), mz.data(), npad, reach2, best.data(),
                      match.data());
      const Eigen::Isometry3f D = fit_pairs(moved, targets, match);
      for (std::size_t p = 0; p < np; ++p) {
        moved[p] = D * moved[p];
        mx[p] = moved[p].x();
        my[p] = moved[p].y();
        mz[p] = moved[p].z();
      }
      total = D * total;
      // Converged: under 0.1 mm and 0.1 mrad.
      const float angle = Eigen::AngleAxisf(D.linear()).angle();
      if (D.translation().norm() < 1e-4F && angle < 1e-4F) break;
    }
  }, 8);
  parallel_for(active.size(), threads, [&](std::size_t i) {
    const std::size_t f = active[i];
    pose_[f] = pose_[f] * correction[i];
    // Keep the rotation exactly orthonormal: float products drift.
    pose_[f].linear() = Eigen::Quaternionf(pose_[f].linear()).normalized().toRotationMatrix();
    const Eigen::Isometry3f inv = correction[i].inverse();
    for (std::size_t k = begin_of(f); k < end_of(f); ++k) {
      const Eigen::Vector3f q = inv * Eigen::Vector3f(lx_[k], ly_[k], lz_[k]);
      lx_[k] = q.x();
      ly_[k] = q.y();
      lz_[k] = q.z();
    }
  }, 64);
  stale_ = true;
}

std::size_t ScanState::choose_by_fit(const Alphabet& alphabet, int k, int threads, bool all_features) {
  if (alphabet.size() == 0) return 0;
  if (!all_features && (k <= 1 || alphabet.size() < 2)) return 0;
  const int dim = alphabet.descriptor_dim;
  const std::size_t nw = alphabet.size();
  const std::vector<PackedWord> packed = pack(alphabet);
  // The words' descriptors one after another.
  std::vector<float> descriptors(nw * static_cast<std::size_t>(dim));
  for (std::size_t w = 0; w < nw; ++w)
    std::copy(alphabet.words[w].descriptor.begin(), alphabet.words[w].descriptor.begin() + dim,
              descriptors.begin() + static_cast<std::ptrdiff_t>(w * static_cast<std::size_t>(dim)));
  std::vector<std::size_t> active;
  for (std::size_t f = 0; f < word_.size(); ++f)
    if (all_features || word_[f] >= 0) active.push_back(f);
  std::vector<std::int32_t> choice(active.size(), -1);
  const auto kk = std::min<std::size_t>(static_cast<std::size_t>(std::max(k, 1)), nw);
  parallel_for(active.size(), threads, [&](std::size_t i) {
    const std::size_t f = active[i];
    thread_local std::vector<float> dist;
    thread_local std::vector<std::pair<float, std::uint32_t>> near;
    thread_local std::vector<std::int32_t> hits;
    thread_local Slabs slabs;
    // The kk nearest words by descriptor (ties: lower id), in order: words come by
    // increasing id, so one enters the list when strictly nearer than its last.
    dist.resize(nw);
    descriptor_distances(scan_.features.descriptor(f), descriptors.data(), nw, dim, dist.data());
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
    float lo[3], hi[3];
    for (int a = 0; a < 3; ++a) {
      lo[a] = packed[near[0].second].lo[a];
      hi[a] = packed[near[0].second].hi[a];
      for (std::size_t c = 1; c < kk; ++c) {
        lo[a] = std::min(lo[a], packed[near[c].second].lo[a]);
        hi[a] = std::max(hi[a], packed[near[c].second].hi[a]);
      }
    }
    slabs.build(lx_.data() + b, ly_.data() + b, lz_.data() + b, sig2_e_.data() + b, e - b, lo, hi);
    hits.resize(slabs.x.size());
    double best = -1e300;
    for (std::size_t c = 0; c < kk; ++c) {
      const PackedWord& w = packed[near[c].second];
      std::size_t explained = 0, unsupported = w.size();
      if (slabs.size > 0) fit_counts_slabs(slabs, w.x.data(), w.y.data(), w.z.data(), w.size(), hits.data(), explained, unsupported);
      const double score = static_cast<double>(explained) - static_cast<double>(unsupported);
      if (score > best) {
        best = score;
        choice[i] = static_cast<std::int32_t>(near[c].second);
      }
    }
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

Model ScanState::model() const {
  Model m;
  for (std::size_t f = 0; f < word_.size(); ++f) {
    if (word_[f] < 0) continue;
    Instance inst;
    inst.word = static_cast<std::uint32_t>(word_[f]);
    inst.T_cloud_word = pose_[f].cast<double>();
    // Orthonormal to double precision (the file format checks it to 1e-6): a feature frame
    // built in float from a short tangent vector, left as it is without ICP fitting
    // (refine_iterations 0), is off by up to ~1e-5.
    inst.T_cloud_word.linear() = Eigen::Quaterniond(inst.T_cloud_word.linear()).normalized().toRotationMatrix();
    inst.feature = static_cast<std::uint32_t>(f);
    m.instances.push_back(inst);
  }
  return m;
}

}  // namespace lex3d::detail
