#pragma once
// atan2 for the encoder's passes over every point of a scan (laser estimation, order-layout
// test): std::atan2 took 7 % of a KITTI encoding's instructions there.

#include <array>
#include <cmath>

namespace lex3d::detail {

/// atan(k / 8) for k = 0..8, from the library once.
inline const std::array<double, 9>& atan_eighths() {
  static const std::array<double, 9> knots = [] {
    std::array<double, 9> a{};
    for (int k = 0; k <= 8; ++k) a[static_cast<std::size_t>(k)] = std::atan(static_cast<double>(k) / 8.0);
    return a;
  }();
  return knots;
}

/// atan2(y, x), the same signs and special cases as std::atan2 and within a few units in
/// the last place of it, in about a third of its instructions: the octant brings t = |y/x|
/// (or |x/y|) into [0, 1]; with c the nearest multiple of 1/8, atan t = atan c + atan u,
/// u = (t - c) / (1 + t c), |u| <= 1/16, and atan u is its series to u^13 (the first term
/// left out, u^15 / 15, is below 6e-20). Zeros, infinities and NaN go to std::atan2.
inline double fast_atan2(double y, double x) {
  constexpr double kPi = 3.14159265358979323846;
  constexpr double kHalfPi = kPi / 2.0;
  const double ax = std::abs(x), ay = std::abs(y);
  if (!(ax < INFINITY && ay < INFINITY) || (ax == 0.0 && ay == 0.0)) return std::atan2(y, x);
  const bool steep = ay > ax;
  const double t = steep ? ax / ay : ay / ax;
  const int k = static_cast<int>(t * 8.0 + 0.5);
  const double c = static_cast<double>(k) / 8.0;
  const double u = (t - c) / (1.0 + t * c);
  const double u2 = u * u;
  const double series =
      u * (1.0 + u2 * (-1.0 / 3.0 + u2 * (1.0 / 5.0 + u2 * (-1.0 / 7.0 + u2 * (1.0 / 9.0 + u2 * (-1.0 / 11.0 + u2 / 13.0))))));
  double a = atan_eighths()[static_cast<std::size_t>(k)] + series;
  if (steep) a = kHalfPi - a;
  if (std::signbit(x)) a = kPi - a;
  return std::signbit(y) ? -a : a;
}

}  // namespace lex3d::detail
