#pragma once
/// \file
/// The one point cloud type that flows through lex3d: contiguous arrays of
/// positions (metres, sensor or world frame as the producer documents) with
/// optional per-point intensity. Conversions to and from pcl::PointCloud live
/// in lex3d/core/pcl_conversions.hpp so that PCL headers stay out of here.

#include <cstddef>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace lex3d {

/// A rigid 6-DoF transform (rotation + translation), double precision.
using Pose = Eigen::Isometry3d;

/// A point cloud: positions and, when the source has them, intensities.
struct Cloud {
  /// Point positions in metres.
  std::vector<Eigen::Vector3f> points;
  /// Per-point intensity; empty when the source had none, else points.size().
  std::vector<float> intensity;
  /// Directions (unit vectors, cloud frame) of beams that returned no echo,
  /// when the source format records them (e.g. the 3DTK `.3d` no-return value).
  std::vector<Eigen::Vector3f> no_return_directions;
  /// Pose of the sensor in the frame the points are expressed in: a PCD file's
  /// VIEWPOINT; identity for the other formats, whose scans are stored in the
  /// sensor frame. Written back as the VIEWPOINT of a PCD file.
  Pose T_cloud_sensor = Pose::Identity();
  /// Pose of the cloud frame in a world frame, when the data provides one
  /// (a `.pose` file, a poses.txt line); identity otherwise.
  Pose T_world_cloud = Pose::Identity();
  /// True when T_world_cloud came from the data rather than the default.
  bool has_world_pose = false;

  [[nodiscard]] std::size_t size() const noexcept { return points.size(); }
  [[nodiscard]] bool empty() const noexcept { return points.empty(); }
  [[nodiscard]] bool has_intensity() const noexcept {
    return !intensity.empty() && intensity.size() == points.size();
  }
};

/// Axis-aligned bounds of a cloud; for an empty cloud both corners are zero
/// and `valid` is false.
struct Bounds {
  Eigen::Vector3f min = Eigen::Vector3f::Zero();
  Eigen::Vector3f max = Eigen::Vector3f::Zero();
  bool valid = false;
};

[[nodiscard]] Bounds compute_bounds(const Cloud& cloud);

/// Returns a copy of `cloud` with every point mapped by `T` (float math); the
/// sensor pose moves with the points and the world pose is kept consistent.
[[nodiscard]] Cloud transformed(const Cloud& cloud, const Pose& T);

}  // namespace lex3d
