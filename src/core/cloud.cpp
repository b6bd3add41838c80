#include "lex3d/core/cloud.hpp"

#include <cstring>

namespace lex3d {

bool is_field_name(const std::string& name) noexcept {
  if (name.empty() || name.size() > 64) return false;
  for (const char c : name)
    if (!((c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_')) return false;
  return true;
}

const char* field_type_name(FieldType t) noexcept {
  switch (t) {
    case FieldType::kInt8: return "int8";
    case FieldType::kUint8: return "uint8";
    case FieldType::kInt16: return "int16";
    case FieldType::kUint16: return "uint16";
    case FieldType::kInt32: return "int32";
    case FieldType::kUint32: return "uint32";
    case FieldType::kFloat32: return "float32";
    case FieldType::kFloat64: return "float64";
    case FieldType::kUnspecified: break;
  }
  return "int32";
}

std::pair<std::int64_t, std::int64_t> field_type_range(FieldType t) noexcept {
  switch (t) {
    case FieldType::kInt8: return {-128, 127};
    case FieldType::kUint8: return {0, 255};
    case FieldType::kInt16: return {-32768, 32767};
    case FieldType::kUint16: return {0, 65535};
    case FieldType::kUint32: return {0, 2147483647};
    default: return {-2147483648LL, 2147483647LL};
  }
}

std::int32_t float_key(float v) noexcept {
  std::uint32_t b = 0;
  std::memcpy(&b, &v, 4);
  return (b & 0x80000000U) != 0 ? -static_cast<std::int32_t>(b & 0x7FFFFFFFU) - 1 : static_cast<std::int32_t>(b);
}

float key_float(std::int32_t key) noexcept {
  const std::uint32_t b = key >= 0 ? static_cast<std::uint32_t>(key) : (0x80000000U | static_cast<std::uint32_t>(-(key + 1)));
  float v = 0.0F;
  std::memcpy(&v, &b, 4);
  return v;
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
