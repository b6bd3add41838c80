// The alphabet learner of ruhnke2010 §III: draw a candidate word, keep it when the
// BIC drops. Adding a word moves to it every feature whose descriptor is nearer to it
// than to its current word; only the points near those features are re-scored.

#include <algorithm>
#include <cmath>
#include <numeric>
#include <random>
#include <stdexcept>

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

LearnResult learn_alphabet(const std::vector<Cloud>& clouds, const LearnParams& params,
                           const std::function<void(const LearnProgress&)>& progress) {
  params.validate();
  LearnResult res;
  Stopwatch sw;
  const int threads = params.model.threads;

  // One word radius for the whole set: the first non-empty scan's unless given.
  double radius = params.model.word_radius;
  if (radius <= 0.0) {
    radius = 0.25;
    for (const auto& c : clouds)
      if (!c.empty()) {
        radius = derive_word_radius(c);
        break;
      }
  }
  res.scans.reserve(clouds.size());
  for (const auto& c : clouds) res.scans.push_back(prepare_scan(c, params.model, radius));
  res.alphabet.word_radius = radius;
  res.alphabet.point_spacing = params.model.word_spacing_factor * radius;
  res.alphabet.descriptor_dim = res.scans.empty() ? 0 : res.scans.front().features.descriptor_dim;
  res.prepare_ms = sw.lap_ms();

  std::vector<detail::ScanState> states;
  states.reserve(res.scans.size());
  std::size_t total_points = 0;
  for (const auto& s : res.scans) {
    states.emplace_back(s, threads);
    total_points += s.cloud.size();
  }
  double log_l = 0.0;
  for (const auto& st : states) log_l += st.log_likelihood();
  std::size_t alphabet_points = 0;
  double current_bic = bic(log_l, 0, total_points);
  res.bic_history.push_back(current_bic);

  // Candidates: every feature of every scan, in a seeded random order.
  std::vector<std::pair<std::uint32_t, std::uint32_t>> candidates;
  for (std::size_t s = 0; s < res.scans.size(); ++s)
    for (std::size_t f = 0; f < res.scans[s].features.size(); ++f)
      candidates.emplace_back(static_cast<std::uint32_t>(s), static_cast<std::uint32_t>(f));
  std::mt19937_64 rng(params.seed);
  std::shuffle(candidates.begin(), candidates.end(), rng);

  // Per scan: descriptor distance of each feature to its current word.
  std::vector<std::vector<float>> dist(res.scans.size());
  for (std::size_t s = 0; s < res.scans.size(); ++s)
    dist[s].assign(res.scans[s].features.size(), std::numeric_limits<float>::infinity());

  const int dim = res.alphabet.descriptor_dim;
  int since_accept = 0;
  int iteration = 0;
  std::vector<std::vector<detail::ScanState::Change>> changes(res.scans.size());
  std::vector<std::vector<float>> new_dist(res.scans.size());
  for (const auto& [s0, f0] : candidates) {
    if (iteration >= params.max_iterations || since_accept >= params.patience) break;
    ++iteration;
    const PreparedScan& src = res.scans[s0];
    const Eigen::Isometry3f T = src.features.features[f0].T_cloud_feature.cast<float>();
    const std::vector<std::uint32_t> nearby(src.nearby(f0), src.nearby(f0) + src.nearby_count(f0));
    Word word = cut_word(src.cloud.points, nearby, T, src.features.descriptor(f0), dim, radius,
                         res.alphabet.point_spacing);
    const auto word_id = static_cast<std::int32_t>(res.alphabet.size());
    double delta_l = 0.0;
    if (word.points.size() >= 3) {
      const detail::PackedWord packed(word);
      for (std::size_t s = 0; s < res.scans.size(); ++s) {
        const PreparedScan& sc = res.scans[s];
        auto& ch = changes[s];
        ch.clear();
        auto& nd = new_dist[s];
        nd.clear();
        for (std::size_t f = 0; f < sc.features.size(); ++f) {
          const float d = descriptor_distance_sq(sc.features.descriptor(f), word.descriptor.data(), dim);
          if (d < dist[s][f]) {
            detail::ScanState::Change c;
            c.feature = static_cast<std::uint32_t>(f);
            c.word = word_id;
            c.word_points = static_cast<std::uint32_t>(word.points.size());
            ch.push_back(std::move(c));
            nd.push_back(d);
          }
        }
        parallel_for(ch.size(), threads, [&](std::size_t i) { states[s].contribution(ch[i].feature, packed, ch[i].contrib); }, 8);
        delta_l += states[s].delta_log_likelihood(ch);
      }
    }
    const double candidate_bic = bic(log_l + delta_l, alphabet_points + word.points.size(), total_points);
    const bool accept = word.points.size() >= 3 && candidate_bic < current_bic;
    if (accept) {
      log_l = 0.0;
      for (std::size_t s = 0; s < res.scans.size(); ++s) {
        for (std::size_t i = 0; i < changes[s].size(); ++i) dist[s][changes[s][i].feature] = new_dist[s][i];
        states[s].apply(changes[s]);
        states[s].recompute();
        log_l += states[s].log_likelihood();
      }
      alphabet_points += word.points.size();
      current_bic = bic(log_l, alphabet_points, total_points);
      res.alphabet.words.push_back(std::move(word));
      ++res.accepted;
      since_accept = 0;
    } else {
      ++res.rejected;
      ++since_accept;
    }
    res.bic_history.push_back(current_bic);
    res.accepted_history.push_back(accept);
    if (progress)
      progress({iteration, std::min<int>(params.max_iterations, static_cast<int>(candidates.size())), current_bic,
                res.alphabet.size(), accept});
  }
  res.learn_ms = sw.lap_ms();

  for (std::size_t s = 0; s < states.size(); ++s) {
    // As encode_scan does: words by fit, pruning, then the ICP fit of what is kept (and
    // the likelihood of the final poses).
    states[s].choose_by_fit(res.alphabet, params.model.fit_candidates, threads);
    if (params.prune) states[s].prune(res.alphabet, threads, params.model.prune_keeps_sole_cover);
    states[s].refine(res.alphabet, params.model.refine_iterations, params.model.refine_reach_factor * radius, threads);
    states[s].rescore(res.alphabet, threads);
  }
  res.log_likelihood = 0.0;
  for (const auto& st : states) {
    res.log_likelihood += st.log_likelihood();
    res.models.push_back(st.model());
  }
  res.final_bic = bic(res.log_likelihood, alphabet_points, total_points);
  res.prune_ms = sw.lap_ms();
  return res;
}

}  // namespace lex3d
