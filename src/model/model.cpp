#include <algorithm>
#include <cmath>
#include <numeric>
#include <string>
#include <unordered_map>

#include <pcl/kdtree/kdtree_flann.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include "lex3d/core/parallel.hpp"
#include "lex3d/core/timer.hpp"
#include "lex3d/model/model.hpp"
#include "model/scan_state.hpp"

namespace lex3d {

namespace {

// Cells of a thinning grid -> the kept points in them (linked through `next`), in a
// flat open-addressing table: a decoder thins ~10^5 points, and a node-based map
// spends most of its time allocating.
class CellTable {
 public:
  /// `expected_cells`: a first guess; the table grows to stay at most half full.
  explicit CellTable(std::size_t expected_cells) { rehash(capacity_for(expected_cells)); }
  /// Head of the list of cell `key`, -1 when empty.
  [[nodiscard]] std::int32_t head(std::uint64_t key) const {
    const std::size_t h = hash(key);
    const std::size_t b = (h >> 40) & kBitMask;
    if (((bits_[b >> 6] >> (b & 63)) & 1U) == 0) return -1;
    for (std::size_t i = h & mask_;; i = (i + 1) & mask_) {
      if (slots_[i].key == key) return slots_[i].head;
      if (slots_[i].key == kEmpty) return -1;
    }
  }
  /// The head slot of cell `key`, created when missing (valid until the next call).
  std::int32_t& slot(std::uint64_t key) {
    if (2 * (used_ + 1) > slots_.size()) rehash(2 * slots_.size());
    const std::size_t h = hash(key);
    const std::size_t b = (h >> 40) & kBitMask;
    bits_[b >> 6] |= std::uint64_t{1} << (b & 63);
    for (std::size_t i = h & mask_;; i = (i + 1) & mask_) {
      if (slots_[i].key == key) return slots_[i].head;
      if (slots_[i].key == kEmpty) {
        ++used_;
        slots_[i].key = key;
        return slots_[i].head;
      }
    }
  }

 private:
  struct Slot {
    std::uint64_t key;
    std::int32_t head;
  };
  static constexpr std::uint64_t kEmpty = ~0ULL;
  static constexpr std::size_t kBitMask = (std::size_t{1} << 22) - 1;
  std::vector<std::uint64_t> bits_ = std::vector<std::uint64_t>((kBitMask + 1) / 64, 0);
  static std::size_t capacity_for(std::size_t cells) {
    std::size_t cap = 16;
    while (cap < 2 * cells) cap <<= 1;
    return cap;
  }
  void rehash(std::size_t cap) {
    std::vector<Slot> old = std::move(slots_);
    slots_.assign(cap, Slot{kEmpty, -1});
    mask_ = cap - 1;
    for (const Slot& s : old) {
      if (s.key == kEmpty) continue;
      std::size_t i = hash(s.key) & mask_;
      while (slots_[i].key != kEmpty) i = (i + 1) & mask_;
      slots_[i] = s;
    }
  }
  static std::size_t hash(std::uint64_t k) {
    k ^= k >> 33;
    k *= 0xff51afd7ed558ccdULL;
    k ^= k >> 33;
    return static_cast<std::size_t>(k);
  }
  std::vector<Slot> slots_;
  std::size_t mask_ = 0;
  std::size_t used_ = 0;
};

/// Thinning cells are 1 / kCellShare point spacings wide (8: kitti00/000000 reconstructs
/// ~1.7x faster than with cells of 2 spacings, where every point probed 8 cells).
constexpr double kCellShare = 0.125;

std::uint64_t cell_key(int x, int y, int z) {
  const auto u = [](int v) { return static_cast<std::uint64_t>(static_cast<std::int64_t>(v) + (1 << 20)) & 0x1FFFFFULL; };
  return u(x) | (u(y) << 21) | (u(z) << 42);
}

}  // namespace

Reconstruction reconstruct(const Model& model, const Alphabet& alphabet, double spacing) {
  Reconstruction out;
  // Every word point placed (in parallel: per instance, into its own range), then eq. 3
  // greedily in instance order: a point is kept when no kept point is closer than `spacing`.
  const std::size_t n_inst = model.instances.size();
  std::vector<std::size_t> offset(n_inst + 1, 0);
  for (std::size_t i = 0; i < n_inst; ++i) {
    const auto w = model.instances[i].word;
    offset[i + 1] = offset[i] + (w < alphabet.size() ? alphabet.words[w].points.size() : 0);
  }
  const std::size_t placed = offset[n_inst];
  std::vector<Eigen::Vector3f> all(placed);
  parallel_for(n_inst, placed > 20000 ? 2 : 1, [&](std::size_t i) {
    const auto& inst = model.instances[i];
    if (inst.word >= alphabet.size()) return;
    const Eigen::Isometry3f T = inst.T_cloud_word.cast<float>();
    Eigen::Vector3f* dst = all.data() + offset[i];
    for (const auto& p : alphabet.words[inst.word].points) *dst++ = T * p;
  }, 256);
  if (!(spacing > 0.0)) {
    out.cloud.points = std::move(all);
    out.word_of_point.reserve(placed);
    for (std::size_t i = 0; i < n_inst; ++i)
      out.word_of_point.insert(out.word_of_point.end(), offset[i + 1] - offset[i], model.instances[i].word);
    return out;
  }
  out.cloud.points.reserve(placed);
  out.word_of_point.reserve(placed);
  // Cells are 1/kCellShare times the spacing: the ball of radius `spacing` around a point
  // meets its own cell and, along an axis, the neighbour on the side of a face nearer than
  // `spacing` (checked with a margin for rounding), so at most 8 cells and mostly one.
  const double inv = kCellShare / spacing;
  const float s2 = static_cast<float>(spacing * spacing);
  constexpr double kNear = kCellShare + 1e-3;
  CellTable cells(placed / 4);
  std::vector<std::int32_t> next;
  next.reserve(placed);
  for (std::size_t i = 0; i < n_inst; ++i) {
    const auto word = model.instances[i].word;
    for (std::size_t k = offset[i]; k < offset[i + 1]; ++k) {
      const Eigen::Vector3f q = all[k];
      int base[3], side[3];
      int need = 0;  // bit a: the neighbour along axis a may hold a point within `spacing`
      for (int a = 0; a < 3; ++a) {
        // (clamped: cell_key keeps 21 bits an axis anyway, and a far point only shares keys;
        // a NaN coordinate, which a damaged file's huge pose and word points can make, goes
        // to cell 0, where no distance to it is ever below `spacing`)
        const double x = static_cast<double>(q[a]) * inv;
        const double g = std::isnan(x) ? 0.0 : std::clamp(x, -1e9, 1e9);
        const double b = std::floor(g);
        base[a] = static_cast<int>(b);
        const double f = g - b;
        side[a] = f < 0.5 ? -1 : 1;
        if (f < kNear || f > 1.0 - kNear) need |= 1 << a;
      }
      bool near = false;
      for (int c = 0; c < 8 && !near; ++c) {
        if ((c & ~need) != 0) continue;
        const std::uint64_t key = cell_key(base[0] + ((c & 1) ? side[0] : 0), base[1] + ((c & 2) ? side[1] : 0),
                                           base[2] + ((c & 4) ? side[2] : 0));
        for (std::int32_t j = cells.head(key); j >= 0; j = next[static_cast<std::size_t>(j)])
          if ((out.cloud.points[static_cast<std::size_t>(j)] - q).squaredNorm() < s2) {
            near = true;
            break;
          }
      }
      if (near) continue;
      std::int32_t& head = cells.slot(cell_key(base[0], base[1], base[2]));
      next.push_back(head);
      head = static_cast<std::int32_t>(out.cloud.points.size());
      out.cloud.points.push_back(q);
      out.word_of_point.push_back(word);
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

Model encode_scan(const PreparedScan& scan, const Alphabet& alphabet, bool prune, const ModelParams& params,
                  EncodeTimings* timings) {
  params.validate();
  Stopwatch sw;
  EncodeTimings t;
  const int threads = params.threads;
  if (alphabet.size() == 0 || scan.features.size() == 0) return {};
  if (alphabet.descriptor_dim != scan.features.descriptor_dim)
    throw std::invalid_argument("encode_scan: the alphabet's descriptors have " +
                                std::to_string(alphabet.descriptor_dim) + " values, the scan's " +
                                std::to_string(scan.features.descriptor_dim));
  detail::ScanState state(scan, threads);
  t.frames_ms = sw.lap_ms();
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
  t.words_ms = sw.lap_ms();
  // Pruning comes before the ICP fit, so that only the instances kept are fitted (about
  // 60 % on KITTI): on kitti00 and balm the files and the inliers barely change (see
  // ModelParams::refine_iterations), and encoding takes ~10 % less time.
  if (prune) state.prune(alphabet, threads, params.prune_keeps_sole_cover);
  t.prune_ms = sw.lap_ms();
  state.refine(alphabet, params.refine_iterations, params.refine_reach_factor * scan.word_radius, threads);
  t.refine_ms = sw.lap_ms();
  if (timings != nullptr) *timings = t;
  return state.model();
}

}  // namespace lex3d
