#pragma once
/// \file
/// Conversions between lex3d::Cloud and pcl::PointCloud<PointT>, header-only, for any
/// PCL point type with x, y, z (pcl::PointXYZ, pcl::PointXYZI, pcl::PointXYZRGB, ...);
/// the intensity is carried when the point type has an `intensity` field. Only code
/// that includes this header pulls in PCL (the rest of lex3d's headers do not); the
/// caller then needs PCL's include directories (find_package(PCL COMPONENTS common)).
///
///     pcl::PointCloud<pcl::PointXYZI> scan = ...;
///     lex3d::PclConversionStats stats;
///     lex3d::Cloud cloud = lex3d::from_pcl(scan, &stats);   // stats.non_finite: points dropped
///     auto file = lex3d::compress(cloud, options);
///     pcl::PointCloud<pcl::PointXYZ> back = lex3d::to_pcl<pcl::PointXYZ>(decoded.cloud);

#include <cmath>
#include <cstddef>
#include <cstdint>

#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include "lex3d/core/cloud.hpp"

// The public API: exported by liblex3d.so, which hides everything else.
#pragma GCC visibility push(default)

namespace lex3d {

/// What from_pcl did not carry over.
struct PclConversionStats {
  /// Points with a NaN or infinite coordinate (an organised cloud's no-returns among
  /// them), dropped as lex3d's readers drop them.
  std::size_t non_finite = 0;
};

/// A lex3d::Cloud of `in`'s finite points, in order, with their intensity when PointT has
/// one. The sensor pose is `in`'s sensor_origin_ / sensor_orientation_ (as a PCD file's
/// VIEWPOINT). An organised cloud (height > 1) keeps its shape: each point's row becomes
/// its ring (laser) and its column its column, as lex3d's PCD reader does. Non-finite
/// points are dropped and counted in `stats`.
template <typename PointT>
[[nodiscard]] Cloud from_pcl(const pcl::PointCloud<PointT>& in, PclConversionStats* stats = nullptr) {
  constexpr bool kIntensity = pcl::traits::has_intensity_v<PointT>;
  const bool organised = in.height > 1 && static_cast<std::size_t>(in.width) * in.height == in.size();
  Cloud out;
  out.points.reserve(in.size());
  if (kIntensity) out.intensity.reserve(in.size());
  if (organised) {
    out.ring.reserve(in.size());
    out.column.reserve(in.size());
    out.rows = in.height;
    out.columns = in.width;
  }
  std::size_t dropped = 0;
  for (std::size_t i = 0; i < in.size(); ++i) {
    const PointT& p = in[i];
    if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) {
      ++dropped;
      continue;
    }
    out.points.emplace_back(p.x, p.y, p.z);
    if constexpr (kIntensity) out.intensity.push_back(static_cast<float>(p.intensity));
    if (organised) {
      out.ring.push_back(static_cast<std::uint16_t>(i / in.width));
      out.column.push_back(static_cast<std::uint32_t>(i % in.width));
    }
  }
  Pose T = Pose::Identity();
  T.linear() = in.sensor_orientation_.toRotationMatrix().template cast<double>();
  T.translation() = in.sensor_origin_.template head<3>().template cast<double>();
  out.T_cloud_sensor = T;
  if (stats) stats->non_finite = dropped;
  return out;
}

/// `cloud` as an unorganised pcl::PointCloud<PointT> (width = points, height = 1), with
/// the intensity when both PointT and the cloud have one (0 where PointT has one and the
/// cloud does not), and the sensor pose as sensor_origin_ / sensor_orientation_.
template <typename PointT>
[[nodiscard]] pcl::PointCloud<PointT> to_pcl(const Cloud& cloud) {
  pcl::PointCloud<PointT> out;
  out.resize(cloud.size());
  const bool intensity = cloud.has_intensity();
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    PointT& p = out[i];
    p.x = cloud.points[i].x();
    p.y = cloud.points[i].y();
    p.z = cloud.points[i].z();
    if constexpr (pcl::traits::has_intensity_v<PointT>)
      p.intensity = intensity ? static_cast<decltype(p.intensity)>(cloud.intensity[i]) : decltype(p.intensity){};
  }
  out.width = static_cast<std::uint32_t>(cloud.size());
  out.height = 1;
  out.is_dense = true;
  out.sensor_origin_ = Eigen::Vector4f::Zero();
  out.sensor_origin_.template head<3>() = cloud.T_cloud_sensor.translation().template cast<float>();
  out.sensor_orientation_ = Eigen::Quaternionf(cloud.T_cloud_sensor.rotation().template cast<float>());
  return out;
}

}  // namespace lex3d

#pragma GCC visibility pop
