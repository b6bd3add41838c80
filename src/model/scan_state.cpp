// ScanState: the likelihood bookkeeping (eq. 9-12), staging and committing changes,
// scoring, and the model it holds (scan_state.hpp).

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

std::vector<PackedWord> pack_words(const Alphabet& alphabet) {
  std::vector<PackedWord> out;
  out.reserve(alphabet.size());
  for (const auto& w : alphabet.words) out.emplace_back(w);
  return out;
}

namespace {

// Σ_p exp(-d²·a) over the word points within reach of each entry (0 when none), times
// norm when not 0 (in double, rounded to float), for the n entries of a feature (a and
// norm are per scan point: scale[idx[k]]).
// Word arrays hold np points padded to npad, a multiple of 8, with far points; the sum
// keeps eight lanes (point p in lane p % 8), each adding its blocks of eight points in
// order, the lanes then added pairwise, so the SSE, AVX2 and AVX-512 builds give the
// same bits.
// A block with no point in reach would add only zeros and is left out (about 60 % of
// them on KITTI). Passes with no data-dependent branch in their inner loops: the entries
// within reach of the word's bounding box; per block, those of them within reach of the
// block's bounding box (eight entries a test), then their exponentials added into each
// entry's lanes (blocks in order).
LEX3D_CLONES_512 void gaussian_sums(const float* lx, const float* ly, const float* lz, const float* reach2,
                                    const PointScale* scale, std::size_t n, const float* wx, const float* wy,
                                    const float* wz, std::size_t np, std::size_t npad, const float* lo,
                                    const float* hi, const std::uint32_t* idx, float* out) {
  // Scratch as plain floats, read and written without alignment assumptions.
  thread_local std::vector<float> cx, cy, cz, cr, cna, acc;
  thread_local std::vector<double> cnorm;
  thread_local std::vector<std::uint32_t> live, cand;
  const std::size_t nb = npad / 8;
  const std::size_t n8 = (n + 7) / 8 * 8;
  if (live.size() < n8 + 8) {
    live.resize(n8 + 8);
    cand.resize(n8 + 8);
    cx.resize(n8 + 1);
    cy.resize(n8 + 1);
    cz.resize(n8 + 1);
    cr.resize(n8 + 1);
    cna.resize(n8 + 1);
    cnorm.resize(n8 + 1);
    acc.resize(8 * (n8 + 1));
  }
  std::fill(out, out + n, 0.0F);
  // The entries within 3σ of the word's bounding box (the others get nothing).
  std::size_t nl = 0;
  std::size_t k0 = 0;
  for (; k0 + 8 <= n; k0 += 8) {
    const V8f qx = load8(lx + k0), qy = load8(ly + k0), qz = load8(lz + k0);
    const V8i in = box_gap2_8(qx, qy, qz, lo, hi) <= load8(reach2 + k0);
    nl = append_lanes(live.data(), nl, lane_bits8(in), static_cast<std::uint32_t>(k0));
    // The scales of the live entries are read next, at scattered points of the scan
    // (most of them not in cache): their loads start here, overlapping this pass.
    for (std::size_t l = 0; l < 8; ++l) __builtin_prefetch(&scale[idx[k0 + l]]);
  }
  for (; k0 < n; ++k0) {
    const float qx = lx[k0], qy = ly[k0], qz = lz[k0];
    const float ox = std::max(std::max(lo[0] - qx, qx - hi[0]), 0.0F);
    const float oy = std::max(std::max(lo[1] - qy, qy - hi[1]), 0.0F);
    const float oz = std::max(std::max(lo[2] - qz, qz - hi[2]), 0.0F);
    live[nl] = static_cast<std::uint32_t>(k0);
    nl += ox * ox + oy * oy + oz * oz > reach2[k0] ? 0 : 1;
  }
  if (nl == 0) return;
  // The live entries side by side, padded to eight with entries nothing reaches, and one
  // more such entry after them (the spare of the pairs below).
  const std::size_t nl8 = (nl + 7) / 8 * 8;
  for (std::size_t u = 0; u <= nl8; ++u) {
    const std::size_t k = live[u < nl ? u : 0];
    cx[u] = lx[k];
    cy[u] = ly[k];
    cz[u] = lz[k];
    cr[u] = u < nl ? reach2[k] : -1.0F;
    cna[u] = -scale[idx[k]].a;
    cnorm[u] = scale[idx[k]].norm;
  }
  std::fill(acc.begin(), acc.begin() + static_cast<std::ptrdiff_t>(8 * (nl8 + 1)), 0.0F);
  for (std::size_t b = 0; b < nb; ++b) {
    const std::size_t p = 8 * b;
    if (p >= np) break;  // only far padding from here on
    float blo[3], bhi[3];
    box_of(wx, wy, wz, p, std::min(p + 8, np), blo, bhi);
    // Live entries within reach of the block's bounding box (no squared distance to a
    // point of the block is below the one to its box).
    std::size_t nc = 0;
    for (std::size_t u = 0; u < nl8; u += 8) {
      const V8f qx = load8(cx.data() + u), qy = load8(cy.data() + u), qz = load8(cz.data() + u);
      const V8i near = box_gap2_8(qx, qy, qz, blo, bhi) <= load8(cr.data() + u);
      nc = append_lanes(cand.data(), nc, lane_bits8(near), static_cast<std::uint32_t>(u));
    }
    // The exponentials go straight into the entry's lanes, in block order, for two
    // candidates at a time (sixteen lanes: one AVX-512 register; an odd count ends with
    // the spare entry, which nothing reaches). A candidate none of whose points is in
    // reach adds eight zeros, which changes no sum (they are +0 and the sums start at
    // +0): cheaper than a branch, or than storing the exponents for a pass of their own.
    if (nc % 2 != 0) cand[nc++] = static_cast<std::uint32_t>(nl8);
    const V8f bx8 = load8(wx + p), by8 = load8(wy + p), bz8 = load8(wz + p);
    const V16f bx = twice8(bx8), by = twice8(by8), bz = twice8(bz8);
    for (std::size_t c = 0; c < nc; c += 2) {
      const std::uint32_t u0 = cand[c], u1 = cand[c + 1];
      const V16f dx = bx - splat2(cx[u0], cx[u1]), dy = by - splat2(cy[u0], cy[u1]),
                 dz = bz - splat2(cz[u0], cz[u1]);
      const V16f d2 = dx * dx + dy * dy + dz * dz;
      // Points beyond reach: d² and the result masked to 0 (as bits).
      const V16i mk = d2 <= splat2(cr[u0], cr[u1]);
      const V16f e = mask16(exp_neg(mask16(d2, mk) * splat2(cna[u0], cna[u1])), mk);
      float* const s0 = acc.data() + 8 * static_cast<std::size_t>(u0);
      float* const s1 = acc.data() + 8 * static_cast<std::size_t>(u1);
      const V8f v0 = load8(s0) + low8(e);
      std::memcpy(s0, &v0, sizeof v0);
      const V8f v1 = load8(s1) + high8(e);
      std::memcpy(s1, &v1, sizeof v1);
    }
  }
  for (std::size_t u = 0; u < nl; ++u) {
    const V8f v = load8(acc.data() + 8 * u);
    const float sum = ((v[0] + v[1]) + (v[2] + v[3])) + ((v[4] + v[5]) + (v[6] + v[7]));
    // A zero sum stays +0 (whatever the norm): the product's bits masked, as a branch
    // on the sum would often be mispredicted.
    const float scaled = static_cast<float>(static_cast<double>(sum) * cnorm[u]);
    std::uint32_t bits;
    std::memcpy(&bits, &scaled, sizeof bits);
    bits &= 0U - static_cast<std::uint32_t>(sum != 0.0F);
    std::memcpy(out + live[u], &bits, sizeof bits);
  }
}

// The n points pts[idx[k]] in a frame T (m: its 4x4 matrix, column-major), as frame_row
// computes them, eight at a time, into (x, y, z); with each point's reach2[idx[k]] into r2.
LEX3D_CLONES void points_in_frame(const float* m, const Eigen::Vector3f* pts, const std::uint32_t* idx,
                                  const float* reach2, std::size_t n, float* x, float* y, float* z, float* r2) {
  std::size_t k = 0;
  for (; k + 8 <= n; k += 8) {
    V8f px, py, pz, pr;
    for (std::size_t l = 0; l < 8; ++l) {
      const std::uint32_t j = idx[k + l];
      px[l] = pts[j].x();
      py[l] = pts[j].y();
      pz[l] = pts[j].z();
      pr[l] = reach2[j];
    }
    float* const c[3] = {x, y, z};
    for (int r = 0; r < 3; ++r) {
      const V8f v = frame_row(m, r, px, py, pz);
      std::memcpy(c[r] + k, &v, sizeof v);
    }
    std::memcpy(r2 + k, &pr, sizeof pr);
  }
  for (; k < n; ++k) {
    const std::uint32_t j = idx[k];
    const float px = pts[j].x(), py = pts[j].y(), pz = pts[j].z();
    x[k] = frame_row(m, 0, px, py, pz);
    y[k] = frame_row(m, 1, px, py, pz);
    z[k] = frame_row(m, 2, px, py, pz);
    r2[k] = reach2[j];
  }
}

}  // namespace

ScanState::ScanState(const PreparedScan& scan, int threads) : scan_(scan) {
  const std::size_t n = scan.cloud.size();
  const std::size_t nf = scan.features.size();
  scale_.resize(n);
  log_floor_.resize(n);
  LargeVector<float> reach2(n);
  const double log_n = std::log(static_cast<double>(std::max<std::size_t>(n, 1)));
  for (std::size_t j = 0; j < n; ++j) {
    const double s = std::max(1e-4, static_cast<double>(scan.sigma[j]));
    scale_[j].a = static_cast<float>(1.0 / (2.0 * s * s));
    reach2[j] = static_cast<float>(9.0 * s * s);
    const double c = 2.0 * M_PI * s * s;
    scale_[j].norm = 1.0 / (c * std::sqrt(c));  // c^(-3/2)
    log_floor_[j] = -1.5 * std::log(c) - 4.5 - log_n;
  }
  S_.assign(n, 0.0);
  word_.assign(nf, -1);
  word_points_.assign(nf, 0);
  pose_.resize(nf);
  off_ = scan.nearby_offset.data();
  idx_ = scan.nearby_index.data();
  const std::size_t entries = off_[nf];
  lx_.resize(entries);
  ly_.resize(entries);
  lz_.resize(entries);
  reach2_e_.resize(entries);
  cache_.assign(entries, 0.0F);
  // delta_ stays empty until a change is first staged (all zeros then): the encoder never
  // stages one, so zeroing it here would only cost first touches of memory never read.
  const std::uint32_t* near = scan.nearby_index.data();
  parallel_for(nf, threads, [&](std::size_t f) {
    pose_[f] = scan.features.features[f].T_cloud_feature.cast<float>();
    const Eigen::Isometry3f T_feature_cloud = pose_[f].inverse();
    const std::size_t b = off_[f];
    points_in_frame(T_feature_cloud.matrix().data(), scan.cloud.points.data(), near + b, reach2.data(), off_[f + 1] - b,
                    lx_.data() + b, ly_.data() + b, lz_.data() + b, reach2_e_.data() + b);
  }, 64);
  recompute();
}

void ScanState::zeroed_delta() {
  if (delta_.size() != S_.size()) delta_.assign(S_.size(), 0.0);
}

double ScanState::log_or_minus_inf(double s) noexcept {
  return s > 0.0 ? std::log(s) : -std::numeric_limits<double>::infinity();
}

void ScanState::refresh_logs() {
  log_s_.resize(S_.size());
  for (std::size_t j = 0; j < S_.size(); ++j) log_s_[j] = log_or_minus_inf(S_[j]);
}

void ScanState::recompute() {
  // ln S is kept with S (the same values log() gives), so this needs no log() of its own.
  if (log_s_.size() != S_.size()) refresh_logs();
  const double lm = log_m(M_);
  log_l_ = 0.0;
  above_ = 0;
  for (std::size_t j = 0; j < S_.size(); ++j) {
    const double v = log_s_[j] - lm;
    if (v > log_floor_[j]) {
      log_l_ += v;
      ++above_;
    } else {
      log_l_ += log_floor_[j];
    }
  }
}

void ScanState::contribution_into(std::size_t f, const PackedWord& word, float* out) const {
  const std::size_t b = begin_of(f), e = end_of(f);
  if (word.size() == 0) {
    std::fill(out, out + (e - b), 0.0F);
    return;
  }
  const float lo[3] = {word.lo.x(), word.lo.y(), word.lo.z()};
  const float hi[3] = {word.hi.x(), word.hi.y(), word.hi.z()};
  gaussian_sums(lx_.data() + b, ly_.data() + b, lz_.data() + b, reach2_e_.data() + b, scale_.data(), e - b,
                word.xp.data(), word.yp.data(), word.zp.data(), word.size(), word.xp.size(), lo, hi, idx_ + b,
                out);
}

void ScanState::contribution(std::size_t f, const PackedWord& word, std::vector<float>& out) const {
  out.resize(end_of(f) - begin_of(f));
  contribution_into(f, word, out.data());
}

std::int64_t ScanState::stage(const std::vector<Change>& changes) {
  zeroed_delta();
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

std::int64_t ScanState::stage_removal(std::size_t f) {
  zeroed_delta();
  for (std::size_t k = begin_of(f); k < end_of(f); ++k) {
    const double before = cache_[k];
    if (before == 0.0) continue;
    const std::uint32_t j = idx_[k];
    if (delta_[j] == 0.0) touched_.push_back(j);
    delta_[j] += 0.0 - before;
    if (delta_[j] == 0.0) delta_[j] = 1e-300;  // keep it marked as touched
  }
  return -static_cast<std::int64_t>(word_points_[f]);
}

double ScanState::staged_delta(std::uint64_t m_new) {
  const double lm_old = log_m(M_);
  const double lm_new = log_m(m_new);
  double d = 0.0;
  std::size_t touched_above = 0;
  staged_log_.resize(touched_.size());
  for (std::size_t i = 0; i < touched_.size(); ++i) {
    const std::uint32_t j = touched_[i];
    const double ln_new = log_or_minus_inf(std::max(0.0, S_[j] + delta_[j]));
    staged_log_[i] = ln_new;
    d += term_of_log(j, ln_new, lm_new) - term_of_log(j, log_s_[j], lm_old);
    touched_above += above_of_log(j, log_s_[j], lm_old) ? 1 : 0;
  }
  // The untouched points above the background only see M change.
  return d - static_cast<double>(above_ - touched_above) * (lm_new - lm_old);
}

void ScanState::commit_staged(std::uint64_t m_new, double delta) {
  log_l_ += delta;
  const double lm_old = log_m(M_);
  const double lm_new = log_m(m_new);
  for (std::size_t i = 0; i < touched_.size(); ++i) {
    const std::uint32_t j = touched_[i];
    const bool was = above_of_log(j, log_s_[j], lm_old);
    S_[j] = std::max(0.0, S_[j] + delta_[j]);
    log_s_[j] = staged_log_[i];
    above_ = above_ + (above_of_log(j, log_s_[j], lm_new) ? 1 : 0) - (was ? 1 : 0);
  }
  unstage();
  M_ = m_new;
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
  commit_staged(m_new, staged_delta(m_new));
  for (const auto& c : changes) {
    word_[c.feature] = c.word;
    word_points_[c.feature] = c.word_points;
    const std::size_t b = begin_of(c.feature), e = end_of(c.feature);
    if (c.contrib.empty()) std::fill(cache_.begin() + static_cast<std::ptrdiff_t>(b), cache_.begin() + static_cast<std::ptrdiff_t>(e), 0.0F);
    else std::copy(c.contrib.begin(), c.contrib.begin() + static_cast<std::ptrdiff_t>(e - b), cache_.begin() + static_cast<std::ptrdiff_t>(b));
  }
}

void ScanState::assign_words(const std::vector<std::int32_t>& words, const Alphabet& alphabet) {
  for (std::size_t f = 0; f < word_.size() && f < words.size(); ++f) {
    word_[f] = words[f];
    word_points_[f] = words[f] >= 0 ? static_cast<std::uint32_t>(alphabet.words[static_cast<std::size_t>(words[f])].points.size()) : 0U;
  }
  stale_ = true;
}

void ScanState::score_contributions(const Alphabet& alphabet, int threads) {
  const std::vector<PackedWord> packed = pack_words(alphabet);
  parallel_for(word_.size(), threads, [&](std::size_t f) {
    const std::size_t b = begin_of(f), e = end_of(f);
    if (word_[f] < 0) {
      std::fill(cache_.begin() + static_cast<std::ptrdiff_t>(b), cache_.begin() + static_cast<std::ptrdiff_t>(e), 0.0F);
      return;
    }
    contribution_into(f, packed[static_cast<std::size_t>(word_[f])], cache_.data() + b);
  }, 16);
}

void ScanState::rescore(const Alphabet& alphabet, int threads) {
  if (!stale_) return;
  score_contributions(alphabet, threads);
  // Sums in feature order: the same S whatever the thread count.
  std::fill(S_.begin(), S_.end(), 0.0);
  M_ = 0;
  for (std::size_t f = 0; f < word_.size(); ++f) {
    if (word_[f] < 0) continue;
    M_ += word_points_[f];
    for (std::size_t k = begin_of(f); k < end_of(f); ++k) S_[idx_[k]] += static_cast<double>(cache_[k]);
  }
  stale_ = false;
  refresh_logs();
  recompute();
}

Model ScanState::model() const {
  Model m;
  // Sized first: growing the list copies it and touches fresh memory at each doubling.
  m.instances.reserve(static_cast<std::size_t>(
      std::count_if(word_.begin(), word_.end(), [](std::int32_t w) { return w >= 0; })));
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
