#include <algorithm>
#include <cmath>
#include <numeric>
#include <string>
#include <unordered_map>

#include <pcl/kdtree/kdtree_flann.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include "lex3d/core/parallel.hpp"
#include "lex3d/model/model.hpp"
#include "model/scan_state.hpp"

namespace lex3d {

namespace {

// Cells of a thinning grid -> the kept points in them (linked through `next`), in a
// flat open-addressing table: a decoder thins ~10^5 points, and a node-based map
// spends most of its time allocating.
class CellTable {
 public:
  explicit CellTable(std::size_t max_cells) {
    std::size_t cap = 16;
    while (cap < 2 * max_cells) cap <<= 1;
    keys_.assign(cap, kEmpty);
    heads_.assign(cap, -1);
    mask_ = cap - 1;
  }
  /// Head of the list of cell `key`, -1 when empty.
  [[nodiscard]] std::int32_t head(std::uint64_t key) const {
    for (std::size_t i = hash(key) & mask_;; i = (i + 1) & mask_) {
      if (keys_[i] == key) return heads_[i];
      if (keys_[i] == kEmpty) return -1;
    }
  }
  /// The head slot of cell `key`, created when missing.
  std::int32_t& slot(std::uint64_t key) {
    for (std::size_t i = hash(key) & mask_;; i = (i + 1) & mask_) {
      if (keys_[i] == key) return heads_[i];
      if (keys_[i] == kEmpty) {
        keys_[i] = key;
        return heads_[i];
      }
    }
  }

 private:
  static constexpr std::uint64_t kEmpty = ~0ULL;
  static std::size_t hash(std::uint64_t k) {
    k ^= k >> 33;
    k *= 0xff51afd7ed558ccdULL;
    k ^= k >> 33;
    return static_cast<std::size_t>(k);
  }
  std::vector<std::uint64_t> keys_;
  std::vector<std::int32_t> heads_;
  std::size_t mask_ = 0;
};

std::uint64_t cell_key(int x, int y, int z) {
  const auto u = [](int v) { return static_cast<std::uint64_t>(static_cast<std::int64_t>(v) + (1 << 20)) & 0x1FFFFFULL; };
  return u(x) | (u(y) << 21) | (u(z) << 42);
}

}  // namespace

Reconstruction reconstruct(const Model& model, const Alphabet& alphabet, double spacing) {
  Reconstruction out;
  std::size_t placed = 0;
  for (const auto& inst : model.instances)
    if (inst.word < alphabet.size()) placed += alphabet.words[inst.word].points.size();
  out.cloud.points.reserve(placed);
  out.word_of_point.reserve(placed);
  // Cells are twice the spacing: the ball of radius `spacing` around a point then
  // meets at most two cells per axis, the point's own and the neighbour on the side
  // of the cell it is nearer to, so 8 cells hold every candidate.
  const float inv = spacing > 0.0 ? static_cast<float>(0.5 / spacing) : 0.0F;
  const float s2 = static_cast<float>(spacing * spacing);
  // Eq. 3 greedily, in instance order: a point is kept when no kept point is closer
  // than `spacing`.
  CellTable cells(inv > 0.0F ? placed : 0);
  std::vector<std::int32_t> next;
  for (const auto& inst : model.instances) {
    if (inst.word >= alphabet.size()) continue;
    const Eigen::Isometry3f T = inst.T_cloud_word.cast<float>();
    for (const auto& p : alphabet.words[inst.word].points) {
      const Eigen::Vector3f q = T * p;
      if (inv > 0.0F) {
        const Eigen::Vector3f g = q * inv;
        const int cx = static_cast<int>(std::floor(g.x()));
        const int cy = static_cast<int>(std::floor(g.y()));
        const int cz = static_cast<int>(std::floor(g.z()));
        const int sx = g.x() - static_cast<float>(cx) < 0.5F ? -1 : 1;
        const int sy = g.y() - static_cast<float>(cy) < 0.5F ? -1 : 1;
        const int sz = g.z() - static_cast<float>(cz) < 0.5F ? -1 : 1;
        bool near = false;
        for (int i = 0; i < 8 && !near; ++i) {
          const std::uint64_t key = cell_key(cx + ((i & 1) ? sx : 0), cy + ((i & 2) ? sy : 0), cz + ((i & 4) ? sz : 0));
          for (std::int32_t k = cells.head(key); k >= 0; k = next[static_cast<std::size_t>(k)])
            if ((out.cloud.points[static_cast<std::size_t>(k)] - q).squaredNorm() < s2) {
              near = true;
              break;
            }
        }
        if (near) continue;
        std::int32_t& head = cells.slot(cell_key(cx, cy, cz));
        next.push_back(head);
        head = static_cast<std::int32_t>(out.cloud.points.size());
      }
      out.cloud.points.push_back(q);
      out.word_of_point.push_back(inst.word);
    }
  }
  return out;
}

double log_likelihood(const PreparedScan& scan, const Model& model, const Alphabet& alphabet) {
  const Reconstruction r = reconstruct(model, alphabet, 0.0);
  const std::size_t n = scan.cloud.size();
  const std::size_t m = r.cloud.size();
  std::vector<double> terms(n, 0.0);
  const double log_n = std::log(static_cast<double>(std::max<std::size_t>(n, 1)));
  const double log_m = m > 1 ? std::log(static_cast<double>(m)) : 0.0;
  pcl::KdTreeFLANN<pcl::PointXYZ> tree(true);
  if (m > 0) {
    auto pc = pcl::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
    for (const auto& p : r.cloud.points) pc->push_back(pcl::PointXYZ(p.x(), p.y(), p.z()));
    tree.setInputCloud(pc);
  }
  for (std::size_t j = 0; j < n; ++j) {
    const double s = std::max(1e-4, static_cast<double>(scan.sigma[j]));
    const double norm = std::pow(2.0 * M_PI * s * s, -1.5);
    const double log_floor = std::log(norm) - 4.5 - log_n;
    double sum = 0.0;
    if (m > 0) {
      std::vector<int> idx;
      std::vector<float> d2;
      const auto& p = scan.cloud.points[j];
      tree.radiusSearch(pcl::PointXYZ(p.x(), p.y(), p.z()), 3.0 * s, idx, d2);
      for (const float d : d2) sum += std::exp(-static_cast<double>(d) / (2.0 * s * s));
      sum *= norm;
    }
    terms[j] = sum > 0.0 ? std::max(std::log(sum) - log_m, log_floor) : log_floor;
  }
  return std::accumulate(terms.begin(), terms.end(), 0.0);
}

double bic(double log_likelihood, std::size_t alphabet_points, std::size_t data_points) {
  const double k = 3.0 * static_cast<double>(alphabet_points);
  return -2.0 * log_likelihood + k * std::log(static_cast<double>(std::max<std::size_t>(data_points, 1)));
}

Model encode_scan(const PreparedScan& scan, const Alphabet& alphabet, bool prune, const ModelParams& params) {
  params.validate();
  const int threads = params.threads;
  if (alphabet.size() == 0 || scan.features.size() == 0) return {};
  if (alphabet.descriptor_dim != scan.features.descriptor_dim)
    throw std::invalid_argument("encode_scan: the alphabet's descriptors have " +
                                std::to_string(alphabet.descriptor_dim) + " values, the scan's " +
                                std::to_string(scan.features.descriptor_dim));
  detail::ScanState state(scan, threads);
  // Words: the nearest descriptor, or the best fit among the fit_candidates nearest.
  // Nothing is scored until the words and poses are final: only pruning needs the
  // likelihood.
  if (params.fit_candidates > 1 && alphabet.size() > 1) {
    state.choose_by_fit(alphabet, params.fit_candidates, threads, true);
  } else {
    const WordIndex index(alphabet);
    const auto matches = index.nearest(scan.features.descriptors.data(), scan.features.size(), threads);
    std::vector<std::int32_t> words(matches.size());
    for (std::size_t f = 0; f < matches.size(); ++f) words[f] = static_cast<std::int32_t>(matches[f].word);
    state.assign_words(words, alphabet);
  }
  state.refine(alphabet, params.refine_iterations, params.refine_reach_factor * scan.word_radius, threads);
  if (prune) state.prune(alphabet, threads);
  return state.model();
}

}  // namespace lex3d
