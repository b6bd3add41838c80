#pragma once
// The "same spot is closer than a different spot" protocol shared by the descriptor tests:
// balm frames 40 and 42 (about 1 m apart, ground-truth poses), and the scoring of spot k of A
// against spot k of B and against a random spot of B at least 2 m away.

#include <cstddef>
#include <functional>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "lex3d/features/features.hpp"
#include "lex3d/io/io.hpp"
#include "support/test_support.hpp"

namespace lex3d::test {

struct BalmOverlap {
  Cloud ca, cb;
  FeatureParams p;                 ///< A's feature parameters (its up direction from its pose)
  FeatureResult fa;                ///< A's features
  DescriptorParams db;             ///< B's descriptor parameters (its own up direction)
  RangeImage img_b;                ///< B's range image
  Eigen::Isometry3f T_b_a;         ///< A's sensor frame into B's
};

/// Frames 40 and 42 of the shared balm sequence with A's features extracted at the given
/// coverage distance (call inside ASSERT_NO_FATAL_FAILURE; the test checks the data exist).
inline void load_balm_overlap(double coverage_distance, BalmOverlap& o) {
  const auto poses = io::read_pose_list(shared_data("balm/poses.txt"));
  ASSERT_TRUE(poses.ok()) << poses.status().to_string();
  o.ca = load_or_fail(shared_data("balm/000040.bin"));
  o.cb = load_or_fail(shared_data("balm/000042.bin"));
  const Pose& Ta = poses.value()[20];
  const Pose& Tb = poses.value()[21];
  o.p.coverage.distance = coverage_distance;
  o.p.descriptor.up = Ta.linear().transpose() * Eigen::Vector3d::UnitZ();
  o.fa = extract_features(o.ca, o.p);
  o.db = o.p.descriptor;
  o.db.up = Tb.linear().transpose() * Eigen::Vector3d::UnitZ();
  o.img_b = make_range_image(o.cb, o.p.range);
  o.T_b_a = (Tb.inverse() * Ta).cast<float>();
}

struct SameSpotScore {
  double sum_same = 0, sum_diff = 0;
  std::size_t wins = 0, pairs = 0;  ///< pairs scored, and those where the same spot was closer
  [[nodiscard]] double share() const { return static_cast<double>(wins) / static_cast<double>(pairs); }
};

/// For every spot k of B (`in_b`), distance(k, k) against distance(k, other) for a random
/// spot `other` of B at least 2 m from it (seeded); spots with none found are skipped.
inline SameSpotScore score_same_spots(const std::vector<Keypoint>& in_b,
                                      const std::function<double(std::size_t, std::size_t)>& distance) {
  SameSpotScore s;
  std::mt19937 rng(7);
  std::uniform_int_distribution<std::size_t> pick(0, in_b.size() - 1);
  for (std::size_t k = 0; k < in_b.size(); ++k) {
    std::size_t other = pick(rng);
    for (int tries = 0; tries < 20 && (in_b[other].point_sensor - in_b[k].point_sensor).norm() < 2.0F; ++tries)
      other = pick(rng);
    if ((in_b[other].point_sensor - in_b[k].point_sensor).norm() < 2.0F) continue;
    const double same = distance(k, k), diff = distance(k, other);
    s.sum_same += same;
    s.sum_diff += diff;
    s.wins += same < diff ? 1 : 0;
    ++s.pairs;
  }
  return s;
}

}  // namespace lex3d::test
