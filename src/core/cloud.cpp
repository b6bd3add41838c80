#include "lex3d/core/cloud.hpp"

namespace lex3d {

bool is_field_name(const std::string& name) noexcept {
  if (name.empty() || name.size() > 64) return false;
  for (const char c : name)
    if (!((c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_')) return false;
  return true;
}

Bounds compute_bounds(const Cloud& cloud) {
  Bounds b;
  if (cloud.empty()) return b;
  b.min = b.max = cloud.points.front();
  for (const auto& p : cloud.points) {
    b.min = b.min.cwiseMin(p);
    b.max = b.max.cwiseMax(p);
  }
  b.valid = true;
  return b;
}

Cloud transformed(const Cloud& cloud, const Pose& T) {
  Cloud out = cloud;
  const Eigen::Matrix3f R = T.linear().cast<float>();
  const Eigen::Vector3f t = T.translation().cast<float>();
  for (auto& p : out.points) p = R * p + t;
  for (auto& d : out.no_return_directions) d = R * d;
  out.T_cloud_sensor = T * cloud.T_cloud_sensor;
  out.T_world_cloud = cloud.T_world_cloud * T.inverse();
  return out;
}

}  // namespace lex3d
