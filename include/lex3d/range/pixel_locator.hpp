#pragma once
/// \file
/// The pixel a sensor-frame point falls into, found without trigonometry.
///
/// RangeImage::project computes a point's azimuth and elevation (atan2, asin, fmod in double
/// precision); callers that look up neighbours only need the integer pixel. PixelLocator
/// keeps the image's column borders as unit vectors and its row borders as sines of the
/// elevation, guesses the column from a cheap float arctangent and the row from a table over the
/// sine of the elevation, and confirms both by comparing the point against the two borders on
/// each axis. A point closer to a border than a small margin
/// (a thousandth of a pixel or more) goes through RangeImage::project instead, so the pixel
/// returned is always floor() of project's coordinates.

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "lex3d/range/range_image.hpp"

// The public API: exported by liblex3d.so, which hides everything else.
#pragma GCC visibility push(default)

namespace lex3d {

/// Pixel lookup tables for one range image. Keeps a pointer to the image: the image must
/// outlive the locator and keep its geometry (size, resolutions, borders).
class PixelLocator {
 public:
  explicit PixelLocator(const RangeImage& img);

  /// Integer image coordinates of a sensor-frame point: exactly floor(x), floor(y) of
  /// RangeImage::project (x not wrapped), and its range r. Returns false where project does.
  bool locate(const Eigen::Vector3f& p_sensor, int& x, int& y, float& r) const noexcept {
    const Result res = locate_fast(p_sensor, x, y, r);
    if (res == Result::kFound) return true;
    if (res == Result::kNoPixel) return false;
    return locate_exact(p_sensor, x, y, r);
  }

  enum class Result : std::uint8_t {
    kFound,     ///< the tables decided the pixel
    kNoPixel,   ///< project returns false (zero or NaN range)
    kUndecided  ///< near a border, off the tables or a degenerate image: use project
  };
  /// The table path alone (for tests and diagnostics).
  Result locate_fast(const Eigen::Vector3f& p_sensor, int& x, int& y, float& r) const noexcept;
  /// The exact path alone: floor() of RangeImage::project.
  bool locate_exact(const Eigen::Vector3f& p_sensor, int& x, int& y, float& r) const noexcept;
  /// Whether the tables are used at all (false for images too coarse or too tall for them).
  [[nodiscard]] bool fast() const noexcept { return fast_; }

 private:
  const RangeImage* img_;
  bool fast_ = false;
  double az_max_ = 0.0;
  float inv_res_az_ = 0.0F;       // columns a radian, for the guess
  double margin_sin_az_sq_ = 0.0; // sin²(margin angle) of the column borders
  std::vector<Eigen::Vector2d> col_edge_;  // width+1 unit vectors: border k at az_max - k·res
  std::vector<double> row_sin_;            // height+1: sin(row_edges[y])
  std::vector<double> row_sin_in_hi_;      // height: sin(row_edges[y] - margin of row y)
  std::vector<double> row_sin_in_lo_;      // height: sin(row_edges[y+1] + margin of row y)
  double sin_lo_ = 0.0;                    // row_sin_.back()
  double sin_scale_ = 0.0;                 // buckets a unit of sine
  std::vector<int> row_guess_;             // the row of each bucket's lower end
};

}  // namespace lex3d

#pragma GCC visibility pop
