// Patch descriptors with a full 6-DoF frame (steder2010 §III-A, after the
// interpolated range patches of Steder et al. 2009). The surface around a feature
// point is seen from a virtual viewpoint on its normal, upright in the world, and
// rasterised into a patch_size x patch_size grid of depths covering a fixed 3D radius.
//
// Compared with PCL's NARF (pcl::NarfDescriptor): NARF builds its patch by
// ray-casting a pcl::RangeImage from the virtual viewpoint and reduces it to a
// rotation-invariant 36-beam histogram with an orientation estimated from the patch.
// lex3d keeps the raw depth patch (100 values, as in the papers) and fixes the
// rotation about the normal with the world's up direction, which is what makes the
// frame a full, repeatable 6-DoF pose for the compression model; and it rasterises
// the points it gathers from the range image with a z-buffer instead of ray-casting,
// which is cheaper and needs no pcl::RangeImage.

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <stdexcept>

#include <Eigen/Eigenvalues>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif
#if defined(__x86_64__)
#include <immintrin.h>
#endif

#include "core/huge_pages.hpp"
#include "lex3d/core/parallel.hpp"
#include "lex3d/features/features.hpp"

namespace lex3d {

void DescriptorParams::validate() const {
  if (!(support_radius > 0.0 && support_radius <= 100.0))
    throw std::invalid_argument("DescriptorParams::support_radius must be in (0, 100] m");
  if (patch_size < 2 || patch_size > 64)
    throw std::invalid_argument("DescriptorParams::patch_size must be in [2, 64]");
  if (!(normal_radius > 0.0 && normal_radius <= 10.0))
    throw std::invalid_argument("DescriptorParams::normal_radius must be in (0, 10] m");
  if (!(up.allFinite() && up.norm() > 1e-9))
    throw std::invalid_argument("DescriptorParams::up must be a finite non-zero vector");
}

// Eight running sums, element i going to sum i % 8, added pairwise at the end: the
// loop vectorises (SSE or AVX2, picked at load time) and every build gives the same bits.
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && !defined(__SANITIZE_ADDRESS__)
__attribute__((target_clones("avx2", "default")))
#endif
void descriptor_distances_sq(const float* q, const float* rows, std::size_t count, int dim, float* out) noexcept {
  const int blocks = dim / 8;
  for (std::size_t w = 0; w < count; ++w) {
    const float* b = rows + w * static_cast<std::size_t>(dim);
    float acc[8] = {0.0F, 0.0F, 0.0F, 0.0F, 0.0F, 0.0F, 0.0F, 0.0F};
    for (int k = 0; k < blocks; ++k)
      for (int l = 0; l < 8; ++l) {
        const float d = q[8 * k + l] - b[8 * k + l];
        acc[l] += d * d;
      }
    for (int i = 8 * blocks; i < dim; ++i) {
      const float d = q[i] - b[i];
      acc[i - 8 * blocks] += d * d;
    }
    out[w] = ((acc[0] + acc[1]) + (acc[2] + acc[3])) + ((acc[4] + acc[5]) + (acc[6] + acc[7]));
  }
}

float descriptor_distance_sq(const float* a, const float* b, int dim) noexcept {
  float d = 0.0F;
  descriptor_distances_sq(a, b, 1, dim, &d);
  return d;
}

std::optional<Keypoint> keypoint_at(const RangeImage& img, const Eigen::Vector3f& point_sensor) {
  float x = 0.0F, y = 0.0F, r = 0.0F;
  if (img.empty() || !img.project(point_sensor, x, y, r)) return std::nullopt;
  if (y < 0.0F || y >= static_cast<float>(img.height)) return std::nullopt;
  if (!img.full_circle && x >= static_cast<float>(img.width)) return std::nullopt;
  Keypoint kp;
  kp.point_sensor = point_sensor;
  kp.x = x;
  kp.y = y;
  return kp;
}

namespace {

// The image's points (RangeImage::point), NaN where there is no return: NaN fails
// every distance test, so no state look-up is needed. Read in place rather than
// copied to 16-byte pixels, whose fresh pages cost more than the unaligned loads.
using Pixel = Eigen::Vector3f;

// The pixels of a window around a keypoint that may hold points within a radius of
// it, sampling at most about (2*max_half+1)^2 of them: rows (image rows in range) and
// columns (wrapped; off a partial image dropped), visited row by row.
struct Window {
  // Each side of a window has fewer than 2 * max_half samples, and max_half <= 64.
  int rows[256];
  int cols[256];
  int nrows = 0;
  int ncols = 0;
};

// Where a keypoint sits, computed once for both of its windows.
struct WindowCentre {
  double range;   // |point|
  double cos_el;  // cosine of the elevation of its row, at least 0.05
  int cx, cy;     // pixel
};

WindowCentre window_centre(const RangeImage& img, const Keypoint& kp) {
  WindowCentre c;
  c.range = static_cast<double>(kp.point_sensor.norm());
  const double el = img.elevation_at(static_cast<double>(kp.y));
  c.cos_el = std::max(std::cos(el), 0.05);
  c.cx = static_cast<int>(std::floor(kp.x));
  c.cy = static_cast<int>(std::floor(kp.y));
  return c;
}

// Where a window may leave out samples: column offsets from the centre column outside
// [col_lo, col_hi] and rows outside [row_lo, row_hi] (the sampling grid stays as it is).
struct WindowBounds {
  int col_lo = std::numeric_limits<int>::min(), col_hi = std::numeric_limits<int>::max();
  int row_lo = std::numeric_limits<int>::min(), row_hi = std::numeric_limits<int>::max();
};

void make_window(const RangeImage& img, const WindowCentre& c, double radius, int max_half, Window& w,
                 const WindowBounds& bounds = WindowBounds{}) {
  const double extent = c.range > radius ? std::asin(radius / c.range) : M_PI;
  const int half_x = static_cast<int>(
      std::min<double>(img.width / 2, std::ceil(extent / (img.azimuth_resolution_rad * c.cos_el))));
  const int half_y = static_cast<int>(std::min<double>(img.height, std::ceil(extent / img.elevation_resolution_rad)));
  const int stride_x = std::max(1, half_x / std::max(1, max_half));
  const int stride_y = std::max(1, half_y / std::max(1, max_half));
  w.nrows = 0;
  for (int dy = -(half_y / stride_y) * stride_y; dy <= half_y; dy += stride_y) {
    const int y = c.cy + dy;
    if (y >= 0 && y < img.height && y >= bounds.row_lo && y <= bounds.row_hi) w.rows[w.nrows++] = y;
  }
  w.ncols = 0;
  for (int dx = -(half_x / stride_x) * stride_x; dx <= half_x; dx += stride_x) {
    if (dx < bounds.col_lo || dx > bounds.col_hi) continue;
    const int x = img.wrap_x(c.cx + dx);
    if (x >= 0) w.cols[w.ncols++] = x;
  }
  // Room for a whole last block of eight: the last column again (its lanes masked off).
  for (int j = w.ncols; j < ((w.ncols + 7) & ~7); ++j) w.cols[j] = w.cols[w.ncols - 1];
}

// The row make_range_image gives a point at elevation el: the last row whose top edge
// is at or above it, within the image.
// Found from a guess at the nominal row height (exact for the evenly spaced rows of
// make_range_image), then moved to the row that holds el.
int row_of_elevation(const RangeImage& img, double el) {
  const std::vector<double>& e = img.row_edges;
  const int h = img.height;
  if (!(el < e[0])) return 0;
  if (!(el > e[static_cast<std::size_t>(h)])) return h - 1;
  double g = std::floor((e[0] - el) / img.elevation_resolution_rad);
  if (!(g >= 0.0)) g = 0.0;
  if (g > h - 1) g = h - 1;
  auto y = static_cast<std::size_t>(g);
  while (y > 0 && !(e[y] >= el)) --y;
  while (!(el > e[y + 1])) ++y;
  return static_cast<int>(y);
}

// The columns and rows outside which no image point can lie in the cube
// |R^T (q - p)| < rad of a patch (p the keypoint, R its frame); false when this gives no
// usable bound. The patch window is the sphere around the cube, which the cube seen
// from the sensor fills only when it stands on a corner: for a wall or the ground a
// good part of the window's pixels hold no point that can fall inside.
//
// With `along` the horizontal component towards p, `across` the horizontal one at right
// angles and z up, and the cube grown by a margin that covers the float rounding of the
// in-cube test and R being orthonormal only to float precision; along > 0 over the
// whole cube (checked at its corners):
// - across / along, a ratio of linear functions, takes its extremes at corners; it is
//   the tangent of az(q) - az(p), whose size it bounds (|atan t| <= |t|);
// - so does z / along, and as along <= |q_h| <= along * sqrt(1 + (across/along)^2),
//   the tangent of the elevation, z / |q_h|, lies between the corners' extremes of
//   z / along, or those divided by the square root where that moves them towards zero.
// A point's column is the floor of its continuous column, which moves by 1/res per
// radian of azimuth, and its row falls as its elevation rises; a margin on the angles
// and one more column and row on each side cover the float rounding of the image's.
bool cube_bounds(const RangeImage& img, const WindowCentre& c, const Eigen::Vector3f& p, const Eigen::Matrix3f& R,
                 double rad, WindowBounds& out) {
  const double ph = std::sqrt(static_cast<double>(p.x()) * p.x() + static_cast<double>(p.y()) * p.y());
  if (!(ph > 0.0) || !(img.azimuth_resolution_rad > 0.0) || !(img.elevation_resolution_rad > 0.0) ||
      img.row_edges.size() != static_cast<std::size_t>(img.height) + 1)
    return false;
  const double vx = p.x() / ph, vy = p.y() / ph;
  const double r = rad * (1.0 + 1e-4) + 1e-4;
  // Each coordinate of a corner is p's plus a sum of three edge terms of either sign.
  double a[3], b[3], z[3];  // the edge terms of along, across and z
  for (int i = 0; i < 3; ++i) {
    const double cx = R(0, i) * r, cy = R(1, i) * r;
    a[i] = vx * cx + vy * cy;
    b[i] = vx * cy - vy * cx;
    z[i] = R(2, i) * r;
  }
  const double a_lo = ph - (std::fabs(a[0]) + std::fabs(a[1]) + std::fabs(a[2]));
  if (!(a_lo > 1e-3 * ph)) return false;  // the cube reaches the sensor's side plane
  double t_min = 0.0, t_max = 0.0;             // across / along
  double e_min = HUGE_VAL, e_max = -HUGE_VAL;  // z / along
  for (int k = 0; k < 8; ++k) {
    const double s0 = (k & 1) != 0 ? 1.0 : -1.0, s1 = (k & 2) != 0 ? 1.0 : -1.0, s2 = (k & 4) != 0 ? 1.0 : -1.0;
    const double along = ph + (s0 * a[0] + s1 * a[1] + s2 * a[2]);
    const double across = s0 * b[0] + s1 * b[1] + s2 * b[2];
    const double qz = p.z() + (s0 * z[0] + s1 * z[1] + s2 * z[2]);
    const double inv = 1.0 / along;  // its rounding is far inside the margins
    t_min = std::min(t_min, across * inv);
    t_max = std::max(t_max, across * inv);
    e_min = std::min(e_min, qz * inv);
    e_max = std::max(e_max, qz * inv);
  }
  // Columns: the keypoint's continuous column (as RangeImage::project has it) relative
  // to the centre column, across the seam of a 360° image; a larger azimuth is a
  // smaller column.
  double daz = img.azimuth_max_rad - std::atan2(static_cast<double>(p.y()), static_cast<double>(p.x()));
  if (daz < 0.0) daz += 2.0 * M_PI;
  if (daz >= 2.0 * M_PI) daz -= 2.0 * M_PI;
  double dc = daz / img.azimuth_resolution_rad - c.cx;
  if (img.full_circle) dc -= img.width * std::floor(dc / img.width + 0.5);
  const double flo = dc - t_max / img.azimuth_resolution_rad - 0.05;
  const double fhi = dc - t_min / img.azimuth_resolution_rad + 0.05;
  // Well inside a quarter turn of the image, so that no sampled offset (at most half the
  // width) reaches the same columns the other way round.
  const double quarter = 0.25 * img.width;
  if (!(flo > -quarter + 2.0 && fhi < quarter - 2.0)) return false;
  out.col_lo = static_cast<int>(std::floor(flo)) - 1;
  out.col_hi = static_cast<int>(std::floor(fhi)) + 1;
  // Rows.
  const double k = std::sqrt(1.0 + std::max(t_max * t_max, t_min * t_min));
  const double lo = e_min <= 0.0 ? e_min : e_min / k;
  const double hi = e_max >= 0.0 ? e_max : e_max / k;
  out.row_lo = row_of_elevation(img, std::atan(hi) + 1e-5) - 1;
  out.row_hi = row_of_elevation(img, std::atan(lo) - 1e-5) + 1;
  return true;
}

// Calls the kernel for the window's points in order: row by row, columns left to
// right. With SSE2, four pixels at a time as x, y and z lanes, with a mask of the lanes
// that are pixels of the window (block(x, y, z, lanes): the last block of a row may be
// short); otherwise one by one (one(pixel)).
#if defined(__SSE2__)
// A 12-byte pixel as x, y, z lanes: one 16-byte load, which reads 4 bytes of the next
// pixel, except in the image's last row, whose last pixel has no next.
inline __m128 load_pixel(const float* p, bool last_row) {
  if (!last_row) return _mm_loadu_ps(p);
  return _mm_movelh_ps(_mm_loadl_pi(_mm_setzero_ps(), reinterpret_cast<const __m64*>(p)), _mm_load_ss(p + 2));
}

template <typename Block, typename One>
inline void for_window(const Pixel* pix, int width, int height, const Window& w, Block&& block,
                       One&& /*one: without SSE2*/) {
  for (int r = 0; r < w.nrows; ++r) {
    const float* row = pix[static_cast<std::ptrdiff_t>(w.rows[r]) * width].data();
    const bool last_row = w.rows[r] + 1 == height;
    for (int j = 0; j < w.ncols; j += 4) {
      const int lanes = w.ncols - j >= 4 ? 0xF : (1 << (w.ncols - j)) - 1;
      __m128 x = load_pixel(row + 3 * w.cols[j], last_row);
      __m128 y = load_pixel(row + 3 * w.cols[j + 1], last_row);
      __m128 z = load_pixel(row + 3 * w.cols[j + 2], last_row);
      __m128 t = load_pixel(row + 3 * w.cols[j + 3], last_row);
      _MM_TRANSPOSE4_PS(x, y, z, t);
      block(x, y, z, lanes);
    }
  }
}

// fn(x[l], y[l], z[l]) for each lane l whose bit is set in `lanes`, lowest first.
template <typename Fn>
inline void for_lanes(int lanes, __m128 x, __m128 y, __m128 z, Fn&& fn) {
  if (lanes == 0) return;
  alignas(16) float ax[4], ay[4], az[4];
  _mm_store_ps(ax, x);
  _mm_store_ps(ay, y);
  _mm_store_ps(az, z);
  for (; lanes != 0; lanes &= lanes - 1) {
    const int l = __builtin_ctz(static_cast<unsigned>(lanes));
    fn(ax[l], ay[l], az[l]);
  }
}
#else
template <typename One>
inline void for_window(const Pixel* pix, int width, int /*height*/, const Window& w, One&& one) {
  for (int r = 0; r < w.nrows; ++r) {
    const Pixel* row = pix + static_cast<std::ptrdiff_t>(w.rows[r]) * width;
    for (int j = 0; j < w.ncols; ++j) one(row[w.cols[j]]);
  }
}
#endif

// Running sums of a plane fit's offsets and of their products (xx, xy, xz, yy, yz,
// zz), in double, added in visiting order.
struct PlaneSums {
  double s0 = 0.0, s1 = 0.0, s2 = 0.0;
  double sxx = 0.0, sxy = 0.0, sxz = 0.0, syy = 0.0, syz = 0.0, szz = 0.0;
  int count = 0;
  void add(float dx, float dy, float dz) {
    const double ex = dx, ey = dy, ez = dz;
    s0 += ex;
    s1 += ey;
    s2 += ez;
    sxx += ex * ex;
    sxy += ex * ey;
    sxz += ex * ez;
    syy += ey * ey;
    syz += ey * ez;
    szz += ez * ez;
    ++count;
  }
};

#if defined(__SSE2__) && defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__)) && \
    !defined(__SANITIZE_ADDRESS__)
#define LEX3D_DESCRIBE_AVX 1
bool cpu_has_avx() {
  static const bool avx = __builtin_cpu_supports("avx");
  return avx;
}

// Eight pixels of a window row as x, y, z lanes (columns c[0..7]).
__attribute__((target("avx"))) inline void load8(const float* row, const int* c, bool last_row, __m256& x,
                                                 __m256& y, __m256& z) {
  const __m256 t0 = _mm256_insertf128_ps(_mm256_castps128_ps256(load_pixel(row + 3 * c[0], last_row)),
                                         load_pixel(row + 3 * c[4], last_row), 1);
  const __m256 t1 = _mm256_insertf128_ps(_mm256_castps128_ps256(load_pixel(row + 3 * c[1], last_row)),
                                         load_pixel(row + 3 * c[5], last_row), 1);
  const __m256 t2 = _mm256_insertf128_ps(_mm256_castps128_ps256(load_pixel(row + 3 * c[2], last_row)),
                                         load_pixel(row + 3 * c[6], last_row), 1);
  const __m256 t3 = _mm256_insertf128_ps(_mm256_castps128_ps256(load_pixel(row + 3 * c[3], last_row)),
                                         load_pixel(row + 3 * c[7], last_row), 1);
  const __m256 u0 = _mm256_unpacklo_ps(t0, t1);  // x0 x1 y0 y1 | x4 x5 y4 y5
  const __m256 u1 = _mm256_unpackhi_ps(t0, t1);  // z0 z1 .  .  | z4 z5 .  .
  const __m256 u2 = _mm256_unpacklo_ps(t2, t3);  // x2 x3 y2 y3 | x6 x7 y6 y7
  const __m256 u3 = _mm256_unpackhi_ps(t2, t3);  // z2 z3 .  .  | z6 z7 .  .
  x = _mm256_shuffle_ps(u0, u2, _MM_SHUFFLE(1, 0, 1, 0));
  y = _mm256_shuffle_ps(u0, u2, _MM_SHUFFLE(3, 2, 3, 2));
  z = _mm256_shuffle_ps(u1, u3, _MM_SHUFFLE(1, 0, 1, 0));
}

// Calls block(dx, dy, dz, lanes) for the window's pixels eight at a time, row by row and
// left to right: their offsets from p as lanes, `lanes` marking the pixels of the window (the
// last block of a row may be short).
template <typename Block>
__attribute__((target("avx"))) inline void for_window8(const Pixel* pix, int width, int height, const Window& w,
                                                       const Eigen::Vector3f& p, Block&& block) {
  const __m256 vpx = _mm256_set1_ps(p.x()), vpy = _mm256_set1_ps(p.y()), vpz = _mm256_set1_ps(p.z());
  for (int r = 0; r < w.nrows; ++r) {
    const float* row = pix[static_cast<std::ptrdiff_t>(w.rows[r]) * width].data();
    const bool last_row = w.rows[r] + 1 == height;
    for (int j = 0; j < w.ncols; j += 8) {
      const int lanes = w.ncols - j >= 8 ? 0xFF : (1 << (w.ncols - j)) - 1;
      __m256 x, y, z;
      load8(row, w.cols + j, last_row, x, y, z);
      block(_mm256_sub_ps(x, vpx), _mm256_sub_ps(y, vpy), _mm256_sub_ps(z, vpz), lanes);
    }
  }
}

// The plane-fit sums of feature_frame over the window's points within sqrt(r2) of
// p, eight pixels at a time: the same float test in each lane as its four-pixel
// kernel, and the points added in the same order.
__attribute__((target("avx"))) void plane_sums_avx(const Pixel* pix, int width, int height, const Window& w,
                                                   const Eigen::Vector3f& p, float r2, PlaneSums& sums) {
  const __m256 vr2 = _mm256_set1_ps(r2);
  for_window8(pix, width, height, w, p, [&](__m256 dx, __m256 dy, __m256 dz, int lanes) __attribute__((target("avx"))) {
    const __m256 sq = _mm256_add_ps(_mm256_mul_ps(dx, dx), _mm256_add_ps(_mm256_mul_ps(dy, dy), _mm256_mul_ps(dz, dz)));
    int m = _mm256_movemask_ps(_mm256_cmp_ps(sq, vr2, _CMP_LE_OS)) & lanes;
    if (m == 0) return;
    alignas(32) float ax[8], ay[8], az[8];
    _mm256_store_ps(ax, dx);
    _mm256_store_ps(ay, dy);
    _mm256_store_ps(az, dz);
    for (; m != 0; m &= m - 1) {
      const int l = __builtin_ctz(static_cast<unsigned>(m));
      sums.add(ax[l], ay[l], az[l]);
    }
  });
}

// The patch's z-buffer filled from a window eight pixels at a time: the same
// products, sums and comparisons in each lane as the four-pixel kernel of
// patch_descriptor, the cells found from the same float values (the cell index
// clamped before truncation instead of after: the same for the non-negative values
// of points inside the cube), and the points put in the same order.
__attribute__((target("avx"))) void rasterise_avx(const Pixel* pix, int width, int height, const Window& w,
                                                  const float* a, const Eigen::Vector3f& p, float rad,
                                                  float inv_cell, int s, int pitch, float* d0) {
  const __m256 a00 = _mm256_set1_ps(a[0]), a01 = _mm256_set1_ps(a[1]), a02 = _mm256_set1_ps(a[2]);
  const __m256 a10 = _mm256_set1_ps(a[3]), a11 = _mm256_set1_ps(a[4]), a12 = _mm256_set1_ps(a[5]);
  const __m256 a20 = _mm256_set1_ps(a[6]), a21 = _mm256_set1_ps(a[7]), a22 = _mm256_set1_ps(a[8]);
  const __m256 vrad = _mm256_set1_ps(rad), vinv = _mm256_set1_ps(inv_cell);
  const __m256 vlast = _mm256_set1_ps(static_cast<float>(s - 1));
  const __m256 abs_mask = _mm256_castsi256_ps(_mm256_set1_epi32(0x7FFFFFFF));
  for_window8(pix, width, height, w, p, [&](__m256 dx, __m256 dy, __m256 dz, int lanes) __attribute__((target("avx"))) {
    const __m256 lx = _mm256_add_ps(_mm256_mul_ps(a00, dx), _mm256_add_ps(_mm256_mul_ps(a01, dy), _mm256_mul_ps(a02, dz)));
    const __m256 ly = _mm256_add_ps(_mm256_mul_ps(a10, dx), _mm256_add_ps(_mm256_mul_ps(a11, dy), _mm256_mul_ps(a12, dz)));
    const __m256 lz = _mm256_add_ps(_mm256_mul_ps(a20, dx), _mm256_add_ps(_mm256_mul_ps(a21, dy), _mm256_mul_ps(a22, dz)));
    const __m256 in =
        _mm256_and_ps(_mm256_and_ps(_mm256_cmp_ps(_mm256_and_ps(lx, abs_mask), vrad, _CMP_LT_OS),
                                    _mm256_cmp_ps(_mm256_and_ps(ly, abs_mask), vrad, _CMP_LT_OS)),
                      _mm256_cmp_ps(_mm256_and_ps(lz, abs_mask), vrad, _CMP_LT_OS));
    int m = _mm256_movemask_ps(in) & lanes;
    if (m == 0) return;
    alignas(32) std::int32_t ix[8], iy[8];
    alignas(32) float depth_of[8];
    _mm256_store_si256(reinterpret_cast<__m256i*>(ix),
                       _mm256_cvttps_epi32(_mm256_min_ps(_mm256_mul_ps(_mm256_add_ps(lx, vrad), vinv), vlast)));
    _mm256_store_si256(reinterpret_cast<__m256i*>(iy),
                       _mm256_cvttps_epi32(_mm256_min_ps(_mm256_mul_ps(_mm256_sub_ps(vrad, ly), vinv), vlast)));
    _mm256_store_ps(depth_of, lz);
    for (; m != 0; m &= m - 1) {
      const int l = __builtin_ctz(static_cast<unsigned>(m));
      float& d = d0[iy[l] * pitch + ix[l]];
      d = std::max(d, depth_of[l]);  // z-buffer: the viewpoint sits on +z
    }
  });
}
#endif


struct Frame {
  Eigen::Matrix3f R;  // columns: x, y, z of the feature frame in the sensor frame
  std::uint16_t support;
};

Frame feature_frame(const RangeImage& img, const Pixel* pix, const Keypoint& kp, const WindowCentre& centre,
                    const DescriptorParams& params, const Eigen::Vector3f& up_sensor, Window& win) {
  const Eigen::Vector3f p = kp.point_sensor;
  const float range = p.norm();
  const Eigen::Vector3f view = range > 0.0F ? Eigen::Vector3f(p / range) : Eigen::Vector3f::UnitX();
  // Normal from a plane fit; the radius grows with range to keep ~2.5 beam spacings.
  const double spacing = std::max(img.azimuth_resolution_rad, img.elevation_resolution_rad) * range;
  const double radius = std::min(params.support_radius, std::max(params.normal_radius, 2.5 * spacing));
  const float r2 = static_cast<float>(radius * radius);
  make_window(img, centre, radius, 7, win);
  // Sums of the offsets and of their products, in visiting order.
  PlaneSums sums;
  const float px = p.x(), py = p.y(), pz = p.z();
  auto add = [&](float dx, float dy, float dz) { sums.add(dx, dy, dz); };
  // Same association as Eigen's squaredNorm of a 3-vector; NaN (no return) fails.
#if defined(LEX3D_DESCRIBE_AVX)
  if (cpu_has_avx()) {
    plane_sums_avx(pix, img.width, img.height, win, p, r2, sums);
  } else
#endif
  for_window(pix, img.width, img.height, win,
#if defined(__SSE2__)
             [&, vpx = _mm_set1_ps(px), vpy = _mm_set1_ps(py), vpz = _mm_set1_ps(pz),
              vr2 = _mm_set1_ps(r2)](__m128 x, __m128 y, __m128 z, int lanes) {
               const __m128 dx = _mm_sub_ps(x, vpx), dy = _mm_sub_ps(y, vpy), dz = _mm_sub_ps(z, vpz);
               const __m128 sq =
                   _mm_add_ps(_mm_mul_ps(dx, dx), _mm_add_ps(_mm_mul_ps(dy, dy), _mm_mul_ps(dz, dz)));
               for_lanes(_mm_movemask_ps(_mm_cmple_ps(sq, vr2)) & lanes, dx, dy, dz, add);
             },
#endif
             [&](const Pixel& q) {
               const float dx = q.x() - px, dy = q.y() - py, dz = q.z() - pz;
               if (dx * dx + (dy * dy + dz * dz) <= r2) add(dx, dy, dz);
             });
  int count = sums.count;
  const double s0 = sums.s0, s1 = sums.s1, s2 = sums.s2;
  const double sxx = sums.sxx, sxy = sums.sxy, sxz = sums.sxz, syy = sums.syy, syz = sums.syz, szz = sums.szz;
  Eigen::Vector3f normal = -view;
  if (count >= 3) {
    const Eigen::Vector3d sum(s0, s1, s2);
    Eigen::Matrix3d sum_sq;
    sum_sq << sxx, sxy, sxz, sxy, syy, syz, sxz, syz, szz;
    const Eigen::Vector3d mean = sum / count;
    const Eigen::Matrix3d cov = sum_sq / count - mean * mean.transpose();
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es;
    es.computeDirect(cov);
    const Eigen::Vector3d ev = es.eigenvalues();
    // A plane needs two spread directions; a line of points (one beam ring) does not fix one.
    if (ev(1) > 1e-3 * ev(2) && ev(2) > 0.0) {
      normal = es.eigenvectors().col(0).cast<float>().normalized();
      if (normal.dot(view) > 0.0F) normal = -normal;
    } else {
      count = 0;
    }
  }
  Eigen::Vector3f y_axis = up_sensor - up_sensor.dot(normal) * normal;
  if (y_axis.norm() < 0.1F) {
    // Near-horizontal surface: point y away from the sensor along the surface.
    y_axis = view - view.dot(normal) * normal;
    if (y_axis.norm() < 1e-3F) {
      y_axis = Eigen::Vector3f::UnitX() - normal.x() * normal;
      if (y_axis.norm() < 1e-3F) y_axis = Eigen::Vector3f::UnitY() - normal.y() * normal;
    }
  }
  y_axis.normalize();
  Frame f;
  f.R.col(2) = normal;
  f.R.col(1) = y_axis;
  f.R.col(0) = y_axis.cross(normal);
  f.support = static_cast<std::uint16_t>(std::min(count, 65535));
  return f;
}

// Where a patch of s x s cells lives in its flat array: cell (x, y) at
// begin + y * pitch + x, surrounded by empty border cells; cells end before `end`.
// The array has room for blocks of eight from `begin` past `end`, plus their
// neighbours one row down.
struct PatchLayout {
  explicit PatchLayout(int s)
      : pitch(s + 1), begin(s + 2), end(s * (s + 1) + s + 1),
        size(static_cast<std::size_t>(begin + 8 * ((end - begin + 7) / 8) + pitch + 8)) {}
  int pitch;
  int begin;
  int end;
  std::size_t size;
};

// One or two passes of hole filling over the cells of `cur` (the z-buffer), writing
// each pass to the other array (`nxt`, all empty on entry); returns the array that
// holds the result. A hole takes the mean of its filled 3x3 neighbours as they were
// before the pass, summed in row-major order, when it has at least two. Empty
// neighbours add +0, which changes nothing (a sum started at +0 never becomes -0), so
// the sums need no branches. `cells` is -1 at cells and 0 at border positions, which
// are never filled. Every variant does the same operations in each lane, so they
// give the same bits.
#if defined(__SSE2__)
const float* fill_holes_sse2(float* cur, float* nxt, const std::int32_t* cells, const PatchLayout& lay) {
  const int ps = lay.pitch;
  const __m128 empty = _mm_set1_ps(-std::numeric_limits<float>::infinity());
  const __m128 one = _mm_set1_ps(1.0F), two = _mm_set1_ps(2.0F);
  for (int pass = 0; pass < 2; ++pass) {
    int holes = 0, left = 0;
    for (int i = lay.begin; i < lay.end; i += 4) {
      const float* const c = cur + i;
      const __m128 cv = _mm_loadu_ps(c);
      const __m128 hole =
          _mm_and_ps(_mm_cmpeq_ps(cv, empty), _mm_castsi128_ps(_mm_loadu_si128(reinterpret_cast<const __m128i*>(cells + i))));
      if (_mm_movemask_ps(hole) == 0) {  // nothing to fill in these four cells
        _mm_storeu_ps(nxt + i, cv);
        continue;
      }
      holes = 1;
      __m128 sum = _mm_setzero_ps(), n = _mm_setzero_ps();
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const __m128 v = _mm_loadu_ps(c + dy * ps + dx);
          const __m128 ok = _mm_cmpneq_ps(v, empty);
          sum = _mm_add_ps(sum, _mm_and_ps(ok, v));
          n = _mm_add_ps(n, _mm_and_ps(ok, one));
        }
      const __m128 fill = _mm_and_ps(hole, _mm_cmpge_ps(n, two));
      left |= _mm_movemask_ps(_mm_andnot_ps(fill, hole));
      _mm_storeu_ps(nxt + i, _mm_or_ps(_mm_and_ps(fill, _mm_div_ps(sum, n)), _mm_andnot_ps(fill, cv)));
    }
    if (holes == 0) break;  // `nxt` is a copy of `cur`
    std::swap(cur, nxt);
    if (left == 0) break;   // no hole left for a second pass
  }
  return cur;
}

#if defined(LEX3D_DESCRIBE_AVX)
// The same eight cells at a time (no FMA: only adds, compares and a division).
__attribute__((target("avx"))) const float* fill_holes_avx(float* cur, float* nxt, const std::int32_t* cells,
                                                            const PatchLayout& lay) {
  const int ps = lay.pitch;
  const __m256 empty = _mm256_set1_ps(-std::numeric_limits<float>::infinity());
  const __m256 one = _mm256_set1_ps(1.0F), two = _mm256_set1_ps(2.0F);
  for (int pass = 0; pass < 2; ++pass) {
    int holes = 0, left = 0;
    for (int i = lay.begin; i < lay.end; i += 8) {
      const float* const c = cur + i;
      const __m256 cv = _mm256_loadu_ps(c);
      const __m256 hole = _mm256_and_ps(_mm256_cmp_ps(cv, empty, _CMP_EQ_OQ),
                                        _mm256_castsi256_ps(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(cells + i))));
      if (_mm256_movemask_ps(hole) == 0) {
        _mm256_storeu_ps(nxt + i, cv);
        continue;
      }
      holes = 1;
      __m256 sum = _mm256_setzero_ps(), n = _mm256_setzero_ps();
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const __m256 v = _mm256_loadu_ps(c + dy * ps + dx);
          const __m256 ok = _mm256_cmp_ps(v, empty, _CMP_NEQ_UQ);
          sum = _mm256_add_ps(sum, _mm256_and_ps(ok, v));
          n = _mm256_add_ps(n, _mm256_and_ps(ok, one));
        }
      const __m256 fill = _mm256_and_ps(hole, _mm256_cmp_ps(n, two, _CMP_GE_OS));
      left |= _mm256_movemask_ps(_mm256_andnot_ps(fill, hole));
      _mm256_storeu_ps(nxt + i, _mm256_or_ps(_mm256_and_ps(fill, _mm256_div_ps(sum, n)), _mm256_andnot_ps(fill, cv)));
    }
    if (holes == 0) break;
    std::swap(cur, nxt);
    if (left == 0) break;
  }
  return cur;
}
#endif

const float* fill_holes(float* cur, float* nxt, const std::int32_t* cells, const PatchLayout& lay) {
#if defined(LEX3D_DESCRIBE_AVX)
  if (cpu_has_avx()) return fill_holes_avx(cur, nxt, cells, lay);
#endif
  return fill_holes_sse2(cur, nxt, cells, lay);
}
#else
const float* fill_holes(float* cur, float* nxt, const std::int32_t* cells, const PatchLayout& lay) {
  const float kEmpty = -std::numeric_limits<float>::infinity();
  for (int pass = 0; pass < 2; ++pass) {
    bool holes = false, left = false;
    for (int i = lay.begin; i < lay.end; ++i) {
      const float* const c = cur + i;
      nxt[i] = *c;
      if (cells[i] == 0 || *c != kEmpty) continue;
      holes = true;
      float sum = 0.0F;
      float n = 0.0F;
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const float v = c[dy * lay.pitch + dx];
          const bool ok = v != kEmpty;
          sum += ok ? v : 0.0F;
          n += ok ? 1.0F : 0.0F;
        }
      if (n >= 2.0F) nxt[i] = sum / n;
      else left = true;
    }
    if (!holes) break;
    std::swap(cur, nxt);
    if (!left) break;
  }
  return cur;
}
#endif

void patch_descriptor(const RangeImage& img, const Pixel* pix, const Keypoint& kp, const WindowCentre& centre,
                      const Eigen::Matrix3f& R, const DescriptorParams& params, Window& win, float* out) {
  const int s = params.patch_size;
  const float rad = static_cast<float>(params.support_radius);
  const float inv_cell = static_cast<float>(s) / (2.0F * rad);
  const float kEmpty = -std::numeric_limits<float>::infinity();
  // The patch with a border of empty cells, so that hole filling needs no bounds
  // checks. One border column between rows (the right border of a row is the left
  // one of the next) lets hole filling run over the cells as one flat array in
  // blocks, with few lanes wasted on borders.
  const PatchLayout lay(s);
  thread_local std::vector<float> depth;
  depth.assign(lay.size, kEmpty);
  const int ps = lay.pitch;
  float* const d0 = depth.data() + lay.begin;  // cell (0, 0)
  // Rows of R^T; each coordinate sums its products as Eigen's 3x3 product does.
  const float a00 = R(0, 0), a01 = R(1, 0), a02 = R(2, 0);
  const float a10 = R(0, 1), a11 = R(1, 1), a12 = R(2, 1);
  const float a20 = R(0, 2), a21 = R(1, 2), a22 = R(2, 2);
  const float px = kp.point_sensor.x(), py = kp.point_sensor.y(), pz = kp.point_sensor.z();
  WindowBounds bounds;
  if (!cube_bounds(img, centre, kp.point_sensor, R, params.support_radius, bounds)) bounds = WindowBounds{};
  make_window(img, centre, params.support_radius * std::sqrt(3.0), s, win, bounds);
  auto put = [&](float lx, float ly, float lz) {
    const int ix = std::min(s - 1, static_cast<int>((lx + rad) * inv_cell));
    const int iy = std::min(s - 1, static_cast<int>((rad - ly) * inv_cell));
    float& d = d0[iy * ps + ix];
    d = std::max(d, lz);  // z-buffer: the viewpoint sits on +z
  };
  // Points inside the cube of half side rad (NaN, no return, fails).
#if defined(LEX3D_DESCRIBE_AVX)
  if (cpu_has_avx()) {
    const float a[9] = {a00, a01, a02, a10, a11, a12, a20, a21, a22};
    rasterise_avx(pix, img.width, img.height, win, a, kp.point_sensor, rad, inv_cell, s, ps, d0);
  } else
#endif
  for_window(pix, img.width, img.height, win,
#if defined(__SSE2__)
             [&, vpx = _mm_set1_ps(px), vpy = _mm_set1_ps(py), vpz = _mm_set1_ps(pz), vrad = _mm_set1_ps(rad),
              abs_mask = _mm_castsi128_ps(_mm_set1_epi32(0x7FFFFFFF))](__m128 x, __m128 y, __m128 z, int lanes) {
               const __m128 dx = _mm_sub_ps(x, vpx), dy = _mm_sub_ps(y, vpy), dz = _mm_sub_ps(z, vpz);
               const __m128 lx = _mm_add_ps(_mm_mul_ps(_mm_set1_ps(a00), dx),
                                            _mm_add_ps(_mm_mul_ps(_mm_set1_ps(a01), dy), _mm_mul_ps(_mm_set1_ps(a02), dz)));
               const __m128 ly = _mm_add_ps(_mm_mul_ps(_mm_set1_ps(a10), dx),
                                            _mm_add_ps(_mm_mul_ps(_mm_set1_ps(a11), dy), _mm_mul_ps(_mm_set1_ps(a12), dz)));
               const __m128 lz = _mm_add_ps(_mm_mul_ps(_mm_set1_ps(a20), dx),
                                            _mm_add_ps(_mm_mul_ps(_mm_set1_ps(a21), dy), _mm_mul_ps(_mm_set1_ps(a22), dz)));
               const __m128 in = _mm_and_ps(_mm_and_ps(_mm_cmplt_ps(_mm_and_ps(lx, abs_mask), vrad),
                                                       _mm_cmplt_ps(_mm_and_ps(ly, abs_mask), vrad)),
                                            _mm_cmplt_ps(_mm_and_ps(lz, abs_mask), vrad));
               for_lanes(_mm_movemask_ps(in) & lanes, lx, ly, lz, put);
             },
#endif
             [&](const Pixel& q) {
               const float dx = q.x() - px, dy = q.y() - py, dz = q.z() - pz;
               const float lx = a00 * dx + (a01 * dy + a02 * dz);
               const float ly = a10 * dx + (a11 * dy + a12 * dz);
               const float lz = a20 * dx + (a21 * dy + a22 * dz);
               if (std::abs(lx) < rad && std::abs(ly) < rad && std::abs(lz) < rad) put(lx, ly, lz);
             });
  // Interpolate small holes from filled neighbours (two passes); what stays empty
  // is "nothing seen within the support" and gets the far value -radius.
  thread_local std::vector<float> next;
  thread_local std::vector<std::int32_t> cells;
  thread_local int cells_for = -1;
  if (cells_for != s) {
    cells.assign(lay.size, 0);
    for (int y = 0; y < s; ++y)
      for (int x = 0; x < s; ++x) cells[static_cast<std::size_t>(lay.begin + y * ps + x)] = -1;
    cells_for = s;
  }
  next.assign(lay.size, kEmpty);
  const float* const filled = fill_holes(depth.data(), next.data(), cells.data(), lay);
  const float* const f0 = filled + lay.begin;
  for (int y = 0; y < s; ++y) {
    int x = 0;
#if defined(__SSE2__)
    // max(q, -1) and min(., 1) pick as std::clamp does for every finite q.
    for (; x + 4 <= s; x += 4) {
      const __m128 v = _mm_loadu_ps(f0 + y * ps + x);
      const __m128 q = _mm_min_ps(_mm_max_ps(_mm_div_ps(v, _mm_set1_ps(rad)), _mm_set1_ps(-1.0F)), _mm_set1_ps(1.0F));
      const __m128 is_empty = _mm_cmpeq_ps(v, _mm_set1_ps(kEmpty));
      _mm_storeu_ps(out + y * s + x,
                    _mm_or_ps(_mm_and_ps(is_empty, _mm_set1_ps(-1.0F)), _mm_andnot_ps(is_empty, q)));
    }
#endif
    for (; x < s; ++x) {
      const float v = f0[y * ps + x];
      out[y * s + x] = v == kEmpty ? -1.0F : std::clamp(v / rad, -1.0F, 1.0F);
    }
  }
}

}  // namespace

Features describe(const RangeImage& img, const std::vector<Keypoint>& keypoints, const DescriptorParams& params,
                  int threads) {
  params.validate();
  Features out;
  out.descriptor_dim = params.patch_size * params.patch_size;
  // The two largest arrays of a scan's model, all fresh memory.
  detail::reserve_on_huge_pages(out.features, keypoints.size());
  out.features.resize(keypoints.size());
  const std::size_t values = keypoints.size() * static_cast<std::size_t>(out.descriptor_dim);
  detail::reserve_on_huge_pages(out.descriptors, values);
  out.descriptors.assign(values, 0.0F);
  for (const auto& kp : keypoints) (kp.kind == FeatureKind::kInterest ? out.interest_count : out.coverage_count)++;
  if (keypoints.empty() || img.empty()) return out;
  const Eigen::Isometry3f T_cloud_sensor = img.T_cloud_sensor.cast<float>();
  const Eigen::Vector3f up_sensor =
      (T_cloud_sensor.linear().transpose() * params.up.cast<float>()).normalized();

  const Pixel* const pix = img.point.data();  // NaN unless kValid (make_range_image)
  // Features are independent: describe them in image order, so that consecutive
  // windows overlap in the cache, and store each at its own index.
  const std::size_t m = keypoints.size();
  std::vector<std::pair<std::int64_t, std::uint32_t>> order(m);
  for (std::size_t i = 0; i < m; ++i) {
    const std::int64_t row = static_cast<std::int64_t>(std::floor(keypoints[i].y));
    const std::int64_t col = static_cast<std::int64_t>(std::floor(keypoints[i].x));
    order[i] = {row * (static_cast<std::int64_t>(img.width) + 1) + col, static_cast<std::uint32_t>(i)};
  }
  std::sort(order.begin(), order.end());
  parallel_for(m, threads, [&](std::size_t o) {
    const std::size_t i = order[o].second;
    const Keypoint& kp = keypoints[i];
    Window win;
    const WindowCentre centre = window_centre(img, kp);
    const Frame f = feature_frame(img, pix, kp, centre, params, up_sensor, win);
    Eigen::Isometry3f T_sensor_feature = Eigen::Isometry3f::Identity();
    T_sensor_feature.linear() = f.R;
    T_sensor_feature.translation() = kp.point_sensor;
    Feature& feat = out.features[i];
    feat.keypoint = kp;
    feat.normal_support = f.support;
    feat.T_cloud_feature = img.T_cloud_sensor * T_sensor_feature.cast<double>();
    patch_descriptor(img, pix, kp, centre, f.R, params, win,
                     out.descriptors.data() + i * static_cast<std::size_t>(out.descriptor_dim));
  });
  return out;
}

}  // namespace lex3d
