#include <cmath>

#include <gtest/gtest.h>

#include "lex3d/core/cloud.hpp"
#include "lex3d/core/parallel.hpp"
#include "lex3d/core/status.hpp"

using namespace lex3d;

TEST(Cloud, BoundsOfEmptyAndRealClouds) {
  Cloud c;
  EXPECT_FALSE(compute_bounds(c).valid);
  c.points = {{1, 2, 3}, {-1, 5, 0}};
  const Bounds b = compute_bounds(c);
  ASSERT_TRUE(b.valid);
  EXPECT_EQ(b.min, Eigen::Vector3f(-1, 2, 0));
  EXPECT_EQ(b.max, Eigen::Vector3f(1, 5, 3));
}

TEST(Cloud, TransformMovesPointsAndSensorAndKeepsTheWorld) {
  Cloud c;
  c.points = {{1, 0, 0}};
  c.no_return_directions = {{0, 1, 0}};
  Pose T = Pose::Identity();
  T.linear() = Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(0, 0, 2);
  const Cloud m = transformed(c, T);
  EXPECT_TRUE(m.points[0].isApprox(Eigen::Vector3f(0, 1, 2), 1e-6F));
  EXPECT_TRUE(m.no_return_directions[0].isApprox(Eigen::Vector3f(-1, 0, 0), 1e-6F));
  EXPECT_TRUE(m.T_cloud_sensor.isApprox(T));
  // The same world point before and after.
  const Eigen::Vector3d w0 = c.T_world_cloud * c.points[0].cast<double>();
  const Eigen::Vector3d w1 = m.T_world_cloud * m.points[0].cast<double>();
  EXPECT_TRUE(w0.isApprox(w1, 1e-6));
}

TEST(Status, OneLineWithOffsetAndExitCodes) {
  const Status s = bad_data("x.pcd: truncated", 42);
  EXPECT_FALSE(s.ok());
  EXPECT_EQ(s.to_string(), "x.pcd: truncated (at byte 42)");
  EXPECT_EQ(exit_code_for(ErrorCode::kOk), 0);
  EXPECT_EQ(exit_code_for(ErrorCode::kInvalidArgument), 1);
  EXPECT_EQ(exit_code_for(ErrorCode::kBadData), 2);
  EXPECT_EQ(exit_code_for(ErrorCode::kIoError), 3);
  StatusOr<int> v(5);
  EXPECT_TRUE(v.ok());
  EXPECT_EQ(v.value(), 5);
  StatusOr<int> e(io_error("gone"));
  EXPECT_FALSE(e.ok());
  EXPECT_EQ(e.status().code(), ErrorCode::kIoError);
  EXPECT_THROW(StatusOr<int>(Status{}), std::logic_error);
}

TEST(Parallel, VisitsEveryIndexOnceForAnyThreadCount) {
  for (int threads : {1, 2, 5}) {
    for (std::size_t n : {0UL, 1UL, 17UL, 1000UL}) {
      std::vector<int> hits(n, 0);
      parallel_for(n, threads, [&](std::size_t i) { hits[i] += 1; }, 7);
      for (std::size_t i = 0; i < n; ++i) ASSERT_EQ(hits[i], 1) << "n=" << n << " threads=" << threads;
    }
  }
}
