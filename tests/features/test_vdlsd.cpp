#include <cmath>
#include <random>
#include <stdexcept>

#include <gtest/gtest.h>

#include "lex3d/features/features.hpp"
#include "lex3d/features/vdlsd.hpp"
#include "lex3d/io/io.hpp"
#include "same_spot.hpp"
#include "support/test_support.hpp"

using namespace lex3d;

namespace {

std::vector<Pose> frames_of(const Features& f, std::size_t n) {
  std::vector<Pose> out;
  for (std::size_t i = 0; i < std::min(n, f.size()); ++i) out.push_back(f.features[i].T_cloud_feature);
  return out;
}

VdlsdParams params_for(const RangeImage& img) {
  VdlsdParams p;
  p.beam_spacing_rad = std::max(img.azimuth_resolution_rad, img.elevation_resolution_rad);
  return p;
}

float distance(const VdlsdResult& a, std::size_t i, const VdlsdResult& b, std::size_t j) {
  const auto d = static_cast<std::size_t>(a.descriptor_dim);
  return std::sqrt(descriptor_distance_sq(a.descriptors.data() + i * d, b.descriptors.data() + j * d, a.descriptor_dim));
}

}  // namespace

TEST(Vdlsd, DimensionIsBinsToTheSixth) {
  EXPECT_EQ(vdlsd_dimension(2), 64);
  EXPECT_EQ(vdlsd_dimension(3), 729);
}

// The scan and its frames moved together (sensor pose included) give the same descriptors:
// positions are binned in the frames, shapes come from eigenvalues, and the neighbourhoods'
// radii from ranges measured from the sensor, which moves along.
TEST(Vdlsd, InvariantUnderARigidMotionOfARealScan) {
  const Cloud c = test::load_or_fail(test::sample("kitti00_000000.bin"));
  FeatureParams fp;
  fp.coverage.distance = 0.0;
  const FeatureResult fr = extract_features(c, fp);
  const std::vector<Pose> frames = frames_of(fr.features, 160);
  ASSERT_GE(frames.size(), 100U);
  Pose T = Pose::Identity();
  T.linear() = (Eigen::AngleAxisd(1.1, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitY()))
                   .toRotationMatrix();
  T.translation() = Eigen::Vector3d(-40.0, 7.0, 2.0);
  const Cloud moved = transformed(c, T);
  std::vector<Pose> moved_frames;
  for (const Pose& F : frames) moved_frames.push_back(T * F);
  const VdlsdParams vp = params_for(fr.image);
  const VdlsdResult a = describe_vdlsd(c, frames, vp);
  const VdlsdResult b = describe_vdlsd(moved, moved_frames, vp);
  ASSERT_EQ(a.descriptor_dim, 64);
  ASSERT_EQ(a.descriptors.size(), frames.size() * 64U);
  EXPECT_LT(a.empty, frames.size() / 10);
  std::size_t same = 0;
  double worst = 0.0;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    const double d = distance(a, i, b, i);
    worst = std::max(worst, d);
    same += d < 0.02 ? 1 : 0;
  }
  RecordProperty("worst_distance", std::to_string(worst));
  // Float round-off may move a point across the support's or a neighbourhood's border.
  EXPECT_GE(static_cast<double>(same), 0.95 * static_cast<double>(frames.size())) << "worst " << worst;
}

// The same spot in two overlapping real scans (balm frames 40 and 42, about 1 m apart,
// ground-truth poses) is closer than two spots at least 2 m apart.
TEST(Vdlsd, SameSpotIsCloserThanDifferentSpotsInOverlappingRealScans) {
  LEX3D_REQUIRE_SHARED("balm/poses.txt");
  test::BalmOverlap o;
  ASSERT_NO_FATAL_FAILURE(test::load_balm_overlap(0.0, o));
  const FeatureResult& fa = o.fa;
  std::vector<Keypoint> in_b;
  std::vector<Pose> frames_a;
  for (std::size_t i = 0; i < fa.features.size(); ++i) {
    const auto kp = keypoint_at(o.img_b, o.T_b_a * fa.features.features[i].keypoint.point_sensor);
    if (!kp) continue;
    in_b.push_back(*kp);
    frames_a.push_back(fa.features.features[i].T_cloud_feature);
  }
  ASSERT_GT(in_b.size(), 60U);
  const Features fb = describe(o.img_b, in_b, o.db, 2);
  const VdlsdResult va = describe_vdlsd(o.ca, frames_a, params_for(fa.image), 2);
  const VdlsdResult vb = describe_vdlsd(o.cb, frames_of(fb, fb.size()), params_for(o.img_b), 2);
  const test::SameSpotScore s =
      test::score_same_spots(in_b, [&](std::size_t a, std::size_t b) { return distance(va, a, vb, b); });
  ASSERT_GT(s.pairs, 50U);
  const double share = s.share();
  RecordProperty("share_same_closer", std::to_string(share));
  EXPECT_LT(s.sum_same, s.sum_diff);
  EXPECT_GT(share, 0.7) << "same " << s.sum_same / static_cast<double>(s.pairs) << " different "
                        << s.sum_diff / static_cast<double>(s.pairs);
}

TEST(Vdlsd, SameResultsOnAnyThreadCount) {
  const Cloud c = test::load_or_fail(test::sample("kitti00_000000.bin"));
  FeatureParams fp;
  fp.coverage.distance = 0.0;
  const FeatureResult fr = extract_features(c, fp);
  const std::vector<Pose> frames = frames_of(fr.features, 120);
  const VdlsdResult a = describe_vdlsd(c, frames, params_for(fr.image), 1);
  const VdlsdResult b = describe_vdlsd(c, frames, params_for(fr.image), 2);
  EXPECT_EQ(a.descriptors, b.descriptors);
  EXPECT_EQ(a.empty, b.empty);
  EXPECT_EQ(a.shapes, b.shapes);
}

// A plane and a line around a feature fall into different shape classes.
TEST(Vdlsd, ShapeClassesTellAPlaneFromALine) {
  Cloud plane, line;
  for (int i = -40; i <= 40; ++i) {
    for (int j = -40; j <= 40; ++j) plane.points.emplace_back(5.0F, 0.03F * static_cast<float>(i), 0.03F * static_cast<float>(j));
    line.points.emplace_back(5.0F, 0.0F, 0.03F * static_cast<float>(i));
  }
  Pose F = Pose::Identity();
  F.translation() = Eigen::Vector3d(5.0, 0.0, 0.0);
  F.linear() << 0, 0, -1, -1, 0, 0, 0, 1, 0;  // z towards the sensor, y up, x = y × z
  ASSERT_NEAR(F.linear().determinant(), 1.0, 1e-9);
  const VdlsdResult p = describe_vdlsd(plane, {F}, VdlsdParams{});
  const VdlsdResult l = describe_vdlsd(line, {F}, VdlsdParams{});
  EXPECT_EQ(p.empty + l.empty, 0U);
  EXPECT_GT(distance(p, 0, l, 0), 1.0F);
  // The plane's mass lies in the planar bins: planarity (property 5) high, linearity and
  // scattering low; the line's in the linear ones. Cell index: x y z lin pla sca, base 2.
  auto mass = [](const VdlsdResult& r, int property, int bin) {
    double m = 0.0;
    for (int c = 0; c < 64; ++c)
      if (((c >> (5 - property)) & 1) == bin) {
        const double v = 0.5 * (static_cast<double>(r.descriptors[static_cast<std::size_t>(c)]) + 1.0);
        m += v * v;
      }
    return m;
  };
  EXPECT_GT(mass(p, 4, 1), 0.8);
  EXPECT_GT(mass(l, 3, 1), 0.9);
}

TEST(Vdlsd, TooFewNeighboursGiveTheEmptyDescriptorAndAreCounted) {
  Cloud sparse;
  sparse.points = {{5.0F, 0.0F, 0.0F}, {5.0F, 0.1F, 0.0F}, {5.0F, 0.0F, 0.1F}};
  Pose near = Pose::Identity(), far = Pose::Identity();
  near.translation() = Eigen::Vector3d(5.0, 0.0, 0.0);
  far.translation() = Eigen::Vector3d(50.0, 0.0, 0.0);
  const VdlsdResult r = describe_vdlsd(sparse, {near, far}, VdlsdParams{});
  EXPECT_EQ(r.empty, 2U);
  ASSERT_EQ(r.descriptors.size(), 128U);
  for (const float v : r.descriptors) EXPECT_EQ(v, -1.0F);
  // Three points have no neighbourhood of five: they are counted as shapeless.
  EXPECT_EQ(r.shapeless_points, 3U);

  const VdlsdResult none = describe_vdlsd(Cloud{}, {near}, VdlsdParams{});
  EXPECT_EQ(none.empty, 1U);
  EXPECT_EQ(none.descriptors.size(), 64U);
  const VdlsdResult no_frames = describe_vdlsd(sparse, {}, VdlsdParams{});
  EXPECT_EQ(no_frames.descriptor_dim, 64);
  EXPECT_TRUE(no_frames.descriptors.empty());

  // All neighbours at one spot: no shape.
  Cloud spot;
  spot.points.assign(50, Eigen::Vector3f(5.0F, 0.0F, 0.0F));
  const VdlsdResult s = describe_vdlsd(spot, {near}, VdlsdParams{});
  EXPECT_EQ(s.empty, 1U);
  EXPECT_EQ(s.shapeless_points, s.support_points);
}

TEST(Vdlsd, BadParametersAndFramesThrow) {
  const Cloud c;
  VdlsdParams p;
  p.bins = 4;
  EXPECT_THROW((void)describe_vdlsd(c, {}, p), std::invalid_argument);
  p = VdlsdParams{};
  p.support_radius = 0.0;
  EXPECT_THROW((void)describe_vdlsd(c, {}, p), std::invalid_argument);
  p = VdlsdParams{};
  p.local_points = 4;
  EXPECT_THROW((void)describe_vdlsd(c, {}, p), std::invalid_argument);
  Pose bad = Pose::Identity();
  bad.translation().x() = std::nan("");
  EXPECT_THROW((void)describe_vdlsd(c, {bad}, VdlsdParams{}), std::invalid_argument);
  EXPECT_THROW((void)describe_vdlsd(c, {}, VdlsdParams{}, 0), std::invalid_argument);
}
