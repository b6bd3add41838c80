// The up direction of a scan from the normals of its surfaces (horizontal and vertical ones),
// for scans without a pose or IMU.

#include "lex3d/place/gravity.hpp"

#include <algorithm>
#include <cmath>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

#include "place/internal.hpp"

namespace lex3d {

const char* to_string(GravitySource s) noexcept {
  switch (s) {
    case GravitySource::kPoses: return "poses";
    case GravitySource::kPoints: return "points";
    case GravitySource::kNone: return "none";
  }
  return "none";
}

GravityEstimate estimate_gravity(const Cloud& cloud, const RangeImageParams& range) {
  GravityEstimate out;
  const Eigen::Vector3d spin = cloud.T_cloud_sensor.linear().col(2).normalized();
  out.up = spin;
  // Surface normals of the scan's coarse range image, as the place module computes them:
  // one a 1.5-degree pixel, so near and far surfaces count alike.
  PlaceScan s;
  s.coarse = detail::make_coarse_image(make_range_image(cloud, range), PlaceStorageParams{});
  detail::make_dense_points(s);
  const std::vector<Eigen::Vector3f>& normals = s.dense_normals;
  out.normals = normals.size();
  if (normals.empty()) return out;
  // Each round: the direction d that maximises sum over horizontal surfaces (n.d)^2 plus
  // sum over vertical ones 1 - (n.d)^2, i.e. the top eigenvector of
  // M = sum_h n n^T + sum_v (I - n n^T), with the classes taken within `window` of the
  // current d. The first window (40 degrees) takes in a sensor tilted by up to about 35
  // degrees (a hand-held one); the last (10) leaves out what is merely sloped.
  Eigen::Vector3d d = spin;
  std::size_t nh = 0, nv = 0;
  Eigen::Matrix3d M = Eigen::Matrix3d::Zero();
  for (const double window_deg : {40.0, 30.0, 20.0, 15.0, 10.0, 10.0, 10.0}) {
    const double w = window_deg * M_PI / 180.0;
    const float ch = static_cast<float>(std::cos(w)), sv = static_cast<float>(std::sin(w));
    const Eigen::Vector3f df = d.cast<float>();
    Eigen::Matrix3f A = Eigen::Matrix3f::Zero();
    std::size_t h = 0, v = 0;
    for (const Eigen::Vector3f& n : normals) {
      const float c = std::abs(n.dot(df));
      if (c >= ch) {
        A.noalias() += n * n.transpose();
        ++h;
      } else if (c <= sv) {
        A.noalias() += Eigen::Matrix3f::Identity() - n * n.transpose();
        ++v;
      }
    }
    nh = h;
    nv = v;
    M = A.cast<double>();
    if (h + v == 0) break;
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(M);
    Eigen::Vector3d e = es.eigenvectors().col(2).normalized();
    if (e.dot(spin) < 0.0) e = -e;
    d = e;
  }
  out.horizontal = nh;
  out.vertical = nv;
  // Enough surfaces of either kind, and a direction they fix: the top eigenvalue clearly
  // above the second (walls of one direction alone leave a circle of directions).
  if ((nh + nv) * 100 < 3 * out.normals) return out;
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(M);
  const Eigen::Vector3d ev = es.eigenvalues();
  if (!(ev(2) > 0.0) || (ev(2) - ev(1)) < 0.1 * static_cast<double>(nh + nv)) return out;
  out.up = d;
  out.source = GravitySource::kPoints;
  out.tilt_deg = std::acos(std::clamp(d.dot(spin), -1.0, 1.0)) * 180.0 / M_PI;
  return out;
}

GravitySource apply_gravity(Cloud& cloud, const RangeImageParams& range) {
  if (cloud.has_world_pose) return GravitySource::kPoses;
  const GravityEstimate g = estimate_gravity(cloud, range);
  if (g.source != GravitySource::kPoints) return g.source;
  cloud.T_world_cloud = Pose::Identity();
  cloud.T_world_cloud.linear() = Eigen::Quaterniond::FromTwoVectors(g.up, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  cloud.has_world_pose = true;
  return GravitySource::kPoints;
}

}  // namespace lex3d
