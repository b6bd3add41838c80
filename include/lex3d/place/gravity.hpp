#pragma once
/// \file
/// The up direction of a scan from its own points, for scans without a pose or IMU.
///
/// Place recognition works in upright frames (features, gravity-aligned hypotheses, surface
/// hypotheses). With a world pose the up direction is known; without one it is estimated
/// here from the surfaces the scan sees: horizontal ones (ground, floors, ceilings: normals
/// along up) and vertical ones (walls, facades, poles: normals across up). Starting from the
/// sensor's spin axis (the axis its range image turns about: the beam layout's), each round
/// takes the direction that best fits both kinds of surface, with a window that narrows
/// from 40 to 10 degrees. The sign follows the spin axis (the sensor is not upside down).

#include <cstddef>

#include "lex3d/core/cloud.hpp"
#include "lex3d/range/range_image.hpp"

// The public API: exported by liblex3d.so, which hides everything else.
#pragma GCC visibility push(default)

namespace lex3d {

/// Where the up direction of a scan came from.
enum class GravitySource {
  kPoses,   ///< the scan's world pose (poses file, IMU)
  kPoints,  ///< estimated from the scan's points (estimate_gravity)
  kNone,    ///< nothing to go on: the sensor's spin axis is taken as up
};
[[nodiscard]] const char* to_string(GravitySource s) noexcept;

struct GravityEstimate {
  /// Unit up direction in the cloud frame (the spin axis when source is kNone).
  Eigen::Vector3d up = Eigen::Vector3d::UnitZ();
  GravitySource source = GravitySource::kNone;
  std::size_t normals = 0;     ///< surface normals looked at
  std::size_t horizontal = 0;  ///< of them on horizontal surfaces (within the last window)
  std::size_t vertical = 0;    ///< of them on vertical surfaces
  /// Angle between `up` and the spin axis, degrees (the sensor's tilt).
  double tilt_deg = 0.0;
};

/// Estimates the up direction of `cloud` from its points (its world pose is ignored).
/// Returns source kNone, up = spin axis, when the surfaces do not fix a direction: fewer
/// than 3 % of the normals on horizontal or vertical surfaces, or only walls of a single
/// direction (no floor and no second wall direction). Deterministic.
[[nodiscard]] GravityEstimate estimate_gravity(const Cloud& cloud, const RangeImageParams& range = {});

/// Gives `cloud` an up direction when it has no world pose: T_world_cloud becomes the
/// smallest rotation that takes the estimated up to +z (no translation; the yaw is
/// arbitrary) and has_world_pose is set, so that prepare_scan and the place module use it
/// as they would a pose's. A cloud with a world pose is left as it is (kPoses). When the
/// estimate finds nothing (kNone), the cloud is left without a pose.
GravitySource apply_gravity(Cloud& cloud, const RangeImageParams& range = {});

}  // namespace lex3d

#pragma GCC visibility pop
