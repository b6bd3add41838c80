// The alphabet learner of ruhnke2010 §III: draw a candidate word, keep it when the
// BIC drops. Adding a word moves to it every feature whose descriptor is nearer to it
// than to its current word; only the points near those features are re-scored.
// LearnScan holds one scan's side, LearnDecisions the BIC loop (lex3d/model/learn.hpp);
// learn_alphabet runs both in one process.

#include "lex3d/model/learn.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <random>
#include <stdexcept>
#include <string>

#include "lex3d/core/parallel.hpp"
#include "lex3d/core/timer.hpp"
#include "lex3d/model/model.hpp"
#include "model/scan_state.hpp"

namespace lex3d {

void LearnParams::validate() const {
  model.validate();
  if (max_iterations < 1 || max_iterations > 1000000)
    throw std::invalid_argument("LearnParams::max_iterations must be in [1, 1e6]");
  if (patience < 1 || patience > 1000000) throw std::invalid_argument("LearnParams::patience must be in [1, 1e6]");
}

// ---------------------------------------------------------------- one scan's side

struct LearnScan::Pending {
  std::vector<detail::ScanState::Change> changes;
  std::vector<float> new_dist;
  bool valid = false;
};

LearnScan::LearnScan(PreparedScan scan, int threads)
    : scan_(std::make_unique<PreparedScan>(std::move(scan))), threads_(threads), pending_(std::make_unique<Pending>()) {
  if (threads < 1 || threads > 64) throw std::invalid_argument("LearnScan threads must be in [1, 64]");
  state_ = std::make_unique<detail::ScanState>(*scan_, threads);
  dist_.assign(scan_->features.size(), std::numeric_limits<float>::infinity());
}

LearnScan::~LearnScan() = default;
LearnScan::LearnScan(LearnScan&&) noexcept = default;
LearnScan& LearnScan::operator=(LearnScan&&) noexcept = default;

double LearnScan::log_likelihood() const { return state_->log_likelihood(); }

Word LearnScan::cut_word(std::size_t feature, double point_spacing) const {
  const PreparedScan& src = *scan_;
  if (feature >= src.features.size())
    throw std::out_of_range("LearnScan::cut_word: feature " + std::to_string(feature) + " of a scan with " +
                            std::to_string(src.features.size()));
  const Eigen::Isometry3f T = src.features.features[feature].T_cloud_feature.cast<float>();
  const std::vector<std::uint32_t> nearby(src.nearby(feature), src.nearby(feature) + src.nearby_count(feature));
  return lex3d::cut_word(src.cloud.points, nearby, T, src.features.descriptor(feature), src.features.descriptor_dim,
                         src.word_radius, point_spacing);
}

double LearnScan::evaluate(const Word& word, std::int32_t word_id) {
  const PreparedScan& sc = *scan_;
  const int dim = sc.features.descriptor_dim;
  if (sc.features.size() > 0 && static_cast<int>(word.descriptor.size()) != dim)
    throw std::invalid_argument("LearnScan::evaluate: a word of " + std::to_string(word.descriptor.size()) +
                                " descriptor values for a scan of " + std::to_string(dim));
  auto& ch = pending_->changes;
  auto& nd = pending_->new_dist;
  ch.clear();
  nd.clear();
  pending_->valid = true;
  for (std::size_t f = 0; f < sc.features.size(); ++f) {
    const float d = descriptor_distance_sq(sc.features.descriptor(f), word.descriptor.data(), dim);
    if (d < dist_[f]) {
      detail::ScanState::Change c;
      c.feature = static_cast<std::uint32_t>(f);
      c.word = word_id;
      c.word_points = static_cast<std::uint32_t>(word.points.size());
      ch.push_back(std::move(c));
      nd.push_back(d);
    }
  }
  if (ch.empty()) return state_->delta_log_likelihood(ch);
  const detail::PackedWord packed(word);
  parallel_for(ch.size(), threads_, [&](std::size_t i) { state_->contribution(ch[i].feature, packed, ch[i].contrib); }, 8);
  return state_->delta_log_likelihood(ch);
}

double LearnScan::commit(bool accept) {
  if (accept) {
    if (!pending_->valid) throw std::logic_error("LearnScan::commit(true) without an evaluated word");
    const auto& ch = pending_->changes;
    for (std::size_t i = 0; i < ch.size(); ++i) dist_[ch[i].feature] = pending_->new_dist[i];
    state_->apply(ch);
    state_->recompute();
  }
  pending_->changes.clear();
  pending_->new_dist.clear();
  pending_->valid = false;
  return state_->log_likelihood();
}

Model LearnScan::finish(const Alphabet& alphabet, const ModelParams& params, bool prune) {
  // As encode_scan does: words by fit, pruning, then the ICP fit of what is kept (and
  // the likelihood of the final poses).
  const double radius = scan_->word_radius;
  state_->choose_by_fit(alphabet, params.fit_candidates, threads_);
  if (prune) state_->prune(alphabet, threads_, params.prune_keeps_sole_cover);
  state_->refine(alphabet, params.refine_iterations, params.refine_reach_factor * radius, threads_);
  state_->rescore(alphabet, threads_);
  return state_->model();
}

PreparedScan LearnScan::release_scan() && {
  state_.reset();  // it refers to the scan
  PreparedScan s = std::move(*scan_);
  scan_.reset();
  return s;
}

// ---------------------------------------------------------------- the loop's side

double learn_word_radius(const ModelParams& params, const Cloud* first_nonempty) {
  if (params.word_radius > 0.0) return params.word_radius;
  if (first_nonempty != nullptr && !first_nonempty->empty()) return derive_word_radius(*first_nonempty);
  return 0.25;
}

LearnDecisions::LearnDecisions(const LearnParams& params, const std::vector<std::size_t>& feature_counts,
                               const std::vector<std::size_t>& point_counts, const std::vector<double>& log_likelihoods)
    : params_(params) {
  params.validate();
  if (point_counts.size() != feature_counts.size() || log_likelihoods.size() != feature_counts.size())
    throw std::invalid_argument("LearnDecisions: feature_counts, point_counts and log_likelihoods must have one entry a scan");
  if (feature_counts.size() > std::numeric_limits<std::uint32_t>::max())
    throw std::invalid_argument("LearnDecisions: at most 2^32 - 1 scans");
  for (std::size_t s = 0; s < feature_counts.size(); ++s) {
    total_points_ += point_counts[s];
    log_l_ += log_likelihoods[s];
  }
  current_bic_ = lex3d::bic(log_l_, 0, total_points_);
  bic_history_.push_back(current_bic_);

  // Candidates: every feature of every scan, in a seeded random order.
  std::size_t total = 0;
  for (const std::size_t c : feature_counts) total += c;
  candidates_.reserve(total);
  for (std::size_t s = 0; s < feature_counts.size(); ++s)
    for (std::size_t f = 0; f < feature_counts[s]; ++f)
      candidates_.push_back({static_cast<std::uint32_t>(s), static_cast<std::uint32_t>(f)});
  std::mt19937_64 rng(params.seed);
  std::shuffle(candidates_.begin(), candidates_.end(), rng);
}

LearnDecisions LearnDecisions::for_scans(const LearnParams& params, const std::vector<LearnScan>& scans) {
  std::vector<std::size_t> features, points;
  std::vector<double> log_ls;
  features.reserve(scans.size());
  points.reserve(scans.size());
  log_ls.reserve(scans.size());
  for (const auto& s : scans) {
    features.push_back(s.feature_count());
    points.push_back(s.point_count());
    log_ls.push_back(s.log_likelihood());
  }
  return LearnDecisions(params, features, points, log_ls);
}

const LearnCandidate* LearnDecisions::next() const {
  if (iteration_ >= params_.max_iterations || since_accept_ >= params_.patience) return nullptr;
  if (static_cast<std::size_t>(iteration_) >= candidates_.size()) return nullptr;
  return &candidates_[static_cast<std::size_t>(iteration_)];
}

bool LearnDecisions::accepts(const Word& word, double delta_log_likelihood) const {
  const double candidate_bic = lex3d::bic(log_l_ + delta_log_likelihood, alphabet_points_ + word.points.size(), total_points_);
  return evaluates(word) && candidate_bic < current_bic_;
}

void LearnDecisions::accept(const Word& word, double log_likelihood) {
  ++iteration_;
  log_l_ = log_likelihood;
  alphabet_points_ += word.points.size();
  current_bic_ = lex3d::bic(log_l_, alphabet_points_, total_points_);
  ++accepted_;
  since_accept_ = 0;
  bic_history_.push_back(current_bic_);
  accepted_history_.push_back(true);
}

void LearnDecisions::reject() {
  ++iteration_;
  ++rejected_;
  ++since_accept_;
  bic_history_.push_back(current_bic_);
  accepted_history_.push_back(false);
}

LearnProgress LearnDecisions::progress(std::size_t alphabet_size) const {
  const bool last = !accepted_history_.empty() && accepted_history_.back();
  return {iteration_, std::min<int>(params_.max_iterations, static_cast<int>(std::min<std::size_t>(candidates_.size(), 1000000))),
          current_bic_, alphabet_size, last};
}

// ---------------------------------------------------------------- both in one process

LearnResult learn_alphabet(const std::vector<Cloud>& clouds, const LearnParams& params,
                           const std::function<void(const LearnProgress&)>& progress) {
  params.validate();
  LearnResult res;
  Stopwatch sw;
  const int threads = params.model.threads;

  // One word radius for the whole set: the first non-empty scan's unless given.
  const Cloud* first = nullptr;
  for (const auto& c : clouds)
    if (!c.empty()) {
      first = &c;
      break;
    }
  const double radius = learn_word_radius(params.model, first);
  std::vector<LearnScan> scans;
  scans.reserve(clouds.size());
  for (const auto& c : clouds) scans.emplace_back(prepare_scan(c, params.model, radius), threads);
  res.alphabet.word_radius = radius;
  res.alphabet.point_spacing = params.model.word_spacing_factor * radius;
  res.alphabet.descriptor_dim = scans.empty() ? 0 : scans.front().scan().features.descriptor_dim;
  res.prepare_ms = sw.lap_ms();

  LearnDecisions loop = LearnDecisions::for_scans(params, scans);

  while (const LearnCandidate* c = loop.next()) {
    Word word = scans[c->scan].cut_word(c->feature, res.alphabet.point_spacing);
    const auto word_id = static_cast<std::int32_t>(res.alphabet.size());
    double delta_l = 0.0;
    if (LearnDecisions::evaluates(word))
      for (auto& s : scans) delta_l += s.evaluate(word, word_id);
    if (loop.accepts(word, delta_l)) {
      double log_l = 0.0;
      for (auto& s : scans) log_l += s.commit(true);
      loop.accept(word, log_l);
      res.alphabet.words.push_back(std::move(word));
    } else {
      loop.reject();
    }
    if (progress) progress(loop.progress(res.alphabet.size()));
  }
  res.bic_history = loop.bic_history();
  res.accepted_history = loop.accepted_history();
  res.accepted = loop.accepted();
  res.rejected = loop.rejected();
  res.learn_ms = sw.lap_ms();

  res.log_likelihood = 0.0;
  for (auto& s : scans) {
    res.models.push_back(s.finish(res.alphabet, params.model, params.prune));
    res.log_likelihood += s.log_likelihood();
  }
  res.final_bic = bic(res.log_likelihood, loop.alphabet_points(), loop.total_points());
  res.scans.reserve(scans.size());
  for (auto& s : scans) res.scans.push_back(std::move(s).release_scan());
  res.prune_ms = sw.lap_ms();
  return res;
}

}  // namespace lex3d
