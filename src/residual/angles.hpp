#pragma once
// Angles wrapped to [-π, π] as IEEE remainder(a, 2π) gives them, without the library call
// where it is not needed: shared by the spherical and sensor-geometry codings.

#include <cmath>

namespace lex3d::residual::detail {

/// IEEE remainder(a, 2π) (formats/model.md §2.5.3), exactly, without the library call
/// for |a| < 9: there the quotient rounds to 0 (|a| <= π) or to ±1, and a ∓ 2π is exact
/// (Sterbenz: a is within a factor of two of 2π), so the result is the same double (a
/// zero keeping a's sign, as remainder's does). 7 % of a KITTI layer's encoding.
inline double wrap_angle(double a) {
  constexpr double kPi = 3.14159265358979323846;
  constexpr double kTwoPi = 2.0 * kPi;
  const double m = std::abs(a);
  if (m <= kPi) return a;
  if (m < 9.0) {
    const double r = a > 0.0 ? a - kTwoPi : a + kTwoPi;
    return r == 0.0 ? std::copysign(0.0, a) : r;
  }
  return std::remainder(a, kTwoPi);
}

}  // namespace lex3d::residual::detail
