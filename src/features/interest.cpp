// The range-image interest operator of steder2010 §III-A: normalised gradients
// (eq. 1-2), Gaussian smoothing, second derivatives (eq. 3-4), interest value
// (eq. 5), the occlusion and straight-line filters, local maxima above a threshold
// and a minimum 3D distance between the points kept.

#include <algorithm>
#include <cmath>
#include <numeric>
#include <stdexcept>
#include <string>

#include "features/point_hash.hpp"
#include "lex3d/features/features.hpp"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace lex3d {

void InterestParams::validate() const {
  if (!(smoothing_sigma_px >= 0.0 && smoothing_sigma_px <= 5.0))
    throw std::invalid_argument("InterestParams::smoothing_sigma_px must be in [0, 5] px");
  if (!(threshold > 0.0 && threshold <= 1.0))
    throw std::invalid_argument("InterestParams::threshold must be in (0, 1]");
  if (!(occlusion_gradient > 0.0 && occlusion_gradient <= 1.0))
    throw std::invalid_argument("InterestParams::occlusion_gradient must be in (0, 1]");
  if (!(line_angle_deg >= 0.0 && line_angle_deg <= 90.0))
    throw std::invalid_argument("InterestParams::line_angle_deg must be in [0, 90] deg");
  if (!(min_distance >= 0.0 && min_distance <= 100.0))
    throw std::invalid_argument("InterestParams::min_distance must be in [0, 100] m");
}

namespace {

constexpr float kTwoOverPi = static_cast<float>(2.0 / M_PI);
constexpr float kInvMaxInterest = static_cast<float>(0.35355339059327373);  // 1 / (2·sqrt(2))
const float kNaN = std::numeric_limits<float>::quiet_NaN();

// Range of a neighbour: finite for a return, +inf for a max-range beam, NaN when unknown.
inline float neighbour_range(const RangeImage& img, int x, int y) {
  if (y < 0 || y >= img.height) return kNaN;
  const int xx = img.wrap_x(x);
  if (xx < 0) return kNaN;
  const std::size_t k = img.index(xx, y);
  switch (img.state[k]) {
    case PixelState::kValid: return img.range[k];
    case PixelState::kMaxRange: return std::numeric_limits<float>::infinity();
    default: return kNaN;
  }
}

// A neighbour's range and its distance in pixels: the first known pixel 1 or 2 steps
// away, so that a single empty pixel (beams and pixels do not line up exactly)
// does not cut a surface in two.
struct Neighbour {
  float range;  // finite, +inf (max range) or NaN (unknown)
  float steps;
};

inline Neighbour neighbour(const RangeImage& img, int x, int y, int dx, int dy) {
  for (int s = 1; s <= 2; ++s) {
    const float r = neighbour_range(img, x + s * dx, y + s * dy);
    if (!std::isnan(r)) return {r, static_cast<float>(s)};
  }
  return {kNaN, 1.0F};
}

// neighbour() for a pixel k whose neighbours 1 and 2 steps of `step` away lie inside
// the image.
inline Neighbour inner_neighbour(const RangeImage& img, std::size_t k, std::ptrdiff_t step) {
  for (int s = 1; s <= 2; ++s) {
    const auto q = static_cast<std::size_t>(static_cast<std::ptrdiff_t>(k) + s * step);
    switch (img.state[q]) {
      case PixelState::kValid: return {img.range[q], static_cast<float>(s)};
      case PixelState::kMaxRange: return {std::numeric_limits<float>::infinity(), static_cast<float>(s)};
      default: break;
    }
  }
  return {kNaN, 1.0F};
}

// Normalised gradient (eq. 1-2) from the two neighbours along one axis, per pixel
// of distance, so that atan(g / (tan α · r)) is the surface's slope angle against
// the beam; a max-range neighbour is a jump to infinity (±1). NaN when neither
// neighbour is known.
inline float normalised_gradient(float r, Neighbour before, Neighbour after, float tan_alpha) {
  float g;
  const bool b_ok = !std::isnan(before.range);
  const bool a_ok = !std::isnan(after.range);
  if (!b_ok && !a_ok) return kNaN;
  if (a_ok && b_ok) {
    if (std::isinf(after.range) && std::isinf(before.range)) return 0.0F;
    if (std::isinf(after.range)) return 1.0F;
    if (std::isinf(before.range)) return -1.0F;
    g = (after.range - before.range) / (after.steps + before.steps);
  } else if (a_ok) {
    if (std::isinf(after.range)) return 1.0F;
    g = (after.range - r) / after.steps;
  } else {
    if (std::isinf(before.range)) return -1.0F;
    g = (r - before.range) / before.steps;
  }
  return std::atan(g / (tan_alpha * r)) * kTwoOverPi;
}

// Normalised convolution with a separable Gaussian: only known values on the same
// surface contribute (range within kSameSurface of the centre pixel's), so the
// smoothing removes noise without blurring occlusion borders away.
constexpr float kSameSurface = 0.05F;

// Both gradient images at once: they are known at the same pixels (every return), so
// the weights of a pixel's neighbours are the same for both.
#if defined(__SSE2__)
// The normalised convolution of `smooth` at four neighbouring pixels (lanes), taps
// i0..i1 `step` floats apart: a tap a lane rejects keeps
// that lane's sums as they were (a select, not an added zero, so even a -0 sum stays
// -0), so each lane's result has the bits of the scalar loop. A lane whose own value
// is unknown gets NaN.
inline void smooth_block(const float* vx, const float* vy, const float* rr, std::ptrdiff_t step, int i0, int i1,
                         const float* kc, float* ox, float* oy) {
  const __m128 rc = _mm_loadu_ps(rr);
  const __m128 tol = _mm_mul_ps(_mm_set1_ps(kSameSurface), rc);
  const __m128 abs_mask = _mm_castsi128_ps(_mm_set1_epi32(0x7FFFFFFF));
  __m128 sx = _mm_setzero_ps(), sy = _mm_setzero_ps(), ws = _mm_setzero_ps();
  for (int i = i0; i <= i1; ++i) {
    const std::ptrdiff_t o = i * step;
    const __m128 v = _mm_loadu_ps(vx + o);
    const __m128 ok = _mm_and_ps(_mm_cmpord_ps(v, v),
                                 _mm_cmple_ps(_mm_and_ps(_mm_sub_ps(_mm_loadu_ps(rr + o), rc), abs_mask), tol));
    const __m128 k = _mm_set1_ps(kc[i]);
    sx = _mm_or_ps(_mm_and_ps(ok, _mm_add_ps(sx, _mm_mul_ps(k, v))), _mm_andnot_ps(ok, sx));
    sy = _mm_or_ps(_mm_and_ps(ok, _mm_add_ps(sy, _mm_mul_ps(k, _mm_loadu_ps(vy + o)))), _mm_andnot_ps(ok, sy));
    ws = _mm_or_ps(_mm_and_ps(ok, _mm_add_ps(ws, k)), _mm_andnot_ps(ok, ws));
  }
  const __m128 centre = _mm_loadu_ps(vx);
  const __m128 known = _mm_cmpord_ps(centre, centre);
  const __m128 nan = _mm_set1_ps(kNaN);
  _mm_storeu_ps(ox, _mm_or_ps(_mm_and_ps(known, _mm_div_ps(sx, ws)), _mm_andnot_ps(known, nan)));
  _mm_storeu_ps(oy, _mm_or_ps(_mm_and_ps(known, _mm_div_ps(sy, ws)), _mm_andnot_ps(known, nan)));
}
#endif

void smooth(std::vector<float>& gx, std::vector<float>& gy, const RangeImage& img, double sigma) {
  const int w = img.width;
  const int h = img.height;
  const bool wrap = img.full_circle;
  const float* const range = img.range.data();
  if (sigma <= 0.0) return;
  const int radius = std::max(1, static_cast<int>(std::ceil(2.0 * sigma)));
  std::vector<float> kernel(static_cast<std::size_t>(2 * radius + 1));
  for (int i = -radius; i <= radius; ++i)
    kernel[static_cast<std::size_t>(i + radius)] = static_cast<float>(std::exp(-0.5 * i * i / (sigma * sigma)));
  const float* const kc = kernel.data() + radius;  // kc[i], i in [-radius, radius]
  std::vector<float> tx(gx.size(), kNaN), ty(gy.size(), kNaN);
  // Horizontal pass.
  for (int y = 0; y < h; ++y) {
    const std::size_t row = static_cast<std::size_t>(y) * static_cast<std::size_t>(w);
    const float* const vx = gx.data() + row;
    const float* const vy = gy.data() + row;
    const float* const rr = range + row;
    for (int x = 0; x < w; ++x) {
#if defined(__SSE2__)
      // Four pixels whose taps all lie inside the row at once; each lane adds the
      // same products in the same order as the code below.
      if (x >= radius && x + 3 + radius < w) {
        smooth_block(vx + x, vy + x, rr + x, 1, -radius, radius, kc, tx.data() + row + x, ty.data() + row + x);
        x += 3;
        continue;
      }
#endif
      if (std::isnan(vx[x])) continue;
      const float rc = rr[x];
      const float tol = kSameSurface * rc;
      float sx = 0.0F, sy = 0.0F, ws = 0.0F;
      for (int i = -radius; i <= radius; ++i) {
        int xx = x + i;
        if (wrap) {
          if (xx < 0 || xx >= w) xx = (xx % w + w) % w;
        } else if (xx < 0 || xx >= w) {
          continue;
        }
        if (std::isnan(vx[xx]) || !(std::abs(rr[xx] - rc) <= tol)) continue;
        const float k = kc[i];
        sx += k * vx[xx];
        sy += k * vy[xx];
        ws += k;
      }
      tx[row + static_cast<std::size_t>(x)] = sx / ws;
      ty[row + static_cast<std::size_t>(x)] = sy / ws;
    }
  }
  // Vertical pass.
  const std::ptrdiff_t stride = w;
  for (int y = 0; y < h; ++y) {
    const int i0 = std::max(-radius, -y);
    const int i1 = std::min(radius, h - 1 - y);
    for (int x = 0; x < w; ++x) {
      const std::size_t k0 = static_cast<std::size_t>(y) * static_cast<std::size_t>(w) + static_cast<std::size_t>(x);
#if defined(__SSE2__)
      if (x + 3 < w) {
        smooth_block(tx.data() + k0, ty.data() + k0, range + k0, stride, i0, i1, kc, gx.data() + k0, gy.data() + k0);
        x += 3;
        continue;
      }
#endif
      if (std::isnan(tx[k0])) continue;
      const float rc = range[k0];
      const float tol = kSameSurface * rc;
      float sx = 0.0F, sy = 0.0F, ws = 0.0F;
      for (int i = i0; i <= i1; ++i) {
        const std::size_t kq = static_cast<std::size_t>(static_cast<std::ptrdiff_t>(k0) + i * stride);
        if (std::isnan(tx[kq]) || !(std::abs(range[kq] - rc) <= tol)) continue;
        const float k = kc[i];
        sx += k * tx[kq];
        sy += k * ty[kq];
        ws += k;
      }
      gx[k0] = sx / ws;
      gy[k0] = sy / ws;
    }
  }
}

// Central difference of a smoothed gradient image, one-sided (doubled) at gaps.
inline float second_derivative(const std::vector<float>& g, const RangeImage& img, int x, int y, bool along_x) {
  auto at = [&](int xx, int yy) -> float {
    if (yy < 0 || yy >= img.height) return kNaN;
    const int wx = img.wrap_x(xx);
    if (wx < 0) return kNaN;
    return g[img.index(wx, yy)];
  };
  const float c = at(x, y);
  const float b = along_x ? at(x - 1, y) : at(x, y - 1);
  const float a = along_x ? at(x + 1, y) : at(x, y + 1);
  if (!std::isnan(a) && !std::isnan(b)) return a - b;
  if (!std::isnan(a)) return 2.0F * (a - c);
  if (!std::isnan(b)) return 2.0F * (c - b);
  return 0.0F;
}

#if defined(__SSE2__)
// second_derivative at four neighbouring pixels g[0..3] away from the image's edges,
// neighbours `step` floats before and after.
inline __m128 second_derivatives(const float* g, std::ptrdiff_t step) {
  const __m128 c = _mm_loadu_ps(g);
  const __m128 b = _mm_loadu_ps(g - step);
  const __m128 a = _mm_loadu_ps(g + step);
  const __m128 a_ok = _mm_cmpord_ps(a, a), b_ok = _mm_cmpord_ps(b, b);
  const __m128 two = _mm_set1_ps(2.0F);
  const __m128 only_b = _mm_and_ps(b_ok, _mm_mul_ps(two, _mm_sub_ps(c, b)));  // 0 when neither
  const __m128 one_side = _mm_or_ps(_mm_and_ps(a_ok, _mm_mul_ps(two, _mm_sub_ps(a, c))), _mm_andnot_ps(a_ok, only_b));
  const __m128 both = _mm_and_ps(a_ok, b_ok);
  return _mm_or_ps(_mm_and_ps(both, _mm_sub_ps(a, b)), _mm_andnot_ps(both, one_side));
}
#endif

inline float angle_diff_mod_pi(float a, float b) {
  float d = std::fmod(std::abs(a - b), static_cast<float>(M_PI));
  return std::min(d, static_cast<float>(M_PI) - d);
}

}  // namespace

std::vector<Keypoint> detect_interest_points(const RangeImage& img, const InterestParams& params,
                                             InterestImage* debug) {
  params.validate();
  std::vector<Keypoint> result;
  InterestImage local;
  InterestImage& out = debug ? *debug : local;
  out = InterestImage{};
  out.width = img.width;
  out.height = img.height;
  if (img.empty()) return result;
  const int w = img.width;
  const int h = img.height;
  const std::size_t n = static_cast<std::size_t>(w) * static_cast<std::size_t>(h);
  const float tan_ax = static_cast<float>(std::tan(img.azimuth_resolution_rad));
  // Rows may follow the sensor's beams, with their own angular heights.
  std::vector<float> tan_row(static_cast<std::size_t>(h));
  for (int y = 0; y < h; ++y) tan_row[static_cast<std::size_t>(y)] = static_cast<float>(std::tan(img.row_height(y)));

  // Eq. 1-2: normalised gradients, then Gaussian smoothing.
  std::vector<float> gx(n, kNaN), gy(n, kNaN);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const std::size_t k = img.index(x, y);
      if (img.state[k] != PixelState::kValid) continue;
      const float r = img.range[k];
      if (x >= 2 && x + 2 < w && y >= 2 && y + 2 < h) {
        // Both steps of every neighbour inside the image: no wrap or bounds to check.
        const auto wide = static_cast<std::ptrdiff_t>(w);
        gx[k] = normalised_gradient(r, inner_neighbour(img, k, -1), inner_neighbour(img, k, 1), tan_ax);
        gy[k] = normalised_gradient(r, inner_neighbour(img, k, -wide), inner_neighbour(img, k, wide),
                                    tan_row[static_cast<std::size_t>(y)]);
      } else {
        gx[k] = normalised_gradient(r, neighbour(img, x, y, -1, 0), neighbour(img, x, y, 1, 0), tan_ax);
        gy[k] = normalised_gradient(r, neighbour(img, x, y, 0, -1), neighbour(img, x, y, 0, 1),
                                    tan_row[static_cast<std::size_t>(y)]);
      }
      if (std::isnan(gx[k])) gx[k] = 0.0F;
      if (std::isnan(gy[k])) gy[k] = 0.0F;
    }
  smooth(gx, gy, img, params.smoothing_sigma_px);

  // Eq. 3-5 and the occlusion filter.
  out.value.assign(n, 0.0F);
  // Direction of change (atan2 of the second derivatives) of a return; only the
  // straight-line filter needs it, at a few pixels, so it is computed there.
  auto angle = [&](std::size_t k) {
    const int x = static_cast<int>(k % static_cast<std::size_t>(w));
    const int y = static_cast<int>(k / static_cast<std::size_t>(w));
    return std::atan2(second_derivative(gy, img, x, y, false), second_derivative(gx, img, x, y, true));
  };
  // atan(step / (tan α · r · px)) · 2/π > occ  <=>  step > tan(occ · π/2) · tan α · r · px
  const float occ_ratio = params.occlusion_gradient >= 1.0
                              ? std::numeric_limits<float>::infinity()
                              : static_cast<float>(std::tan(params.occlusion_gradient * M_PI / 2.0));
  const float thr = static_cast<float>(params.threshold);
  // Eq. 5 done; the occlusion filter, then the pixel's value.
  auto finish = [&](int x, int y, std::size_t k, float interest) {
    if (interest >= thr) {
      // Shadow side of a jump: a nearer neighbour (1 or 2 px away) with a normalised
      // range step close to 1. Such borders depend on the viewpoint.
      const float r = img.range[k];
      bool shadow = false;
      for (int step = 1; step <= 2 && !shadow; ++step) {
        const int dxs[4] = {-step, step, 0, 0};
        const int dys[4] = {0, 0, -step, step};
        for (int j = 0; j < 4 && !shadow; ++j) {
          const float rq = neighbour_range(img, x + dxs[j], y + dys[j]);
          if (!(rq < r)) continue;  // NaN, inf or not nearer
          const float tan_a = dxs[j] != 0 ? tan_ax : tan_row[static_cast<std::size_t>(y)];
          shadow = (r - rq) > occ_ratio * tan_a * r * static_cast<float>(step);
        }
      }
      if (shadow) {
        interest = 0.0F;
        ++out.occlusion_rejected;
      }
    }
    out.value[k] = interest;
  };
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const std::size_t k = img.index(x, y);
#if defined(__SSE2__)
      // Four pixels with all their neighbours inside the image (no wrap, no edge):
      // the same differences, products and square root in each lane, chosen by
      // selects where the scalar code branches.
      if (y > 0 && y + 1 < h && x > 0 && x + 4 < w) {
        const __m128 dx2 = second_derivatives(gx.data() + k, 1);
        const __m128 dy2 = second_derivatives(gy.data() + k, static_cast<std::ptrdiff_t>(w));
        alignas(16) float value[4];
        _mm_store_ps(value, _mm_mul_ps(_mm_sqrt_ps(_mm_add_ps(_mm_mul_ps(dx2, dx2), _mm_mul_ps(dy2, dy2))),
                                       _mm_set1_ps(kInvMaxInterest)));
        for (int l = 0; l < 4; ++l)
          if (img.state[k + static_cast<std::size_t>(l)] == PixelState::kValid)
            finish(x + l, y, k + static_cast<std::size_t>(l), value[l]);
        x += 3;
        continue;
      }
#endif
      if (img.state[k] != PixelState::kValid) continue;
      const float gx2 = second_derivative(gx, img, x, y, true);
      const float gy2 = second_derivative(gy, img, x, y, false);
      // |G'| <= 1 bounds each second derivative by 2, so dividing by 2·sqrt(2) maps
      // eq. 5 onto [0, 1] without clipping the strongest corners into a tie.
      finish(x, y, k, std::sqrt(gx2 * gx2 + gy2 * gy2) * kInvMaxInterest);
    }

  // Local maxima above the threshold, then the straight-line filter.
  const float line_angle = static_cast<float>(params.line_angle_deg * M_PI / 180.0);
  std::vector<std::size_t> candidates;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const std::size_t k = img.index(x, y);
      const float v = out.value[k];
      if (!(v >= thr)) continue;
      bool is_max = true;
      for (int dy = -1; dy <= 1 && is_max; ++dy)
        for (int dx = -1; dx <= 1 && is_max; ++dx) {
          if (dx == 0 && dy == 0) continue;
          const int yy = y + dy;
          const int xx = img.wrap_x(x + dx);
          if (yy < 0 || yy >= h || xx < 0) continue;
          const std::size_t q = img.index(xx, yy);
          const float u = out.value[q];
          // Ties go to the pixel that comes first in row-major order.
          if (u > v || (u == v && q < k)) is_max = false;
        }
      if (!is_max) continue;
      ++out.maxima;
      // The edge through this pixel runs perpendicular to the direction of change.
      const float th = angle(k);
      const int sx = static_cast<int>(std::lround(-2.0 * std::sin(th)));
      const int sy = static_cast<int>(std::lround(2.0 * std::cos(th)));
      int continuing = 0;
      for (int sgn = -1; sgn <= 1; sgn += 2) {
        const int yy = y + sgn * sy;
        const int xx = img.wrap_x(x + sgn * sx);
        if (yy < 0 || yy >= h || xx < 0) continue;
        const std::size_t q = img.index(xx, yy);
        if (img.state[q] != PixelState::kValid || out.value[q] < 0.5F * thr) continue;
        if (angle_diff_mod_pi(angle(q), th) < line_angle) ++continuing;
      }
      if (continuing == 2) {
        ++out.line_rejected;
        continue;
      }
      candidates.push_back(k);
    }
  std::stable_sort(candidates.begin(), candidates.end(),
                   [&](std::size_t a, std::size_t b) { return out.value[a] > out.value[b]; });

  // Minimum 3D distance, strongest first.
  const float min_d = static_cast<float>(params.min_distance);
  detail::PointHash taken(std::max(min_d, 1e-3F));
  for (const std::size_t k : candidates) {
    const Eigen::Vector3f& p = img.point[k];
    if (min_d > 0.0F && taken.any_within(p)) continue;
    taken.insert(p);
    Keypoint kp;
    kp.point_sensor = p;
    kp.x = static_cast<float>(k % static_cast<std::size_t>(w)) + 0.5F;
    kp.y = static_cast<float>(k / static_cast<std::size_t>(w)) + 0.5F;
    kp.interest = out.value[k];
    kp.kind = FeatureKind::kInterest;
    result.push_back(kp);
  }
  return result;
}

}  // namespace lex3d
