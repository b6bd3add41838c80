// Point-to-point distances between an original cloud and a decoded one, and the
// range-dependent inliers/outliers of ruhnke2010 §IV.
//
// Definitions agree with the independent checker /work/shared/tools/pcmetrics.py:
// points with a non-finite coordinate are left out, every distance is computed in
// double precision from the float32 coordinates, coverage counts d(a, B) <= tau and
// outliers count d(b, A) > tau. Nearest neighbours are exact (FLANN's single kd-tree
// with eps = 0, double coordinates); per-point results go to per-index arrays that
// are summed in index order, so the results do not depend on the thread count.

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include <flann/algorithms/dist.h>
#include <flann/algorithms/kdtree_single_index.h>

#include "lex3d/core/parallel.hpp"
#include "lex3d/eval/metrics.hpp"

namespace lex3d::eval {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
// Indices handed to a thread at a time: a kd-tree query is ~1 us, so chunks of a few
// hundred keep the shared counter out of the way.
constexpr std::size_t kGrain = 256;

void check_threads(int threads, const char* field) {
  if (threads < 1 || threads > 64) throw std::invalid_argument(std::string(field) + " must be in [1, 64]");
}

/// The finite points of `cloud` as packed double x y z triples.
std::vector<double> finite_xyz(const Cloud& cloud) {
  std::vector<double> xyz;
  xyz.reserve(cloud.points.size() * 3);
  for (const auto& p : cloud.points) {
    if (!p.allFinite()) continue;
    xyz.push_back(static_cast<double>(p.x()));
    xyz.push_back(static_cast<double>(p.y()));
    xyz.push_back(static_cast<double>(p.z()));
  }
  return xyz;
}

double squared_distance(const double* p, const double* q) noexcept {
  const double dx = p[0] - q[0];
  const double dy = p[1] - q[1];
  const double dz = p[2] - q[2];
  return dx * dx + dy * dy + dz * dz;
}

/// FLANN result set keeping only the nearest point, without allocating.
class NearestResult final : public flann::ResultSet<double> {
 public:
  bool full() const override { return true; }
  void addPoint(double dist, std::size_t index) override {
    if (dist < best_dist) {
      best_dist = dist;
      best_index = index;
    }
  }
  double worstDist() const override { return best_dist; }

  double best_dist = std::numeric_limits<double>::max();
  std::size_t best_index = 0;
};

/// Exact nearest-neighbour queries over x y z triples (non-empty). Concurrent queries
/// are safe once built.
class NearestIndex {
 public:
  explicit NearestIndex(std::vector<double> xyz)
      : xyz_(std::move(xyz)),
        index_(flann::Matrix<double>(xyz_.data(), xyz_.size() / 3, 3),
               flann::KDTreeSingleIndexParams(/*leaf_max_size=*/10, /*reorder=*/true)) {
    index_.buildIndex();
  }

  /// Squared distance from q to the nearest indexed point, recomputed from that point.
  double nearest_sq(const double* q) const {
    NearestResult result;
    index_.findNeighbors(result, q, flann::SearchParams(flann::FLANN_CHECKS_UNLIMITED, /*eps=*/0.0F));
    return squared_distance(q, xyz_.data() + 3 * result.best_index);
  }

 private:
  std::vector<double> xyz_;
  flann::KDTreeSingleIndex<flann::L2_Simple<double>> index_;
};

/// Squared distance from every query point to its nearest point of `index`.
std::vector<double> nearest_squared(const std::vector<double>& queries, const NearestIndex& index, int threads) {
  std::vector<double> out(queries.size() / 3);
  parallel_for(
      out.size(), threads, [&](std::size_t i) { out[i] = index.nearest_sq(queries.data() + 3 * i); }, kGrain);
  return out;
}

}  // namespace

void DistanceParams::validate() const {
  if (!(std::isfinite(peak) && peak > 0.0))
    throw std::invalid_argument("DistanceParams::peak must be finite and > 0 m");
  for (std::size_t k = 0; k < taus.size(); ++k)
    if (!(std::isfinite(taus[k]) && taus[k] > 0.0))
      throw std::invalid_argument("DistanceParams::taus[" + std::to_string(k) + "] must be finite and > 0 m");
  check_threads(threads, "DistanceParams::threads");
}

DistanceResult compare_clouds(const Cloud& a, const Cloud& b, const DistanceParams& params) {
  params.validate();
  std::vector<double> xyz_a = finite_xyz(a);
  std::vector<double> xyz_b = finite_xyz(b);
  DistanceResult r;
  r.points_a = xyz_a.size() / 3;
  r.points_b = xyz_b.size() / 3;
  const std::size_t taus = params.taus.size();

  if (r.points_a == 0 || r.points_b == 0) {
    const bool both = r.points_a == 0 && r.points_b == 0;
    const double d = both ? 0.0 : kInf;
    r.mse_ab = r.mse_ba = r.rmse = r.chamfer = r.hausdorff = d;
    r.d1_psnr_db = both ? kInf : -kInf;
    r.coverage.assign(taus, 0.0);
    r.outliers.assign(taus, 1.0);
    return r;
  }

  // Both directions; each query array is built before its index takes the other array.
  std::vector<double> d_ab;  // squared d(a_i, B)
  std::vector<double> d_ba;  // squared d(b_j, A)
  {
    const NearestIndex index_b(xyz_b);
    d_ab = nearest_squared(xyz_a, index_b, params.threads);
  }
  {
    const NearestIndex index_a(std::move(xyz_a));
    d_ba = nearest_squared(xyz_b, index_a, params.threads);
  }

  // Sums in index order: deterministic whatever the thread count.
  struct Side {
    double mse = 0.0, mean = 0.0, max = 0.0;
    std::vector<std::size_t> within;  // per tau: distances <= tau
  };
  auto summarise = [&](const std::vector<double>& sq) {
    Side s;
    s.within.assign(taus, 0);
    double sum_sq = 0.0, sum = 0.0;
    for (const double q : sq) {
      const double d = std::sqrt(q);
      sum_sq += q;
      sum += d;
      s.max = std::max(s.max, d);
      for (std::size_t k = 0; k < taus; ++k)
        if (d <= params.taus[k]) ++s.within[k];
    }
    const auto n = static_cast<double>(sq.size());
    s.mse = sum_sq / n;
    s.mean = sum / n;
    return s;
  };
  const Side sa = summarise(d_ab);
  const Side sb = summarise(d_ba);

  r.mse_ab = sa.mse;
  r.mse_ba = sb.mse;
  const double mse = std::max(sa.mse, sb.mse);
  r.rmse = std::sqrt(mse);
  r.d1_psnr_db = mse > 0.0 ? 10.0 * std::log10(3.0 * params.peak * params.peak / mse) : kInf;
  r.chamfer = sa.mean + sb.mean;
  r.hausdorff = std::max(sa.max, sb.max);
  r.coverage.resize(taus);
  r.outliers.resize(taus);
  for (std::size_t k = 0; k < taus; ++k) {
    r.coverage[k] = static_cast<double>(sa.within[k]) / static_cast<double>(r.points_a);
    r.outliers[k] = static_cast<double>(r.points_b - sb.within[k]) / static_cast<double>(r.points_b);
  }
  return r;
}

double RangeSigma::at(const Eigen::Vector3f& p) const noexcept {
  return std::max(min_sigma, factor * (p.cast<double>() - origin).norm());
}

InlierResult inliers_outliers(const Cloud& input, const Cloud& reconstruction, const RangeSigma& sigma,
                              int threads) {
  if (!(std::isfinite(sigma.factor) && sigma.factor >= 0.0))
    throw std::invalid_argument("RangeSigma::factor must be finite and >= 0");
  if (!(std::isfinite(sigma.min_sigma) && sigma.min_sigma >= 0.0))
    throw std::invalid_argument("RangeSigma::min_sigma must be finite and >= 0 m");
  if (!sigma.origin.allFinite()) throw std::invalid_argument("RangeSigma::origin must be finite");
  check_threads(threads, "inliers_outliers threads");

  std::vector<double> xyz_in = finite_xyz(input);
  std::vector<double> xyz_rec = finite_xyz(reconstruction);
  const std::size_t n_in = xyz_in.size() / 3;
  const std::size_t n_rec = xyz_rec.size() / 3;
  InlierResult r;
  if (n_in == 0) {
    r.inliers = 0.0;
    r.outliers = n_rec == 0 ? 0.0 : 1.0;  // nothing in the input explains any reconstructed point
    return r;
  }
  if (n_rec == 0) {
    r.inliers = 0.0;
    r.outliers = 0.0;
    return r;
  }

  // A point is within sigma of the other cloud exactly when its nearest neighbour is.
  auto sigma_at = [&](const double* p) {
    return std::max(sigma.min_sigma,
                    sigma.factor * (Eigen::Vector3d(p[0], p[1], p[2]) - sigma.origin).norm());
  };
  std::vector<std::uint8_t> inlier(n_in), outlier(n_rec);
  {
    const NearestIndex index_rec(xyz_rec);
    parallel_for(
        n_in, threads,
        [&](std::size_t i) {
          const double* p = xyz_in.data() + 3 * i;
          inlier[i] = std::sqrt(index_rec.nearest_sq(p)) <= sigma_at(p) ? 1 : 0;
        },
        kGrain);
  }
  {
    const NearestIndex index_in(std::move(xyz_in));
    parallel_for(
        n_rec, threads,
        [&](std::size_t j) {
          const double* q = xyz_rec.data() + 3 * j;
          outlier[j] = std::sqrt(index_in.nearest_sq(q)) > sigma_at(q) ? 1 : 0;
        },
        kGrain);
  }
  std::size_t n_inliers = 0, n_outliers = 0;
  for (const auto v : inlier) n_inliers += v;
  for (const auto v : outlier) n_outliers += v;
  r.inliers = static_cast<double>(n_inliers) / static_cast<double>(n_in);
  r.outliers = static_cast<double>(n_outliers) / static_cast<double>(n_rec);
  return r;
}

}  // namespace lex3d::eval
