#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "lex3d/features/features.hpp"
#include "lex3d/io/io.hpp"
#include "same_spot.hpp"
#include "support/test_support.hpp"

using namespace lex3d;

namespace {

constexpr double kDeg = M_PI / 180.0;

// A synthetic lidar looking at a wall 8 m away along +x.
Cloud wall() {
  Cloud c;
  for (double el = -20.0; el <= 20.0; el += 0.4)
    for (double az = -50.0; az <= 50.0; az += 0.2) {
      const double a = az * kDeg, e = el * kDeg;
      const Eigen::Vector3d d(std::cos(e) * std::cos(a), std::cos(e) * std::sin(a), std::sin(e));
      c.points.push_back((d * (8.0 / d.x())).cast<float>());
    }
  return c;
}

}  // namespace

TEST(Descriptor, FrameIsOrthonormalAlongTheNormalAndUpright) {
  const Cloud c = wall();
  const RangeImage img = make_range_image(c);
  const auto kp = keypoint_at(img, Eigen::Vector3f(8.0F, 1.0F, 0.5F));
  ASSERT_TRUE(kp.has_value());
  const Features f = describe(img, {*kp}, DescriptorParams{});
  ASSERT_EQ(f.size(), 1U);
  const Eigen::Matrix3d R = f.features[0].T_cloud_feature.linear();
  EXPECT_TRUE((R.transpose() * R).isApprox(Eigen::Matrix3d::Identity(), 1e-5));
  EXPECT_NEAR(R.determinant(), 1.0, 1e-5);
  EXPECT_NEAR(R.col(2).x(), -1.0, 1e-3);  // the wall's normal, towards the sensor
  EXPECT_NEAR(R.col(1).z(), 1.0, 1e-3);   // upright
  EXPECT_GE(f.features[0].normal_support, 3U);
  // A plane seen along its normal is a flat patch.
  for (int i = 0; i < f.descriptor_dim; ++i) EXPECT_NEAR(f.descriptor(0)[i], 0.0F, 0.02F);
}

TEST(Descriptor, FollowsTheScanUnderARigidMotion) {
  const Cloud c = test::load_or_fail(test::sample("kitti00_000000.bin"));
  Pose T = Pose::Identity();
  T.linear() = (Eigen::AngleAxisd(1.1, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitY()))
                   .toRotationMatrix();
  T.translation() = Eigen::Vector3d(-40.0, 7.0, 2.0);
  const Cloud moved = transformed(c, T);  // the sensor pose moves with the points
  FeatureParams p;
  p.range.azimuth_resolution_rad = 0.2 * kDeg;
  p.range.elevation_resolution_rad = 0.45 * kDeg;
  // Coverage points are greedy in a hash grid: float round-off in the sensor frame
  // may swap one for a neighbour, so compare the interest points, which must agree.
  p.coverage.distance = 0.0;
  const FeatureResult a = extract_features(c, p);
  p.descriptor.up = T.linear() * Eigen::Vector3d::UnitZ();  // the world's up moved too
  const FeatureResult b = extract_features(moved, p);
  ASSERT_GT(a.features.size(), 50U);
  // Same pixels and points in the sensor frame, so the features must agree (their
  // order may differ where round-off reorders equal interest values).
  std::size_t close = 0;
  for (std::size_t i = 0; i < a.features.size(); ++i) {
    const Pose expect = T * a.features.features[i].T_cloud_feature;
    for (std::size_t j = 0; j < b.features.size(); ++j) {
      const Pose& got = b.features.features[j].T_cloud_feature;
      if ((expect.translation() - got.translation()).norm() > 1e-3) continue;
      EXPECT_LT((expect.linear() - got.linear()).norm(), 1e-3);
      const float d = std::sqrt(
          descriptor_distance_sq(a.features.descriptor(i), b.features.descriptor(j), a.features.descriptor_dim));
      close += d < 0.05F ? 1 : 0;
      break;
    }
  }
  EXPECT_GT(static_cast<double>(close), 0.99 * static_cast<double>(a.features.size()));
}

// The same 3D spot seen in two overlapping real scans (consecutive balm frames,
// 1 s and a few decimetres apart, with their ground-truth poses) has closer
// descriptors than two different spots.
TEST(Descriptor, SameSpotIsCloserThanDifferentSpotsInOverlappingRealScans) {
  LEX3D_REQUIRE_SHARED("balm/poses.txt");
  test::BalmOverlap o;
  ASSERT_NO_FATAL_FAILURE(test::load_balm_overlap(1.0, o));
  const FeatureResult& fa = o.fa;
  const RangeImage& img_b = o.img_b;

  // Spots of A that B sees on its visible surface.
  std::vector<Keypoint> in_b;
  std::vector<std::size_t> from_a;
  for (std::size_t i = 0; i < fa.features.size(); ++i) {
    const Eigen::Vector3f q = o.T_b_a * fa.features.features[i].keypoint.point_sensor;
    const auto kp = keypoint_at(img_b, q);
    if (!kp) continue;
    const int x = img_b.wrap_x(static_cast<int>(kp->x)), y = static_cast<int>(kp->y);
    if (x < 0 || !img_b.valid(x, y) || std::abs(img_b.range[img_b.index(x, y)] - q.norm()) > 0.1F) continue;
    if (fa.features.features[i].normal_support < 3) continue;
    in_b.push_back(*kp);
    from_a.push_back(i);
  }
  ASSERT_GT(in_b.size(), 200U);
  const Features fb = describe(img_b, in_b, o.db, 2);
  const int dim = fb.descriptor_dim;
  const test::SameSpotScore s = test::score_same_spots(in_b, [&](std::size_t a, std::size_t b) {
    return std::sqrt(descriptor_distance_sq(fa.features.descriptor(from_a[a]), fb.descriptor(b), dim));
  });
  ASSERT_GT(s.pairs, 100U);
  const double share = s.share();
  RecordProperty("mean_same", std::to_string(s.sum_same / static_cast<double>(s.pairs)));
  RecordProperty("mean_different", std::to_string(s.sum_diff / static_cast<double>(s.pairs)));
  RecordProperty("share_same_closer", std::to_string(share));
  EXPECT_LT(s.sum_same, s.sum_diff);
  EXPECT_GT(share, 0.7) << "same " << s.sum_same / static_cast<double>(s.pairs) << " different "
                        << s.sum_diff / static_cast<double>(s.pairs);
}

TEST(Descriptor, KeypointOutsideAPartialImageIsRejected) {
  const RangeImage img = make_range_image(wall());
  ASSERT_FALSE(img.full_circle);
  EXPECT_FALSE(keypoint_at(img, Eigen::Vector3f(-8.0F, 0.0F, 0.0F)).has_value());  // behind the sensor
  EXPECT_FALSE(keypoint_at(img, Eigen::Vector3f(0.0F, 0.0F, 0.0F)).has_value());
  EXPECT_TRUE(keypoint_at(img, Eigen::Vector3f(8.0F, 0.0F, 0.0F)).has_value());
}

TEST(Descriptor, EmptyInputs) {
  const Features f = describe(RangeImage{}, {}, DescriptorParams{});
  EXPECT_EQ(f.size(), 0U);
  EXPECT_EQ(f.descriptor_dim, 100);
}
