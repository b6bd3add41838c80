// ScanState::prune: instance pruning by the likelihood rule, optionally keeping the sole
// cover of a point.

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

}  // namespace

std::size_t ScanState::prune(const Alphabet& alphabet, int threads, bool keep_sole_cover) {
  // A stale state is scored as rescore() does, its S summed in the same order.
  const bool fresh = stale_;
  if (fresh) {
    score_contributions(alphabet, threads);
    std::fill(S_.begin(), S_.end(), 0.0);
    M_ = 0;
    for (std::size_t f = 0; f < word_.size(); ++f)
      if (word_[f] >= 0) M_ += word_points_[f];
  }
  std::vector<std::size_t> count(alphabet.size(), 0);
  for (const auto w : word_)
    if (w >= 0) ++count[static_cast<std::size_t>(w)];
  std::vector<std::uint32_t> order(alphabet.size());
  std::iota(order.begin(), order.end(), 0U);
  std::stable_sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t b) { return count[a] > count[b]; });
  // The features holding a word in the order they are tried: words in that order, the
  // features of each word in feature order (a counting sort).
  std::vector<std::size_t> start(alphabet.size());
  std::size_t placed = 0;
  for (const std::uint32_t w : order) {
    start[w] = placed;
    placed += count[w];
  }
  std::vector<std::uint32_t> seq(placed);
  for (std::size_t f = 0; f < word_.size(); ++f)
    if (word_[f] >= 0) seq[start[static_cast<std::size_t>(word_[f])]++] = static_cast<std::uint32_t>(f);
  // With keep_sole_cover: which entries (instance, nearby scan point) have a word point
  // within the point's σ, and how many instances cover each scan point so.
  std::vector<std::uint8_t> covers;
  std::vector<std::uint32_t> cover_count;
  if (keep_sole_cover) {
    covers.assign(cache_.size(), 0);
    cover_count.assign(S_.size(), 0);
    const std::vector<PackedWord> packed = pack_words(alphabet);
    parallel_for(word_.size(), threads, [&](std::size_t f) {
      if (word_[f] < 0) return;
      const std::size_t b = begin_of(f), e = end_of(f);
      const PackedWord& w = packed[static_cast<std::size_t>(word_[f])];
      thread_local std::vector<std::int32_t> hits, sup;
      thread_local std::vector<float> sig2;
      hits.resize(e - b);
      sup.resize(w.size());
      sig2.resize(e - b);
      for (std::size_t k = b; k < e; ++k) sig2[k - b] = reach2_e_[k] / 9.0F;
      fit_counts(lx_.data() + b, ly_.data() + b, lz_.data() + b, sig2.data(), e - b, w.x.data(), w.y.data(),
                 w.z.data(), w.size(), hits.data(), sup.data());
      for (std::size_t k = b; k < e; ++k) covers[k] = hits[k - b] != 0 ? 1 : 0;
    }, 16);
    for (std::size_t f = 0; f < word_.size(); ++f)
      if (word_[f] >= 0)
        for (std::size_t k = begin_of(f); k < end_of(f); ++k) cover_count[idx_[k]] += covers[k];
  }
  // rescore's sum, in feature order (the entries of features without a word hold 0).
  const std::size_t nf = word_.size();
  if (fresh)
    for (std::size_t f = 0; f < nf; ++f)
      for (std::size_t k = begin_of(f); k < end_of(f); ++k) S_[idx_[k]] += static_cast<double>(cache_[k]);
  // Whether some instance names a point twice among the entries it contributes to
  // (cache_ not 0): every removal then goes through stage_removal and staged_delta
  // instead (the points of one neighbourhood are distinct in practice). The scan lists
  // them in ascending order, which rules that out with no look at the points; other
  // lists are checked point by point.
  bool ascending = true;
  for (std::size_t f = 0; f < nf; ++f)
    for (std::size_t k = begin_of(f) + 1; k < end_of(f); ++k) ascending &= idx_[k - 1] < idx_[k];
  bool repeats = false;
  if (!ascending) {
    std::vector<std::uint32_t> last(S_.size(), std::numeric_limits<std::uint32_t>::max());
    for (std::size_t f = 0; f < nf; ++f) {
      const auto ff = static_cast<std::uint32_t>(f);
      for (std::size_t k = begin_of(f); k < end_of(f); ++k) {
        const std::uint32_t j = idx_[k];
        const bool nz = cache_[k] != 0.0F;
        repeats |= nz && last[j] == ff;
        last[j] = nz ? ff : last[j];
      }
    }
  }
  if (fresh) {
    stale_ = false;
    refresh_logs();
    recompute();
  }
  // With keep_sole_cover: whether f must stay; otherwise its cover is taken away.
  const auto sole_cover = [&](std::size_t f) {
    if (!keep_sole_cover) return false;
    for (std::size_t k = begin_of(f); k < end_of(f); ++k)
      if (covers[k] != 0 && cover_count[idx_[k]] == 1) return true;
    for (std::size_t k = begin_of(f); k < end_of(f); ++k) cover_count[idx_[k]] -= covers[k];
    return false;
  };
  const auto drop = [&](std::size_t f) {
    word_[f] = -1;
    word_points_[f] = 0;
    std::fill(cache_.begin() + static_cast<std::ptrdiff_t>(begin_of(f)), cache_.begin() + static_cast<std::ptrdiff_t>(end_of(f)), 0.0F);
  };
  // Each removal is scored once: a dropped instance is committed from the same figures
  // (what delta_log_likelihood then apply would compute).
  std::size_t dropped = 0;
  if (repeats) {
    for (const std::uint32_t f : seq) {
      const std::int64_t dm = stage_removal(f);
      const auto m_new = static_cast<std::uint64_t>(static_cast<std::int64_t>(M_) + dm);
      const double d = staged_delta(m_new);
      if (d < 0.0 || sole_cover(f)) {
        unstage();
        continue;
      }
      commit_staged(m_new, d);
      drop(f);
      ++dropped;
    }
    recompute();
    return dropped;
  }
  // No instance names a point twice: a removal is scored from its entries alone, Δ_j
  // being minus the entry's value (staged_delta's sum, in the same order). The entries
  // not 0 of each instance are listed first (no branch on the value), in scratch that
  // stays in cache: lists of all instances at once would be fresh memory, whose first
  // touch costs more than the scoring.
  std::vector<std::uint32_t> nz_j;
  std::vector<float> nz_c;
  for (std::size_t t = 0; t < seq.size(); ++t) {
    // The entries of the instance after next start to load (each instance's are
    // contiguous, but the instances come in no useful order).
    if (t + 2 < seq.size())
      for (std::size_t k = begin_of(seq[t + 2]); k < end_of(seq[t + 2]); k += 16) {
        __builtin_prefetch(&cache_[k]);
        __builtin_prefetch(&idx_[k]);
      }
    const std::uint32_t f = seq[t];
    const std::size_t b = begin_of(f), e = end_of(f);
    nz_j.resize(e - b);
    nz_c.resize(e - b);
    std::size_t ne = 0;
    for (std::size_t k = b; k < e; ++k) {
      nz_j[ne] = idx_[k];
      nz_c[ne] = cache_[k];
      ne += cache_[k] != 0.0F ? 1 : 0;
    }
    const auto m_new = static_cast<std::uint64_t>(static_cast<std::int64_t>(M_) -
                                                  static_cast<std::int64_t>(word_points_[f]));
    const double lm_old = log_m(M_);
    const double lm_new = log_m(m_new);
    double d = 0.0;
    std::size_t touched_above = 0;
    staged_log_.resize(ne);
    // A removal is kept out as soon as it is certain to lower ln L: no term still to
    // come adds more than gain = ln M - ln M' (S_j only falls; the background stays), nor
    // does any point above the background not yet seen, so d plus that many gains bounds
    // the final d (the margin covers rounding). Saves the log() of the remaining points.
    const double gain = lm_old - lm_new;
    bool lowers = false;
    for (std::size_t i = 0; i < ne; ++i) {
      const std::uint32_t j = nz_j[i];
      const double ln_new = log_or_minus_inf(std::max(0.0, S_[j] + -static_cast<double>(nz_c[i])));
      staged_log_[i] = ln_new;
      d += term_of_log(j, ln_new, lm_new) - term_of_log(j, log_s_[j], lm_old);
      touched_above += above_of_log(j, log_s_[j], lm_old) ? 1 : 0;
      if ((i & 7) == 7) {
        const double most = d + static_cast<double>(above_ - touched_above + (ne - 1 - i)) * gain;
        if (most < -1e-6 * (1.0 + std::fabs(d))) {
          lowers = true;
          break;
        }
      }
    }
    if (lowers) continue;
    d -= static_cast<double>(above_ - touched_above) * (lm_new - lm_old);
    if (d < 0.0 || sole_cover(f)) continue;
    log_l_ += d;
    for (std::size_t i = 0; i < ne; ++i) {
      const std::uint32_t j = nz_j[i];
      const bool was = above_of_log(j, log_s_[j], lm_old);
      S_[j] = std::max(0.0, S_[j] + -static_cast<double>(nz_c[i]));
      log_s_[j] = staged_log_[i];
      above_ = above_ + (above_of_log(j, log_s_[j], lm_new) ? 1 : 0) - (was ? 1 : 0);
    }
    M_ = m_new;
    drop(f);
    ++dropped;
  }
  recompute();
  return dropped;
}

}  // namespace lex3d::detail
