#pragma once
/// \file
/// The one point cloud type that flows through lex3d: contiguous arrays of
/// positions (metres, sensor or world frame as the producer documents) with
/// optional per-point intensity. Conversions to and from pcl::PointCloud live
/// in the io module, so that PCL headers stay out of here.

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace lex3d {

/// A rigid 6-DoF transform (rotation + translation), double precision.
using Pose = Eigen::Isometry3d;

/// The beam layout of a spinning lidar: one entry per laser (a row of its range image)
/// and an azimuth grid of `columns` steps a turn. A point of laser `l` in column `c` at
/// beam length `r` (metres from the beam's origin) lies, in the sensor head's frame, at
///
///     α = azimuth0 + direction · 2π · c / columns + column_azimuth[l]
///     o = radial_offset[l] · (cos α, sin α, 0) + (0, 0, z_offset[l])
///     u = (cos(α + beam_azimuth[l]) cos φ, sin(α + beam_azimuth[l]) cos φ, sin φ),  φ = elevation[l]
///     p = o + r · u
///
/// and in the cloud's sensor frame at `T_sensor_head · p`. Readers of raw sensor logs fill
/// it exactly from the sensor's metadata; the residual layer estimates it from the points
/// when no reader did (formats/model.md describes how it is stored).
struct SensorGeometry {
  std::vector<double> elevation;       ///< φ per laser, radians
  std::vector<double> beam_azimuth;    ///< beam azimuth relative to its column, radians
  std::vector<double> column_azimuth;  ///< azimuth shift of the laser's columns (stagger, firing time), radians
  std::vector<double> z_offset;        ///< height of the beam origin, metres
  std::vector<double> radial_offset;   ///< distance of the beam origin from the spin axis, metres
  std::uint32_t columns = 0;           ///< azimuth steps a full turn
  double azimuth0 = 0.0;               ///< azimuth of column 0, radians
  int direction = 1;                   ///< +1: azimuth grows with the column; -1: it falls
  Pose T_sensor_head = Pose::Identity();
  std::string source;                  ///< where it came from: "metadata", "model table", "estimated", ...
  std::string sensor;                  ///< the sensor's name when known (e.g. "OS-1-128", "VLP-16")

  [[nodiscard]] std::size_t lasers() const noexcept { return elevation.size(); }
};

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
  /// Laser (range-image row) of each point when the source knows it (an organised
  /// cloud's row, a `ring` field, a raw sensor log); empty otherwise, else points.size().
  std::vector<std::uint16_t> ring;
  /// Azimuth column of each point when the source knows it (an organised cloud's
  /// column, a raw sensor log's measurement column); empty otherwise, else points.size().
  std::vector<std::uint32_t> column;
  /// Range-image shape of an organised source (rows × columns, no-return pixels
  /// not counted as points); 0 × 0 for an unorganised one.
  std::uint32_t rows = 0;
  std::uint32_t columns = 0;
  /// The sensor's beam layout when the source gives it (raw logs with metadata).
  std::optional<SensorGeometry> geometry;

  [[nodiscard]] bool has_rings() const noexcept { return !ring.empty() && ring.size() == points.size(); }
  [[nodiscard]] bool has_columns() const noexcept { return !column.empty() && column.size() == points.size(); }

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
