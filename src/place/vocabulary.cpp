// The recognition vocabulary: a vocabulary tree learned with FLANN's hierarchical k-means,
// the FAB-MAP statistics of its leaves (Chow–Liu tree), and its VOCB byte format.

#include <flann/flann.hpp>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <string>

#include "lex3d/core/timer.hpp"
#include "lex3d/place/place.hpp"
#include "lex3d/place/vocabulary.hpp"

namespace lex3d {

namespace {

constexpr std::uint32_t kMaxNodes = 1u << 22;
constexpr std::uint32_t kMaxDim = 4096;
constexpr std::uint32_t kMaxBranching = 256;

void check(bool ok, const char* what) {
  if (!ok) throw std::invalid_argument(what);
}

float squared_distance(const float* a, const float* b, int dim) {
  float s = 0.0F;
  for (int k = 0; k < dim; ++k) {
    const float d = a[k] - b[k];
    s += d * d;
  }
  return s;
}

}  // namespace

void VocabularyParams::validate() const {
  check(words >= 2 && words <= (1 << 20), "VocabularyParams::words must be in [2, 2^20]");
  check(branching >= 2 && branching <= 256, "VocabularyParams::branching must be in [2, 256]");
  check(min_descriptors_per_child >= 1 && min_descriptors_per_child <= 1000,
        "VocabularyParams::min_descriptors_per_child must be in [1, 1000]");
  check(kmeans_iterations >= 1 && kmeans_iterations <= 100, "VocabularyParams::kmeans_iterations must be in [1, 100]");
}

std::size_t PlaceVocabulary::leaves() const noexcept {
  return static_cast<std::size_t>(std::count(child_count.begin(), child_count.end(), 0u));
}

bool PlaceVocabulary::finish() {
  const std::size_t n = child_count.size();
  first_child.assign(n, 0);
  std::uint64_t next = 1;
  for (std::size_t i = 0; i < n; ++i) {
    // Breadth-first: a node's children come after it and after the children of the nodes before it.
    if (child_count[i] > 0 && next <= i) return false;
    first_child[i] = static_cast<std::uint32_t>(std::min<std::uint64_t>(next, n));
    next += child_count[i];
    if (next > n) return false;
  }
  return next == n;
}

void PlaceVocabulary::path(const float* descriptor, std::vector<std::uint32_t>& nodes_out) const {
  nodes_out.clear();
  std::uint32_t node = 0;
  while (node < child_count.size() && child_count[node] > 0) {
    const std::uint32_t a = first_child[node];
    std::uint32_t best = a;
    float best_d = std::numeric_limits<float>::infinity();
    for (std::uint32_t c = a; c < a + child_count[node]; ++c) {
      const float d = squared_distance(descriptor, centres.data() + static_cast<std::size_t>(c - 1) * descriptor_dim, descriptor_dim);
      if (d < best_d) {  // ties: the lower node id
        best_d = d;
        best = c;
      }
    }
    node = best;
    nodes_out.push_back(node);
  }
}

std::vector<std::pair<std::uint32_t, std::uint32_t>> PlaceVocabulary::words(const float* descriptors, std::size_t n) const {
  std::vector<std::uint32_t> all, p;
  for (std::size_t i = 0; i < n; ++i) {
    path(descriptors + i * static_cast<std::size_t>(descriptor_dim), p);
    all.insert(all.end(), p.begin(), p.end());
  }
  std::sort(all.begin(), all.end());
  std::vector<std::pair<std::uint32_t, std::uint32_t>> out;
  for (std::size_t i = 0; i < all.size();) {
    std::size_t j = i;
    while (j < all.size() && all[j] == all[i]) ++j;
    out.emplace_back(all[i], static_cast<std::uint32_t>(j - i));
    i = j;
  }
  return out;
}

std::vector<std::pair<std::uint32_t, std::uint32_t>> PlaceVocabulary::words(const PlaceScan& scan) const {
  if (empty() || scan.descriptor_dim != descriptor_dim ||
      scan.descriptors.size() != scan.features.size() * static_cast<std::size_t>(std::max(0, descriptor_dim)))
    return {};
  return words(scan.descriptors.data(), scan.features.size());
}

PlaceVocabulary learn_vocabulary(const std::vector<const PlaceScan*>& scans, const VocabularyParams& params,
                                 VocabularyStats* stats) {
  params.validate();
  Stopwatch sw;
  int dim = 0;
  std::size_t total = 0;
  for (const PlaceScan* s : scans) {
    if (s == nullptr || s->features.empty()) continue;
    if (dim == 0) dim = s->descriptor_dim;
    if (s->descriptor_dim != dim || s->descriptors.size() != s->features.size() * static_cast<std::size_t>(dim))
      throw std::invalid_argument("learn_vocabulary: scan '" + s->name + "' has descriptors of another size");
    total += s->features.size();
  }
  if (dim <= 0 || total == 0) throw std::invalid_argument("learn_vocabulary: the training scans have no descriptors");
  // All training descriptors, one row each.
  std::vector<float> data;
  data.reserve(total * static_cast<std::size_t>(dim));
  for (const PlaceScan* s : scans)
    if (s != nullptr && !s->features.empty()) data.insert(data.end(), s->descriptors.begin(), s->descriptors.end());

  PlaceVocabulary v;
  v.descriptor_dim = dim;
  v.branching = params.branching;
  v.seed = params.seed;
  int depth = 1;
  for (double leaves = params.branching; leaves < params.words; leaves *= params.branching) ++depth;
  // Breadth-first construction: each queued node holds the rows of its descriptors.
  struct Pending {
    std::vector<std::uint32_t> rows;
    int level = 0;
  };
  std::vector<Pending> queue;
  queue.push_back({std::vector<std::uint32_t>(total), 0});
  std::iota(queue[0].rows.begin(), queue[0].rows.end(), 0u);
  v.child_count.push_back(0);
  std::size_t leaf_budget = static_cast<std::size_t>(params.words);
  std::size_t leaves_now = 1;
  const auto b = static_cast<std::size_t>(params.branching);
  for (std::size_t qi = 0; qi < queue.size(); ++qi) {
    const std::vector<std::uint32_t> rows = std::move(queue[qi].rows);
    const int level = queue[qi].level;
    if (level >= depth || rows.size() < b * static_cast<std::size_t>(params.min_descriptors_per_child) ||
        leaves_now + b - 1 > leaf_budget)
      continue;
    // FLANN's hierarchical k-means of this node's descriptors, cut at `branching` clusters.
    std::vector<float> sub(rows.size() * static_cast<std::size_t>(dim));
    for (std::size_t r = 0; r < rows.size(); ++r)
      std::memcpy(sub.data() + r * dim, data.data() + static_cast<std::size_t>(rows[r]) * dim, sizeof(float) * dim);
    flann::Matrix<float> points(sub.data(), rows.size(), static_cast<std::size_t>(dim));
    std::vector<float> centre_data(b * static_cast<std::size_t>(dim));
    flann::Matrix<float> centres(centre_data.data(), b, static_cast<std::size_t>(dim));
    flann::KMeansIndexParams kp(params.branching, params.kmeans_iterations, flann::FLANN_CENTERS_KMEANSPP);
    flann::seed_random(static_cast<unsigned int>((params.seed * 0x9E3779B97F4A7C15ULL + v.child_count.size()) >> 16));
    const int got = flann::hierarchicalClustering<flann::L2<float>>(points, centres, kp);
    if (got < 2) continue;
    const auto k = static_cast<std::size_t>(got);
    // Children: assign the node's descriptors to the nearest centre; empty children dropped.
    std::vector<std::vector<std::uint32_t>> parts(k);
    for (std::size_t r = 0; r < rows.size(); ++r) {
      std::size_t best = 0;
      float best_d = std::numeric_limits<float>::infinity();
      for (std::size_t c = 0; c < k; ++c) {
        const float d = squared_distance(sub.data() + r * dim, centre_data.data() + c * dim, dim);
        if (d < best_d) {
          best_d = d;
          best = c;
        }
      }
      parts[best].push_back(rows[r]);
    }
    std::uint32_t made = 0;
    for (std::size_t c = 0; c < k; ++c) {
      if (parts[c].empty()) continue;
      v.child_count.push_back(0);
      v.centres.insert(v.centres.end(), centre_data.begin() + static_cast<std::ptrdiff_t>(c * dim),
                       centre_data.begin() + static_cast<std::ptrdiff_t>((c + 1) * dim));
      queue.push_back({std::move(parts[c]), level + 1});
      ++made;
    }
    if (made < 2) {  // one non-empty child: no split (undo)
      v.child_count.resize(v.child_count.size() - made);
      v.centres.resize(v.centres.size() - static_cast<std::size_t>(made) * dim);
      queue.resize(queue.size() - made);
      continue;
    }
    v.child_count[qi] = made;
    leaves_now += made - 1;
  }
  if (!v.finish()) throw std::logic_error("learn_vocabulary: tree is not breadth-first");

  // Leaf statistics over the training scans (presence of a leaf in a scan).
  const std::size_t nodes = v.nodes();
  const double N = static_cast<double>(scans.size());
  std::vector<double> n_word(nodes, 0.0);
  std::vector<std::vector<std::uint32_t>> present;  // leaves of each training scan, sorted
  std::vector<std::uint32_t> p;
  for (const PlaceScan* s : scans) {
    std::vector<std::uint32_t> leaves;
    if (s != nullptr)
      for (const auto& [w, c] : v.words(*s)) {
        n_word[w] += 1.0;
        if (v.is_leaf(w)) leaves.push_back(w);
      }
    present.push_back(std::move(leaves));
  }
  v.training_scans = static_cast<std::uint32_t>(scans.size());
  v.p_word.resize(nodes);
  for (std::size_t i = 0; i < nodes; ++i) v.p_word[i] = static_cast<float>((n_word[i] + 1.0) / (N + 2.0));
  // Co-occurrence of leaf pairs (a < b) in the training scans.
  std::vector<std::uint64_t> pairs;
  for (const auto& l : present)
    for (std::size_t i = 0; i < l.size(); ++i)
      for (std::size_t j = i + 1; j < l.size(); ++j) pairs.push_back(static_cast<std::uint64_t>(l[i]) << 32 | l[j]);
  std::sort(pairs.begin(), pairs.end());
  struct Edge {
    double mi;
    std::uint32_t a, b, n11;
  };
  std::vector<Edge> edges;
  // Mutual information of a 2x2 table with 0.5 added to each cell.
  auto cells = [&](double na, double nb, double n11, double out[4]) {
    out[0] = n11 + 0.5;                  // a, b
    out[1] = na - n11 + 0.5;             // a, not b
    out[2] = nb - n11 + 0.5;             // not a, b
    out[3] = N - na - nb + n11 + 0.5;    // neither
  };
  for (std::size_t i = 0; i < pairs.size();) {
    std::size_t j = i;
    while (j < pairs.size() && pairs[j] == pairs[i]) ++j;
    const auto a = static_cast<std::uint32_t>(pairs[i] >> 32), bb = static_cast<std::uint32_t>(pairs[i] & 0xFFFFFFFFu);
    double c[4];
    cells(n_word[a], n_word[bb], static_cast<double>(j - i), c);
    const double t = N + 2.0;
    const double pa = (c[0] + c[1]) / t, pb = (c[0] + c[2]) / t;
    const double ma[4] = {pa, pa, 1 - pa, 1 - pa}, mb[4] = {pb, 1 - pb, pb, 1 - pb};
    double mi = 0.0;
    for (int k = 0; k < 4; ++k) mi += c[k] / t * std::log(c[k] / t / (ma[k] * mb[k]));
    edges.push_back({mi, a, bb, static_cast<std::uint32_t>(j - i)});
    i = j;
  }
  // Maximum spanning forest (Kruskal; ties by the lower pair).
  std::sort(edges.begin(), edges.end(), [](const Edge& x, const Edge& y) {
    if (x.mi != y.mi) return x.mi > y.mi;
    return x.a != y.a ? x.a < y.a : x.b < y.b;
  });
  std::vector<std::uint32_t> set(nodes);
  std::iota(set.begin(), set.end(), 0u);
  auto find = [&](std::uint32_t x) {
    while (set[x] != x) x = set[x] = set[set[x]];
    return x;
  };
  std::vector<std::vector<std::uint32_t>> adj(nodes);
  std::size_t tree_edges = 0;
  for (const Edge& e : edges) {
    const std::uint32_t ra = find(e.a), rb = find(e.b);
    if (ra == rb) continue;
    set[ra] = rb;
    adj[e.a].push_back(e.b);
    adj[e.b].push_back(e.a);
    ++tree_edges;
  }
  // Orient each tree from its lowest leaf id; conditionals from the training counts.
  v.parent.assign(nodes, PlaceVocabulary::kNoParent);
  v.p_given_parent.assign(nodes, 0.5F);
  v.p_given_no_parent.assign(nodes, 0.5F);
  std::vector<char> seen(nodes, 0);
  auto co = [&](std::uint32_t a, std::uint32_t bb) {
    const std::uint64_t key = static_cast<std::uint64_t>(std::min(a, bb)) << 32 | std::max(a, bb);
    const auto r = std::equal_range(pairs.begin(), pairs.end(), key);
    return static_cast<double>(r.second - r.first);
  };
  for (std::uint32_t root = 0; root < nodes; ++root) {
    if (!v.is_leaf(root) || seen[root]) continue;
    std::vector<std::uint32_t> stack{root};
    seen[root] = 1;
    while (!stack.empty()) {
      const std::uint32_t x = stack.back();
      stack.pop_back();
      for (const std::uint32_t y : adj[x]) {
        if (seen[y]) continue;
        seen[y] = 1;
        v.parent[y] = x;
        const double n11 = co(x, y);
        v.p_given_parent[y] = static_cast<float>((n11 + 0.5) / (n_word[x] + 1.0));
        v.p_given_no_parent[y] = static_cast<float>((n_word[y] - n11 + 0.5) / (N - n_word[x] + 1.0));
        stack.push_back(y);
      }
    }
  }
  if (stats != nullptr) {
    stats->training_scans = scans.size();
    stats->training_descriptors = total;
    stats->leaves = v.leaves();
    stats->nodes = nodes;
    stats->chow_liu_edges = tree_edges;
    stats->learn_ms = sw.elapsed_ms();
  }
  return v;
}

// --- VOCB bytes (formats/place_db.md §3.5) ---

namespace {

void put32(std::vector<std::uint8_t>& b, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) b.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
}
void put64(std::vector<std::uint8_t>& b, std::uint64_t v) {
  for (int i = 0; i < 8; ++i) b.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
}
void putf(std::vector<std::uint8_t>& b, float f) {
  std::uint32_t v = 0;
  std::memcpy(&v, &f, 4);
  put32(b, v);
}
std::uint32_t get32(const std::uint8_t* p) {
  return static_cast<std::uint32_t>(p[0]) | static_cast<std::uint32_t>(p[1]) << 8 |
         static_cast<std::uint32_t>(p[2]) << 16 | static_cast<std::uint32_t>(p[3]) << 24;
}
float getf(const std::uint8_t* p) {
  const std::uint32_t v = get32(p);
  float f = 0;
  std::memcpy(&f, &v, 4);
  return f;
}
constexpr std::size_t kVocabHeader = 24;

}  // namespace

std::vector<std::uint8_t> encode_vocabulary(const PlaceVocabulary& v) {
  std::vector<std::uint8_t> b;
  const std::size_t n = v.nodes();
  b.reserve(kVocabHeader + n * 20 + v.centres.size() * 4);
  put32(b, static_cast<std::uint32_t>(v.descriptor_dim));
  put32(b, static_cast<std::uint32_t>(v.branching));
  put32(b, static_cast<std::uint32_t>(n));
  put32(b, v.training_scans);
  put64(b, v.seed);
  for (std::size_t i = 0; i < n; ++i) put32(b, v.child_count[i]);
  for (const float c : v.centres) putf(b, c);
  for (std::size_t i = 0; i < n; ++i) {
    putf(b, v.p_word[i]);
    put32(b, v.parent[i]);
    putf(b, v.p_given_parent[i]);
    putf(b, v.p_given_no_parent[i]);
  }
  return b;
}

StatusOr<PlaceVocabulary> decode_vocabulary(const std::uint8_t* p, std::size_t n, std::uint64_t base) {
  if (n < kVocabHeader) return bad_data("place database: VOCB too short", base);
  PlaceVocabulary v;
  const std::uint32_t dim = get32(p), branching = get32(p + 4), nodes = get32(p + 8);
  v.training_scans = get32(p + 12);
  v.seed = static_cast<std::uint64_t>(get32(p + 16)) | static_cast<std::uint64_t>(get32(p + 20)) << 32;
  if (dim == 0 || dim > kMaxDim) return bad_data("place database: VOCB descriptor size " + std::to_string(dim) + " out of range", base);
  if (branching < 2 || branching > kMaxBranching)
    return bad_data("place database: VOCB branching " + std::to_string(branching) + " out of range", base + 4);
  if (nodes < 2 || nodes > kMaxNodes) return bad_data("place database: VOCB node count " + std::to_string(nodes) + " out of range", base + 8);
  // Sizes in 64 bits from bounded values: no overflow.
  const std::uint64_t need = kVocabHeader + 4ull * nodes + 4ull * (nodes - 1) * dim + 16ull * nodes;
  if (need != n) return bad_data("place database: VOCB sizes do not add up to its length", base + 8);
  v.descriptor_dim = static_cast<int>(dim);
  v.branching = static_cast<int>(branching);
  const std::uint8_t* q = p + kVocabHeader;
  v.child_count.resize(nodes);
  for (std::uint32_t i = 0; i < nodes; ++i, q += 4) {
    v.child_count[i] = get32(q);
    if (v.child_count[i] > branching)
      return bad_data("place database: VOCB node " + std::to_string(i) + " has more children than the branching", base + (q - p));
  }
  if (!v.finish()) return bad_data("place database: VOCB child counts are not a breadth-first tree", base + kVocabHeader);
  const std::uint64_t centres_at = base + (q - p);
  v.centres.resize(static_cast<std::size_t>(nodes - 1) * dim);
  for (std::size_t i = 0; i < v.centres.size(); ++i, q += 4) {
    v.centres[i] = getf(q);
    if (!std::isfinite(v.centres[i])) return bad_data("place database: VOCB centre value is not finite", centres_at + 4 * i);
  }
  v.p_word.resize(nodes);
  v.parent.resize(nodes);
  v.p_given_parent.resize(nodes);
  v.p_given_no_parent.resize(nodes);
  auto prob = [](float x) { return std::isfinite(x) && x > 0.0F && x < 1.0F; };
  for (std::uint32_t i = 0; i < nodes; ++i, q += 16) {
    v.p_word[i] = getf(q);
    v.parent[i] = get32(q + 4);
    v.p_given_parent[i] = getf(q + 8);
    v.p_given_no_parent[i] = getf(q + 12);
    const bool parent_ok = v.parent[i] == PlaceVocabulary::kNoParent ||
                           (v.parent[i] < nodes && v.parent[i] != i && v.child_count[i] == 0 && v.child_count[v.parent[i]] == 0);
    if (!prob(v.p_word[i]) || !prob(v.p_given_parent[i]) || !prob(v.p_given_no_parent[i]) || !parent_ok)
      return bad_data("place database: VOCB statistics of node " + std::to_string(i) + " out of range", base + (q - p));
  }
  return v;
}

}  // namespace lex3d
