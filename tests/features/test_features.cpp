#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "lex3d/features/features.hpp"
#include "support/test_support.hpp"

using namespace lex3d;

namespace {

constexpr double kDeg = M_PI / 180.0;

// A synthetic lidar (0.2° x 0.5° beams, ±15°) looking at a wall 8 m away along +x,
// optionally with a 1 m cube standing 5 m in front of the sensor.
Cloud wall_scene(bool with_cube) {
  Cloud c;
  for (double el = -15.0; el <= 15.0; el += 0.5)
    for (double az = -60.0; az <= 60.0; az += 0.2) {
      const double a = az * kDeg, e = el * kDeg;
      const Eigen::Vector3d d(std::cos(e) * std::cos(a), std::cos(e) * std::sin(a), std::sin(e));
      double t = 8.0 / d.x();  // the wall x = 8
      if (with_cube) {
        // Slab intersection with the box [5,6] x [-0.5,0.5] x [-0.5,0.5].
        double t0 = 0, t1 = 1e9;
        const double lo[3] = {5, -0.5, -0.5}, hi[3] = {6, 0.5, 0.5};
        bool hit = true;
        for (int k = 0; k < 3 && hit; ++k) {
          if (std::abs(d(k)) < 1e-12) {
            hit = lo[k] <= 0 && 0 <= hi[k];
            continue;
          }
          double ta = lo[k] / d(k), tb = hi[k] / d(k);
          if (ta > tb) std::swap(ta, tb);
          t0 = std::max(t0, ta);
          t1 = std::min(t1, tb);
          hit = t0 <= t1;
        }
        if (hit) t = std::min(t, t0);
      }
      c.points.push_back((d * t).cast<float>());
    }
  return c;
}

FeatureParams default_params() {
  FeatureParams p;
  p.threads = 2;
  return p;
}

}  // namespace

TEST(Interest, EmptyCloudHasNoFeatures) {
  const FeatureResult r = extract_features(Cloud{}, default_params());
  EXPECT_TRUE(r.image.empty());
  EXPECT_EQ(r.features.size(), 0U);
}

TEST(Interest, SinglePointGetsOneCoverageFeature) {
  Cloud c;
  c.points.emplace_back(4.0F, 1.0F, 0.5F);
  const FeatureResult r = extract_features(c, default_params());
  EXPECT_EQ(r.features.interest_count, 0U);
  ASSERT_EQ(r.features.coverage_count, 1U);
  EXPECT_TRUE(r.features.features[0].T_cloud_feature.translation().isApprox(c.points[0].cast<double>(), 1e-6));
  // No neighbours: the normal falls back to the viewing direction, towards the sensor.
  const Eigen::Vector3d z = r.features.features[0].T_cloud_feature.linear().col(2);
  EXPECT_LT(z.dot(c.points[0].cast<double>().normalized()), -0.999);
}

TEST(Interest, NaNLacedCloudGivesTheSameFeatures) {
  const Cloud clean = wall_scene(true);
  Cloud dirty = clean;
  dirty.points.emplace_back(std::nanf(""), 0.0F, 0.0F);
  dirty.points.insert(dirty.points.begin(), Eigen::Vector3f(INFINITY, 1.0F, 1.0F));
  const FeatureResult a = extract_features(clean, default_params());
  const FeatureResult b = extract_features(dirty, default_params());
  ASSERT_EQ(a.features.size(), b.features.size());
  EXPECT_EQ(a.features.descriptors, b.features.descriptors);
}

TEST(Interest, PlainWallHasNoInterestPoints) {
  const FeatureResult r = extract_features(wall_scene(false), default_params());
  EXPECT_EQ(r.features.interest_count, 0U);
  EXPECT_GT(r.features.coverage_count, 10U);
}

// A clean 3 m depth step scores about 0.24 at the cube's corners (noise-free data
// has no stronger structure), so this scene is run at a threshold of 0.2.
TEST(Interest, CubeCornersAreFoundAndShadowsAreNot) {
  FeatureParams p = default_params();
  p.interest.threshold = 0.2;
  const FeatureResult r = extract_features(wall_scene(true), p);
  ASSERT_GT(r.features.interest_count, 0U);
  // Every interest point lies on the cube (x in [5, 6]), none on the wall's shadow border.
  std::size_t near_corner = 0;
  for (std::size_t i = 0; i < r.features.interest_count; ++i) {
    const Eigen::Vector3f p = r.features.features[i].keypoint.point_sensor;
    EXPECT_LT(p.x(), 6.01F) << "interest point off the cube at " << p.transpose();
    if (std::abs(std::abs(p.y()) - 0.5F) < 0.15F && std::abs(std::abs(p.z()) - 0.5F) < 0.15F) ++near_corner;
  }
  EXPECT_GE(near_corner, 2U);
}

TEST(Interest, RealScanCountsAndMinimumDistance) {
  const Cloud c = test::load_or_fail(test::sample("kitti00_000000.bin"));
  const FeatureResult r = extract_features(c, default_params());
  EXPECT_GE(r.features.interest_count, 50U);
  EXPECT_LE(r.features.interest_count, 400U);
  for (std::size_t i = 0; i < r.features.interest_count; ++i)
    for (std::size_t j = i + 1; j < r.features.interest_count; ++j) {
      const float d = (r.features.features[i].keypoint.point_sensor - r.features.features[j].keypoint.point_sensor).norm();
      ASSERT_GT(d, 0.5F) << i << " " << j;
    }
  // Interest points come first, sorted by decreasing interest.
  for (std::size_t i = 1; i < r.features.interest_count; ++i)
    EXPECT_GE(r.features.features[i - 1].keypoint.interest, r.features.features[i].keypoint.interest);
}

// Rotating the scan about the sensor's vertical axis by a non-integer number of
// pixels resamples the whole image; the interest points must be found again.
TEST(Interest, RepeatableAfterRigidMotionOfARealScan) {
  const Cloud c = test::load_or_fail(test::sample("kitti00_000000.bin"));
  FeatureParams p = default_params();
  p.coverage.distance = 0.0;
  p.range.azimuth_resolution_rad = 1.25 * 0.17 * kDeg;
  p.range.elevation_resolution_rad = 1.25 * 0.36 * kDeg;
  const FeatureResult a = extract_features(c, p);
  ASSERT_GT(a.features.interest_count, 20U);
  const double yaw = 7.37 * p.range.azimuth_resolution_rad;  // 7.37 pixels
  Pose T = Pose::Identity();
  T.linear() = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  Cloud rotated = transformed(c, T);
  rotated.T_cloud_sensor = Pose::Identity();  // the sensor itself turned: points move in its frame
  const FeatureResult b = extract_features(rotated, p);
  const Eigen::Matrix3f R = T.linear().cast<float>();
  std::size_t found = 0;
  for (std::size_t i = 0; i < a.features.interest_count; ++i) {
    const Eigen::Vector3f expect = R * a.features.features[i].keypoint.point_sensor;
    float ex = 0, ey = 0, er = 0;
    ASSERT_TRUE(b.image.project(expect, ex, ey, er));
    for (std::size_t j = 0; j < b.features.interest_count; ++j) {
      const Keypoint& kb = b.features.features[j].keypoint;
      float dx = std::abs(kb.x - ex);
      dx = std::min(dx, static_cast<float>(b.image.width) - dx);
      if (dx <= 2.0F && std::abs(kb.y - ey) <= 2.0F) {
        ++found;
        break;
      }
    }
  }
  const double repeatability = static_cast<double>(found) / static_cast<double>(a.features.interest_count);
  RecordProperty("repeatability", std::to_string(repeatability));
  EXPECT_GT(repeatability, 0.5) << found << " of " << a.features.interest_count;
}

TEST(Coverage, EveryPointIsWithinTheCoverageDistance) {
  const Cloud c = test::load_or_fail(test::sample("newer_college_00.bin"));
  FeatureParams p = default_params();
  p.coverage.distance = 0.6;
  const FeatureResult r = extract_features(c, p);
  ASSERT_GT(r.features.coverage_count, 0U);
  // Brute force over every point and every feature.
  const float d2 = static_cast<float>(p.coverage.distance * p.coverage.distance) + 1e-6F;
  std::size_t uncovered = 0;
  for (const auto& q : c.points) {
    if (q.norm() < static_cast<float>(p.range.min_range)) continue;
    bool ok = false;
    for (const auto& f : r.features.features)
      if ((f.keypoint.point_sensor - q).squaredNorm() <= d2) {
        ok = true;
        break;
      }
    uncovered += ok ? 0 : 1;
  }
  EXPECT_EQ(uncovered, 0U);
}

TEST(Features, DeterministicAndIndependentOfThreadCount) {
  const Cloud c = test::load_or_fail(test::sample("kitti00_000000.bin"));
  FeatureParams p1 = default_params();
  p1.threads = 1;
  FeatureParams p2 = default_params();
  p2.threads = 2;
  const FeatureResult a = extract_features(c, p1);
  const FeatureResult b = extract_features(c, p2);
  ASSERT_EQ(a.features.size(), b.features.size());
  EXPECT_EQ(a.features.descriptors, b.features.descriptors);
  for (std::size_t i = 0; i < a.features.size(); ++i)
    ASSERT_TRUE(a.features.features[i].T_cloud_feature.isApprox(b.features.features[i].T_cloud_feature, 0.0));
}

TEST(Features, RejectBadParameters) {
  FeatureParams p;
  p.interest.threshold = 0.0;
  EXPECT_THROW(extract_features(Cloud{}, p), std::invalid_argument);
  p = {};
  p.descriptor.patch_size = 1;
  EXPECT_THROW(p.validate(), std::invalid_argument);
  p = {};
  p.descriptor.up = Eigen::Vector3d::Zero();
  EXPECT_THROW(p.validate(), std::invalid_argument);
  p = {};
  p.coverage.distance = -1.0;
  EXPECT_THROW(p.validate(), std::invalid_argument);
  p = {};
  p.threads = 0;
  EXPECT_THROW(p.validate(), std::invalid_argument);
}
