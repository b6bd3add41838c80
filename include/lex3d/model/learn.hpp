#pragma once
/// \file
/// The alphabet learner (ruhnke2010 §III) in two halves, so that the scans can live in
/// other processes or on other machines than the BIC loop:
///
/// - LearnScan is one scan's side: its prepared state, the candidate words cut from it,
///   and, for a candidate word, the change of its ln L (eq. 6-12) were the word added.
///   The likelihood of a set of scans is the sum of the scans' (eq. 4), so a candidate's
///   gain is the sum of what every LearnScan returns for it.
/// - LearnDecisions is the loop's side: the candidate order, and the BIC decision
///   (eq. 4-5) for each candidate from that sum.
///
/// learn_alphabet (model.hpp) is these two pieces run in one process; a distributed learner
/// that sums the per-scan changes in scan order, starting from 0, takes the same decisions
/// bit for bit and so learns the same alphabet.

#include <cstddef>
#include <cstdint>
#include <memory>
#include <utility>
#include <vector>

#include "lex3d/model/model.hpp"

// The public API: exported by liblex3d.so, which hides everything else.
#pragma GCC visibility push(default)

namespace lex3d {

namespace detail {
class ScanState;
}

/// One scan's part of learning: owns its PreparedScan and likelihood state.
class LearnScan {
 public:
  /// Takes the prepared scan (prepare_scan with the set's one word radius). `threads`:
  /// threads of the per-candidate work; results do not depend on it; [1, 64].
  explicit LearnScan(PreparedScan scan, int threads = 1);
  ~LearnScan();
  LearnScan(LearnScan&&) noexcept;
  LearnScan& operator=(LearnScan&&) noexcept;
  LearnScan(const LearnScan&) = delete;
  LearnScan& operator=(const LearnScan&) = delete;

  [[nodiscard]] const PreparedScan& scan() const noexcept { return *scan_; }
  [[nodiscard]] std::size_t feature_count() const noexcept { return scan_->features.size(); }
  [[nodiscard]] std::size_t point_count() const noexcept { return scan_->cloud.size(); }
  /// ln L of the scan under the words accepted so far.
  [[nodiscard]] double log_likelihood() const;

  /// The candidate word cut around feature `feature` (radius: the scan's word radius;
  /// points thinned to `point_spacing` metres). Throws std::out_of_range for a feature
  /// the scan does not have.
  [[nodiscard]] Word cut_word(std::size_t feature, double point_spacing) const;

  /// Δ ln L of this scan if `word` became word number `word_id` of the alphabet: every
  /// feature whose descriptor is nearer to it than to its current word moves to it. The
  /// change is kept until the next evaluate() or commit(). A word of fewer than 3 points
  /// is never evaluated by the learner (LearnDecisions::evaluates).
  double evaluate(const Word& word, std::int32_t word_id);
  /// Applies the change of the last evaluate() when `accept` (and rescores the scan),
  /// forgets it otherwise; returns ln L afterwards.
  double commit(bool accept);

  /// After the loop, as encode_scan does: words by fit, pruning (when `prune`), the ICP
  /// fit of the kept instances and their likelihood. Returns the scan's model.
  Model finish(const Alphabet& alphabet, const ModelParams& params, bool prune);

  /// Moves the prepared scan out (the object is unusable afterwards).
  [[nodiscard]] PreparedScan release_scan() &&;

 private:
  std::unique_ptr<PreparedScan> scan_;
  std::unique_ptr<detail::ScanState> state_;
  int threads_ = 1;
  std::vector<float> dist_;  // descriptor distance of each feature to its current word
  struct Pending;
  std::unique_ptr<Pending> pending_;
};

/// A candidate: the feature `feature` of scan `scan`.
struct LearnCandidate {
  std::uint32_t scan = 0;
  std::uint32_t feature = 0;
  friend bool operator==(const LearnCandidate& a, const LearnCandidate& b) {
    return a.scan == b.scan && a.feature == b.feature;
  }
};

/// The word radius learning uses for a set of scans: params.word_radius when given, else
/// that of the first scan with points (derive_word_radius), else 0.25 m. `first_nonempty`:
/// the set's first scan with points, or null when none has any.
[[nodiscard]] double learn_word_radius(const ModelParams& params, const Cloud* first_nonempty);

/// The loop's side of learning: the candidates in their seeded order and the BIC decisions.
class LearnDecisions {
 public:
  /// `feature_counts[s]`, `point_counts[s]`, `log_likelihoods[s]`: scan s's features,
  /// points and initial ln L (LearnScan's, before any word). Throws std::invalid_argument
  /// for invalid params or arrays of different lengths.
  LearnDecisions(const LearnParams& params, const std::vector<std::size_t>& feature_counts,
                 const std::vector<std::size_t>& point_counts, const std::vector<double>& log_likelihoods);
  /// The same, with the counts and initial ln L read from the scans of one process
  /// (`scans[s]` is scan s).
  [[nodiscard]] static LearnDecisions for_scans(const LearnParams& params, const std::vector<LearnScan>& scans);

  /// Every candidate in the order they are drawn (all features of all scans, seeded shuffle).
  [[nodiscard]] const std::vector<LearnCandidate>& candidates() const noexcept { return candidates_; }
  /// The next candidate to draw, or none when the loop is over (max_iterations drawn,
  /// `patience` rejections in a row, or no candidate left).
  [[nodiscard]] const LearnCandidate* next() const;
  /// Whether a cut word is evaluated at all (3 points or more); one that is not is rejected.
  [[nodiscard]] static bool evaluates(const Word& word) noexcept { return word.points.size() >= 3; }
  /// The decision on the drawn candidate given the sum over scans, in scan order from
  /// 0.0, of LearnScan::evaluate (0 when not evaluated). Does not record it.
  [[nodiscard]] bool accepts(const Word& word, double delta_log_likelihood) const;
  /// Records an accepted candidate: `log_likelihood` is the sum, in scan order from 0.0,
  /// of LearnScan::commit(true); the word joins `alphabet_points`.
  void accept(const Word& word, double log_likelihood);
  /// Records a rejected candidate.
  void reject();

  [[nodiscard]] int iteration() const noexcept { return iteration_; }
  [[nodiscard]] double bic() const noexcept { return current_bic_; }
  [[nodiscard]] double log_likelihood() const noexcept { return log_l_; }
  [[nodiscard]] std::size_t alphabet_points() const noexcept { return alphabet_points_; }
  [[nodiscard]] std::size_t total_points() const noexcept { return total_points_; }
  [[nodiscard]] std::size_t accepted() const noexcept { return accepted_; }
  [[nodiscard]] std::size_t rejected() const noexcept { return rejected_; }
  /// BIC after every candidate (the first entry: the empty alphabet).
  [[nodiscard]] const std::vector<double>& bic_history() const noexcept { return bic_history_; }
  [[nodiscard]] const std::vector<bool>& accepted_history() const noexcept { return accepted_history_; }
  /// The progress report after the last candidate recorded.
  [[nodiscard]] LearnProgress progress(std::size_t alphabet_size) const;

 private:
  LearnParams params_;
  std::vector<LearnCandidate> candidates_;
  std::size_t total_points_ = 0;
  std::size_t alphabet_points_ = 0;
  double log_l_ = 0.0;
  double current_bic_ = 0.0;
  int iteration_ = 0;
  int since_accept_ = 0;
  std::size_t accepted_ = 0;
  std::size_t rejected_ = 0;
  std::vector<double> bic_history_;
  std::vector<bool> accepted_history_;
};

}  // namespace lex3d

#pragma GCC visibility pop
