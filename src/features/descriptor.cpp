// Patch descriptors with a full 6-DoF frame (steder2010 §III-A, after the
// interpolated range patches of Steder et al. 2009). The surface around a feature
// point is seen from a virtual viewpoint on its normal, upright in the world, and
// rasterised into a patch_size x patch_size grid of depths covering a fixed 3D radius.
//
// Compared with PCL's NARF (pcl::NarfDescriptor): NARF builds its patch by
// ray-casting a pcl::RangeImage from the virtual viewpoint and reduces it to a
// rotation-invariant 36-beam histogram with an orientation estimated from the patch.
// lex3d keeps the raw depth patch (100 values, as in the papers) and fixes the
// rotation about the normal with the world's up direction, which is what makes the
// frame a full, repeatable 6-DoF pose for the compression model; and it rasterises
// the points it gathers from the range image with a z-buffer instead of ray-casting,
// which is cheaper and needs no pcl::RangeImage.

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include <Eigen/Eigenvalues>

#include "lex3d/core/parallel.hpp"
#include "lex3d/features/features.hpp"

namespace lex3d {

void DescriptorParams::validate() const {
  if (!(support_radius > 0.0 && support_radius <= 100.0))
    throw std::invalid_argument("DescriptorParams::support_radius must be in (0, 100] m");
  if (patch_size < 2 || patch_size > 64)
    throw std::invalid_argument("DescriptorParams::patch_size must be in [2, 64]");
  if (!(normal_radius > 0.0 && normal_radius <= 10.0))
    throw std::invalid_argument("DescriptorParams::normal_radius must be in (0, 10] m");
  if (!(up.allFinite() && up.norm() > 1e-9))
    throw std::invalid_argument("DescriptorParams::up must be a finite non-zero vector");
}

// Eight running sums, element i going to sum i % 8, added pairwise at the end: the
// loop vectorises (SSE or AVX2, picked at load time) and every build gives the same bits.
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && !defined(__SANITIZE_ADDRESS__)
__attribute__((target_clones("avx2", "default")))
#endif
float descriptor_distance_sq(const float* a, const float* b, int dim) noexcept {
  float acc[8] = {0.0F, 0.0F, 0.0F, 0.0F, 0.0F, 0.0F, 0.0F, 0.0F};
  const int blocks = dim / 8;
  for (int k = 0; k < blocks; ++k)
    for (int l = 0; l < 8; ++l) {
      const float d = a[8 * k + l] - b[8 * k + l];
      acc[l] += d * d;
    }
  for (int i = 8 * blocks; i < dim; ++i) {
    const float d = a[i] - b[i];
    acc[i - 8 * blocks] += d * d;
  }
  return ((acc[0] + acc[1]) + (acc[2] + acc[3])) + ((acc[4] + acc[5]) + (acc[6] + acc[7]));
}

std::optional<Keypoint> keypoint_at(const RangeImage& img, const Eigen::Vector3f& point_sensor) {
  float x = 0.0F, y = 0.0F, r = 0.0F;
  if (img.empty() || !img.project(point_sensor, x, y, r)) return std::nullopt;
  if (y < 0.0F || y >= static_cast<float>(img.height)) return std::nullopt;
  if (!img.full_circle && x >= static_cast<float>(img.width)) return std::nullopt;
  Keypoint kp;
  kp.point_sensor = point_sensor;
  kp.x = x;
  kp.y = y;
  return kp;
}

namespace {

// Visits the valid pixels of a window around `kp` that may hold points within
// `radius` of it, sampling at most about (2*max_half+1)^2 of them.
template <typename Fn>
void for_window(const RangeImage& img, const Keypoint& kp, double radius, int max_half, Fn&& fn) {
  const double r = static_cast<double>(kp.point_sensor.norm());
  const double extent = r > radius ? std::asin(radius / r) : M_PI;
  const double el = img.elevation_at(static_cast<double>(kp.y));
  const double cos_el = std::max(std::cos(el), 0.05);
  const int half_x = static_cast<int>(std::min<double>(img.width / 2, std::ceil(extent / (img.azimuth_resolution_rad * cos_el))));
  const int half_y = static_cast<int>(std::min<double>(img.height, std::ceil(extent / img.elevation_resolution_rad)));
  const int stride_x = std::max(1, half_x / std::max(1, max_half));
  const int stride_y = std::max(1, half_y / std::max(1, max_half));
  const int cx = static_cast<int>(std::floor(kp.x));
  const int cy = static_cast<int>(std::floor(kp.y));
  for (int dy = -(half_y / stride_y) * stride_y; dy <= half_y; dy += stride_y) {
    const int y = cy + dy;
    if (y < 0 || y >= img.height) continue;
    for (int dx = -(half_x / stride_x) * stride_x; dx <= half_x; dx += stride_x) {
      const int x = img.wrap_x(cx + dx);
      if (x < 0) continue;
      const std::size_t k = img.index(x, y);
      if (img.state[k] == PixelState::kValid) fn(img.point[k]);
    }
  }
}

struct Frame {
  Eigen::Matrix3f R;  // columns: x, y, z of the feature frame in the sensor frame
  std::uint16_t support;
};

Frame feature_frame(const RangeImage& img, const Keypoint& kp, const DescriptorParams& params,
                    const Eigen::Vector3f& up_sensor) {
  const Eigen::Vector3f p = kp.point_sensor;
  const float range = p.norm();
  const Eigen::Vector3f view = range > 0.0F ? Eigen::Vector3f(p / range) : Eigen::Vector3f::UnitX();
  // Normal from a plane fit; the radius grows with range to keep ~2.5 beam spacings.
  const double spacing = std::max(img.azimuth_resolution_rad, img.elevation_resolution_rad) * range;
  const double radius = std::min(params.support_radius, std::max(params.normal_radius, 2.5 * spacing));
  const float r2 = static_cast<float>(radius * radius);
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  Eigen::Matrix3d sum_sq = Eigen::Matrix3d::Zero();
  int count = 0;
  for_window(img, kp, radius, 7, [&](const Eigen::Vector3f& q) {
    if ((q - p).squaredNorm() > r2) return;
    const Eigen::Vector3d d = (q - p).cast<double>();
    sum += d;
    sum_sq += d * d.transpose();
    ++count;
  });
  Eigen::Vector3f normal = -view;
  if (count >= 3) {
    const Eigen::Vector3d mean = sum / count;
    const Eigen::Matrix3d cov = sum_sq / count - mean * mean.transpose();
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es;
    es.computeDirect(cov);
    const Eigen::Vector3d ev = es.eigenvalues();
    // A plane needs two spread directions; a line of points (one beam ring) does not fix one.
    if (ev(1) > 1e-3 * ev(2) && ev(2) > 0.0) {
      normal = es.eigenvectors().col(0).cast<float>().normalized();
      if (normal.dot(view) > 0.0F) normal = -normal;
    } else {
      count = 0;
    }
  }
  Eigen::Vector3f y_axis = up_sensor - up_sensor.dot(normal) * normal;
  if (y_axis.norm() < 0.1F) {
    // Near-horizontal surface: point y away from the sensor along the surface.
    y_axis = view - view.dot(normal) * normal;
    if (y_axis.norm() < 1e-3F) {
      y_axis = Eigen::Vector3f::UnitX() - normal.x() * normal;
      if (y_axis.norm() < 1e-3F) y_axis = Eigen::Vector3f::UnitY() - normal.y() * normal;
    }
  }
  y_axis.normalize();
  Frame f;
  f.R.col(2) = normal;
  f.R.col(1) = y_axis;
  f.R.col(0) = y_axis.cross(normal);
  f.support = static_cast<std::uint16_t>(std::min(count, 65535));
  return f;
}

void patch_descriptor(const RangeImage& img, const Keypoint& kp, const Eigen::Matrix3f& R,
                      const DescriptorParams& params, float* out) {
  const int s = params.patch_size;
  const float rad = static_cast<float>(params.support_radius);
  const float inv_cell = static_cast<float>(s) / (2.0F * rad);
  const float kEmpty = -std::numeric_limits<float>::infinity();
  thread_local std::vector<float> depth, next;
  depth.assign(static_cast<std::size_t>(s * s), kEmpty);
  const Eigen::Matrix3f Rt = R.transpose();
  const Eigen::Vector3f p = kp.point_sensor;
  for_window(img, kp, params.support_radius * std::sqrt(3.0), s, [&](const Eigen::Vector3f& q) {
    const Eigen::Vector3f l = Rt * (q - p);
    if (std::abs(l.x()) >= rad || std::abs(l.y()) >= rad || std::abs(l.z()) >= rad) return;
    const int ix = std::min(s - 1, static_cast<int>((l.x() + rad) * inv_cell));
    const int iy = std::min(s - 1, static_cast<int>((rad - l.y()) * inv_cell));
    float& d = depth[static_cast<std::size_t>(iy * s + ix)];
    d = std::max(d, l.z());  // z-buffer: the viewpoint sits on +z
  });
  // Interpolate small holes from filled neighbours (two passes); what stays empty
  // is "nothing seen within the support" and gets the far value -radius.
  for (int pass = 0; pass < 2; ++pass) {
    next = depth;
    for (int y = 0; y < s; ++y)
      for (int x = 0; x < s; ++x) {
        if (depth[static_cast<std::size_t>(y * s + x)] != kEmpty) continue;
        float sum = 0.0F;
        int n = 0;
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            const int xx = x + dx, yy = y + dy;
            if (xx < 0 || yy < 0 || xx >= s || yy >= s) continue;
            const float v = depth[static_cast<std::size_t>(yy * s + xx)];
            if (v == kEmpty) continue;
            sum += v;
            ++n;
          }
        if (n >= 2) next[static_cast<std::size_t>(y * s + x)] = sum / static_cast<float>(n);
      }
    depth.swap(next);
  }
  for (int i = 0; i < s * s; ++i) {
    const float v = depth[static_cast<std::size_t>(i)];
    out[i] = v == kEmpty ? -1.0F : std::clamp(v / rad, -1.0F, 1.0F);
  }
}

}  // namespace

Features describe(const RangeImage& img, const std::vector<Keypoint>& keypoints, const DescriptorParams& params,
                  int threads) {
  params.validate();
  Features out;
  out.descriptor_dim = params.patch_size * params.patch_size;
  out.features.resize(keypoints.size());
  out.descriptors.assign(keypoints.size() * static_cast<std::size_t>(out.descriptor_dim), 0.0F);
  for (const auto& kp : keypoints) (kp.kind == FeatureKind::kInterest ? out.interest_count : out.coverage_count)++;
  if (keypoints.empty() || img.empty()) return out;
  const Eigen::Isometry3f T_cloud_sensor = img.T_cloud_sensor.cast<float>();
  const Eigen::Vector3f up_sensor =
      (T_cloud_sensor.linear().transpose() * params.up.cast<float>()).normalized();
  parallel_for(keypoints.size(), threads, [&](std::size_t i) {
    const Keypoint& kp = keypoints[i];
    const Frame f = feature_frame(img, kp, params, up_sensor);
    Eigen::Isometry3f T_sensor_feature = Eigen::Isometry3f::Identity();
    T_sensor_feature.linear() = f.R;
    T_sensor_feature.translation() = kp.point_sensor;
    Feature& feat = out.features[i];
    feat.keypoint = kp;
    feat.normal_support = f.support;
    feat.T_cloud_feature = img.T_cloud_sensor * T_sensor_feature.cast<double>();
    patch_descriptor(img, kp, f.R, params,
                     out.descriptors.data() + i * static_cast<std::size_t>(out.descriptor_dim));
  });
  return out;
}

}  // namespace lex3d
