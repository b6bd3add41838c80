#include <random>

#include <gtest/gtest.h>

#include "lex3d/alphabet/alphabet.hpp"

using namespace lex3d;

namespace {

Alphabet small_alphabet() {
  Alphabet a;
  a.descriptor_dim = 4;
  a.word_radius = 0.3;
  a.point_spacing = 0.03;
  for (int w = 0; w < 3; ++w) {
    Word word;
    for (int i = 0; i < 5 + w; ++i) word.points.emplace_back(0.01F * static_cast<float>(i), -0.02F * static_cast<float>(w), 0.0F);
    word.descriptor = {static_cast<float>(w), 0.5F, -0.25F, 1.0F};
    a.words.push_back(word);
  }
  return a;
}

}  // namespace

TEST(Word, CutKeepsPointsWithinTheRadiusInTheFeatureFrame) {
  std::vector<Eigen::Vector3f> pts;
  std::vector<std::uint32_t> nearby;
  for (int i = 0; i < 100; ++i) {
    pts.emplace_back(10.0F + 0.01F * static_cast<float>(i), 2.0F, 1.0F);
    nearby.push_back(static_cast<std::uint32_t>(i));
  }
  Eigen::Isometry3f T = Eigen::Isometry3f::Identity();
  T.translation() = Eigen::Vector3f(10.5F, 2.0F, 1.0F);
  T.linear() = Eigen::AngleAxisf(0.5F, Eigen::Vector3f::UnitZ()).toRotationMatrix();
  const float desc[2] = {0.25F, -0.5F};
  const Word w = cut_word(pts, nearby, T, desc, 2, 0.2, 0.0);
  EXPECT_EQ(w.descriptor, std::vector<float>({0.25F, -0.5F}));
  ASSERT_EQ(w.points.size(), 41U);  // x in [10.30, 10.70]
  for (const auto& p : w.points) {
    EXPECT_LE(p.norm(), 0.2F + 1e-6F);
    // Back in the scan, the point is one of the inputs.
    const Eigen::Vector3f q = T * p;
    EXPECT_NEAR(q.y(), 2.0F, 1e-5F);
  }
  // Thinning keeps at most one point a cell.
  const Word thin = cut_word(pts, nearby, T, desc, 2, 0.2, 0.05);
  EXPECT_LT(thin.points.size(), 12U);
  EXPECT_GT(thin.points.size(), 5U);
}

TEST(WordIndex, FindsTheNearestDescriptorWithDeterministicTies) {
  const Alphabet a = small_alphabet();
  const WordIndex index(a);
  const std::vector<float> q = {1.1F, 0.5F, -0.25F, 1.0F, /* a tie between words 0 and 1 */ 0.5F, 0.5F, -0.25F, 1.0F};
  const auto m = index.nearest(q.data(), 2, 2);
  ASSERT_EQ(m.size(), 2U);
  EXPECT_EQ(m[0].word, 1U);
  EXPECT_NEAR(m[0].distance_sq, 0.01F, 1e-6F);
  EXPECT_EQ(m[1].word, 0U);
  EXPECT_TRUE(WordIndex(Alphabet{}).nearest(q.data(), 2).empty());
}

