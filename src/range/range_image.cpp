#include "lex3d/range/range_image.hpp"
#include "core/huge_pages.hpp"
#include "range/spacing.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <memory>
#include <stdexcept>
#include <string>

namespace lex3d {

namespace {
constexpr double kTwoPi = 2.0 * M_PI;
constexpr double kMinRes = 1e-5;
constexpr double kMaxRes = 0.2;
const float kNaN = std::numeric_limits<float>::quiet_NaN();

void check_resolution(double v, const char* name) {
  if (v != 0.0 && !(v >= kMinRes && v <= kMaxRes))
    throw std::invalid_argument(std::string("RangeImageParams::") + name +
                                " must be 0 (estimate) or in [1e-5, 0.2] rad, got " + std::to_string(v));
}
}  // namespace

namespace {

// std::clamp(static_cast<int>(img.row_at(el)), 0, height - 1), with the row found from
// the nominal row height and checked against the row table instead of searched for.
int row_index(const RangeImage& img, double el) {
  const std::vector<double>& e = img.row_edges;
  if (e.size() < 2) return 0;
  const int h = img.height;
  if (el >= e.front()) return 0;  // row_at <= 0
  if (!(el > e.back())) return h - 1;  // row_at >= height (row_at's search would run off at e.back())
  // The row y with e[y] >= el > e[y+1] (upper_bound's answer): a guess, then a check.
  // The guess only picks where the search starts (the two loops below end at the same
  // row from any start), so a product with the reciprocal does as well as a division.
  const double inv_nominal = img.elevation_resolution_rad > 0 ? 1.0 / img.elevation_resolution_rad : 1.0;
  double g = std::floor((e.front() - el) * inv_nominal);
  if (!(g >= 0.0)) g = 0.0;
  if (g > h - 1) g = h - 1;
  auto y = static_cast<std::size_t>(g);
  while (y > 0 && !(e[y] >= el)) --y;
  while (!(el > e[y + 1])) ++y;
  const double at = static_cast<double>(y) + (e[y] - el) / (e[y] - e[y + 1]);
  return std::clamp(static_cast<int>(at), 0, h - 1);
}

}  // namespace

void RangeImageParams::validate() const {
  check_resolution(azimuth_resolution_rad, "azimuth_resolution_rad");
  check_resolution(elevation_resolution_rad, "elevation_resolution_rad");
  if (!(min_range >= 0.0) || !std::isfinite(min_range))
    throw std::invalid_argument("RangeImageParams::min_range must be finite and >= 0 m");
  if (!(max_range > min_range))
    throw std::invalid_argument("RangeImageParams::max_range must be > min_range");
  if (!(pixel_scale >= 0.5 && pixel_scale <= 4.0))
    throw std::invalid_argument("RangeImageParams::pixel_scale must be in [0.5, 4], got " + std::to_string(pixel_scale));
}

bool RangeImage::project(const Eigen::Vector3f& p, float& x, float& y, float& r) const noexcept {
  r = p.norm();
  if (!(r > 0.0F)) return false;
  const double az = std::atan2(static_cast<double>(p.y()), static_cast<double>(p.x()));
  const double el = std::asin(std::clamp(static_cast<double>(p.z()) / r, -1.0, 1.0));
  // Angles are measured clockwise from the left edge, in [0, 2π); a partial image
  // simply has no columns past its width.
  double daz = std::fmod(azimuth_max_rad - az, kTwoPi);
  if (daz < 0) daz += kTwoPi;
  x = static_cast<float>(daz / azimuth_resolution_rad);
  y = static_cast<float>(row_at(el));
  return true;
}

double RangeImage::row_at(double el) const noexcept {
  if (row_edges.size() < 2) return 0.0;
  const double top = row_edges.front();
  const double bottom = row_edges.back();
  const double nominal = elevation_resolution_rad > 0 ? elevation_resolution_rad : 1.0;
  if (el >= top) return -(el - top) / nominal;
  if (el < bottom) return static_cast<double>(height) + (bottom - el) / nominal;
  // First edge below `el`: the rows are sorted by decreasing elevation.
  const auto it = std::upper_bound(row_edges.begin(), row_edges.end(), el, std::greater<double>());
  const auto y = static_cast<std::size_t>(it - row_edges.begin()) - 1;
  return static_cast<double>(y) + (row_edges[y] - el) / (row_edges[y] - row_edges[y + 1]);
}

double RangeImage::elevation_at(double y) const noexcept {
  if (row_edges.size() < 2) return 0.0;
  const double nominal = elevation_resolution_rad;
  if (y <= 0.0) return row_edges.front() - y * nominal;
  if (y >= height) return row_edges.back() - (y - height) * nominal;
  const auto row = static_cast<std::size_t>(y);
  const double frac = y - static_cast<double>(row);
  return row_edges[row] - frac * (row_edges[row] - row_edges[row + 1]);
}

Eigen::Vector3f RangeImage::ray(double x, double y) const noexcept {
  const double az = azimuth_max_rad - x * azimuth_resolution_rad;
  const double el = elevation_at(y);
  return {static_cast<float>(std::cos(el) * std::cos(az)), static_cast<float>(std::cos(el) * std::sin(az)),
          static_cast<float>(std::sin(el))};
}

RangeImage make_range_image(const Cloud& cloud, const RangeImageParams& params) {
  params.validate();
  RangeImage img;
  img.T_cloud_sensor = cloud.T_cloud_sensor;
  img.points_in = cloud.size();
  img.min_range = params.min_range;

  // Sensor-frame points and their directions, computed once (float trigonometry:
  // 1e-7 rad is far below any beam spacing).
  const Eigen::Isometry3f T_sensor_cloud = cloud.T_cloud_sensor.inverse().cast<float>();
  const Eigen::Matrix3f R_sensor_cloud = T_sensor_cloud.linear();
  // Per accepted direction: its range and cloud index (-1 for a no-return direction);
  // a point's sensor-frame position is computed again, by the same expression, only
  // when it claims a pixel. Left uninitialised: every used element is written first.
  // The three arrays share one block of fresh memory (16 bytes a ray, 2 MB on KITTI),
  // with room for a 2 MiB page more, on huge pages where it can.
  const std::size_t max_rays = cloud.size() + cloud.no_return_directions.size();
  constexpr std::size_t kRayBytes = sizeof(detail::Direction) + sizeof(float) + sizeof(std::int32_t);
  const std::size_t ray_bytes = max_rays * kRayBytes;
  const std::size_t block_bytes = ray_bytes + (ray_bytes >= detail::kHugePage / 2 ? detail::kHugePage : 0);
  const std::unique_ptr<unsigned char[]> block(new unsigned char[block_bytes]);
  detail::advise_huge_pages(block.get(), block_bytes);
  auto* const dirs = reinterpret_cast<detail::Direction*>(block.get());
  auto* const ray_range = reinterpret_cast<float*>(dirs + max_rays);
  auto* const ray_index = reinterpret_cast<std::int32_t*>(ray_range + max_rays);
  std::size_t used = 0;
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    if (!cloud.points[i].allFinite()) {
      ++img.points_non_finite;
      continue;
    }
    const Eigen::Vector3f q = T_sensor_cloud * cloud.points[i];
    const float r = q.norm();
    if (!(static_cast<double>(r) >= params.min_range) || r == 0.0F) {
      ++img.points_too_close;
      continue;
    }
    ray_range[used] = r;
    ray_index[used] = static_cast<std::int32_t>(i);
    dirs[used] = {std::atan2(q.y(), q.x()), std::asin(std::clamp(q.z() / r, -1.0F, 1.0F))};
    ++used;
  }
  const std::size_t returns = used;
  for (const auto& d : cloud.no_return_directions) {
    const Eigen::Vector3f q = (R_sensor_cloud * d).normalized();
    if (!q.allFinite()) continue;
    ray_range[used] = std::numeric_limits<float>::infinity();
    ray_index[used] = -1;
    dirs[used] = {std::atan2(q.y(), q.x()), std::asin(std::clamp(q.z(), -1.0F, 1.0F))};
    ++used;
  }
  if (used == 0) return img;

  double res_az = params.azimuth_resolution_rad;
  double res_el = params.elevation_resolution_rad;
  if (res_az == 0.0 || res_el == 0.0) {
    const auto est = detail::estimate_spacing(dirs, returns, AngularResolutionParams{}.max_samples);
    img.beam_spacing = est;
    // Without enough points to measure, fall back to 0.2°, a common lidar spacing.
    const double fallback = 0.2 * M_PI / 180.0;
    const double scale = params.pixel_scale;
    if (res_az == 0.0) res_az = est ? std::clamp(scale * est->azimuth_rad, kMinRes, kMaxRes) : fallback;
    if (res_el == 0.0) res_el = est ? std::clamp(scale * est->elevation_rad, kMinRes, kMaxRes) : fallback;
  }
  img.azimuth_resolution_rad = res_az;
  img.elevation_resolution_rad = res_el;

  // Elevation extent from the data; azimuth: full circle unless the scan leaves a gap.
  double el_min = dirs[0].el;
  double el_max = el_min;
  std::array<bool, 360> az_bin{};
  for (std::size_t i = 0; i < used; ++i) {
    const detail::Direction& d = dirs[i];
    el_min = std::min(el_min, static_cast<double>(d.el));
    el_max = std::max(el_max, static_cast<double>(d.el));
    az_bin[static_cast<std::size_t>(std::clamp(static_cast<int>((d.az + M_PI) / kTwoPi * 360.0), 0, 359))] = true;
  }
  // Largest circular run of empty 1° bins.
  int best_gap = 0;
  int best_gap_end = 0;  // first occupied bin after the gap
  for (int start = 0; start < 360; ++start) {
    if (az_bin[static_cast<std::size_t>(start)]) continue;
    if (!az_bin[static_cast<std::size_t>((start + 359) % 360)] && start != 0) continue;  // not a run start
    int len = 0;
    while (len < 360 && !az_bin[static_cast<std::size_t>((start + len) % 360)]) ++len;
    if (len > best_gap) {
      best_gap = len;
      best_gap_end = (start + len) % 360;
    }
  }
  img.full_circle = best_gap < 30;
  // Pixels at most max(16 a ray, 2^18): a resolution measured on a degenerate cloud (random
  // bytes read as points, a cloud inside a millimetre) is coarsened until the image fits, so
  // its memory follows the input's size. A real scan has about one ray a pixel.
  const double max_pixels = std::max(16.0 * static_cast<double>(used), 262144.0);
  const double span_rad =
      img.full_circle ? kTwoPi : (360.0 - best_gap + 2.0) * M_PI / 180.0;  // azimuth the image covers
  {
    const double cols = std::ceil(span_rad / res_az);
    const double rows = std::floor((el_max - el_min) / res_el + 0.5) + 1.0;
    if (cols * rows > max_pixels) {
      const double f = std::sqrt(cols * rows / max_pixels) * 1.01;
      res_az = std::min(res_az * f, span_rad);
      res_el = std::min(res_el * f, M_PI);
      img.elevation_resolution_rad = res_el;
      img.azimuth_resolution_rad = res_az;
    }
  }
  if (img.full_circle) {
    img.azimuth_max_rad = M_PI;
    img.width = std::max(1, static_cast<int>(std::ceil(kTwoPi / res_az - 1e-6)));
    // Make the columns tile the circle exactly so that wrapping is seamless.
    img.azimuth_resolution_rad = kTwoPi / img.width;
  } else {
    // The scan spans from the end of the gap (counter-clockwise) around to its start.
    const double span_deg = 360.0 - best_gap + 2.0;
    const double az_lo = (best_gap_end - 1) * M_PI / 180.0 - M_PI;
    img.azimuth_max_rad = az_lo + span_deg * M_PI / 180.0;
    img.width = std::max(1, static_cast<int>(std::ceil(span_deg * M_PI / 180.0 / res_az)));
  }
  {
    const double top = el_max + 0.5 * res_el;
    img.height = std::max(1, static_cast<int>(std::floor((top - el_min) / res_el)) + 1);
    img.row_edges.resize(static_cast<std::size_t>(img.height) + 1);
    for (int y = 0; y <= img.height; ++y) img.row_edges[static_cast<std::size_t>(y)] = top - y * res_el;
  }
  const std::size_t n = static_cast<std::size_t>(img.width) * static_cast<std::size_t>(img.height);
  img.state.assign(n, PixelState::kUnobserved);
  img.range.assign(n, kNaN);
  img.point.assign(n, Eigen::Vector3f::Constant(kNaN));
  img.source.assign(n, -1);

  const float max_range = static_cast<float>(std::min(params.max_range, 1e30));
  for (std::size_t i = 0; i < used; ++i) {
    const float ray_r = ray_range[i];
    const std::int32_t ray_idx = ray_index[i];
    const detail::Direction& dir = dirs[i];
    double daz = img.azimuth_max_rad - dir.az;
    if (!(daz >= 0.0 && daz < kTwoPi)) {  // fmod returns an angle already in [0, 2π) unchanged
      daz = std::fmod(daz, kTwoPi);
      if (daz < 0) daz += kTwoPi;
    }
    int x = static_cast<int>(daz / img.azimuth_resolution_rad);
    // x %= width, without the integer division for the columns already in range.
    if (img.full_circle && (x < 0 || x >= img.width)) x %= img.width;
    if (x < 0 || x >= img.width) continue;
    const int y = row_index(img, dir.el);
    const std::size_t k = img.index(x, y);
    if (ray_idx < 0 || ray_r >= max_range) {
      // A beam with no return: only fills a pixel no return has claimed.
      if (img.state[k] == PixelState::kUnobserved) img.state[k] = PixelState::kMaxRange;
      continue;
    }
    if (img.state[k] == PixelState::kValid) {
      ++img.points_hidden;
      if (ray_r >= img.range[k]) continue;
    } else {
      ++img.valid_count;
    }
    img.state[k] = PixelState::kValid;
    img.range[k] = ray_r;
    img.point[k] = T_sensor_cloud * cloud.points[static_cast<std::size_t>(ray_idx)];
    img.source[k] = ray_idx;
  }
  return img;
}

}  // namespace lex3d
