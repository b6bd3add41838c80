#include "lex3d/range/pixel_locator.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace lex3d {

namespace {

constexpr double kTwoPi = 2.0 * M_PI;

// arctan on [-1, 1] as an odd polynomial (least-squares fit, |error| < 2e-6 rad). It only
// guesses the pixel: the borders decide it, so its accuracy affects speed, never the answer.
inline float atan_unit(float t) noexcept {
  const float s = t * t;
  float p = -0.011769974F;
  p = p * s + 0.052822195F;
  p = p * s - 0.116649978F;
  p = p * s + 0.193669885F;
  p = p * s - 0.332655430F;
  p = p * s + 0.999979854F;
  return p * t;
}

// atan2(y, x) to about 2e-6 rad; (0, 0) must be excluded by the caller.
inline float atan2_guess(float y, float x) noexcept {
  const float ax = std::abs(x), ay = std::abs(y);
  const bool steep = ay > ax;
  float a = atan_unit(steep ? ax / ay : ay / ax);
  if (steep) a = static_cast<float>(M_PI_2) - a;
  if (x < 0.0F) a = static_cast<float>(M_PI) - a;
  return y < 0.0F ? -a : a;
}

// Margin, in pixels, kept from a border: far above the double rounding of project's angles
// and above the rounding of its float result (half a float ulp at `extent` pixels).
double pixel_margin(double extent) {
  const auto e = static_cast<float>(extent);
  const double ulp = static_cast<double>(std::nextafter(e, std::numeric_limits<float>::infinity()) - e);
  return std::max(1e-3, 4.0 * ulp);
}

}  // namespace

PixelLocator::PixelLocator(const RangeImage& img) : img_(&img) {
  const int w = img.width, h = img.height;
  const double res_az = img.azimuth_resolution_rad;
  const double res_el = img.elevation_resolution_rad;
  if (img.empty() || img.row_edges.size() != static_cast<std::size_t>(h) + 1) return;
  // Column borders as unit vectors: a wedge narrower than a quarter turn, borders that do not
  // overlap around the circle.
  if (!(res_az > 0.0 && res_az <= 0.5) || !(res_az * w <= kTwoPi * (1.0 + 1e-12))) return;
  if (!(res_el > 0.0) || !std::isfinite(img.azimuth_max_rad)) return;
  // Row borders strictly decreasing within [-90°, 90°], where the sine orders them the same way.
  const std::vector<double>& e = img.row_edges;
  if (!(e.front() <= M_PI_2) || !(e.back() >= -M_PI_2)) return;
  for (int y = 0; y < h; ++y)
    if (!(e[static_cast<std::size_t>(y)] > e[static_cast<std::size_t>(y) + 1])) return;

  az_max_ = img.azimuth_max_rad;
  inv_res_az_ = static_cast<float>(1.0 / res_az);
  const double margin_az = pixel_margin(static_cast<double>(w) + 1.0) * res_az;
  margin_sin_az_sq_ = std::sin(margin_az) * std::sin(margin_az);
  col_edge_.resize(static_cast<std::size_t>(w) + 1);
  for (int k = 0; k <= w; ++k) {
    const double a = az_max_ - k * res_az;
    col_edge_[static_cast<std::size_t>(k)] = {std::cos(a), std::sin(a)};
  }
  const double margin_el = pixel_margin(static_cast<double>(h) + 1.0);
  row_sin_.resize(static_cast<std::size_t>(h) + 1);
  row_sin_in_hi_.resize(static_cast<std::size_t>(h));
  row_sin_in_lo_.resize(static_cast<std::size_t>(h));
  for (std::size_t y = 0; y <= static_cast<std::size_t>(h); ++y) row_sin_[y] = std::sin(e[y]);
  // Row guesses by the sine itself: buckets of equal width in sine, each starting at the row
  // that holds its lower end (a few rows a bucket at most; the walk in locate_fast finishes).
  const double span = row_sin_.front() - row_sin_.back();
  if (!(span > 0.0)) return;
  const std::size_t buckets = 8 * static_cast<std::size_t>(h);
  sin_lo_ = row_sin_.back();
  sin_scale_ = static_cast<double>(buckets) / span;
  row_guess_.resize(buckets);
  int row = h - 1;
  for (std::size_t b = 0; b < buckets; ++b) {
    const double sb = sin_lo_ + static_cast<double>(b) / sin_scale_;
    while (row > 0 && !(sb < row_sin_[static_cast<std::size_t>(row)])) --row;
    row_guess_[b] = row;
  }
  for (std::size_t y = 0; y < static_cast<std::size_t>(h); ++y) {
    const double m = margin_el * (e[y] - e[y + 1]);
    row_sin_in_hi_[y] = std::sin(e[y] - m);
    row_sin_in_lo_[y] = std::sin(e[y + 1] + m);
  }
  fast_ = true;
}

bool PixelLocator::locate_exact(const Eigen::Vector3f& p, int& x, int& y, float& r) const noexcept {
  float fx = 0.0F, fy = 0.0F;
  if (!img_->project(p, fx, fy, r)) return false;
  x = static_cast<int>(std::floor(fx));
  y = static_cast<int>(std::floor(fy));
  return true;
}

PixelLocator::Result PixelLocator::locate_fast(const Eigen::Vector3f& p, int& x, int& y, float& r) const noexcept {
  r = p.norm();  // the same expression as project's
  if (!(r > 0.0F)) return Result::kNoPixel;
  if (!fast_ || !std::isfinite(r)) return Result::kUndecided;
  const double px = p.x(), py = p.y();
  const double hxy2 = px * px + py * py;
  if (!(hxy2 > 0.0)) return Result::kUndecided;

  // Row: project's elevation is asin(s); the sines of the borders order s the same way.
  const double s = std::clamp(static_cast<double>(p.z()) / r, -1.0, 1.0);
  const int h = img_->height;
  if (!(s < row_sin_.front() && s > row_sin_.back())) return Result::kUndecided;
  const auto b = std::min(static_cast<std::size_t>((s - sin_lo_) * sin_scale_), row_guess_.size() - 1);
  int row = row_guess_[b];
  while (row > 0 && !(s < row_sin_[static_cast<std::size_t>(row)])) --row;
  while (row < h - 1 && !(s > row_sin_[static_cast<std::size_t>(row) + 1])) ++row;
  const auto ru = static_cast<std::size_t>(row);
  if (!(s < row_sin_in_hi_[ru] && s > row_sin_in_lo_[ru])) return Result::kUndecided;

  // Column k spans the wedge from border k+1 (counter-clockwise) to border k: the point lies
  // inside when it is left of border k+1 and right of border k, by more than the margin.
  const int w = img_->width;
  const bool wrap = img_->full_circle;
  double daz = az_max_ - static_cast<double>(atan2_guess(p.y(), p.x()));
  if (daz < 0.0) daz += kTwoPi;
  if (daz >= kTwoPi) daz -= kTwoPi;
  int k = static_cast<int>(static_cast<float>(daz) * inv_res_az_);
  if (k >= w) {
    if (!wrap) return Result::kUndecided;
    k = w - 1;
  }
  const double limit = margin_sin_az_sq_ * hxy2;
  for (int step = 0; step < 3; ++step) {
    const Eigen::Vector2d& lo = col_edge_[static_cast<std::size_t>(k)];
    const Eigen::Vector2d& hi = col_edge_[static_cast<std::size_t>(k) + 1];
    const double c_right = px * lo.y() - py * lo.x();  // > 0: clockwise of border k
    const double c_left = hi.x() * py - hi.y() * px;   // > 0: counter-clockwise of border k+1
    if (c_right > 0.0 && c_left > 0.0) {
      if (!(c_right * c_right > limit && c_left * c_left > limit)) return Result::kUndecided;
      x = k;
      y = row;
      return Result::kFound;
    }
    if (!(c_right > 0.0)) {
      if (k == 0 && !wrap) return Result::kUndecided;
      k = k == 0 ? w - 1 : k - 1;
    } else {
      if (k == w - 1 && !wrap) return Result::kUndecided;
      k = k == w - 1 ? 0 : k + 1;
    }
  }
  return Result::kUndecided;
}

}  // namespace lex3d
