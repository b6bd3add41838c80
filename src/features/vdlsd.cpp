// VD-LSD (Taati et al. 2007; collier2012 §3.1: three positional and three dispersion
// properties, two bins each). For every feature, the points within the support radius are
// gathered with a kd-tree, each support point's shape is taken from the eigenvalues of its
// own neighbourhood's covariance, and the points are binned jointly by their position in the
// feature's frame and their shape. Bins are soft (linear between bin centres), so that a
// point near a bin border counts for both sides and re-sampling moves the histogram little.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>

#include <Eigen/Eigenvalues>
#include <pcl/kdtree/kdtree_flann.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include "lex3d/core/parallel.hpp"
#include "lex3d/features/vdlsd.hpp"

namespace lex3d {

void VdlsdParams::validate() const {
  auto check = [](bool ok, const char* what) {
    if (!ok) throw std::invalid_argument(what);
  };
  check(support_radius > 0.0 && support_radius <= 100.0, "VdlsdParams::support_radius must be in (0, 100] m");
  check(local_radius > 0.0 && local_radius <= 10.0, "VdlsdParams::local_radius must be in (0, 10] m");
  check(beam_spacing_rad >= 0.0 && beam_spacing_rad <= 0.2, "VdlsdParams::beam_spacing_rad must be in [0, 0.2]");
  check(local_points >= 5 && local_points <= 4096, "VdlsdParams::local_points must be in [5, 4096]");
  check(bins >= 2 && bins <= 3, "VdlsdParams::bins must be in [2, 3]");
  check(max_support >= 8 && max_support <= 65536, "VdlsdParams::max_support must be in [8, 65536]");
  check(min_support >= 1 && min_support <= 65536, "VdlsdParams::min_support must be in [1, 65536]");
}

int vdlsd_dimension(int bins) {
  int d = 1;
  for (int k = 0; k < 6; ++k) d *= bins;
  return d;
}

namespace {

// Shape of a neighbourhood: linearity, planarity, scattering ((l1 - l2) / l1, (l2 - l3) / l1,
// l3 / l1 with l1 >= l2 >= l3 the covariance's eigenvalues); they sum to 1.
struct Shape {
  float value[3] = {0.0F, 0.0F, 0.0F};
  bool valid = false;
};

// The two bins a value in [0, 1] falls between (centres at (k + 0.5) / bins) and the
// weight of the lower one; clamped at the ends.
inline void soft_bin(float v, int bins, int& lo, float& w_lo) {
  const float t = std::clamp(v, 0.0F, 1.0F) * static_cast<float>(bins) - 0.5F;
  if (t <= 0.0F) {
    lo = 0;
    w_lo = 1.0F;
    return;
  }
  if (t >= static_cast<float>(bins - 1)) {
    lo = bins - 2;
    w_lo = 0.0F;
    return;
  }
  lo = static_cast<int>(t);
  w_lo = 1.0F - (t - static_cast<float>(lo));
}

}  // namespace

VdlsdResult describe_vdlsd(const Cloud& cloud, const std::vector<Pose>& T_cloud_feature, const VdlsdParams& params,
                           int threads) {
  params.validate();
  if (threads < 1 || threads > 64) throw std::invalid_argument("describe_vdlsd: threads must be in [1, 64]");
  for (const Pose& T : T_cloud_feature)
    if (!T.matrix().allFinite()) throw std::invalid_argument("describe_vdlsd: a feature frame is not finite");
  VdlsdResult out;
  const int bins = params.bins;
  const int dim = vdlsd_dimension(bins);
  out.descriptor_dim = dim;
  const std::size_t m = T_cloud_feature.size();
  out.descriptors.assign(m * static_cast<std::size_t>(dim), -1.0F);
  if (m == 0) return out;
  if (cloud.points.empty()) {
    out.empty = m;
    return out;
  }

  // The kd-tree holds the points that a support or a support point's neighbourhood can
  // reach: within support_radius plus the largest local radius of some feature.
  const Eigen::Vector3f origin = cloud.T_cloud_sensor.translation().cast<float>();
  const double grow = 2.5 * params.beam_spacing_rad;
  std::vector<Eigen::Vector3f> centres(m);
  std::vector<float> reach2(m);
  for (std::size_t i = 0; i < m; ++i) {
    centres[i] = T_cloud_feature[i].translation().cast<float>();
    const double far = static_cast<double>((centres[i] - origin).norm()) + params.support_radius;
    const double reach = params.support_radius + std::max(params.local_radius, grow * far) + 1e-3;
    reach2[i] = static_cast<float>(reach * reach);
  }
  auto pc = pcl::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
  std::vector<std::uint32_t> cloud_index;  // tree point -> cloud point
  for (std::size_t j = 0; j < cloud.points.size(); ++j) {
    const Eigen::Vector3f& p = cloud.points[j];
    for (std::size_t i = 0; i < m; ++i)
      if ((p - centres[i]).squaredNorm() <= reach2[i]) {
        pc->push_back(pcl::PointXYZ(p.x(), p.y(), p.z()));
        cloud_index.push_back(static_cast<std::uint32_t>(j));
        break;
      }
  }
  if (pc->empty()) {
    out.empty = m;
    return out;
  }
  pcl::KdTreeFLANN<pcl::PointXYZ> tree(/*sorted=*/true);
  tree.setInputCloud(pc);
  // Points by tree index.
  std::vector<Eigen::Vector3f> pts(cloud_index.size());
  for (std::size_t j = 0; j < pts.size(); ++j) pts[j] = cloud.points[cloud_index[j]];

  // 1. The support of each feature: its points within the radius, in index order, at most
  //    max_support of them evenly spaced.
  const auto radius = static_cast<float>(params.support_radius);
  std::vector<std::vector<std::uint32_t>> support(m);
  parallel_for(
      m, threads,
      [&](std::size_t i) {
        const Eigen::Vector3d o = T_cloud_feature[i].translation();
        pcl::Indices idx;
        std::vector<float> d2;
        tree.radiusSearch(pcl::PointXYZ(static_cast<float>(o.x()), static_cast<float>(o.y()), static_cast<float>(o.z())),
                          radius, idx, d2);
        std::sort(idx.begin(), idx.end());
        const std::size_t n = idx.size();
        const auto cap = static_cast<std::size_t>(params.max_support);
        auto& s = support[i];
        if (n <= cap) {
          s.assign(idx.begin(), idx.end());
        } else {
          s.reserve(cap);
          for (std::size_t k = 0; k < cap; ++k) s.push_back(static_cast<std::uint32_t>(idx[k * n / cap]));
        }
      },
      4);

  // 2. The shape of every distinct support point (each computed once, written to its slot).
  std::vector<std::uint32_t> distinct;
  for (const auto& s : support) {
    distinct.insert(distinct.end(), s.begin(), s.end());
    out.support_points += s.size();
  }
  std::sort(distinct.begin(), distinct.end());
  distinct.erase(std::unique(distinct.begin(), distinct.end()), distinct.end());
  out.shapes = distinct.size();
  std::vector<Shape> shapes(distinct.size());
  parallel_for(
      distinct.size(), threads,
      [&](std::size_t k) {
        const Eigen::Vector3f& q = pts[distinct[k]];
        const double r = std::max(params.local_radius, grow * static_cast<double>((q - origin).norm()));
        pcl::Indices idx;
        std::vector<float> d2;
        // The nearest local_points points, those within r kept (d2 increasing).
        tree.nearestKSearch(pcl::PointXYZ(q.x(), q.y(), q.z()), params.local_points, idx, d2);
        const auto r2 = static_cast<float>(r * r);
        int n = 0;
        while (n < static_cast<int>(d2.size()) && d2[static_cast<std::size_t>(n)] <= r2) ++n;
        if (n < 5) return;
        // Covariance about the mean, in double, in the order the search gives (sorted by
        // distance, ties by FLANN's deterministic traversal).
        Eigen::Vector3d mean = Eigen::Vector3d::Zero();
        for (int j = 0; j < n; ++j) mean += (pts[static_cast<std::size_t>(idx[static_cast<std::size_t>(j)])] - q).cast<double>();
        mean /= n;
        Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
        for (int j = 0; j < n; ++j) {
          const Eigen::Vector3d d =
              (pts[static_cast<std::size_t>(idx[static_cast<std::size_t>(j)])] - q).cast<double>() - mean;
          cov += d * d.transpose();
        }
        cov /= n;
        Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es;
        es.computeDirect(cov, Eigen::EigenvaluesOnly);
        const Eigen::Vector3d ev = es.eigenvalues();  // increasing
        const double l1 = ev(2), l2 = std::max(ev(1), 0.0), l3 = std::max(ev(0), 0.0);
        if (!(l1 > 1e-12)) return;  // every neighbour at one spot
        Shape& s = shapes[k];
        s.value[0] = static_cast<float>((l1 - l2) / l1);
        s.value[1] = static_cast<float>((l2 - l3) / l1);
        s.value[2] = static_cast<float>(l3 / l1);
        s.valid = true;
      },
      64);

  // 3. The joint soft histogram of each feature.
  std::vector<std::size_t> empty_flag(m, 0), shapeless(m, 0);
  parallel_for(
      m, threads,
      [&](std::size_t i) {
        const Eigen::Matrix3f Rt = T_cloud_feature[i].linear().transpose().cast<float>();
        const Eigen::Vector3f o = T_cloud_feature[i].translation().cast<float>();
        std::vector<double> h(static_cast<std::size_t>(dim), 0.0);
        int used = 0;
        for (const std::uint32_t p : support[i]) {
          const auto k = static_cast<std::size_t>(std::lower_bound(distinct.begin(), distinct.end(), p) - distinct.begin());
          const Shape& s = shapes[k];
          if (!s.valid) {
            ++shapeless[i];
            continue;
          }
          ++used;
          const Eigen::Vector3f local = Rt * (pts[p] - o);
          float v[6];
          for (int a = 0; a < 3; ++a) v[a] = 0.5F * (local(a) / radius + 1.0F);
          for (int a = 0; a < 3; ++a) v[3 + a] = s.value[a];
          int lo[6];
          float w[6];
          for (int a = 0; a < 6; ++a) soft_bin(v[a], bins, lo[a], w[a]);
          // The 2^6 corners of the cell the point falls in.
          for (int c = 0; c < 64; ++c) {
            double weight = 1.0;
            int cell = 0;
            for (int a = 0; a < 6; ++a) {
              const bool up = ((c >> a) & 1) != 0;
              weight *= up ? 1.0 - w[a] : w[a];
              cell = cell * bins + lo[a] + (up ? 1 : 0);
            }
            if (weight > 0.0) h[static_cast<std::size_t>(cell)] += weight;
          }
        }
        if (used < params.min_support) {
          empty_flag[i] = 1;
          return;
        }
        double total = 0.0;
        for (const double x : h) total += x;
        float* d = out.descriptors.data() + i * static_cast<std::size_t>(dim);
        for (int c = 0; c < dim; ++c)
          d[c] = static_cast<float>(2.0 * std::sqrt(h[static_cast<std::size_t>(c)] / total) - 1.0);
      },
      4);
  for (std::size_t i = 0; i < m; ++i) {
    out.empty += empty_flag[i];
    out.shapeless_points += shapeless[i];
  }
  return out;
}

}  // namespace lex3d
