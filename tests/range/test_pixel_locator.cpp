#include <cmath>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "lex3d/range/pixel_locator.hpp"
#include "lex3d/range/range_image.hpp"
#include "support/test_support.hpp"

using namespace lex3d;

namespace {

constexpr double kDeg = M_PI / 180.0;

struct Tally {
  std::size_t points = 0;
  std::size_t fast = 0;
  std::size_t mismatches = 0;
};

// Compares PixelLocator with floor() of RangeImage::project on one point, both paths.
void compare(const RangeImage& img, const PixelLocator& loc, const Eigen::Vector3f& p, Tally& t) {
  float fx = 0, fy = 0, fr = 0;
  const bool ok = img.project(p, fx, fy, fr);
  // Points inside the image count towards the share the tables decide.
  const bool inside = ok && fx >= 0.0F && fx < static_cast<float>(img.width) && fy >= 0.0F &&
                      fy < static_cast<float>(img.height);
  t.points += inside ? 1 : 0;
  int x = -7, y = -7;
  float r = -1;
  const bool got = loc.locate(p, x, y, r);
  int xf = -7, yf = -7;
  float rf = -1;
  const PixelLocator::Result fast = loc.locate_fast(p, xf, yf, rf);
  if (inside && fast == PixelLocator::Result::kFound) ++t.fast;
  bool same = got == ok;
  if (ok && got) same = x == static_cast<int>(std::floor(fx)) && y == static_cast<int>(std::floor(fy)) && r == fr;
  if (fast == PixelLocator::Result::kFound)
    same = same && ok && xf == static_cast<int>(std::floor(fx)) && yf == static_cast<int>(std::floor(fy));
  if (fast == PixelLocator::Result::kNoPixel) same = same && !ok;
  if (!same) {
    if (t.mismatches < 5)
      ADD_FAILURE() << "point (" << p.x() << ", " << p.y() << ", " << p.z() << "): project " << fx << ", " << fy
                    << " locate " << x << ", " << y << " fast " << static_cast<int>(fast) << " " << xf << ", " << yf;
    ++t.mismatches;
  }
}

// Every point of the cloud moved by a random rigid motion (as a scan seen from another pose),
// random directions at random ranges, and points on and next to every pixel border.
Tally check_image(const RangeImage& img, const Cloud& cloud, unsigned seed) {
  const PixelLocator loc(img);
  EXPECT_TRUE(loc.fast());
  Tally t;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-1.0F, 1.0F);
  const Eigen::Matrix3f R =
      Eigen::AngleAxisf(0.3F * u(rng), Eigen::Vector3f(u(rng), u(rng), 1.0F).normalized()).toRotationMatrix();
  const Eigen::Vector3f tr(2.0F * u(rng), 2.0F * u(rng), 0.3F * u(rng));
  for (const auto& p : cloud.points) {
    compare(img, loc, p, t);
    compare(img, loc, R * p + tr, t);
  }
  std::normal_distribution<float> n(0.0F, 1.0F);
  for (int i = 0; i < 200000; ++i) {
    const Eigen::Vector3f d = Eigen::Vector3f(n(rng), n(rng), n(rng)).normalized();
    compare(img, loc, d * (0.1F + 80.0F * (u(rng) + 1.0F)), t);
  }
  // Points on the borders are decided by project; they count as mismatches only.
  const std::size_t away_points = t.points, away_fast = t.fast;
  std::uniform_real_distribution<double> frac(0.0, 1.0);
  std::uniform_int_distribution<int> col(0, img.width), row(0, img.height);
  for (int i = 0; i < 20000; ++i) {
    const int x = col(rng), y = row(rng);
    const float range = 1.0F + 40.0F * static_cast<float>(frac(rng));
    const Eigen::Vector3f on_col = img.ray(x, y + frac(rng)) * range;
    const Eigen::Vector3f on_row = img.ray(x + frac(rng), y) * range;
    const Eigen::Vector3f corner = img.ray(x, y) * range;
    for (const Eigen::Vector3f& p : {on_col, on_row, corner}) {
      compare(img, loc, p, t);
      for (int k = 0; k < 3; ++k) {
        Eigen::Vector3f q = p;
        q[k] = std::nextafter(q[k], q[k] + 1.0F);
        compare(img, loc, q, t);
      }
    }
  }
  t.points = away_points;
  t.fast = away_fast;
  return t;
}

Cloud sector(const Cloud& c, double az_lo, double az_hi) {
  Cloud out;
  for (const auto& p : c.points) {
    const double a = std::atan2(p.y(), p.x());
    if (a >= az_lo && a <= az_hi) out.points.push_back(p);
  }
  return out;
}

void check_scan(const Cloud& cloud, const std::string& name) {
  std::vector<RangeImageParams> settings(4);
  settings[1].azimuth_resolution_rad = 1.0 * kDeg;  // coarse images like a place database's
  settings[1].elevation_resolution_rad = 2.0 * kDeg;
  settings[2].azimuth_resolution_rad = 2.0 * kDeg;
  settings[2].elevation_resolution_rad = 4.0 * kDeg;
  settings[3].pixel_scale = 0.5;
  unsigned seed = 1;
  for (const auto& params : settings) {
    const RangeImage img = make_range_image(cloud, params);
    ASSERT_FALSE(img.empty()) << name;
    const Tally t = check_image(img, cloud, seed++);
    EXPECT_EQ(t.mismatches, 0U) << name << " " << img.width << "x" << img.height;
    // The tables decide nearly every point of the image away from the borders.
    EXPECT_GT(static_cast<double>(t.fast), 0.8 * static_cast<double>(t.points)) << name;
  }
  // A partial image (a 200° sector): columns do not wrap.
  const Cloud part = sector(cloud, -1.2, 2.3);
  const RangeImage img = make_range_image(part, settings[1]);
  ASSERT_FALSE(img.full_circle) << name;
  const Tally t = check_image(img, cloud, seed);
  EXPECT_EQ(t.mismatches, 0U) << name << " partial";
  EXPECT_GT(t.fast, t.points / 4) << name << " partial";
}

}  // namespace

TEST(PixelLocator, SameAsProjectOnSampleScans) {
  for (const std::string name : {"kitti00_000000.bin", "newer_college_00.bin"}) {
    SCOPED_TRACE(name);
    check_scan(test::load_or_fail(test::sample(name)), name);
  }
}

TEST(PixelLocator, SameAsProjectOnBalm) {
  LEX3D_REQUIRE_SHARED("balm/000000.bin");
  for (const std::string name : {"balm/000000.bin", "balm/000100.bin"}) {
    SCOPED_TRACE(name);
    check_scan(test::load_or_fail(test::shared_data(name)), name);
  }
}

TEST(PixelLocator, NoPixelWhereProjectHasNone) {
  const Cloud c = test::load_or_fail(test::sample("kitti00_000000.bin"));
  const RangeImage img = make_range_image(c);
  const PixelLocator loc(img);
  int x = 0, y = 0;
  float r = 0;
  EXPECT_FALSE(loc.locate(Eigen::Vector3f::Zero(), x, y, r));
  const float nan = std::numeric_limits<float>::quiet_NaN();
  EXPECT_FALSE(loc.locate(Eigen::Vector3f(nan, 1.0F, 0.0F), x, y, r));
  // Straight up and straight down: no azimuth, decided by project.
  float fx = 0, fy = 0, fr = 0;
  for (const float z : {5.0F, -5.0F}) {
    ASSERT_TRUE(img.project(Eigen::Vector3f(0, 0, z), fx, fy, fr));
    ASSERT_TRUE(loc.locate(Eigen::Vector3f(0, 0, z), x, y, r));
    EXPECT_EQ(x, static_cast<int>(std::floor(fx)));
    EXPECT_EQ(y, static_cast<int>(std::floor(fy)));
  }
}

TEST(PixelLocator, EmptyImageUsesProject) {
  const RangeImage img;
  const PixelLocator loc(img);
  EXPECT_FALSE(loc.fast());
  int x = 0, y = 0;
  float r = 0;
  EXPECT_TRUE(loc.locate(Eigen::Vector3f(1, 2, 3), x, y, r));
  EXPECT_FLOAT_EQ(r, std::sqrt(14.0F));
}
