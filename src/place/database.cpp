// The place database: scans (stored ones read when needed, added ones in memory), the
// inverted index word id -> scans, tf-idf retrieval and verified queries.

#include <algorithm>
#include <iterator>
#include <cmath>
#include <cstring>
#include <list>
#include <mutex>
#include <unordered_map>
#include <stdexcept>
#include <string>

#include "lex3d/core/parallel.hpp"
#include "lex3d/core/timer.hpp"
#include "lex3d/place/place.hpp"
#include "place/internal.hpp"

namespace lex3d {

namespace {

using detail::ld32;
using detail::ld64;
using detail::ldf64;
constexpr std::size_t kEntryBytes = 36;  // formats/place_db.md §3.4

}  // namespace

// Recently decoded stored scans, least recently used first out.
struct PlaceDatabase::DecodedCache {
  std::mutex mutex;
  std::size_t capacity = 32;
  std::list<std::pair<std::size_t, std::shared_ptr<const PlaceScan>>> lru;  // most recent first
  std::unordered_map<std::size_t, decltype(lru)::iterator> where;
};

PlaceDatabase::PlaceDatabase(PlaceStorageParams storage)
    : storage_(storage), norm_cache_(std::make_shared<NormCache>()), global_norm_cache_(std::make_shared<NormCache>()),
      decoded_cache_(std::make_shared<DecodedCache>()),
      vnorm_cache_(std::make_shared<NormCache>()) {
  storage_.validate();
}

void PlaceDatabase::set_decoded_cache(std::size_t scans) {
  auto c = std::make_shared<DecodedCache>();
  c->capacity = scans;
  decoded_cache_ = std::move(c);
}

StatusOr<std::shared_ptr<const PlaceScan>> PlaceDatabase::decoded(std::size_t i, double& decode_ms) const {
  DecodedCache& c = *decoded_cache_;
  {
    std::lock_guard<std::mutex> lock(c.mutex);
    const auto it = c.where.find(i);
    if (it != c.where.end()) {
      c.lru.splice(c.lru.begin(), c.lru, it->second);
      return it->second->second;
    }
  }
  Stopwatch sw;
  auto x = read_scan(i);
  decode_ms = sw.elapsed_ms();
  if (!x.ok()) return x.status();
  auto s = std::make_shared<const PlaceScan>(std::move(x).value());
  std::lock_guard<std::mutex> lock(c.mutex);
  if (c.capacity == 0 || c.where.count(i) != 0) return s;
  c.lru.emplace_front(i, s);
  c.where[i] = c.lru.begin();
  while (c.lru.size() > c.capacity) {
    c.where.erase(c.lru.back().first);
    c.lru.pop_back();
  }
  return s;
}

std::size_t PlaceDatabase::add(PlaceScan scan) {
  if (scan.descriptor != storage_.descriptor)
    throw std::invalid_argument("PlaceDatabase::add: scan '" + scan.name + "' has " + to_string(scan.descriptor) +
                                " descriptors, the database " + to_string(storage_.descriptor));
  if (!scan.features.empty() && descriptor_dim_ != 0 && scan.descriptor_dim != descriptor_dim_ &&
      (index_.scans > 0 || !added_.empty()))
    throw std::invalid_argument("PlaceDatabase::add: scan '" + scan.name + "' has descriptors of " +
                                std::to_string(scan.descriptor_dim) + " values, the database " +
                                std::to_string(descriptor_dim_));
  if (scan.descriptor_bits != storage_.descriptor_bits)
    throw std::invalid_argument("PlaceDatabase::add: scan '" + scan.name + "' was quantised to " +
                                std::to_string(scan.descriptor_bits) + " bits, the database uses " +
                                std::to_string(storage_.descriptor_bits));
  if (vocabulary_ != nullptr && !scan.features.empty() && scan.descriptor_dim != vocabulary_->descriptor_dim)
    throw std::invalid_argument("PlaceDatabase::add: scan '" + scan.name + "' has descriptors of " +
                                std::to_string(scan.descriptor_dim) + " values, the recognition vocabulary " +
                                std::to_string(vocabulary_->descriptor_dim));
  // Word ids index the inverted lists; one out of range (a scan decoded from damaged bytes)
  // would otherwise grow them to its size.
  const std::size_t word_limit = has_alphabet_ ? alphabet_.size() : kMaxWordsWithoutAlphabet;
  for (const auto& wc : scan.words)
    if (wc.first >= word_limit)
      throw std::invalid_argument("PlaceDatabase::add: scan '" + scan.name + "' holds word " + std::to_string(wc.first) +
                                  (has_alphabet_ ? ", the database's alphabet has " + std::to_string(alphabet_.size()) + " words"
                                                 : ", beyond the " + std::to_string(kMaxWordsWithoutAlphabet) +
                                                       " words a database without an alphabet takes"));
  if (!scan.features.empty()) descriptor_dim_ = scan.descriptor_dim;
  const auto index = static_cast<std::uint32_t>(size());
  std::uint32_t total = 0;
  for (const auto& [word, count] : scan.words) {
    if (word >= added_inverted_.size()) added_inverted_.resize(static_cast<std::size_t>(word) + 1);
    added_inverted_[word].push_back({index, count});
    total += count;
  }
  added_total_.push_back(total);
  if (vocabulary_ != nullptr) {
    std::uint32_t vtotal = 0;
    for (const auto& [word, count] : detail::vocabulary_words(*vocabulary_, scan)) {
      if (word >= added_vinverted_.size()) added_vinverted_.resize(static_cast<std::size_t>(word) + 1);
      added_vinverted_[word].push_back({index, count});
      vtotal += count;
    }
    added_vtotal_.push_back(vtotal);
    vnorm_cache_ = std::make_shared<NormCache>();
  }
  added_.push_back(std::move(scan));
  norm_cache_ = std::make_shared<NormCache>();  // idf changed; copies keep their own cache
  global_norm_cache_ = std::make_shared<NormCache>();
  return index;
}

const std::vector<double>& PlaceDatabase::norms() const {
  NormCache& c = *norm_cache_;
  std::lock_guard<std::mutex> lock(c.mutex);
  if (c.valid) return c.norm2;
  detail::tfidf_norms(size(), index_, added_inverted_, [this](std::uint32_t s) { return word_total(s); }, c.norm2);
  c.valid = true;
  return c.norm2;
}

template <class Idf, class Norm2>
std::vector<std::pair<std::size_t, double>> PlaceDatabase::rank_tfidf(const PlaceScan& query, std::size_t k, Idf idf,
                                                                      Norm2 norm2) const {
  std::vector<std::pair<std::size_t, double>> out;
  const std::size_t n = size();
  if (n == 0 || k == 0) return out;
  double qtotal = 0.0;
  for (const auto& wc : query.words) qtotal += wc.second;
  if (qtotal <= 0.0) return out;
  std::vector<double> dot(n, 0.0);
  double qnorm2 = 0.0;
  for (const auto& [word, count] : query.words) {
    const double w_idf = idf(word);
    if (w_idf == 0.0) continue;
    const double qv = static_cast<double>(count) / qtotal * w_idf;
    qnorm2 += qv * qv;
    const std::size_t ns = stored_postings(word);
    if (ns > 0) {
      const std::uint8_t* p = index_.postings + 8 * ld64(index_.word_start + 8 * static_cast<std::size_t>(word));
      for (std::size_t j = 0; j < ns; ++j, p += 8) {
        const std::uint32_t s = ld32(p);
        dot[s] += qv * static_cast<double>(ld32(p + 4)) / static_cast<double>(ld32(index_.entries + s * kEntryBytes + 16)) * w_idf;
      }
    }
    if (word < added_inverted_.size())
      for (const auto& p : added_inverted_[word])
        dot[p.scan] += qv * static_cast<double>(p.count) / static_cast<double>(word_total(p.scan)) * w_idf;
  }
  if (qnorm2 <= 0.0) return out;
  for (std::size_t i = 0; i < n; ++i) {
    if (!(dot[i] > 0.0)) continue;
    const double n2 = norm2(i);
    if (n2 > 0.0) out.emplace_back(i, dot[i] / std::sqrt(n2 * qnorm2));
  }
  const std::size_t keep = std::min(k, out.size());
  std::partial_sort(out.begin(), out.begin() + static_cast<std::ptrdiff_t>(keep), out.end(),
                    [](const auto& a, const auto& b) { return a.second != b.second ? a.second > b.second : a.first < b.first; });
  out.resize(keep);
  return out;
}

std::vector<std::pair<std::size_t, double>> PlaceDatabase::retrieve(const PlaceScan& query, std::size_t k) const {
  const std::size_t n = size();
  const auto idf = [&](std::uint32_t word) {
    const std::size_t df = stored_postings(word) + (word < added_inverted_.size() ? added_inverted_[word].size() : 0);
    return df == 0 ? 0.0 : std::log(1.0 + static_cast<double>(n) / static_cast<double>(df));
  };
  // Without added entries the norms stored with the index (computed for this N).
  if (added_.empty())
    return rank_tfidf(query, k, idf, [&](std::size_t i) { return ldf64(index_.entries + i * kEntryBytes + 28); });
  const std::vector<double>& norm2 = norms();
  return rank_tfidf(query, k, idf, [&](std::size_t i) { return norm2[i]; });
}

PlaceWordStatistics& PlaceWordStatistics::operator+=(const PlaceWordStatistics& other) {
  scans += other.scans;
  if (df.size() < other.df.size()) df.resize(other.df.size(), 0);
  for (std::size_t w = 0; w < other.df.size(); ++w) df[w] += other.df[w];
  return *this;
}

PlaceWordStatistics PlaceDatabase::word_statistics() const {
  PlaceWordStatistics st;
  st.scans = size();
  const std::size_t words = std::max<std::size_t>(index_.word_slots, added_inverted_.size());
  st.df.assign(words, 0);
  for (std::size_t w = 0; w < words; ++w)
    st.df[w] = stored_postings(static_cast<std::uint32_t>(w)) + (w < added_inverted_.size() ? added_inverted_[w].size() : 0);
  while (!st.df.empty() && st.df.back() == 0) st.df.pop_back();
  return st;
}

std::vector<std::pair<std::size_t, double>> PlaceDatabase::retrieve(const PlaceScan& query, std::size_t k,
                                                                    const PlaceWordStatistics& global) const {
  const std::size_t n = size();
  if (global.scans < n)
    throw std::invalid_argument("PlaceDatabase::retrieve: the global statistics hold " + std::to_string(global.scans) +
                                " scans, this database " + std::to_string(n));
  auto global_df = [&](std::size_t w) { return w < global.df.size() ? global.df[w] : std::uint64_t{0}; };
  const auto N = static_cast<double>(global.scans);
  // The entries' norms under the global idf, kept while the same statistics come.
  std::vector<double> norm2;
  {
    NormCache& c = *global_norm_cache_;
    std::lock_guard<std::mutex> lock(c.mutex);
    if (!c.valid || !(c.stats == global)) {
      c.valid = false;
      detail::tfidf_norms_with(
          n, index_, added_inverted_, [this](std::uint32_t s) { return word_total(s); },
          [&](std::size_t w, std::size_t postings) {
            const std::uint64_t g = global_df(w);
            if (g < postings)
              throw std::invalid_argument("PlaceDatabase::retrieve: the global statistics hold " + std::to_string(g) +
                                          " scans with word " + std::to_string(w) + ", this database " +
                                          std::to_string(postings));
            return std::log(1.0 + N / static_cast<double>(g));
          },
          c.norm2);
      c.stats = global;
      c.valid = true;
    }
    norm2 = c.norm2;
  }
  // As retrieve(query, k), with the global document frequencies.
  return rank_tfidf(
      query, k,
      [&](std::uint32_t word) {
        const std::uint64_t g = global_df(word);
        return g == 0 ? 0.0 : std::log(1.0 + N / static_cast<double>(g));
      },
      [&](std::size_t i) { return norm2[i]; });
}

namespace {

// The order of verified matches: valid ones first, then by score, then by lower index.
bool match_order(const PlaceMatch& a, const PlaceMatch& b) {
  if (a.valid != b.valid) return a.valid;
  if (a.score != b.score) return a.score > b.score;
  return a.scan < b.scan;
}

}  // namespace

PlaceVerified PlaceDatabase::verify(const PlaceScan& query, const std::vector<std::pair<std::size_t, double>>& cands,
                                    const PlaceParams& params, bool second_round) const {
  params.validate();
  for (const auto& c : cands)
    if (c.first >= size())
      throw std::out_of_range("PlaceDatabase::verify: candidate " + std::to_string(c.first) + " of a database of " +
                              std::to_string(size()) + " scans");
  PlaceVerified v;
  v.matches.resize(cands.size());
  // Candidates' entries are decoded here (stored ones) and kept for the dense step.
  std::vector<std::shared_ptr<const PlaceScan>> held(cands.size());
  std::vector<const PlaceScan*> cand(cands.size(), nullptr);
  std::vector<Status> errors(cands.size());
  std::vector<double> decode_ms(cands.size(), 0.0);
  std::vector<PlaceMatch> all(cands.size());
  PlaceParams coarse = params;
  coarse.dense_iterations = 0;
  if (second_round) {
    // Candidates ranked lower share fewer words with the query, and their interest points
    // repeat less, so feature hypotheses rarely find them (and they are most of a
    // candidate's cost): the surface hypotheses alone.
    coarse.hypotheses_per_size = 1;
    coarse.gravity_pairs = 0;
  }
  parallel_for(
      cands.size(), params.threads,
      [&](std::size_t i) {
        const std::size_t s = cands[i].first;
        if (s < index_.scans) {
          auto x = decoded(s, decode_ms[i]);
          if (!x.ok()) {
            errors[i] = x.status();
            return;
          }
          held[i] = std::move(x).value();
          cand[i] = held[i].get();
        } else {
          cand[i] = &added_[s - index_.scans];
        }
        PlaceMatch m = match_scans(query, *cand[i], coarse);
        m.scan = s;
        m.retrieval_similarity = cands[i].second;
        v.matches[i] = std::move(m);
      },
      1);
  for (const auto& e : errors)
    if (!e.ok()) throw PlaceDataError(e);
  for (const double d : decode_ms) {
    v.decode_ms += d;
    v.decoded += d > 0.0 ? 1 : 0;
  }
  auto by_index = [&](std::size_t s) -> const PlaceScan& {
    for (std::size_t i = 0; i < cands.size(); ++i)
      if (cands[i].first == s) return *cand[i];
    throw std::logic_error("PlaceDatabase::verify: candidate not found");
  };
  std::stable_sort(v.matches.begin(), v.matches.end(), match_order);
  if (params.dense_iterations > 0) {
    const std::size_t nd = std::min(v.matches.size(), static_cast<std::size_t>(params.dense_candidates));
    v.refined.assign(v.matches.begin(), v.matches.begin() + static_cast<std::ptrdiff_t>(nd));
    parallel_for(
        nd, params.threads, [&](std::size_t i) { refine_match(query, by_index(v.refined[i].scan), v.refined[i], params); },
        1);
  }
  return v;
}

PlaceQueryResult merge_verified(std::vector<PlaceVerified> parts, const std::vector<std::size_t>& offsets,
                                const PlaceParams& params) {
  if (parts.size() != offsets.size())
    throw std::invalid_argument("merge_verified: " + std::to_string(parts.size()) + " parts and " +
                                std::to_string(offsets.size()) + " offsets");
  PlaceQueryResult r;
  std::vector<PlaceMatch> refined;
  for (std::size_t i = 0; i < parts.size(); ++i) {
    for (auto& m : parts[i].matches) {
      m.scan += offsets[i];
      r.matches.push_back(std::move(m));
    }
    for (auto& m : parts[i].refined) {
      m.scan += offsets[i];
      refined.push_back(std::move(m));
    }
    r.decode_ms += parts[i].decode_ms;
    r.decoded += parts[i].decoded;
  }
  std::stable_sort(r.matches.begin(), r.matches.end(), match_order);
  if (params.dense_iterations > 0) {
    const std::size_t nd = std::min(r.matches.size(), static_cast<std::size_t>(params.dense_candidates));
    for (std::size_t i = 0; i < nd; ++i) {
      const auto it = std::find_if(refined.begin(), refined.end(),
                                   [&](const PlaceMatch& m) { return m.scan == r.matches[i].scan; });
      if (it == refined.end())
        throw std::invalid_argument("merge_verified: candidate " + std::to_string(r.matches[i].scan) +
                                    " is among the best " + std::to_string(nd) + " but its part did not align it densely");
      r.matches[i] = *it;
    }
    // Densely aligned candidates first: their scores are not comparable with the others'.
    std::stable_sort(r.matches.begin(), r.matches.end(), [&](const PlaceMatch& a, const PlaceMatch& b) {
      if (a.dense_refined != b.dense_refined) return a.dense_refined;
      return match_order(a, b);
    });
  }
  r.accepted = !r.matches.empty() && r.matches.front().valid && r.matches.front().score >= params.accept_score;
  return r;
}

PlaceQueryResult PlaceDatabase::query(const PlaceScan& query, const PlaceParams& params) const {
  params.validate();
  Stopwatch sw;
  PlaceRetrieval method = resolve(params.retrieval);
  double new_place = -1.0;
  // The first round verifies the top_k candidates; when none is accepted, a second round
  // verifies the next more_candidates (retrieved with the first, in rank order).
  const std::size_t k1 = static_cast<std::size_t>(params.top_k);
  const std::size_t k2 = k1 + static_cast<std::size_t>(params.more_candidates);
  const auto cands = retrieve(query, k2, method, params, method == PlaceRetrieval::kFabmap ? &new_place : nullptr);
  const double retrieval_ms = sw.lap_ms();
  const std::size_t n1 = std::min(k1, cands.size());
  const std::vector<std::pair<std::size_t, double>> first(cands.begin(), cands.begin() + static_cast<std::ptrdiff_t>(n1));
  PlaceQueryResult r = merge_verified({verify(query, first, params)}, {0}, params);
  r.retrieved = n1;
  if (!r.accepted && cands.size() > n1) {
    const std::vector<std::pair<std::size_t, double>> second(cands.begin() + static_cast<std::ptrdiff_t>(n1), cands.end());
    merge_round(r, merge_verified({verify(query, second, params, true)}, {0}, params), params);
    r.retrieved = cands.size();
  }
  r.retrieval = method;
  r.new_place_probability = new_place;
  r.retrieval_ms = retrieval_ms;
  r.verification_ms = sw.lap_ms();
  return r;
}

void merge_round(PlaceQueryResult& r, PlaceQueryResult second, const PlaceParams& params) {
  for (auto& m : second.matches) r.matches.push_back(std::move(m));
  r.decode_ms += second.decode_ms;
  r.decoded += second.decoded;
  // Densely aligned candidates first (their scores are not comparable with the others'), as
  // merge_verified orders one round.
  std::stable_sort(r.matches.begin(), r.matches.end(), [&](const PlaceMatch& a, const PlaceMatch& b) {
    if (params.dense_iterations > 0 && a.dense_refined != b.dense_refined) return a.dense_refined;
    return match_order(a, b);
  });
  r.accepted = !r.matches.empty() && r.matches.front().valid && r.matches.front().score >= params.accept_score;
}

}  // namespace lex3d
