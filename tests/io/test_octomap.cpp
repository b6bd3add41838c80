#include <fstream>
#include <string>

#include <gtest/gtest.h>
#include <octomap/OcTree.h>

#include "lex3d/io/io.hpp"
#include "support/test_support.hpp"

using namespace lex3d;

namespace {
/// A wall 5 m ahead of the origin, 2 m x 1 m, points 5 cm apart.
Cloud wall_at_5m() {
  Cloud wall;
  for (int i = -20; i <= 20; ++i)
    for (int k = -10; k <= 10; ++k) wall.points.emplace_back(5.0F, 0.05F * static_cast<float>(i), 0.05F * static_cast<float>(k));
  return wall;
}
}  // namespace

TEST(Octomap, WritesOccupiedAndFreeSpaceFromTheSensor) {
  const Cloud wall = wall_at_5m();
  const auto dir = test::temp_dir("octomap");
  const std::string path = (dir / "wall.bt").string();
  const auto r = io::write_octomap(path, wall, Eigen::Vector3d::Zero(), 0.1);
  ASSERT_TRUE(r.ok()) << r.status().to_string();
  EXPECT_GT(r.value().occupied_leaves, 20U);
  EXPECT_GT(r.value().free_leaves, 20U);  // the rays from the sensor to the wall
  // OctoMap itself reads the file back with the same occupancy.
  octomap::OcTree tree(0.1);
  ASSERT_TRUE(tree.readBinary(path));
  std::size_t occupied = 0, free = 0;
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it)
    (tree.isNodeOccupied(*it) ? occupied : free)++;
  EXPECT_EQ(occupied, r.value().occupied_leaves);
  EXPECT_EQ(free, r.value().free_leaves);
  EXPECT_NEAR(tree.getResolution(), 0.1, 1e-12);
}

TEST(Octomap, WithoutAnOriginOnlyThePointsAreOccupied) {
  const Cloud wall = wall_at_5m();
  const auto dir = test::temp_dir("octomap_map");
  const std::string path = (dir / "map.bt").string();
  const auto r = io::write_octomap(path, wall, std::nullopt, 0.1);
  ASSERT_TRUE(r.ok()) << r.status().to_string();
  EXPECT_GT(r.value().occupied_leaves, 20U);
  EXPECT_EQ(r.value().free_leaves, 0U);
  octomap::OcTree tree(0.1);
  ASSERT_TRUE(tree.readBinary(path));
  const octomap::OcTreeNode* at_wall = tree.search(5.0, 0.0, 0.0);
  ASSERT_NE(at_wall, nullptr);
  EXPECT_TRUE(tree.isNodeOccupied(at_wall));
  EXPECT_EQ(tree.search(2.5, 0.0, 0.0), nullptr) << "no free space between the origin and the wall";
}

TEST(Octomap, EmptyCloudAndBadResolution) {
  const auto dir = test::temp_dir("octomap_empty");
  const auto r = io::write_octomap((dir / "empty.bt").string(), Cloud{}, Eigen::Vector3d::Zero(), 0.2);
  ASSERT_TRUE(r.ok()) << r.status().to_string();
  EXPECT_EQ(r.value().occupied_leaves, 0U);
  const auto bad = io::write_octomap((dir / "bad.bt").string(), Cloud{}, Eigen::Vector3d::Zero(), 0.0);
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), ErrorCode::kInvalidArgument);
  EXPECT_FALSE(std::ifstream((dir / "bad.bt").string()).good());
  const auto nodir = io::write_octomap((dir / "no" / "x.bt").string(), Cloud{}, Eigen::Vector3d::Zero(), 0.2);
  ASSERT_FALSE(nodir.ok());
  EXPECT_EQ(nodir.status().code(), ErrorCode::kIoError);
}
