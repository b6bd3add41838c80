#pragma once
/// \file
/// Spherical range images of lidar scans.
///
/// Pixel (x, y) covers azimuth [az_max - (x+1)·α_az, az_max - x·α_az) and elevation
/// [row_edges[y+1], row_edges[y]): row 0 is the top row, azimuth decreases to the right,
/// so a 360° scan reads like a panorama seen from the sensor. Rows are uniform today;
/// the row table leaves room for rows that follow a sensor's uneven beams. A pixel
/// keeps the closest return that falls into it (the visible surface), with the exact
/// 3D point, so no geometry is lost to pixel-centre rounding.

#include <cstdint>
#include <limits>
#include <optional>
#include <vector>

#include "lex3d/core/cloud.hpp"

// The public API: exported by liblex3d.so, which hides everything else.
#pragma GCC visibility push(default)

namespace lex3d {

/// Angular spacing of a scan's beams, in radians.
struct AngularResolution {
  double azimuth_rad = 0.0;    ///< horizontal spacing between neighbouring returns
  double elevation_rad = 0.0;  ///< vertical spacing between neighbouring returns
};

struct AngularResolutionParams {
  /// Number of points sampled (evenly through the cloud) to measure spacings; [16, 1e6].
  std::size_t max_samples = 1000;
  /// Points closer than this to the sensor are ignored, metres; [0, 1e3].
  double min_range = 0.05;
  void validate() const;
};

/// Estimates the beam spacing from the scan itself: for sampled returns, the
/// angular distance to the nearest horizontal and the nearest vertical neighbour,
/// medians over the samples. Works on unordered clouds. Returns nullopt when the
/// cloud has too few points (< 16) or no measurable spacing.
[[nodiscard]] std::optional<AngularResolution> estimate_angular_resolution(
    const Cloud& cloud, const AngularResolutionParams& params = {});

/// State of a range image pixel.
enum class PixelState : std::uint8_t {
  kUnobserved = 0,  ///< no beam information for this direction
  kMaxRange = 1,    ///< a beam went out and returned nothing within max_range
  kValid = 2,       ///< a return; range and point are set
};

struct RangeImageParams {
  /// Horizontal pixel size, radians; 0 = estimate from the scan's beam spacing; else [1e-5, 0.2].
  double azimuth_resolution_rad = 0.0;
  /// Vertical pixel size, radians; 0 = estimate from the scan's beam spacing; else [1e-5, 0.2].
  double elevation_resolution_rad = 0.0;
  /// Estimated pixel sizes are this many beam spacings; [0.5, 4]. Slightly more than one
  /// leaves few empty pixels where firings jitter or beams are unevenly spaced (an
  /// HDL-64E mixes 1/3° and 1/2°), which makes interest points markedly more repeatable
  /// (about 0.62 against 0.55 of them found again after a half-pixel turn on KITTI).
  double pixel_scale = 1.25;
  /// Returns closer than this are ignored (the vehicle, the operator), metres; [0, max_range).
  double min_range = 0.05;
  /// Returns at or beyond this are max-range pixels, metres; (min_range, inf].
  double max_range = std::numeric_limits<double>::infinity();
  void validate() const;
};

/// A spherical range image plus the pose of the sensor it is seen from.
struct RangeImage {
  int width = 0;
  int height = 0;
  double azimuth_resolution_rad = 0.0;
  double elevation_resolution_rad = 0.0;  ///< nominal (median) row height
  /// The scan's beam spacing as estimated for the pixel sizes (estimate_angular_resolution
  /// of the returns); nullopt when both pixel sizes were given or too few returns.
  std::optional<AngularResolution> beam_spacing;
  double azimuth_max_rad = 0.0;    ///< left edge of column 0
  /// Elevation of the row borders, height+1 values, decreasing: row y spans
  /// [row_edges[y+1], row_edges[y]).
  std::vector<double> row_edges;
  bool full_circle = true;         ///< columns wrap around (360° scan)
  double min_range = 0.0;          ///< returns closer than this were ignored, metres
  /// Sensor pose in the cloud's frame; pixel points are in the sensor frame.
  Pose T_cloud_sensor = Pose::Identity();

  std::vector<PixelState> state;        ///< width*height
  std::vector<float> range;             ///< metres; NaN unless kValid
  std::vector<Eigen::Vector3f> point;   ///< sensor frame; NaN unless kValid
  std::vector<std::int32_t> source;     ///< index of the cloud point, -1 unless kValid

  std::size_t valid_count = 0;          ///< pixels in state kValid
  std::size_t points_in = 0;            ///< cloud points considered
  std::size_t points_hidden = 0;        ///< points that lost their pixel to a closer return
  std::size_t points_too_close = 0;     ///< points under min_range
  std::size_t points_non_finite = 0;    ///< points with a NaN or Inf coordinate, skipped

  [[nodiscard]] bool empty() const noexcept { return width == 0 || height == 0; }
  [[nodiscard]] std::size_t index(int x, int y) const noexcept {
    return static_cast<std::size_t>(y) * static_cast<std::size_t>(width) + static_cast<std::size_t>(x);
  }
  [[nodiscard]] bool in_image(int x, int y) const noexcept {
    return x >= 0 && y >= 0 && x < width && y < height;
  }
  /// Wraps a column index around for 360° images; returns -1 when off a partial image.
  [[nodiscard]] int wrap_x(int x) const noexcept {
    if (full_circle) {
      // Windows reach at most one turn past either edge: no division needed then.
      if (x >= 0 && x < width) return x;
      if (x < 0 && x >= -width) return x + width;
      if (x >= width && x < 2 * width) return x - width;
      x %= width;
      return x < 0 ? x + width : x;
    }
    return (x < 0 || x >= width) ? -1 : x;
  }
  [[nodiscard]] bool valid(int x, int y) const noexcept {
    return in_image(x, y) && state[index(x, y)] == PixelState::kValid;
  }
  /// Continuous image coordinates (pixel centres at .5) of a sensor-frame point.
  /// Returns false for the origin; `x` is not wrapped.
  bool project(const Eigen::Vector3f& p_sensor, float& x, float& y, float& r) const noexcept;
  /// Unit ray through continuous image coordinates (x, y), sensor frame.
  [[nodiscard]] Eigen::Vector3f ray(double x, double y) const noexcept;
  /// Angular height of row y, radians.
  [[nodiscard]] double row_height(int y) const noexcept {
    return row_edges[static_cast<std::size_t>(y)] - row_edges[static_cast<std::size_t>(y) + 1];
  }
  /// Elevation at continuous row coordinate y (row centres at .5), radians.
  [[nodiscard]] double elevation_at(double y) const noexcept;
  /// Continuous row coordinate of an elevation (may be outside [0, height)).
  [[nodiscard]] double row_at(double elevation) const noexcept;
};

/// Builds the range image of `cloud` as seen from `cloud.T_cloud_sensor`.
/// An empty cloud gives an empty image. Throws std::invalid_argument on bad params.
[[nodiscard]] RangeImage make_range_image(const Cloud& cloud, const RangeImageParams& params = {});

}  // namespace lex3d

#pragma GCC visibility pop
