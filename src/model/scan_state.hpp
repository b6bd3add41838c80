#pragma once
// Incremental likelihood bookkeeping of one scan, shared by the learner, the encoder
// and pruning. For every point j it keeps S_j = Σ over placed word points r within
// 3σ_j of N(d_j; r, σ_j), so that P(d_j) = S_j / M with M the number of placed word
// points (eq. 9-12). A point nothing explains gets a background density instead, that
// of one Gaussian at 3σ in a reconstruction as large as the scan, g_j(3σ_j) / N; it
// does not depend on M, so an empty model is a valid, poor model. A word placed at
// feature f can only reach the points in scan.nearby(f), so changing an instance
// re-scores just those; the other points only see M change, which moves those above
// the background by -Δ ln M each (points that cross the background that way are
// caught by recompute()).
//
// Word choice by fit and pose refinement change instances without scoring them (the
// encoder needs the likelihood only for pruning); they leave the state stale until
// rescore() scores every instance once.

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <new>
#include <type_traits>
#include <utility>
#include <vector>
#include "core/huge_pages.hpp"
#include "lex3d/alphabet/alphabet.hpp"
#include "lex3d/model/model.hpp"

namespace lex3d::detail {

/// Allocator of the large per-entry and per-point arrays: a block of 1 MiB or more is
/// aligned to 2 MiB and, on Linux, marked for transparent huge pages, so that filling it
/// takes one page fault per 2 MiB instead of one per 4 KiB (first touching these arrays
/// cost more than the work done on them).
template <class T>
struct LargeAllocator {
  using value_type = T;
  static constexpr std::size_t kLarge = std::size_t{1} << 20;
  LargeAllocator() = default;
  template <class U>
  LargeAllocator(const LargeAllocator<U>& /*other*/) noexcept {}
  T* allocate(std::size_t n) {
    const std::size_t bytes = n * sizeof(T);
    if (bytes < kLarge) return static_cast<T*>(::operator new(bytes));
    const std::size_t size = (bytes + kHugePage - 1) / kHugePage * kHugePage;
    void* p = std::aligned_alloc(kHugePage, size);
    if (p == nullptr) throw std::bad_alloc();
    advise_huge_pages(p, size);
    return static_cast<T*>(p);
  }
  void deallocate(T* p, std::size_t n) noexcept {
    if (n * sizeof(T) < kLarge) ::operator delete(p);
    else std::free(p);
  }
  // resize() and the size constructor leave the elements default-initialised (for
  // numbers: unwritten): every one of these arrays is filled right after, and zeroing it
  // first would touch all its memory twice. assign() and the (size, value) constructor
  // still write their value.
  template <class U>
  void construct(U* p) noexcept(std::is_nothrow_default_constructible<U>::value) {
    ::new (static_cast<void*>(p)) U;
  }
  template <class U, class... Args>
  void construct(U* p, Args&&... args) {
    ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
  }
  template <class U>
  bool operator==(const LargeAllocator<U>& /*other*/) const noexcept { return true; }
  template <class U>
  bool operator!=(const LargeAllocator<U>& /*other*/) const noexcept { return false; }
};
template <class T>
using LargeVector = std::vector<T, LargeAllocator<T>>;

/// The two per-point factors of a point's Gaussian, side by side: the contribution of
/// an entry reads both, and one cache line then serves the two (the entries of a
/// neighbourhood visit the scan's points in no useful order).
struct PointScale {
  double norm;  // (2πσ²)^(-3/2)
  float a;      // 1 / (2σ²)
};

/// A word's points as separate coordinate arrays (the inner loops over word points
/// vectorise), with their bounding box.
struct PackedWord {
  std::vector<float> x, y, z;
  std::vector<float> xp, yp, zp;  // the same, padded with far points to a multiple of 8
  Eigen::Vector3f lo = Eigen::Vector3f::Zero();
  Eigen::Vector3f hi = Eigen::Vector3f::Zero();
  PackedWord() = default;
  explicit PackedWord(const Word& word);
  [[nodiscard]] std::size_t size() const noexcept { return x.size(); }
};

/// The alphabet's words packed for the kernels, in word order.
std::vector<PackedWord> pack_words(const Alphabet& alphabet);


class ScanState {
 public:
  explicit ScanState(const PreparedScan& scan, int threads = 1);

  /// Contribution of `word` placed at feature f to each point of scan.nearby(f).
  void contribution(std::size_t f, const PackedWord& word, std::vector<float>& out) const;

  /// A proposed new word for feature f (-1: no word) with its contribution.
  struct Change {
    std::uint32_t feature = 0;
    std::int32_t word = -1;
    std::uint32_t word_points = 0;
    std::vector<float> contrib;
  };
  /// Change of ln L if `changes` were applied (each feature at most once).
  [[nodiscard]] double delta_log_likelihood(const std::vector<Change>& changes);
  /// Applies `changes` (their contributions are copied into the cache).
  void apply(const std::vector<Change>& changes);

  [[nodiscard]] double log_likelihood() const { return log_l_; }
  /// Recomputes ln L and the count of points above the background from scratch.
  void recompute();
  [[nodiscard]] std::size_t points() const noexcept { return S_.size(); }
  [[nodiscard]] std::int32_t word_of(std::size_t f) const noexcept { return word_[f]; }
  [[nodiscard]] std::uint64_t placed_points() const noexcept { return M_; }

  /// Sets the word of every feature (-1: none) without scoring: the state is stale
  /// until rescore().
  void assign_words(const std::vector<std::int32_t>& words, const Alphabet& alphabet);
  /// Whether instances changed since they were last scored.
  [[nodiscard]] bool stale() const noexcept { return stale_; }
  /// Scores every instance afresh (contributions, S, M, ln L) when the state is stale.
  void rescore(const Alphabet& alphabet, int threads);

  /// Drops instances whose removal does not lower ln L, words by decreasing
  /// occurrence count (ruhnke2010 §III-D), except, with `keep_sole_cover`, an instance
  /// that is the last one with a word point within σ of some scan point. Returns how many
  /// were dropped. Rescores a stale state first.
  std::size_t prune(const Alphabet& alphabet, int threads = 1, bool keep_sole_cover = false);

  /// Refines the pose of every instance by point-to-point ICP of its word against the
  /// scan points near it (correspondences within max_distance, `iterations` rounds).
  /// Leaves the state stale.
  void refine(const Alphabet& alphabet, int iterations, double max_distance, int threads);

  /// Re-chooses each instance's word among the `k` nearest by descriptor, by how well it
  /// fits the scan around it: scan points it explains (a word point within σ) minus word
  /// points nothing supports. With `all_features`, every feature gets a word this way
  /// (the nearest descriptors of features without one included). Returns how many
  /// instances changed word; leaves the state stale when any did.
  std::size_t choose_by_fit(const Alphabet& alphabet, int k, int threads, bool all_features = false);

  /// The model: one instance per feature that holds a word.
  [[nodiscard]] Model model() const;

 private:
  [[nodiscard]] double log_term(std::size_t j, double s, double log_m) const noexcept {
    if (!(s > 0.0)) return log_floor_[j];
    const double v = std::log(s) - log_m;
    return v > log_floor_[j] ? v : log_floor_[j];
  }
  [[nodiscard]] bool above(std::size_t j, double s, double log_m) const noexcept {
    return s > 0.0 && std::log(s) - log_m > log_floor_[j];
  }
  [[nodiscard]] static double log_m(std::uint64_t m) noexcept {
    return m > 1 ? std::log(static_cast<double>(m)) : 0.0;
  }
  [[nodiscard]] std::size_t begin_of(std::size_t f) const noexcept { return off_[f]; }
  [[nodiscard]] std::size_t end_of(std::size_t f) const noexcept { return off_[f + 1]; }

  // log_term and above from a cached ln S_j (-inf when S_j is not positive): the same
  // values without calling log().
  [[nodiscard]] double term_of_log(std::size_t j, double ln_s, double log_m) const noexcept {
    const double v = ln_s - log_m;
    return v > log_floor_[j] ? v : log_floor_[j];
  }
  [[nodiscard]] bool above_of_log(std::size_t j, double ln_s, double log_m) const noexcept {
    return ln_s - log_m > log_floor_[j];
  }
  [[nodiscard]] static double log_or_minus_inf(double s) noexcept;

  // Accumulates the contribution changes of `changes` into delta_ (marking touched_);
  // returns the change of M.
  std::int64_t stage(const std::vector<Change>& changes);
  // The same for removing the instance of feature f.
  std::int64_t stage_removal(std::size_t f);
  // ln L change of the staged changes if M became m_new; keeps ln S_j + Δ_j of each
  // touched point in staged_log_ (in touched_ order).
  [[nodiscard]] double staged_delta(std::uint64_t m_new);
  // Applies the staged changes to S, ln S, the count above the background, M and ln L
  // (`delta`: what staged_delta returned), then unstages.
  void commit_staged(std::uint64_t m_new, double delta);
  void unstage();
  // Allocates delta_, all zeros, when it is not yet.
  void zeroed_delta();
  // Fills ln S from S.
  void refresh_logs();
  // The contribution of every instance into cache_ (rescore's first part).
  void score_contributions(const Alphabet& alphabet, int threads);
  // Contribution of `word` at feature f written to out[0, entries of f).
  void contribution_into(std::size_t f, const PackedWord& word, float* out) const;

  const PreparedScan& scan_;
  std::vector<Eigen::Isometry3f> pose_;  // instance pose of each feature (cloud frame)
  // The nearby points of all features, flat (the scan's own arrays): feature f owns
  // entries [off_[f], off_[f+1]).
  const std::size_t* off_ = nullptr;
  const std::uint32_t* idx_ = nullptr;  // the scan point of each entry
  LargeVector<float> lx_, ly_, lz_;     // the entry's point in its feature's instance frame
  LargeVector<float> reach2_e_;         // (3σ)² of the entry's point (σ² taken as (3σ)² / 9)
  LargeVector<float> cache_;            // current contribution of each feature's instance
  LargeVector<PointScale> scale_;       // per point: its Gaussian's norm and exponent factor
  LargeVector<double> log_floor_;       // ln of the background density, per point
  LargeVector<double> S_;
  LargeVector<double> log_s_;  // ln S_j, -inf when S_j is not positive (kept with S_)
  std::vector<std::int32_t> word_;
  std::vector<std::uint32_t> word_points_;
  std::uint64_t M_ = 0;
  double log_l_ = 0.0;       // ln L, kept up to date by apply() and recompute()
  std::size_t above_ = 0;    // points whose S_j / M exceeds the background
  bool stale_ = false;
  // Scratch for delta evaluation.
  LargeVector<double> delta_;
  std::vector<std::uint32_t> touched_;
  std::vector<double> staged_log_;
};

}  // namespace lex3d::detail
