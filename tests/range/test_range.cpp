#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "lex3d/range/range_image.hpp"
#include "support/test_support.hpp"

using namespace lex3d;

namespace {

constexpr double kDeg = M_PI / 180.0;

// A synthetic spinning lidar inside a box room: beams on a regular grid of
// az_step x el_step, ranges to the walls of a 20 x 14 x 6 m box.
Cloud synthetic_scan(double az_step_deg, double el_step_deg, double el_lo_deg, double el_hi_deg,
                     double jitter_deg = 0.0, unsigned seed = 1) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> jit(-jitter_deg, jitter_deg);
  Cloud c;
  for (double el = el_lo_deg; el <= el_hi_deg + 1e-9; el += el_step_deg)
    for (double az = -180.0 + 0.5 * az_step_deg; az < 180.0 - 1e-9; az += az_step_deg) {
      const double a = (az + jit(rng)) * kDeg, e = el * kDeg;
      const Eigen::Vector3d d(std::cos(e) * std::cos(a), std::cos(e) * std::sin(a), std::sin(e));
      // Distance to the box walls x=±10, y=±7, z=-1.5/+4.5.
      double t = 1e9;
      for (int k = 0; k < 3; ++k) {
        const double lo[3] = {-10, -7, -1.5}, hi[3] = {10, 7, 4.5};
        if (d(k) > 1e-9) t = std::min(t, hi[k] / d(k));
        if (d(k) < -1e-9) t = std::min(t, lo[k] / d(k));
      }
      c.points.push_back((d * t).cast<float>());
    }
  return c;
}

}  // namespace

TEST(AngularResolution, RecoversSyntheticGrid) {
  const Cloud c = synthetic_scan(0.2, 1.0, -15.0, 15.0);
  const auto r = estimate_angular_resolution(c);
  ASSERT_TRUE(r.has_value());
  EXPECT_NEAR(r->azimuth_rad / kDeg, 0.2, 0.01);
  EXPECT_NEAR(r->elevation_rad / kDeg, 1.0, 0.05);
}

TEST(AngularResolution, RecoversAnisotropicGridWithJitter) {
  // VLP-16-like: 2° between beams, 0.1° between firings (20:1), with firing jitter.
  const Cloud c = synthetic_scan(0.1, 2.0, -15.0, 15.0, 0.01);
  const auto r = estimate_angular_resolution(c);
  ASSERT_TRUE(r.has_value());
  EXPECT_NEAR(r->azimuth_rad / kDeg, 0.1, 0.02);
  EXPECT_NEAR(r->elevation_rad / kDeg, 2.0, 0.1);
}

TEST(AngularResolution, TooFewPointsGivesNothing) {
  Cloud c;
  EXPECT_FALSE(estimate_angular_resolution(c).has_value());
  c.points.emplace_back(1.0F, 0.0F, 0.0F);
  EXPECT_FALSE(estimate_angular_resolution(c).has_value());
}

TEST(AngularResolution, KittiHdl64) {
  const Cloud c = test::load_or_fail(test::sample("kitti00_000000.bin"));
  const auto r = estimate_angular_resolution(c);
  ASSERT_TRUE(r.has_value());
  // HDL-64E at 10 Hz: ~0.17° between firings, 26.9° over 64 beams (~0.4°).
  EXPECT_NEAR(r->azimuth_rad / kDeg, 0.17, 0.03);
  EXPECT_GT(r->elevation_rad / kDeg, 0.3);
  EXPECT_LT(r->elevation_rad / kDeg, 0.5);
}

TEST(AngularResolution, BalmOuster64) {
  LEX3D_REQUIRE_SHARED("balm/000000.bin");
  const Cloud c = test::load_or_fail(test::shared_data("balm/000000.bin"));
  const auto r = estimate_angular_resolution(c);
  ASSERT_TRUE(r.has_value());
  // 64 beams over about 90° of elevation.
  EXPECT_GT(r->elevation_rad / kDeg, 1.1);
  EXPECT_LT(r->elevation_rad / kDeg, 1.6);
  EXPECT_LT(r->azimuth_rad / kDeg, 0.4);
}

TEST(RangeImage, DegenerateCloudsGetABoundedImage) {
  // Random floats (random bytes read as points) and a cloud inside a millimetre: the measured
  // spacing is tiny, the image must still be sized by the number of points.
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> wide(-1e4F, 1e4F), mm(0.0F, 1e-3F);
  Cloud random_cloud, tiny;
  for (int i = 0; i < 20000; ++i) {
    random_cloud.points.emplace_back(wide(rng), wide(rng), wide(rng) * 1e-3F);
    tiny.points.emplace_back(10.0F + mm(rng), mm(rng), mm(rng));
  }
  for (const Cloud* c : {&random_cloud, &tiny}) {
    const RangeImage img = make_range_image(*c);
    const double pixels = static_cast<double>(img.width) * img.height;
    EXPECT_LE(pixels, std::max(16.0 * static_cast<double>(c->size()), 262144.0) * 1.05);
    EXPECT_GT(img.valid_count, 0U);
  }
}

TEST(RangeImage, EmptyCloudGivesEmptyImage) {
  const RangeImage img = make_range_image(Cloud{});
  EXPECT_TRUE(img.empty());
  EXPECT_EQ(img.valid_count, 0U);
}

TEST(RangeImage, SinglePoint) {
  Cloud c;
  c.points.emplace_back(3.0F, 4.0F, 1.0F);
  const RangeImage img = make_range_image(c);
  ASSERT_FALSE(img.empty());
  EXPECT_EQ(img.valid_count, 1U);
  float x = 0, y = 0, r = 0;
  ASSERT_TRUE(img.project(c.points[0], x, y, r));
  const int px = static_cast<int>(x), py = static_cast<int>(y);
  ASSERT_TRUE(img.valid(px, py));
  EXPECT_EQ(img.source[img.index(px, py)], 0);
  EXPECT_NEAR(r, std::sqrt(26.0F), 1e-5);
}

TEST(RangeImage, NaNPointsAreSkippedAndCounted) {
  Cloud c = synthetic_scan(1.0, 2.0, -10.0, 10.0);
  const std::size_t n = c.size();
  c.points.emplace_back(std::nanf(""), 1.0F, 1.0F);
  c.points.emplace_back(1.0F, INFINITY, 1.0F);
  const RangeImage img = make_range_image(c);
  EXPECT_EQ(img.points_non_finite, 2U);
  EXPECT_EQ(img.valid_count + img.points_hidden, n);
}

TEST(RangeImage, KeepsTheClosestReturnOfAPixel) {
  Cloud c = synthetic_scan(1.0, 2.0, -10.0, 10.0);
  const Eigen::Vector3f far = c.points[5];
  c.points.push_back(far * 0.5F);  // same direction, half the range
  RangeImageParams p;
  p.azimuth_resolution_rad = 1.0 * kDeg;
  p.elevation_resolution_rad = 2.0 * kDeg;
  const RangeImage img = make_range_image(c, p);
  float x = 0, y = 0, r = 0;
  ASSERT_TRUE(img.project(far, x, y, r));
  const std::size_t k = img.index(static_cast<int>(x), static_cast<int>(y));
  EXPECT_EQ(img.source[k], static_cast<std::int32_t>(c.size() - 1));
  EXPECT_NEAR(img.range[k], 0.5F * far.norm(), 1e-4);
  EXPECT_EQ(img.points_hidden, 1U);
}

TEST(RangeImage, EveryValidPixelHoldsAPointThatProjectsIntoIt) {
  const Cloud c = test::load_or_fail(test::sample("kitti00_000000.bin"));
  const RangeImage img = make_range_image(c);
  ASSERT_GT(img.valid_count, c.size() / 2);
  EXPECT_EQ(img.valid_count + img.points_hidden + img.points_too_close, c.size());
  EXPECT_TRUE(img.full_circle);
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) {
      if (!img.valid(x, y)) continue;
      const std::size_t k = img.index(x, y);
      float u = 0, v = 0, r = 0;
      ASSERT_TRUE(img.project(img.point[k], u, v, r));
      // Float trigonometry puts a point at most a hair across a pixel border.
      EXPECT_NEAR(u, static_cast<float>(x) + 0.5F, 0.5F + 1e-3F);
      EXPECT_NEAR(v, static_cast<float>(y) + 0.5F, 0.5F + 1e-3F);
      EXPECT_EQ(img.point[k], c.points[static_cast<std::size_t>(img.source[k])]);
    }
}

TEST(RangeImage, MaxRangeAndNoReturnPixels) {
  Cloud c = synthetic_scan(1.0, 2.0, -10.0, 10.0);
  c.no_return_directions.emplace_back(0.0F, 0.0F, 1.0F);  // straight up: outside every return's pixel
  RangeImageParams p;
  p.max_range = 9.0;  // the box walls beyond 9 m become max-range pixels
  const RangeImage img = make_range_image(c, p);
  std::size_t max_range = 0;
  for (const auto s : img.state) max_range += s == PixelState::kMaxRange ? 1 : 0;
  EXPECT_GT(max_range, 10U);
  for (std::size_t k = 0; k < img.state.size(); ++k)
    if (img.state[k] == PixelState::kValid) EXPECT_LT(img.range[k], 9.0F);
  // The zenith beam stretched the image to the top.
  EXPECT_GT(img.row_edges.front(), 80.0 * kDeg);
}

TEST(RangeImage, SensorPoseIsHonoured) {
  const Cloud c = test::load_or_fail(test::sample("kitti00_000000.bin"));
  Pose T = Pose::Identity();
  T.linear() = (Eigen::AngleAxisd(0.7, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(0.2, Eigen::Vector3d::UnitX()))
                   .toRotationMatrix();
  T.translation() = Eigen::Vector3d(12.0, -3.0, 1.5);
  const Cloud moved = transformed(c, T);
  RangeImageParams p;
  p.azimuth_resolution_rad = 0.17 * kDeg;
  p.elevation_resolution_rad = 0.4 * kDeg;
  const RangeImage a = make_range_image(c, p);
  const RangeImage b = make_range_image(moved, p);
  ASSERT_EQ(a.width, b.width);
  ASSERT_EQ(a.height, b.height);
  std::size_t same = 0;
  for (std::size_t k = 0; k < a.state.size(); ++k)
    if (a.state[k] == PixelState::kValid && b.state[k] == PixelState::kValid && a.source[k] == b.source[k]) ++same;
  // Round-off moves a few points across pixel borders, nothing more.
  EXPECT_GT(static_cast<double>(same), 0.995 * static_cast<double>(a.valid_count));
}

TEST(RangeImage, RejectsBadParameters) {
  RangeImageParams p;
  p.azimuth_resolution_rad = -1.0;
  EXPECT_THROW(p.validate(), std::invalid_argument);
  p = {};
  p.pixel_scale = 0.1;
  EXPECT_THROW(p.validate(), std::invalid_argument);
  p = {};
  p.max_range = 0.01;
  EXPECT_THROW(make_range_image(Cloud{}, p), std::invalid_argument);
  AngularResolutionParams a;
  a.max_samples = 3;
  EXPECT_THROW(a.validate(), std::invalid_argument);
}
