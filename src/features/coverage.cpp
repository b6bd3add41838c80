// Uniform coverage points (ruhnke2010 §III-C): feature points spread over the
// scan so that every point lies within a set distance of one, so plain surfaces
// get words too.

#include <stdexcept>

#include "features/point_hash.hpp"
#include "lex3d/features/features.hpp"

namespace lex3d {

void CoverageParams::validate() const {
  if (!(distance >= 0.0 && distance <= 100.0))
    throw std::invalid_argument("CoverageParams::distance must be in [0, 100] m (0 disables)");
}

std::vector<Keypoint> coverage_points(const Cloud& cloud, const RangeImage& img,
                                      const std::vector<Keypoint>& existing, const CoverageParams& params) {
  params.validate();
  std::vector<Keypoint> added;
  if (params.distance <= 0.0 || img.empty()) return added;
  detail::PointHash hash(static_cast<float>(params.distance));
  for (const auto& kp : existing) hash.insert(kp.point_sensor);

  auto add = [&](const Eigen::Vector3f& p, float x, float y) {
    hash.insert(p);
    Keypoint kp;
    kp.point_sensor = p;
    kp.x = x;
    kp.y = y;
    kp.interest = 0.0F;
    kp.kind = FeatureKind::kCoverage;
    added.push_back(kp);
  };
  // Visible surface first, in image order: neighbouring pixels are neighbours in 3D,
  // which keeps the points evenly spread and the hash's last-hit shortcut effective.
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) {
      const std::size_t k = img.index(x, y);
      if (img.state[k] == PixelState::kValid && !hash.any_within(img.point[k]))
        add(img.point[k], static_cast<float>(x) + 0.5F, static_cast<float>(y) + 0.5F);
    }
  // Then the returns hidden behind a closer one in the same pixel, so the guarantee
  // holds for every point of the scan (points under min_range excepted).
  const Eigen::Isometry3f T_sensor_cloud = img.T_cloud_sensor.inverse().cast<float>();
  std::vector<bool> in_image(cloud.size(), false);
  for (const auto s : img.source)
    if (s >= 0 && static_cast<std::size_t>(s) < in_image.size()) in_image[static_cast<std::size_t>(s)] = true;
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    if (in_image[i]) continue;
    const Eigen::Vector3f q = T_sensor_cloud * cloud.points[i];
    // What RangeImage::project and the min_range test decide from the range alone,
    // before the angles, which only a point that adds a keypoint needs.
    const float range = q.norm();
    if (!(range > 0.0F) || static_cast<double>(range) < img.min_range) continue;
    if (hash.any_within(q)) continue;
    float x = 0.0F, y = 0.0F, r = 0.0F;
    if (img.project(q, x, y, r)) add(q, x, y);
  }
  return added;
}

}  // namespace lex3d
