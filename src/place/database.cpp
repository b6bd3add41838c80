// The place database: scans, the inverted index word id -> scans, tf-idf retrieval and
// verified queries.

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "lex3d/core/parallel.hpp"
#include "lex3d/core/timer.hpp"
#include "lex3d/place/place.hpp"

namespace lex3d {

PlaceDatabase::PlaceDatabase(PlaceStorageParams storage) : storage_(storage) { storage_.validate(); }

std::size_t PlaceDatabase::add(PlaceScan scan) {
  if (!scans_.empty() && !scan.features.empty() && !scans_.front().features.empty() &&
      scan.descriptor_dim != scans_.front().descriptor_dim)
    throw std::invalid_argument("PlaceDatabase::add: scan '" + scan.name + "' has descriptors of " +
                                std::to_string(scan.descriptor_dim) + " values, the database " +
                                std::to_string(scans_.front().descriptor_dim));
  if (scan.descriptor_bits != storage_.descriptor_bits)
    throw std::invalid_argument("PlaceDatabase::add: scan '" + scan.name + "' was quantised to " +
                                std::to_string(scan.descriptor_bits) + " bits, the database uses " +
                                std::to_string(storage_.descriptor_bits));
  const auto index = static_cast<std::uint32_t>(scans_.size());
  std::uint32_t total = 0;
  for (const auto& [word, count] : scan.words) {
    if (word >= inverted_.size()) inverted_.resize(static_cast<std::size_t>(word) + 1);
    inverted_[word].push_back({index, count});
    total += count;
  }
  scan_word_total_.push_back(total);
  scans_.push_back(std::move(scan));
  return index;
}

std::vector<std::pair<std::size_t, double>> PlaceDatabase::retrieve(const PlaceScan& query, std::size_t k) const {
  std::vector<std::pair<std::size_t, double>> out;
  const std::size_t n = scans_.size();
  if (n == 0 || k == 0) return out;
  std::vector<double> idf(inverted_.size(), 0.0);
  for (std::size_t w = 0; w < inverted_.size(); ++w)
    if (!inverted_[w].empty()) idf[w] = std::log(1.0 + static_cast<double>(n) / static_cast<double>(inverted_[w].size()));
  // Database vectors' norms (tf = count / instances of the scan).
  std::vector<double> norm2(n, 0.0);
  for (std::size_t w = 0; w < inverted_.size(); ++w)
    for (const auto& p : inverted_[w]) {
      const double v = static_cast<double>(p.count) / static_cast<double>(scan_word_total_[p.scan]) * idf[w];
      norm2[p.scan] += v * v;
    }
  double qtotal = 0.0;
  for (const auto& wc : query.words) qtotal += wc.second;
  if (qtotal <= 0.0) return out;
  std::vector<double> dot(n, 0.0);
  double qnorm2 = 0.0;
  for (const auto& [word, count] : query.words) {
    if (word >= inverted_.size() || inverted_[word].empty()) continue;
    const double qv = static_cast<double>(count) / qtotal * idf[word];
    qnorm2 += qv * qv;
    for (const auto& p : inverted_[word])
      dot[p.scan] += qv * static_cast<double>(p.count) / static_cast<double>(scan_word_total_[p.scan]) * idf[word];
  }
  if (qnorm2 <= 0.0) return out;
  for (std::size_t i = 0; i < n; ++i)
    if (dot[i] > 0.0 && norm2[i] > 0.0) out.emplace_back(i, dot[i] / std::sqrt(norm2[i] * qnorm2));
  const std::size_t keep = std::min(k, out.size());
  std::partial_sort(out.begin(), out.begin() + static_cast<std::ptrdiff_t>(keep), out.end(),
                    [](const auto& a, const auto& b) { return a.second != b.second ? a.second > b.second : a.first < b.first; });
  out.resize(keep);
  return out;
}

PlaceQueryResult PlaceDatabase::query(const PlaceScan& query, const PlaceParams& params) const {
  params.validate();
  PlaceQueryResult r;
  Stopwatch sw;
  const auto cands = retrieve(query, static_cast<std::size_t>(params.top_k));
  r.retrieved = cands.size();
  r.retrieval_ms = sw.lap_ms();
  r.matches.resize(cands.size());
  // Feature transforms of every candidate, then dense alignment of the best few.
  PlaceParams coarse = params;
  coarse.dense_iterations = 0;
  parallel_for(
      cands.size(), params.threads,
      [&](std::size_t i) {
        PlaceMatch m = match_scans(query, scans_[cands[i].first], coarse);
        m.scan = cands[i].first;
        m.retrieval_similarity = cands[i].second;
        r.matches[i] = std::move(m);
      },
      1);
  auto order = [](const PlaceMatch& a, const PlaceMatch& b) {
    if (a.valid != b.valid) return a.valid;
    if (a.score != b.score) return a.score > b.score;
    return a.scan < b.scan;
  };
  std::stable_sort(r.matches.begin(), r.matches.end(), order);
  if (params.dense_iterations > 0) {
    const std::size_t nd = std::min(r.matches.size(), static_cast<std::size_t>(params.dense_candidates));
    parallel_for(
        nd, params.threads, [&](std::size_t i) { refine_match(query, scans_[r.matches[i].scan], r.matches[i], params); },
        1);
    // Densely aligned candidates first: their scores are not comparable with the others'.
    std::stable_sort(r.matches.begin(), r.matches.end(), [&](const PlaceMatch& a, const PlaceMatch& b) {
      if (a.dense_refined != b.dense_refined) return a.dense_refined;
      return order(a, b);
    });
  }
  r.accepted = !r.matches.empty() && r.matches.front().valid && r.matches.front().score >= params.accept_score;
  r.verification_ms = sw.lap_ms();
  return r;
}

}  // namespace lex3d
