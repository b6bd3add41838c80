// The first stage over the recognition vocabulary: tf-idf over its words (every tree level)
// and a FAB-MAP-style likelihood over its leaves (collier2012 §3).

#include <algorithm>
#include <cmath>
#include <cstring>
#include <mutex>
#include <stdexcept>
#include <string>

#include "lex3d/place/place.hpp"
#include "place/internal.hpp"

namespace lex3d {

namespace {

using detail::ld32;
using detail::ld64;
using detail::ldf64;
constexpr std::size_t kVEntryBytes = 12;  // formats/place_db.md §3.6

void keep_best(std::vector<std::pair<std::size_t, double>>& out, std::size_t k) {
  const std::size_t keep = std::min(k, out.size());
  std::partial_sort(out.begin(), out.begin() + static_cast<std::ptrdiff_t>(keep), out.end(),
                    [](const auto& a, const auto& b) { return a.second != b.second ? a.second > b.second : a.first < b.first; });
  out.resize(keep);
}

}  // namespace

const char* to_string(PlaceRetrieval r) noexcept {
  switch (r) {
    case PlaceRetrieval::kTfidfAlphabet: return "tfidf-alphabet";
    case PlaceRetrieval::kTfidf: return "tfidf";
    case PlaceRetrieval::kFabmap: return "fabmap";
    default: return "default";
  }
}

namespace detail {

std::vector<std::pair<std::uint32_t, std::uint32_t>> vocabulary_words(const PlaceVocabulary& v, const PlaceScan& scan) {
  const std::size_t n = scan.features.size();
  const auto dim = static_cast<std::size_t>(std::max(0, v.descriptor_dim));
  if (v.empty() || n == 0 || scan.descriptor_dim != v.descriptor_dim) return {};
  if (scan.descriptors.size() == n * dim) return v.words(scan.descriptors.data(), n);
  if (scan.descriptor_codes.size() != n * dim) return {};
  std::vector<float> d(n * dim);
  for (std::size_t i = 0; i < d.size(); ++i) d[i] = dequantise_descriptor_value(scan.descriptor_codes[i], scan.descriptor_bits);
  return v.words(d.data(), n);
}

}  // namespace detail

void PlaceDatabase::set_vocabulary(PlaceVocabulary vocabulary) {
  if (size() > 0) throw std::logic_error("PlaceDatabase::set_vocabulary: the database already holds scans");
  if (vocabulary.empty() || vocabulary.first_child.size() != vocabulary.nodes())
    throw std::invalid_argument("PlaceDatabase::set_vocabulary: empty vocabulary");
  if (descriptor_dim_ != 0 && vocabulary.descriptor_dim != descriptor_dim_)
    throw std::invalid_argument("PlaceDatabase::set_vocabulary: the vocabulary's descriptors have " +
                                std::to_string(vocabulary.descriptor_dim) + " values, the database's " +
                                std::to_string(descriptor_dim_));
  vocabulary_ = std::make_shared<const PlaceVocabulary>(std::move(vocabulary));
  vnorm_cache_ = std::make_shared<NormCache>();
}

PlaceRetrieval PlaceDatabase::resolve(PlaceRetrieval method) const noexcept {
  // The alphabet's tf-idf stays the default: over the vocabulary the first stage was not better
  // on balm at 100-5,000 entries and the final recall at 1,000-5,000 was lower (bench/README.md).
  return method != PlaceRetrieval::kDefault ? method : PlaceRetrieval::kTfidfAlphabet;
}

std::uint32_t PlaceDatabase::vocab_total(std::size_t i) const {
  return i < vindex_.scans ? ld32(vindex_.entries + i * kVEntryBytes) : added_vtotal_[i - vindex_.scans];
}

std::size_t PlaceDatabase::vocab_stored_postings(std::uint32_t word) const {
  if (word >= vindex_.word_slots) return 0;
  return static_cast<std::size_t>(ld64(vindex_.word_start + 8 * (static_cast<std::size_t>(word) + 1)) -
                                  ld64(vindex_.word_start + 8 * static_cast<std::size_t>(word)));
}

const std::vector<double>& PlaceDatabase::vocab_norms() const {
  NormCache& c = *vnorm_cache_;
  std::lock_guard<std::mutex> lock(c.mutex);
  if (c.valid) return c.norm2;
  detail::tfidf_norms(size(), vindex_, added_vinverted_, [this](std::uint32_t s) { return vocab_total(s); }, c.norm2);
  c.valid = true;
  return c.norm2;
}

std::vector<std::pair<std::size_t, double>> PlaceDatabase::retrieve(const PlaceScan& query, std::size_t k,
                                                                    PlaceRetrieval method, const PlaceParams& params,
                                                                    double* new_place_probability) const {
  method = resolve(method);
  if (method == PlaceRetrieval::kTfidfAlphabet) return retrieve(query, k);
  if (vocabulary_ == nullptr)
    throw std::invalid_argument(std::string("PlaceDatabase::retrieve: ") + to_string(method) +
                                " needs a recognition vocabulary and the database has none");
  std::vector<std::pair<std::size_t, double>> out;
  const std::size_t n = size();
  if (n == 0 || k == 0) return out;
  const PlaceVocabulary& V = *vocabulary_;
  const auto qwords = detail::vocabulary_words(V, query);
  // Visits the postings of word w: f(scan, count).
  auto postings = [&](std::uint32_t w, auto&& f) {
    const std::size_t ns = vocab_stored_postings(w);
    if (ns > 0) {
      const std::uint8_t* p = vindex_.postings + 8 * ld64(vindex_.word_start + 8 * static_cast<std::size_t>(w));
      for (std::size_t j = 0; j < ns; ++j, p += 8) f(static_cast<std::size_t>(ld32(p)), ld32(p + 4));
    }
    if (w < added_vinverted_.size())
      for (const auto& q : added_vinverted_[w]) f(static_cast<std::size_t>(q.scan), q.count);
  };
  auto df = [&](std::uint32_t w) {
    return vocab_stored_postings(w) + (w < added_vinverted_.size() ? added_vinverted_[w].size() : 0);
  };

  if (method == PlaceRetrieval::kTfidf) {
    double qtotal = 0.0;
    for (const auto& wc : qwords) qtotal += wc.second;
    if (qtotal <= 0.0) return out;
    std::vector<double> dot(n, 0.0);
    double qnorm2 = 0.0;
    for (const auto& [word, count] : qwords) {
      const std::size_t nw = df(word);
      if (nw == 0) continue;
      const double idf = std::log(1.0 + static_cast<double>(n) / static_cast<double>(nw));
      const double qv = static_cast<double>(count) / qtotal * idf;
      qnorm2 += qv * qv;
      postings(word, [&](std::size_t s, std::uint32_t c) {
        dot[s] += qv * static_cast<double>(c) / static_cast<double>(vocab_total(s)) * idf;
      });
    }
    if (qnorm2 <= 0.0) return out;
    if (added_vtotal_.empty()) {
      for (std::size_t i = 0; i < n; ++i) {
        if (!(dot[i] > 0.0)) continue;
        const double n2 = ldf64(vindex_.entries + i * kVEntryBytes + 4);
        if (n2 > 0.0) out.emplace_back(i, dot[i] / std::sqrt(n2 * qnorm2));
      }
    } else {
      const std::vector<double>& norm2 = vocab_norms();
      for (std::size_t i = 0; i < n; ++i)
        if (dot[i] > 0.0 && norm2[i] > 0.0) out.emplace_back(i, dot[i] / std::sqrt(norm2[i] * qnorm2));
    }
    keep_best(out, k);
    return out;
  }

  // FAB-MAP (Cummins and Newman 2008, as collier2012 §3 uses it), over the leaves. The query's
  // appearance vector z; a place L's word existence e_q is its stored scan's observation
  // through the detector model: p(e_q | L) = p(e_q | o_q) with the prior p(e_q) from the
  // training share; p(z_q | z_parent, L) = sum_e p(z_q | e_q = e, z_parent) p(e_q = e | L)
  // with the Chow–Liu conditional folded in by FAB-MAP's approximation.
  const std::size_t nodes = V.nodes();
  std::vector<char> z(nodes, 0);
  for (const auto& wc : qwords) z[wc.first] = 1;
  const double pd = params.fabmap_p_detect, pf = params.fabmap_p_false;
  auto cond = [&](std::uint32_t q, int e) {
    const bool zq = z[q] != 0;
    const double a = e ? (zq ? pd : 1 - pd) : (zq ? pf : 1 - pf);
    const double a_flip = 1.0 - a;
    const std::uint32_t par = V.parent[q];
    if (par == PlaceVocabulary::kNoParent) return a;
    const double pz1 = z[par] ? V.p_given_parent[q] : V.p_given_no_parent[q];
    const double b = zq ? pz1 : 1.0 - pz1;
    const double c = zq ? V.p_word[q] : 1.0 - V.p_word[q];
    const double num = a * b / c, other = a_flip * (1.0 - b) / (1.0 - c);
    return num / (num + other);
  };
  double base = 0.0, fresh = 0.0;
  std::vector<double> delta(nodes, 0.0);
  for (std::uint32_t q = 0; q < nodes; ++q) {
    if (!V.is_leaf(q)) continue;
    const double pe = std::clamp((static_cast<double>(V.p_word[q]) - pf) / (pd - pf), 1e-3, 1.0 - 1e-3);
    const double post1 = pd * pe / (pd * pe + pf * (1 - pe));
    const double post0 = (1 - pd) * pe / ((1 - pd) * pe + (1 - pf) * (1 - pe));
    const double c1 = cond(q, 1), c0 = cond(q, 0);
    const double t0 = std::log(c1 * post0 + c0 * (1 - post0));
    const double t1 = std::log(c1 * post1 + c0 * (1 - post1));
    base += t0;
    fresh += std::log(c1 * pe + c0 * (1 - pe));
    delta[q] = t1 - t0;
  }
  std::vector<double> ll(n, base);
  for (std::uint32_t q = 0; q < nodes; ++q)
    if (V.is_leaf(q) && delta[q] != 0.0) postings(q, [&](std::size_t s, std::uint32_t) { ll[s] += delta[q]; });
  double m = fresh;
  for (const double v : ll) m = std::max(m, v);
  const double prior_old = (1.0 - params.fabmap_new_place_prior) / static_cast<double>(n);
  double zsum = std::exp(fresh - m) * params.fabmap_new_place_prior;
  for (const double v : ll) zsum += std::exp(v - m) * prior_old;
  out.reserve(n);
  for (std::size_t i = 0; i < n; ++i) out.emplace_back(i, ll[i]);
  keep_best(out, k);
  for (auto& o : out) o.second = std::exp(o.second - m) * prior_old / zsum;
  if (new_place_probability != nullptr) *new_place_probability = std::exp(fresh - m) * params.fabmap_new_place_prior / zsum;
  return out;
}

}  // namespace lex3d
