#include <algorithm>
#include <cmath>
#include <numeric>
#include <stdexcept>
#include <string>

#include "lex3d/range/range_image.hpp"
#include "range/spacing.hpp"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace lex3d {

void AngularResolutionParams::validate() const {
  if (max_samples < 16 || max_samples > 1000000)
    throw std::invalid_argument("AngularResolutionParams::max_samples must be in [16, 1e6], got " +
                                std::to_string(max_samples));
  if (!(min_range >= 0.0 && min_range <= 1e3))
    throw std::invalid_argument("AngularResolutionParams::min_range must be in [0, 1000] m");
}

namespace {

double median_of(std::vector<double>& v) {
  const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

}  // namespace

// The spacing is measured locally: for a sample of returns, the nearest neighbour in
// the horizontal direction (|Δel| small against |Δaz|·cos el) and in the vertical one.
// Neighbours are found through a hash grid over (azimuth, elevation) whose cell is a
// few times the mean spacing sqrt(solid angle / N), so that anisotropic sensors
// (vertical spacing up to ~30x the horizontal one) still find their vertical neighbour
// in the 3x3 cells around a sample.
namespace detail {
namespace {
// The directions as a read-only array.
struct Directions {
  const Direction* data;
  std::size_t count;
  [[nodiscard]] std::size_t size() const noexcept { return count; }
  const Direction& operator[](std::size_t i) const noexcept { return data[i]; }
  [[nodiscard]] const Direction* begin() const noexcept { return data; }
  [[nodiscard]] const Direction* end() const noexcept { return data + count; }
};
}  // namespace

std::optional<AngularResolution> estimate_spacing(const Direction* dir_data, std::size_t count, std::size_t max_samples) {
  const Directions dirs{dir_data, count};
  if (dirs.size() < 16) return std::nullopt;

  // Robust elevation extent (1st..99th percentile) for the mean-spacing estimate.
  std::vector<float> els(dirs.size());
  std::transform(dirs.begin(), dirs.end(), els.begin(), [](const Direction& d) { return d.el; });
  const auto lo_it = els.begin() + static_cast<std::ptrdiff_t>(els.size() / 100);
  std::nth_element(els.begin(), lo_it, els.end());
  const double el_lo = *lo_it;
  const auto hi_it = els.begin() + static_cast<std::ptrdiff_t>(els.size() - 1 - els.size() / 100);
  // Past lo_it, which the first selection left in place with nothing smaller after it.
  std::nth_element(lo_it + 1, hi_it, els.end());
  const double el_hi = *hi_it;
  const double solid_angle =
      2.0 * M_PI * std::max(1e-4, std::sin(std::max(el_lo, el_hi)) - std::sin(std::min(el_lo, el_hi)));
  const double mean_spacing = std::sqrt(solid_angle / static_cast<double>(dirs.size()));
  // The grid has about 4π / cell² cells: at most four a direction (and a few thousand), so
  // directions crowded into a tiny cone (a degenerate cloud) cannot ask for gigabytes.
  const double min_cell = std::sqrt(4.0 * M_PI / (4.0 * static_cast<double>(dirs.size()) + 4096.0));
  const double cell = std::clamp(6.0 * mean_spacing, std::max(1e-4, min_cell), 0.5);

  // Hash grid: rows of constant elevation, each row with its own azimuth cell count.
  const int rows = std::max(1, static_cast<int>(std::ceil(M_PI / cell)));
  std::vector<int> row_cols(static_cast<std::size_t>(rows));
  std::vector<std::size_t> row_offset(static_cast<std::size_t>(rows) + 1, 0);
  for (int r = 0; r < rows; ++r) {
    const double el_mid = -M_PI / 2 + (r + 0.5) * cell;
    const double circumference = 2.0 * M_PI * std::max(std::cos(el_mid), 1e-3);
    row_cols[static_cast<std::size_t>(r)] = std::max(1, static_cast<int>(std::floor(circumference / cell)));
    row_offset[static_cast<std::size_t>(r) + 1] =
        row_offset[static_cast<std::size_t>(r)] + static_cast<std::size_t>(row_cols[static_cast<std::size_t>(r)]);
  }
  auto row_of = [&](float el) {
    return std::clamp(static_cast<int>((el + M_PI / 2) / cell), 0, rows - 1);
  };
  auto col_of = [&](int row, float az) {
    const int n = row_cols[static_cast<std::size_t>(row)];
    const int c = static_cast<int>((az + M_PI) / (2.0 * M_PI) * n);
    return std::clamp(c, 0, n - 1);
  };
  const std::size_t cells = row_offset.back();
  std::vector<std::uint32_t> start(cells + 1, 0);
  std::vector<std::uint32_t> cell_of(dirs.size());
  for (std::size_t i = 0; i < dirs.size(); ++i) {
    const int row = row_of(dirs[i].el);
    cell_of[i] = static_cast<std::uint32_t>(row_offset[static_cast<std::size_t>(row)] +
                                            static_cast<std::size_t>(col_of(row, dirs[i].az)));
    ++start[cell_of[i] + 1];
  }
  std::partial_sum(start.begin(), start.end(), start.begin());
  // The directions in cell order, so that a cell's are read contiguously.
  std::vector<Direction> by_cell(dirs.size());
  {
    std::vector<std::uint32_t> fill(start.begin(), start.end() - 1);
    for (std::size_t i = 0; i < dirs.size(); ++i) by_cell[fill[cell_of[i]]++] = dirs[i];
  }

  const std::size_t samples = std::min(max_samples, dirs.size());
  const double stride = static_cast<double>(dirs.size()) / static_cast<double>(samples);
  std::vector<double> horizontal;
  std::vector<double> vertical;
  horizontal.reserve(samples);
  vertical.reserve(samples);
  const double kSame = 1e-7;  // coincident directions are duplicates, not neighbours
  for (std::size_t s = 0; s < samples; ++s) {
    const Direction& d = dirs[static_cast<std::size_t>(static_cast<double>(s) * stride)];
    const double cos_el = std::cos(d.el);
    double best_h = std::numeric_limits<double>::infinity();
    double best_v = std::numeric_limits<double>::infinity();
    const int row = row_of(d.el);
#if defined(__SSE2__)
    const __m128d v_daz = _mm_set1_pd(static_cast<double>(d.az)), v_del = _mm_set1_pd(static_cast<double>(d.el));
    const __m128d v_pi = _mm_set1_pd(M_PI), v_minus_pi = _mm_set1_pd(-M_PI), v_two_pi = _mm_set1_pd(2 * M_PI);
    const __m128d v_abs = _mm_castsi128_pd(_mm_set1_epi64x(0x7FFFFFFFFFFFFFFFLL));
    const __m128d v_cos_el = _mm_set1_pd(cos_el), v_same = _mm_set1_pd(kSame), v_half = _mm_set1_pd(0.5);
    const __m128d v_inf = _mm_set1_pd(std::numeric_limits<double>::infinity());
    __m128d bh = v_inf, bv = v_inf;
#endif
    for (int dr = -1; dr <= 1; ++dr) {
      const int rr = row + dr;
      if (rr < 0 || rr >= rows) continue;
      const int n = row_cols[static_cast<std::size_t>(rr)];
      const int c0 = col_of(rr, d.az);
      for (int dc = -1; dc <= 1; ++dc) {
        if (n < 3 && dc != 0) continue;
        const int cc = ((c0 + dc) % n + n) % n;
        const std::size_t cell_index = row_offset[static_cast<std::size_t>(rr)] + static_cast<std::size_t>(cc);
        std::uint32_t k = start[cell_index];
        const std::uint32_t k_end = start[cell_index + 1];
#if defined(__SSE2__)
        // Two candidates at a time, with the same double arithmetic; a rejected one
        // offers +inf to the minimum.
        for (; k + 2 <= k_end; k += 2) {
          const __m128 pair = _mm_loadu_ps(&by_cell[k].az);  // az0 el0 az1 el1
          const __m128d az = _mm_cvtps_pd(_mm_shuffle_ps(pair, pair, _MM_SHUFFLE(2, 0, 2, 0)));
          const __m128d el = _mm_cvtps_pd(_mm_shuffle_ps(pair, pair, _MM_SHUFFLE(3, 1, 3, 1)));
          __m128d daz = _mm_sub_pd(az, v_daz);
          daz = _mm_sub_pd(daz, _mm_and_pd(_mm_cmpgt_pd(daz, v_pi), v_two_pi));
          daz = _mm_add_pd(daz, _mm_and_pd(_mm_cmplt_pd(daz, v_minus_pi), v_two_pi));
          const __m128d h = _mm_mul_pd(_mm_and_pd(daz, v_abs), v_cos_el);
          const __m128d v = _mm_and_pd(_mm_sub_pd(el, v_del), v_abs);
          const __m128d same = _mm_and_pd(_mm_cmplt_pd(h, v_same), _mm_cmplt_pd(v, v_same));
          const __m128d is_h = _mm_cmplt_pd(v, _mm_mul_pd(v_half, h));
          const __m128d take_h = _mm_andnot_pd(same, is_h);
          const __m128d take_v = _mm_andnot_pd(same, _mm_andnot_pd(is_h, _mm_cmplt_pd(h, _mm_mul_pd(v_half, v))));
          bh = _mm_min_pd(bh, _mm_or_pd(_mm_and_pd(take_h, h), _mm_andnot_pd(take_h, v_inf)));
          bv = _mm_min_pd(bv, _mm_or_pd(_mm_and_pd(take_v, v), _mm_andnot_pd(take_v, v_inf)));
        }
#endif
        for (; k < k_end; ++k) {
          const Direction& e = by_cell[k];
          double daz = static_cast<double>(e.az) - d.az;
          if (daz > M_PI) daz -= 2 * M_PI;
          if (daz < -M_PI) daz += 2 * M_PI;
          const double h = std::abs(daz) * cos_el;
          const double v = std::abs(static_cast<double>(e.el) - d.el);
          if (h < kSame && v < kSame) continue;
          if (v < 0.5 * h) best_h = std::min(best_h, h);
          else if (h < 0.5 * v) best_v = std::min(best_v, v);
        }
      }
    }
#if defined(__SSE2__)
    {
      alignas(16) double lanes_h[2], lanes_v[2];
      _mm_store_pd(lanes_h, bh);
      _mm_store_pd(lanes_v, bv);
      best_h = std::min(best_h, std::min(lanes_h[0], lanes_h[1]));
      best_v = std::min(best_v, std::min(lanes_v[0], lanes_v[1]));
    }
#endif
    if (std::isfinite(best_h)) horizontal.push_back(best_h);
    if (std::isfinite(best_v)) vertical.push_back(best_v);
  }
  if (horizontal.size() < 8 || vertical.size() < 8) return std::nullopt;
  AngularResolution res;
  res.azimuth_rad = median_of(horizontal);
  res.elevation_rad = median_of(vertical);
  return res;
}

}  // namespace detail

std::optional<AngularResolution> estimate_angular_resolution(const Cloud& cloud,
                                                             const AngularResolutionParams& params) {
  params.validate();
  const Eigen::Isometry3f T_sensor_cloud = cloud.T_cloud_sensor.inverse().cast<float>();
  std::vector<detail::Direction> dirs;
  dirs.reserve(cloud.size());
  for (const auto& p : cloud.points) {
    const Eigen::Vector3f q = T_sensor_cloud * p;
    const float r = q.norm();
    if (!(r > static_cast<float>(params.min_range))) continue;
    dirs.push_back({std::atan2(q.y(), q.x()), std::asin(std::clamp(q.z() / r, -1.0F, 1.0F))});
  }
  return detail::estimate_spacing(dirs.data(), dirs.size(), params.max_samples);
}

}  // namespace lex3d
