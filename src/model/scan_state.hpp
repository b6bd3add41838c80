#pragma once
// Incremental likelihood bookkeeping of one scan, shared by the learner, the encoder
// and pruning. For every point j it keeps S_j = Σ over placed word points r within
// 3σ_j of N(d_j; r, σ_j), so that P(d_j) = S_j / M with M the number of placed word
// points (eq. 9-12). A point nothing explains gets a background density instead, that
// of one Gaussian at 3σ in a reconstruction as large as the scan, g_j(3σ_j) / N; it
// does not depend on M, so an empty model is a valid, poor model. A word placed at
// feature f can only reach the points in scan.nearby[f], so changing an instance
// re-scores just those; the other points only see M change, which moves those above
// the background by -Δ ln M each (points that cross the background that way are
// caught by recompute()).

#include <cstdint>
#include <vector>

#include "lex3d/alphabet/alphabet.hpp"
#include "lex3d/model/model.hpp"

namespace lex3d::detail {

class ScanState {
 public:
  explicit ScanState(const PreparedScan& scan);

  /// Contribution of `word` placed at feature f to each point of scan.nearby[f].
  void contribution(std::size_t f, const Word& word, std::vector<float>& out) const;

  /// A proposed new word for feature f (-1: no word) with its contribution.
  struct Change {
    std::uint32_t feature = 0;
    std::int32_t word = -1;
    std::uint32_t word_points = 0;
    std::vector<float> contrib;
  };
  /// Change of ln L if `changes` were applied (each feature at most once).
  [[nodiscard]] double delta_log_likelihood(const std::vector<Change>& changes);
  /// Applies `changes` (their contributions are moved into the cache).
  void apply(std::vector<Change>& changes);

  [[nodiscard]] double log_likelihood() const { return log_l_; }
  /// Recomputes ln L and the count of points above the background from scratch.
  void recompute();
  [[nodiscard]] std::size_t points() const noexcept { return S_.size(); }
  [[nodiscard]] std::int32_t word_of(std::size_t f) const noexcept { return word_[f]; }
  [[nodiscard]] std::uint64_t placed_points() const noexcept { return M_; }

  /// Drops instances whose removal does not lower ln L, words by decreasing
  /// occurrence count (ruhnke2010 §III-D). Returns how many were dropped.
  std::size_t prune(const Alphabet& alphabet);

  /// Refines the pose of every instance by point-to-point ICP of its word against the
  /// scan points near it (correspondences within max_distance, `iterations` rounds),
  /// then re-scores the changed instances.
  void refine(const Alphabet& alphabet, int iterations, double max_distance, int threads);

  /// Re-chooses each instance's word among the `k` nearest by descriptor, by how well it
  /// fits the scan around it: scan points it explains (a word point within σ) minus word
  /// points nothing supports. Returns how many instances changed word.
  std::size_t choose_by_fit(const Alphabet& alphabet, int k, int threads);

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

  // Accumulates the contribution changes of `changes` into delta_ (marking touched_);
  // returns the change of M.
  std::int64_t stage(const std::vector<Change>& changes);
  // ln L change of the staged changes if M became m_new.
  [[nodiscard]] double staged_delta(std::uint64_t m_new) const;
  void unstage();

  const PreparedScan& scan_;
  std::vector<Eigen::Isometry3f> pose_;               // instance pose of each feature (cloud frame)
  std::vector<std::vector<Eigen::Vector3f>> local_;  // nearby points in that pose's frame
  std::vector<float> inv_two_sigma2_;                 // 1 / (2σ²)
  std::vector<float> reach2_;                         // (3σ)²
  std::vector<double> norm_;                          // (2πσ²)^(-3/2)
  std::vector<double> log_floor_;                     // ln of the background density
  std::vector<double> S_;
  std::vector<std::int32_t> word_;
  std::vector<std::uint32_t> word_points_;
  std::vector<std::vector<float>> cache_;  // current contribution of each feature's instance
  std::uint64_t M_ = 0;
  double log_l_ = 0.0;       // ln L, kept up to date by apply() and recompute()
  std::size_t above_ = 0;    // points whose S_j / M exceeds the background
  // Scratch for delta evaluation.
  std::vector<double> delta_;
  std::vector<std::uint32_t> touched_;
};

}  // namespace lex3d::detail
