// core/layout.hpp: the order a spinning lidar's points keep in a file that does not say it.

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "lex3d/core/layout.hpp"

namespace lex3d {
namespace {

/// `lasers` beams with elevations in a scrambled order (as a HDL-32E fires them), `columns`
/// firings a turn over walls 5-30 m away; every `hole`-th return is a (0, 0, 0) placeholder.
std::vector<Eigen::Vector3f> scan(std::uint32_t lasers, std::uint32_t columns, bool firing_major, int hole = 7) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> range(5.0, 30.0);
  std::vector<double> elevation(lasers);
  for (std::uint32_t l = 0; l < lasers; ++l)
    elevation[l] = (-25.0 + 30.0 * ((l * 7) % lasers) / lasers) * M_PI / 180.0;
  std::vector<Eigen::Vector3f> p(static_cast<std::size_t>(lasers) * columns, Eigen::Vector3f::Zero());  // Eigen leaves a vector uninitialised
  for (std::uint32_t c = 0; c < columns; ++c)
    for (std::uint32_t l = 0; l < lasers; ++l) {
      const double az = -2.0 * M_PI * c / columns;
      const double r = range(rng);
      const std::size_t i = firing_major ? static_cast<std::size_t>(c) * lasers + l : static_cast<std::size_t>(l) * columns + c;
      if (static_cast<int>(i % static_cast<std::size_t>(hole)) == 0) continue;  // a no-return placeholder
      p[i] = Eigen::Vector3f(static_cast<float>(r * std::cos(elevation[l]) * std::cos(az)),
                             static_cast<float>(r * std::cos(elevation[l]) * std::sin(az)),
                             static_cast<float>(r * std::sin(elevation[l])));
    }
  return p;
}

TEST(OrderLayout, FiringByFiringGivesLasersSortedByElevation) {
  const auto p = scan(32, 1800, true);
  const auto layout = detect_order_layout(p);
  ASSERT_TRUE(layout.has_value());
  EXPECT_TRUE(layout->firing_major);
  EXPECT_EQ(layout->lasers, 32U);
  EXPECT_EQ(layout->columns, 1800U);
  // laser 0 is the top beam: position 29 in a firing fires the highest ((29 * 7) % 32 = 11 of 32 ... the largest)
  double top = -10;
  std::uint32_t top_position = 0;
  for (std::uint32_t k = 0; k < 32; ++k) {
    const double e = -25.0 + 30.0 * ((k * 7) % 32) / 32.0;
    if (e > top) {
      top = e;
      top_position = k;
    }
  }
  EXPECT_EQ(layout->ring(top_position), 0U);
  EXPECT_EQ(layout->column(32 * 5 + 3), 5U);
}

TEST(OrderLayout, RowByRow) {
  const auto p = scan(16, 1024, false);
  const auto layout = detect_order_layout(p);
  ASSERT_TRUE(layout.has_value());
  EXPECT_FALSE(layout->firing_major);
  EXPECT_EQ(layout->lasers, 16U);
  EXPECT_EQ(layout->columns, 1024U);
  EXPECT_EQ(layout->column(1024 * 3 + 17), 17U);
}

TEST(OrderLayout, ACloudThatDroppedItsNoReturnsHasNoLayoutWhateverItsCount) {
  // Ten lasers firing by firing, one return in 200 dropped (not kept as a placeholder), and
  // the cloud cut to a multiple of ten points: points a firing apart still agree in 19 of 20
  // pairs, but after the first drop-out position i % 10 is no longer laser i % 10.
  const auto full = scan(10, 1800, true, 1 << 30);
  std::vector<Eigen::Vector3f> p;
  for (std::size_t i = 0; i < full.size(); ++i)
    if (i % 200 != 77) p.push_back(full[i]);
  p.resize(p.size() - p.size() % 10);
  ASSERT_EQ(p.size() % 10, 0U);
  EXPECT_FALSE(detect_order_layout(p).has_value());
  // the same cloud with its placeholders keeps its layout
  EXPECT_TRUE(detect_order_layout(full).has_value());
}

TEST(OrderLayout, NoOrderNoLayout) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(-20.0F, 20.0F);
  std::vector<Eigen::Vector3f> p(32 * 1000);
  for (auto& q : p) q = Eigen::Vector3f(u(rng), u(rng), 0.2F * u(rng));
  EXPECT_FALSE(detect_order_layout(p).has_value());
  EXPECT_FALSE(detect_order_layout({}).has_value());
  EXPECT_FALSE(detect_order_layout(std::vector<Eigen::Vector3f>(5000, Eigen::Vector3f::Zero())).has_value());
}

}  // namespace
}  // namespace lex3d
