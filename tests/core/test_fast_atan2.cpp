// core/fast_atan2.hpp: the encoder's arc tangent against the library's.

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <random>

#include "core/fast_atan2.hpp"

namespace lex3d {
namespace {

/// How many doubles lie between a and b (both finite, the same sign or zero).
std::int64_t ulps_apart(double a, double b) {
  std::int64_t ia = 0, ib = 0;
  std::memcpy(&ia, &a, sizeof a);
  std::memcpy(&ib, &b, sizeof b);
  if (ia < 0) ia = std::numeric_limits<std::int64_t>::min() - ia;
  if (ib < 0) ib = std::numeric_limits<std::int64_t>::min() - ib;
  return ia > ib ? ia - ib : ib - ia;
}

TEST(FastAtan2, WithinFourUnitsInTheLastPlaceOfTheLibrary) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> coord(-100.0, 100.0);
  std::uniform_real_distribution<double> exponent(-30.0, 30.0);
  std::int64_t worst = 0;
  for (int k = 0; k < 2000000; ++k) {
    double x = coord(rng), y = coord(rng);
    if (k % 4 == 1) y *= std::exp2(exponent(rng));  // far from the axes and close to them
    if (k % 4 == 2) x *= std::exp2(exponent(rng));
    const double want = std::atan2(y, x), got = detail::fast_atan2(y, x);
    ASSERT_EQ(std::signbit(want), std::signbit(got)) << x << ' ' << y;
    worst = std::max(worst, ulps_apart(want, got));
  }
  EXPECT_LE(worst, 4);
  // Directions next to the octants' edges and the table's knots (t = k / 8 ± a little).
  for (int k = 0; k <= 8; ++k)
    for (const double d : {-1e-12, -1e-17, 0.0, 1e-17, 1e-12, 0.0624, 0.0626})
      for (const double sx : {1.0, -1.0})
        for (const double sy : {1.0, -1.0}) {
          const double t = static_cast<double>(k) / 8.0 + d;
          if (t < 0.0) continue;
          EXPECT_LE(ulps_apart(std::atan2(sy * t, sx), detail::fast_atan2(sy * t, sx)), 4) << t;
          EXPECT_LE(ulps_apart(std::atan2(sx, sy * t), detail::fast_atan2(sx, sy * t)), 4) << t;
        }
}

TEST(FastAtan2, ZerosInfinitiesAndNaNAsTheLibraryGivesThem) {
  const double inf = std::numeric_limits<double>::infinity(), nan = std::numeric_limits<double>::quiet_NaN();
  for (const double y : {0.0, -0.0, 1.0, -1.0, inf, -inf})
    for (const double x : {0.0, -0.0, 2.0, -2.0, inf, -inf}) {
      const double want = std::atan2(y, x), got = detail::fast_atan2(y, x);
      EXPECT_EQ(std::signbit(want), std::signbit(got)) << y << ' ' << x;
      EXPECT_LE(ulps_apart(want, got), 1) << y << ' ' << x;
    }
  EXPECT_TRUE(std::isnan(detail::fast_atan2(nan, 1.0)));
  EXPECT_TRUE(std::isnan(detail::fast_atan2(1.0, nan)));
}

}  // namespace
}  // namespace lex3d
