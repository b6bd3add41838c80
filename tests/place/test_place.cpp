// Place recognition: parameters, revisits of the real balm sequence found with the right
// relative pose, far scans rejected, database save/load and corrupt bytes rejected.

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <random>
#include <memory>
#include <stdexcept>
#include <string>

#include <gtest/gtest.h>

#include "lex3d/io/io.hpp"
#include "lex3d/place/gravity.hpp"
#include "lex3d/place/place.hpp"
#include "support/test_support.hpp"

namespace lex3d {
namespace {

const char* kBalm = "balm/poses.txt";

// Prepared balm scans, each prepared once per test binary (about 60 ms a scan).
class Balm {
 public:
  static Balm& get() {
    static Balm b;
    return b;
  }
  const PreparedScan& prepared(const std::string& frame) {
    auto it = prepared_.find(frame);
    if (it != prepared_.end()) return it->second;
    Cloud c = test::load_or_fail(test::shared_data("balm/" + frame + ".bin"));
    c.T_world_cloud = pose(frame);
    c.has_world_pose = true;
    ModelParams mp;
    return prepared_.emplace(frame, prepare_scan(c, mp, 0.39)).first->second;
  }
  Pose pose(const std::string& frame) const { return poses_.at(std::stoi(frame) / 2); }
  // A small alphabet: descriptors of every 60th feature of scan 000000 (the place module
  // only needs word ids; a learned alphabet takes seconds).
  const Alphabet& alphabet() {
    if (alphabet_.size() == 0) {
      const PreparedScan& s = prepared("000000");
      alphabet_.descriptor_dim = s.features.descriptor_dim;
      alphabet_.word_radius = s.word_radius;
      for (std::size_t i = 0; i < s.features.size(); i += 60) {
        Word w;
        w.descriptor.assign(s.features.descriptor(i), s.features.descriptor(i) + s.features.descriptor_dim);
        alphabet_.words.push_back(std::move(w));
      }
    }
    return alphabet_;
  }
  PlaceScan place(const std::string& frame, const PlaceStorageParams& st = {}) {
    return make_place_scan(prepared(frame), alphabet(), st, ModelParams{}.features.range, frame);
  }

 private:
  Balm() {
    auto p = io::read_pose_list(test::shared_data(kBalm));
    if (p.ok()) poses_ = std::move(p).value();
  }
  std::map<std::string, PreparedScan> prepared_;
  std::vector<Pose> poses_;
  Alphabet alphabet_;
};

void expect_pose_near(const Pose& estimate, const Pose& truth, double max_m, double max_deg, const std::string& what) {
  const Pose d = truth.inverse() * estimate;
  const double t = d.translation().norm();
  const double a = Eigen::AngleAxisd(d.linear()).angle() * 180.0 / M_PI;
  EXPECT_LT(t, max_m) << what << ": translation error " << t << " m";
  EXPECT_LT(a, max_deg) << what << ": rotation error " << a << " deg";
}

TEST(PlaceParams, ValidateNamesTheField) {
  PlaceParams p;
  EXPECT_NO_THROW(p.validate());
  p.ratio = 1.5;
  try {
    p.validate();
    FAIL() << "no throw";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("ratio"), std::string::npos);
  }
  p = PlaceParams{};
  p.dense_gate_end = 2.0 * p.dense_gate_start;
  EXPECT_THROW(p.validate(), std::invalid_argument);
  p = PlaceParams{};
  p.dense_candidates = 0;
  EXPECT_THROW(p.validate(), std::invalid_argument);
  p = PlaceParams{};
  p.max_distance = -1.0;
  EXPECT_THROW(p.validate(), std::invalid_argument);
  p = PlaceParams{};
  p.surface_yaws = 37;
  EXPECT_THROW(p.validate(), std::invalid_argument);
  p = PlaceParams{};
  p.max_conflict = 0.0;
  EXPECT_THROW(p.validate(), std::invalid_argument);
  PlaceStorageParams s;
  s.descriptor_bits = 5;
  EXPECT_THROW(s.validate(), std::invalid_argument);
}

TEST(PlaceQuantise, DescriptorCodesRoundTrip) {
  for (const int bits : {4, 8}) {
    const float step = 2.0F / static_cast<float>((1 << bits) - 1);
    for (float v = -1.0F; v <= 1.0F; v += 0.01F) {
      const float back = detail::dequantise_descriptor_value(detail::quantise_descriptor_value(v, bits), bits);
      EXPECT_LE(std::abs(back - v), step / 2 + 1e-6F);
    }
  }
}

TEST(PlaceDatabase, EmptyDatabaseAnswersUnknown) {
  PlaceDatabase db;
  PlaceScan q;
  q.descriptor_bits = db.storage().descriptor_bits;
  const auto r = db.query(q, {});
  EXPECT_FALSE(r.accepted);
  EXPECT_TRUE(r.matches.empty());
  auto back = PlaceDatabase::load(db.save());
  ASSERT_TRUE(back.ok()) << back.status().to_string();
  EXPECT_EQ(back.value().size(), 0U);
}

struct Revisit {
  const char* query;
  const char* match;
};

class PlaceRevisit : public ::testing::TestWithParam<Revisit> {};

// The revisits listed in ../shared/data/README.md, each queried against a database of
// the earlier scan plus three others far from the query.
TEST_P(PlaceRevisit, FoundWithTheRightRelativePose) {
  LEX3D_REQUIRE_SHARED(kBalm);
  const Revisit rv = GetParam();
  Balm& b = Balm::get();
  PlaceDatabase db;
  for (const char* f : {"000040", rv.match, "000060", "000080"})
    if (std::string(f) != rv.query) db.add(b.place(f));
  const PlaceScan q = b.place(rv.query);
  PlaceParams params;
  const auto r = db.query(q, params);
  ASSERT_TRUE(r.best() != nullptr);
  const PlaceMatch& m = *r.best();
  EXPECT_TRUE(r.accepted) << "best score " << m.score;
  EXPECT_EQ(db.scan(m.scan).name, rv.match) << "best score " << m.score;
  EXPECT_GE(m.inliers, 6U);
  const Pose truth = b.pose(rv.match).inverse() * b.pose(rv.query);
  expect_pose_near(m.T_match_query, truth, 0.3, 2.0, std::string(rv.query) + " -> " + rv.match);
  // Dense alignment of the coarse images: well under the feature transform's error.
  EXPECT_TRUE(m.dense_refined);
  expect_pose_near(m.T_match_query, truth, 0.2, 0.6, std::string(rv.query) + " -> " + rv.match + " (dense)");
  const Pose d = truth.inverse() * m.T_match_query;
  const Pose df = truth.inverse() * m.T_feature;
  std::printf("%s -> %s: error %.3f m %.2f deg (features: %.3f m %.2f deg)\n", rv.query, rv.match,
              d.translation().norm(), Eigen::AngleAxisd(d.linear()).angle() * 180.0 / M_PI, df.translation().norm(),
              Eigen::AngleAxisd(df.linear()).angle() * 180.0 / M_PI);
  std::printf("%s -> %s: score %.3f (%.3f/%.3f), %zu corr, %zu inliers, rms %.3f m, verify %.1f ms\n", rv.query,
              rv.match, m.score, m.score_query_in_match, m.score_match_in_query, m.correspondences, m.inliers,
              m.rms_inlier_m, r.verification_ms);
}

std::string revisit_name(const ::testing::TestParamInfo<Revisit>& info) {
  return std::string("q") + info.param.query + "_m" + info.param.match;
}

// 000120 -> 000008 and 000110 -> 000080: under the true transform only 4-7 of ~100
// interest points repeat within 0.3 m (see PlaceDiag.DISABLED_Stats) and no feature
// hypothesis comes within 1.9 m / 16 degrees of the truth (000110 -> 000080 slides 4 m
// along a corridor); the surface hypotheses (PlaceParams::surface_yaws) find both.
INSTANTIATE_TEST_SUITE_P(Balm, PlaceRevisit,
                         ::testing::Values(Revisit{"000124", "000000"}, Revisit{"000176", "000114"},
                                           Revisit{"000120", "000008"}, Revisit{"000110", "000080"}),
                         revisit_name);

// The surface hypotheses use only the up direction of the upright frames: turning both
// scans' world poses by the same yaw (balm's world axes happen to run along its walls)
// gives the same relative transform.
TEST(PlaceMatch, SurfaceHypothesesDoNotDependOnTheWorldYaw) {
  LEX3D_REQUIRE_SHARED(kBalm);
  Balm& b = Balm::get();
  const Pose truth = b.pose("000080").inverse() * b.pose("000110");
  PlaceParams p;
  p.gravity_pairs = 0;  // surface and correspondence hypotheses only
  for (const double yaw_deg : {0.0, 37.0, -101.0}) {
    PlaceScan q = b.place("000110"), m = b.place("000080");
    Pose turn = Pose::Identity();
    turn.linear() = Eigen::AngleAxisd(yaw_deg * M_PI / 180.0, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    for (PlaceScan* s : {&q, &m}) {
      s->T_world_cloud = turn * s->T_world_cloud;
      detail::finish_place_scan(*s);
    }
    const PlaceMatch r = match_scans(q, m, p);
    ASSERT_TRUE(r.valid) << "world yaw " << yaw_deg;
    EXPECT_GE(r.score, p.accept_score) << "world yaw " << yaw_deg;
    expect_pose_near(r.T_match_query, truth, 0.2, 0.6, "world yaw " + std::to_string(yaw_deg));
  }
}

// Dense alignment (point-to-plane ICP of the stored coarse images) converges to the
// ground-truth transform from starts about as far off as feature transforms are.
TEST(PlaceDense, ConvergesFromPerturbedTruth) {
  LEX3D_REQUIRE_SHARED(kBalm);
  Balm& b = Balm::get();
  for (const auto& [qf, mf] : {std::pair{"000176", "000114"}, std::pair{"000124", "000000"},
                               std::pair{"000174", "000108"}}) {
    const PlaceScan q = b.place(qf), m = b.place(mf);
    ASSERT_GT(q.dense_points.size(), 1000U);
    ASSERT_EQ(q.dense_points.size(), q.dense_normals.size());
    const Pose truth = b.pose(mf).inverse() * b.pose(qf);
    for (const double s : {-1.0, 1.0}) {
      Pose start = truth;
      start.translation() += Eigen::Vector3d(0.3 * s, -0.2 * s, 0.1);
      start.linear() = Eigen::AngleAxisd(2.0 * s * M_PI / 180.0, Eigen::Vector3d::UnitZ()).toRotationMatrix() *
                       Eigen::AngleAxisd(1.0 * M_PI / 180.0, Eigen::Vector3d::UnitX()).toRotationMatrix() *
                       start.linear();
      const DenseAlignment a = dense_align(q, m, start, PlaceParams{});
      EXPECT_GT(a.used, 500U);
      expect_pose_near(a.T_match_query, truth, 0.15, 0.5, std::string(qf) + " -> " + mf);
    }
  }
}

// Points of a scan against its own image: everything is supported, nothing in free space.
TEST(PlaceDense, SelfConsistency) {
  LEX3D_REQUIRE_SHARED(kBalm);
  const PlaceScan s = Balm::get().place("000000");
  const DenseConsistency c = dense_consistency(s, s, Pose::Identity(), PlaceParams{});
  EXPECT_GT(c.points, 1000U);
  EXPECT_EQ(c.conflict, 0U);
  EXPECT_GT(static_cast<double>(c.support), 0.95 * static_cast<double>(c.points));
}

// The query path describes a cloud from one feature extraction: the same PlaceScan as the
// prepared scan gives, derived state included.
TEST(PlaceScanFromCloud, SameAsFromThePreparedScan) {
  LEX3D_REQUIRE_SHARED(kBalm);
  Balm& b = Balm::get();
  const Alphabet& alphabet = b.alphabet();
  const PlaceScan a = b.place("000106");
  ModelParams mp;
  const PlaceScan c = make_place_scan(b.prepared("000106").cloud, alphabet, PlaceStorageParams{}, mp, "000106");
  EXPECT_EQ(a.words, c.words);
  ASSERT_EQ(a.features.size(), c.features.size());
  for (std::size_t i = 0; i < a.features.size(); ++i) {
    EXPECT_EQ(a.features[i].position, c.features[i].position);
    EXPECT_EQ(a.features[i].rotation.coeffs(), c.features[i].rotation.coeffs());
  }
  EXPECT_EQ(a.descriptor_codes, c.descriptor_codes);
  EXPECT_EQ(a.coarse.range.size(), c.coarse.range.size());
  EXPECT_TRUE(std::equal(a.coarse.state.begin(), a.coarse.state.end(), c.coarse.state.begin(), c.coarse.state.end()));
  EXPECT_EQ(a.validation, c.validation);
  EXPECT_EQ(a.dense_points, c.dense_points);
  EXPECT_EQ(a.dense_index, c.dense_index);
  ASSERT_EQ(a.pairs.size(), c.pairs.size());
  EXPECT_GT(a.pairs.size(), 1000U);
}

// --descriptor vdlsd: the same features, frames and words as the patch scan, VD-LSDs stored
// instead of patches (the same from the prepared scan on one thread as from the cloud on two),
// and a balm revisit found with them.
TEST(PlaceScanFromCloud, VdlsdKeepsTheFramesAndWordsAndFindsARevisit) {
  LEX3D_REQUIRE_SHARED(kBalm);
  Balm& b = Balm::get();
  PlaceStorageParams st;
  st.descriptor = PlaceDescriptor::kVdlsd;
  const PlaceScan patch = b.place("000124");
  const PlaceScan v = b.place("000124", st);
  ModelParams mp;
  const PlaceScan c = make_place_scan(b.prepared("000124").cloud, b.alphabet(), st, mp, "000124");
  EXPECT_EQ(v.descriptor, PlaceDescriptor::kVdlsd);
  EXPECT_EQ(v.descriptor_dim, 64);
  EXPECT_EQ(v.words, patch.words);
  ASSERT_EQ(v.features.size(), patch.features.size());
  for (std::size_t i = 0; i < v.features.size(); ++i) EXPECT_EQ(v.features[i].position, patch.features[i].position);
  ASSERT_EQ(v.descriptor_codes.size(), v.features.size() * 64U);
  EXPECT_EQ(v.descriptor_codes, c.descriptor_codes);
  EXPECT_LT(v.empty_descriptors, v.features.size() / 10);
  PlaceDatabase db(st);
  for (const char* f : {"000040", "000000", "000060", "000080"}) db.add(b.place(f, st));
  const auto r = db.query(v, PlaceParams{});
  ASSERT_TRUE(r.best() != nullptr);
  EXPECT_TRUE(r.accepted);
  EXPECT_EQ(db.scan(r.best()->scan).name, "000000") << "best score " << r.best()->score;
  EXPECT_THROW(db.add(patch), std::invalid_argument);
}

// Derived state against plain oracles: the pair table in (horizontal, a, b) order, every
// pair at least 1 m apart listed; dense points on the pixel-centre rays.
TEST(PlaceScanDerived, PairTableAndDensePointsMatchOracles) {
  LEX3D_REQUIRE_SHARED(kBalm);
  const PlaceScan s = Balm::get().place("000040");
  const Eigen::Matrix3f R = s.T_world_cloud.linear().cast<float>();
  std::vector<PlaceScan::FeaturePair> want;
  for (std::size_t a = 0; a < s.features.size(); ++a)
    for (std::size_t b2 = a + 1; b2 < s.features.size(); ++b2) {
      const Eigen::Vector3f v = R * s.features[b2].position - R * s.features[a].position;
      const float h = std::hypot(v.x(), v.y());
      if (h >= 1.0F) want.push_back({h, v.z(), std::atan2(v.y(), v.x()), static_cast<std::uint16_t>(a), static_cast<std::uint16_t>(b2)});
    }
  std::sort(want.begin(), want.end(), [](const PlaceScan::FeaturePair& x, const PlaceScan::FeaturePair& y) {
    return x.horizontal != y.horizontal ? x.horizontal < y.horizontal : (x.a != y.a ? x.a < y.a : x.b < y.b);
  });
  ASSERT_EQ(want.size(), s.pairs.size());
  for (std::size_t i = 0; i < want.size(); ++i) {
    ASSERT_EQ(want[i].a, s.pairs[i].a) << i;
    ASSERT_EQ(want[i].b, s.pairs[i].b) << i;
    ASSERT_EQ(want[i].horizontal, s.pairs[i].horizontal) << i;
    ASSERT_EQ(want[i].angle, s.pairs[i].angle) << i;
  }
  const RangeImage& c = s.coarse;
  const Eigen::Matrix3f Rs = c.T_cloud_sensor.linear().cast<float>();
  const Eigen::Vector3f ts = c.T_cloud_sensor.translation().cast<float>();
  std::size_t checked = 0;
  for (int y = 0; y < c.height; ++y)
    for (int x = 0; x < c.width; ++x) {
      const std::int32_t k = s.dense_index[c.index(x, y)];
      if (k < 0) continue;
      const Eigen::Vector3f p = Rs * (c.ray(x + 0.5, y + 0.5) * c.range[c.index(x, y)]) + ts;
      ASSERT_EQ(p, s.dense_points[static_cast<std::size_t>(k)]) << x << " " << y;
      ++checked;
    }
  EXPECT_EQ(checked, s.dense_points.size());
  EXPECT_GT(checked, 1000U);
}

TEST(PlaceDatabase, ThreadsDoNotChangeResults) {
  LEX3D_REQUIRE_SHARED(kBalm);
  Balm& b = Balm::get();
  PlaceDatabase db;
  for (const char* f : {"000000", "000040", "000106", "000114"}) db.add(b.place(f));
  const PlaceScan q = b.place("000176");
  PlaceParams p1, p2;
  p2.threads = 2;
  const auto r1 = db.query(q, p1), r2 = db.query(q, p2);
  ASSERT_EQ(r1.matches.size(), r2.matches.size());
  for (std::size_t i = 0; i < r1.matches.size(); ++i) {
    EXPECT_EQ(r1.matches[i].scan, r2.matches[i].scan);
    EXPECT_EQ(r1.matches[i].score, r2.matches[i].score);
    EXPECT_TRUE(r1.matches[i].T_match_query.isApprox(r2.matches[i].T_match_query, 0.0));
  }
}

TEST(PlaceMatch, FarScansAreRejected) {
  LEX3D_REQUIRE_SHARED(kBalm);
  Balm& b = Balm::get();
  // Planar distances 13.6 to 14 m: no overlap worth a match.
  for (const auto& [qf, mf] : {std::pair{"000080", "000000"}, std::pair{"000080", "000124"},
                               std::pair{"000040", "000176"}}) {
    const PlaceMatch m = match_scans(b.place(qf), b.place(mf), PlaceParams{});
    EXPECT_LT(m.score, PlaceParams{}.accept_score) << qf << " vs " << mf << ": " << m.inliers << " inliers";
  }
}

// A transform that aligns two scans well can still put them farther apart than the
// question asks: max_distance rejects it, on the distance the transform itself implies.
TEST(PlaceMatch, MaxDistanceLimitsTheImpliedSensorDistance) {
  LEX3D_REQUIRE_SHARED(kBalm);
  Balm& b = Balm::get();
  const PlaceScan q = b.place("000124"), m = b.place("000000");
  const Pose truth = b.pose("000000").inverse() * b.pose("000124");
  const double true_distance = truth.translation().norm();  // ~4.3 m
  PlaceParams p;
  const PlaceMatch any = match_scans(q, m, p);
  ASSERT_TRUE(any.valid);
  EXPECT_NEAR(any.sensor_distance_m, true_distance, 0.3);
  EXPECT_FALSE(any.rejected_distance);
  p.max_distance = true_distance + 1.0;
  const PlaceMatch within = match_scans(q, m, p);
  EXPECT_TRUE(within.valid);
  EXPECT_GE(within.score, p.accept_score);
  p.max_distance = true_distance - 1.0;
  const PlaceMatch beyond = match_scans(q, m, p);
  // The right transform is gone; whatever is left implies at most the allowed distance.
  EXPECT_TRUE(!beyond.valid || beyond.sensor_distance_m <= p.max_distance) << beyond.sensor_distance_m << " m";
  EXPECT_FALSE(beyond.valid && (truth.inverse() * beyond.T_match_query).translation().norm() < 0.3);
}

// Revisits 7.7-7.8 m apart, asked as "seen from within 8 m?": the best feature-stage
// transform of 000112 -> 000072 is wrong (a 6 m shift that overlays the walls), densely
// aligned it fails the free-space check, and the candidate's next transform is the right
// one. Aligning only the best (dense_hypotheses = 1) loses the revisit.
TEST(PlaceMatch, DenseAlignmentFallsBackOnTheNextTransform) {
  LEX3D_REQUIRE_SHARED(kBalm);
  Balm& b = Balm::get();
  const PlaceScan q = b.place("000112"), m = b.place("000072");
  const Pose truth = b.pose("000072").inverse() * b.pose("000112");
  ASSERT_GT(truth.translation().head<2>().norm(), 7.5);
  PlaceParams p;
  p.max_distance = 8.0;
  const PlaceMatch r = match_scans(q, m, p);
  ASSERT_TRUE(r.valid) << "conflict " << r.rejected_conflict << ", distance " << r.rejected_distance;
  EXPECT_TRUE(r.dense_refined);
  EXPECT_GT(r.dense_tried, 1U) << "the best feature transform is right: the fallback is not exercised";
  EXPECT_GT(r.score, 0.15);
  expect_pose_near(r.T_match_query, truth, 0.1, 0.75, "000112 -> 000072");
  const Pose d = truth.inverse() * r.T_match_query;
  std::printf("000112 -> 000072: score %.3f, transform %zu of %zu, error %.3f m %.2f deg\n", r.score, r.dense_tried,
              r.alternatives.size() + 1, d.translation().norm(), Eigen::AngleAxisd(d.linear()).angle() * 180.0 / M_PI);
  p.dense_hypotheses = 1;
  const PlaceMatch only_best = match_scans(q, m, p);
  EXPECT_TRUE(!only_best.valid || (truth.inverse() * only_best.T_match_query).translation().norm() > 1.0);
}

// A query that accepts none of its first top_k candidates verifies the next more_candidates.
// A decoy holds the query's own words (retrieved first, tf-idf similarity 1) with the
// geometry of a scan 14 m away; with top_k = 1 the revisit 7.8 m away is found only by the
// second round.
TEST(PlaceDatabase, MoreCandidatesWhenNoneIsAccepted) {
  LEX3D_REQUIRE_SHARED(kBalm);
  Balm& b = Balm::get();
  const PlaceScan q = b.place("000162");
  PlaceDatabase db;
  PlaceScan decoy = b.place("000040");
  decoy.words = q.words;
  decoy.name = "decoy";
  db.add(std::move(decoy));
  for (const char* f : {"000060", "000108", "000000"}) db.add(b.place(f));
  const auto ranked = db.retrieve(q, db.size());
  ASSERT_FALSE(ranked.empty());
  ASSERT_EQ(db.name(ranked.front().first), "decoy");
  PlaceParams p;
  p.max_distance = 8.0;
  p.top_k = 1;
  p.more_candidates = 0;
  const auto first = db.query(q, p);
  EXPECT_EQ(first.retrieved, 1U);
  EXPECT_FALSE(first.accepted);
  for (const auto& m : first.matches) EXPECT_NE(db.name(m.scan), "000108");
  p.more_candidates = 8;
  const auto more = db.query(q, p);
  EXPECT_EQ(more.retrieved, ranked.size());
  ASSERT_TRUE(more.best() != nullptr);
  ASSERT_TRUE(more.best()->valid);
  EXPECT_EQ(db.name(more.best()->scan), "000108");
  const Pose truth = b.pose("000108").inverse() * b.pose("000162");
  expect_pose_near(more.best()->T_match_query, truth, 0.1, 0.75, "000162 -> 000108");
  const Pose d = truth.inverse() * more.best()->T_match_query;
  std::printf("000162 -> 000108: score %.3f, error %.3f m %.2f deg\n", more.best()->score, d.translation().norm(),
              Eigen::AngleAxisd(d.linear()).angle() * 180.0 / M_PI);
}

// Scans 17.7 m apart in a courtyard with a 90-degree symmetry: a transform turned by 90
// degrees aligns them with a score above the threshold, but many points of one scan then
// lie where the other scan's beams passed through; the free-space check rejects it.
TEST(PlaceMatch, FreeSpaceCheckRejectsASymmetricWrongTransform) {
  LEX3D_REQUIRE_SHARED(kBalm);
  Balm& b = Balm::get();
  const PlaceScan q = b.place("000088"), m = b.place("000036");
  PlaceParams off;
  off.max_conflict = 1.0;
  const PlaceMatch wrong = match_scans(q, m, off);
  ASSERT_TRUE(wrong.valid);
  const Pose truth = b.pose("000036").inverse() * b.pose("000088");
  const Pose d = truth.inverse() * wrong.T_match_query;
  EXPECT_GT(Eigen::AngleAxisd(d.linear()).angle() * 180.0 / M_PI, 45.0) << "the transform is not the wrong one any more";
  EXPECT_GT(std::max(wrong.dense_q.conflict_share(), wrong.dense_m.conflict_share()), PlaceParams{}.max_conflict);
  const PlaceMatch checked = match_scans(q, m, PlaceParams{});
  EXPECT_FALSE(checked.valid);
  EXPECT_TRUE(checked.rejected_conflict);
  // A true revisit passes the same check.
  const PlaceMatch right = match_scans(b.place("000176"), b.place("000114"), PlaceParams{});
  EXPECT_TRUE(right.valid);
  EXPECT_FALSE(right.rejected_conflict);
  EXPECT_LE(std::max(right.dense_q.conflict_share(), right.dense_m.conflict_share()), PlaceParams{}.max_conflict);
}

TEST(PlaceDatabase, SaveLoadRoundTrip) {
  LEX3D_REQUIRE_SHARED(kBalm);
  Balm& b = Balm::get();
  for (const int bits : {4, 8}) {
    PlaceStorageParams st;
    st.descriptor_bits = bits;
    PlaceDatabase db(st);
    db.set_alphabet(b.alphabet());
    db.add(b.place("000000", st));
    db.add(b.place("000114", st));
    const auto bytes = db.save();
    auto back = PlaceDatabase::load(bytes);
    ASSERT_TRUE(back.ok()) << back.status().to_string();
    const PlaceDatabase& d2 = back.value();
    ASSERT_EQ(d2.size(), 2U);
    EXPECT_TRUE(d2.has_alphabet());
    EXPECT_EQ(d2.alphabet().size(), b.alphabet().size());
    EXPECT_EQ(d2.save(), bytes);
    for (std::size_t i = 0; i < 2; ++i) {
      const PlaceScan& x = db.scan(i);
      const PlaceScan& y = d2.scan(i);
      EXPECT_EQ(x.name, y.name);
      EXPECT_EQ(x.words, y.words);
      EXPECT_EQ(x.descriptor_codes, y.descriptor_codes);
      EXPECT_EQ(x.validation, y.validation);
      ASSERT_EQ(x.features.size(), y.features.size());
      for (std::size_t k = 0; k < x.features.size(); ++k) {
        EXPECT_EQ(x.features[k].position, y.features[k].position);
        EXPECT_LT(x.features[k].rotation.angularDistance(y.features[k].rotation), 2e-4F);
      }
      ASSERT_EQ(x.coarse.state, y.coarse.state);
      for (std::size_t k = 0; k < x.coarse.range.size(); ++k)
        if (x.coarse.state[k] == PixelState::kValid) EXPECT_FLOAT_EQ(x.coarse.range[k], y.coarse.range[k]);
      if (bits == PlaceStorageParams{}.descriptor_bits)
        EXPECT_LE(stored_bytes(x), 20U * 1024U) << "stored bytes of " << x.name;
    }
    // A query gives the same answer on the loaded database.
    const PlaceScan q = b.place("000176", st);
    const auto r1 = db.query(q, {});
    const auto r2 = d2.query(q, {});
    ASSERT_EQ(r1.matches.size(), r2.matches.size());
    for (std::size_t i = 0; i < r1.matches.size(); ++i) {
      EXPECT_EQ(r1.matches[i].scan, r2.matches[i].scan);
      EXPECT_DOUBLE_EQ(r1.matches[i].score, r2.matches[i].score);
    }
  }
}

// A small database (alphabet + one scan with few features) for the corruption tests.
std::vector<std::uint8_t> small_database_bytes() {
  PlaceDatabase db;
  Alphabet a;
  a.descriptor_dim = 4;
  a.word_radius = 0.4;
  a.words.resize(3);
  for (auto& w : a.words) w.descriptor = {0.1F, 0.2F, 0.3F, 0.4F};
  db.set_alphabet(a);
  PlaceScan s;
  s.name = "tiny";
  s.words = {{0, 5}, {2, 1}};
  s.descriptor_dim = 4;
  s.descriptor_bits = db.storage().descriptor_bits;
  for (int i = 0; i < 3; ++i) {
    PlaceFeature f;
    f.position = Eigen::Vector3f(static_cast<float>(i), 1.0F, 0.5F);
    s.features.push_back(f);
    for (int k = 0; k < 4; ++k) s.descriptor_codes.push_back(static_cast<std::uint8_t>((i + k) % 16));
  }
  s.coarse.width = 4;
  s.coarse.height = 2;
  s.coarse.azimuth_resolution_rad = M_PI / 2;
  s.coarse.elevation_resolution_rad = 0.1;
  s.coarse.row_edges = {0.1, 0.0, -0.1};
  s.coarse.state.assign(8, PixelState::kValid);
  s.coarse.state[3] = PixelState::kMaxRange;
  s.coarse.state[5] = PixelState::kUnobserved;
  s.coarse.range.assign(8, 5.0F);
  detail::finish_place_scan(s);
  db.add(s);
  return db.save();
}

TEST(PlaceDatabase, EveryTruncationIsRejected) {
  const auto bytes = small_database_bytes();
  ASSERT_TRUE(PlaceDatabase::load(bytes).ok());
  for (std::size_t n = 0; n < bytes.size(); ++n) {
    const std::vector<std::uint8_t> prefix(bytes.begin(), bytes.begin() + static_cast<std::ptrdiff_t>(n));
    const auto r = PlaceDatabase::load(prefix);
    ASSERT_FALSE(r.ok()) << "prefix of " << n << " bytes accepted";
    EXPECT_EQ(r.status().code(), ErrorCode::kBadData);
  }
  // A byte after the committed database is what an unfinished append leaves: ignored, counted.
  auto longer = bytes;
  longer.push_back(0);
  const auto r = PlaceDatabase::load(longer);
  ASSERT_TRUE(r.ok()) << r.status().to_string();
  EXPECT_EQ(r.value().file_info().ignored_tail_bytes, 1U);
}

TEST(PlaceDatabase, EveryFlippedByteIsRejected) {
  // Every byte is covered by the header CRC, a commit record's CRC or a chunk CRC (or is
  // the magic); a scan's chunk is checked when the scan is read. The commit record not in
  // force (bytes 20-47 of a new file) is a spare: a flip there is ignored.
  const auto bytes = small_database_bytes();
  for (std::size_t i = 0; i < bytes.size(); ++i) {
    auto bad = bytes;
    bad[i] ^= 0x01;
    const auto r = PlaceDatabase::load(bad);
    if (i >= 20 && i < 48) continue;
    EXPECT_TRUE(!r.ok() || !r.value().read_scan(0).ok()) << "flip at byte " << i << " accepted";
  }
  auto bad = bytes;
  bad[bad.size() - 1] ^= 0xFF;  // the last CRC byte (of PIDX)
  const auto r = PlaceDatabase::load(bad);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("CRC"), std::string::npos) << r.status().message();
}

TEST(PlaceDatabase, AbsurdLengthsAreRejectedBeforeAllocating) {
  const auto bytes = small_database_bytes();
  // The PHDR chunk starts at byte 76 (after the commit records); its length field at 80 (u64).
  for (const std::uint64_t len : {std::uint64_t{1} << 40, ~std::uint64_t{0}, std::uint64_t{bytes.size()}}) {
    auto bad = bytes;
    for (int k = 0; k < 8; ++k) bad[80 + static_cast<std::size_t>(k)] = static_cast<std::uint8_t>(len >> (8 * k));
    const auto r = PlaceDatabase::load(bad);
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.status().message().find("exceeds"), std::string::npos) << r.status().message();
  }
  // Bad magic and an unknown major version.
  auto bad = bytes;
  bad[0] = 'X';
  EXPECT_NE(PlaceDatabase::load(bad).status().message().find("magic"), std::string::npos);
  bad = bytes;
  bad[8] = 9;
  EXPECT_NE(PlaceDatabase::load(bad).status().message().find("version"), std::string::npos);
}

// Diagnostics (run with --gtest_also_run_disabled_tests): interest-point repeatability,
// descriptor ranks and frame consistency of the four revisits under the true transform.
TEST(PlaceDiag, DISABLED_Stats) {
  Balm& b = Balm::get();
  for (const float rad : {0.3F, 0.6F, 1.0F})
  for (const auto& [qf, mf] : {std::pair{"000124", "000000"}, std::pair{"000120", "000008"},
                               std::pair{"000176", "000114"}, std::pair{"000110", "000080"}, std::pair{"000002", "000000"}}) {
    PlaceStorageParams st;
    st.descriptor_bits = 8;
    const PlaceScan q = b.place(qf, st), m = b.place(mf, st);
    const Pose T = b.pose(mf).inverse() * b.pose(qf);
    const int dim = q.descriptor_dim;
    std::size_t repeat = 0, rank1 = 0, rank5 = 0, ratio_ok = 0;
    double angsum = 0;
    for (std::size_t i = 0; i < q.features.size(); ++i) {
      const Eigen::Vector3f p = (T.cast<float>() * q.features[i].position);
      std::size_t best = 0;
      float bd = 1e9F;
      for (std::size_t j = 0; j < m.features.size(); ++j) {
        const float d = (m.features[j].position - p).norm();
        if (d < bd) { bd = d; best = j; }
      }
      if (bd > rad) continue;
      ++repeat;
      const Eigen::Matrix3f Rq = (T.linear().cast<float>() * q.features[i].rotation.toRotationMatrix());
      const Eigen::Matrix3f Rm = m.features[best].rotation.toRotationMatrix();
      angsum += Eigen::AngleAxisf(Rq.transpose() * Rm).angle() * 180 / M_PI;
      const float dt = descriptor_distance_sq(q.descriptors.data() + i * dim, m.descriptors.data() + best * dim, dim);
      std::size_t rank = 0;
      float d1 = 1e9F, d2 = 1e9F;
      for (std::size_t j = 0; j < m.features.size(); ++j) {
        const float d = descriptor_distance_sq(q.descriptors.data() + i * dim, m.descriptors.data() + j * dim, dim);
        if (d < dt) ++rank;
        if (d < d1) { d2 = d1; d1 = d; } else if (d < d2) d2 = d;
      }
      if (rank == 0) ++rank1;
      if (rank < 5) ++rank5;
      if (rank == 0 && d1 < 0.64F * d2) ++ratio_ok;
    }
    if (rad == 0.3F) std::printf("truth scores %s->%s: %.3f / %.3f\n", qf, mf, validation_score(q, m, T, PlaceParams{}), validation_score(m, q, T.inverse(), PlaceParams{}));
    std::printf("%s->%s: q %zu m %zu feats; repeatable %zu; rank1 %zu rank5 %zu ratio-ok %zu; mean frame angle %.1f deg (r %.1f)\n",
                qf, mf, q.features.size(), m.features.size(), repeat, rank1, rank5, ratio_ok, repeat ? angsum / repeat : 0.0, double(rad));
  }
}

// Without a pose, the up direction comes from the scan's own surfaces. On every balm scan
// (hand-held, tilted by 10 degrees in the median and up to about 35) the estimate, turned
// into the world frame by the scan's ground-truth pose, is within a few degrees of one
// common vertical. That vertical is 2.4 degrees off the world z axis of balm's poses (the
// mapping pipeline's world frame is not levelled), so each estimate is compared with the
// mean of all of them, and the mean with the world z only loosely.
TEST(PlaceGravity, BalmUpFromPointsAgreesWithThePoses) {
  LEX3D_REQUIRE_SHARED(kBalm);
  auto poses = io::read_pose_list(test::shared_data(kBalm));
  ASSERT_TRUE(poses.ok());
  std::vector<Eigen::Vector3d> world;
  std::vector<double> tilt;
  for (std::size_t i = 0; i < poses.value().size(); ++i) {
    char name[32];
    std::snprintf(name, sizeof name, "balm/%06zu.bin", 2 * i);
    const Cloud c = test::load_or_fail(test::shared_data(name));
    ASSERT_FALSE(c.has_world_pose);
    const GravityEstimate g = estimate_gravity(c, ModelParams{}.features.range);
    ASSERT_EQ(g.source, GravitySource::kPoints) << name;
    world.push_back(poses.value()[i].linear() * g.up);
    tilt.push_back(std::acos(std::clamp(poses.value()[i](2, 2), -1.0, 1.0)) * 180.0 / M_PI);
  }
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& w : world) mean += w;
  mean.normalize();
  auto deg = [](const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
    return std::acos(std::clamp(a.dot(b), -1.0, 1.0)) * 180.0 / M_PI;
  };
  std::vector<double> err;
  for (std::size_t i = 0; i < world.size(); ++i) {
    err.push_back(deg(world[i], mean));
    EXPECT_LT(err.back(), 3.0) << "scan " << 2 * i << ": tilt " << tilt[i] << " deg";
  }
  EXPECT_LT(deg(mean, Eigen::Vector3d::UnitZ()), 5.0);
  std::sort(err.begin(), err.end());
  std::sort(tilt.begin(), tilt.end());
  std::printf("balm up from points: %zu scans, error median %.2f deg, max %.2f deg about their common vertical "
              "(%.2f deg off the poses' z); tilt median %.1f, max %.1f deg\n",
              err.size(), err[err.size() / 2], err.back(), deg(mean, Eigen::Vector3d::UnitZ()), tilt[tilt.size() / 2],
              tilt.back());
  // apply_gravity gives a cloud without a pose the rotation that takes the estimate to +z.
  Cloud c = test::load_or_fail(test::shared_data("balm/000120.bin"));
  EXPECT_EQ(apply_gravity(c, ModelParams{}.features.range), GravitySource::kPoints);
  ASSERT_TRUE(c.has_world_pose);
  const Eigen::Vector3d up = c.T_world_cloud.linear().transpose() * Eigen::Vector3d::UnitZ();
  const Eigen::Vector3d truth = poses.value()[60].linear().transpose() * Eigen::Vector3d::UnitZ();
  EXPECT_LT(std::acos(std::clamp(up.dot(truth), -1.0, 1.0)) * 180.0 / M_PI, 5.0);
  EXPECT_EQ(apply_gravity(c, ModelParams{}.features.range), GravitySource::kPoses);  // a pose stays
}

// Nothing to go on (no points): the spin axis, source none, and no pose is made up.
TEST(PlaceGravity, NoSurfacesGiveNone) {
  Cloud c;
  const GravityEstimate g = estimate_gravity(c);
  EXPECT_EQ(g.source, GravitySource::kNone);
  EXPECT_TRUE(g.up.isApprox(Eigen::Vector3d::UnitZ()));
  EXPECT_EQ(apply_gravity(c), GravitySource::kNone);
  EXPECT_FALSE(c.has_world_pose);
}

// Right alignments of balm scans 7.7-8 m apart, dense alignment from the ground truth: the
// other scan's beams reach beyond the ground and walls it sees at a grazing angle (a pixel
// spans metres of range there), which is no evidence against the point. Counted as
// conflicts, 13-14 % of the visible points were, above the shares of wrong transforms.
TEST(PlaceMatch, FreeSpaceCheckKeepsRightAlignmentsOfFarViewpoints) {
  LEX3D_REQUIRE_SHARED(kBalm);
  Balm& b = Balm::get();
  const PlaceParams p;
  for (const auto& [qf, mf] : {std::pair{"000174", "000080"}, std::pair{"000176", "000126"}}) {
    const PlaceScan q = b.place(qf), m = b.place(mf);
    const Pose truth = b.pose(mf).inverse() * b.pose(qf);
    ASSERT_GT(truth.translation().head<2>().norm(), 7.5);
    const DenseAlignment a = dense_align(q, m, truth, p);
    const DenseConsistency cq = dense_consistency(q, m, a.T_match_query, p);
    const DenseConsistency cm = dense_consistency(m, q, a.T_match_query.inverse(), p);
    EXPECT_GT(cq.visible, 500U);
    EXPECT_LT(std::max(cq.conflict_share(), cm.conflict_share()), p.max_conflict) << qf << " -> " << mf;
  }
}

// kitti00 (HDL-64E on a car): frames 0 and 8, 5.9 m apart along the street, matched in both
// directions with the right pose within 0.1 m / 0.5 deg, also with half of the query's points
// dropped; the free-space check does not reject them.
TEST(PlaceMatch, KittiScansSixMetresApartPassTheFreeSpaceCheck) {
  LEX3D_REQUIRE_SHARED("kitti00/poses.txt");
  auto poses = io::read_pose_list(test::shared_data("kitti00/poses.txt"));
  ASSERT_TRUE(poses.ok());
  // KITTI's poses are of the left camera; the lidar-to-camera transform is the one KITTI's
  // odometry calibration gives for sequences 00-02 (the shared calib.txt has only the cameras).
  Eigen::Matrix4d tr;
  tr << 4.276802385584e-04, -9.999672484946e-01, -8.084491683471e-03, -1.198459927713e-02,  //
      -7.210626507497e-03, 8.081198471645e-03, -9.999413164504e-01, -5.403984729748e-02,   //
      9.999738645903e-01, 4.859485810390e-04, -7.206933692422e-03, -2.921968648686e-01,    //
      0, 0, 0, 1;
  const Pose camera_lidar(tr);
  auto lidar_pose = [&](int k) { return Pose(camera_lidar.inverse() * poses.value()[static_cast<std::size_t>(k)] * camera_lidar); };
  Alphabet alphabet;
  std::map<int, PlaceScan> scans;
  for (const int k : {0, 8, 100, 108}) {  // 100 + k: frame k with every other point dropped at random
    const int f = k % 100;
    char name[32];
    std::snprintf(name, sizeof name, "kitti00/%06d.bin", f);
    Cloud c = test::load_or_fail(test::shared_data(name));
    if (k >= 100) {
      std::mt19937 rng(static_cast<unsigned>(k));
      Cloud half;
      for (std::size_t i = 0; i < c.size(); ++i)
        if (rng() % 2 == 0) half.points.push_back(c.points[i]);
      ASSERT_NEAR(static_cast<double>(half.size()), 0.5 * static_cast<double>(c.size()), 0.01 * static_cast<double>(c.size()));
      c = std::move(half);
    }
    c.T_world_cloud = lidar_pose(f);
    c.has_world_pose = true;
    const ModelParams mp;
    const PreparedScan s = prepare_scan(c, mp, 0.39);
    if (alphabet.size() == 0) {
      alphabet.descriptor_dim = s.features.descriptor_dim;
      alphabet.word_radius = s.word_radius;
      for (std::size_t i = 0; i < s.features.size(); i += 60) {
        Word w;
        w.descriptor.assign(s.features.descriptor(i), s.features.descriptor(i) + s.features.descriptor_dim);
        alphabet.words.push_back(std::move(w));
      }
    }
    scans.emplace(k, make_place_scan(s, alphabet, PlaceStorageParams{}, mp.features.range, name));
  }
  for (const auto& [qk, mk] : {std::pair{8, 0}, std::pair{0, 8}, std::pair{108, 0}, std::pair{100, 8}}) {
    const std::string what = std::to_string(qk) + " -> " + std::to_string(mk);
    const PlaceMatch m = match_scans(scans.at(qk), scans.at(mk), PlaceParams{});
    EXPECT_TRUE(m.valid) << what << (m.rejected_conflict ? ": rejected by the free-space check" : "");
    EXPECT_FALSE(m.rejected_conflict) << what;
    EXPECT_GE(m.score, PlaceParams{}.accept_score) << what;
    EXPECT_LT(std::max(m.dense_q.conflict_share(), m.dense_m.conflict_share()), PlaceParams{}.max_conflict) << what;
    const Pose truth = lidar_pose(mk % 100).inverse() * lidar_pose(qk % 100);
    EXPECT_GT(truth.translation().norm(), 5.0);
    expect_pose_near(m.T_match_query, truth, 0.1, 0.5, what);
    const Pose d = truth.inverse() * m.T_match_query;
    std::printf("%s: score %.3f, error %.3f m %.2f deg\n", what.c_str(), m.score, d.translation().norm(),
                Eigen::AngleAxisd(d.linear()).angle() * 180.0 / M_PI);
  }
}

// Free-space conflicts of right alignments (dense alignment from the ground truth) of balm
// scans 4-10 m apart, 20 s or more apart in time: the shares the check bounds.
TEST(PlaceDiag, DISABLED_ConflictAtTruth) {
  Balm& b = Balm::get();
  PlaceParams p;
  std::vector<double> shares;
  for (int i = 0; i < 89; i += 1)
    for (int j = i + 20; j < 89; j += 1) {
      char qf[16], mf[16];
      std::snprintf(qf, sizeof qf, "%06d", 2 * j);
      std::snprintf(mf, sizeof mf, "%06d", 2 * i);
      const Pose truth = b.pose(mf).inverse() * b.pose(qf);
      const double dist = (b.pose(mf).translation() - b.pose(qf).translation()).head<2>().norm();
      if (dist < 4.0 || dist > 10.0) continue;
      const PlaceScan q = b.place(qf), m = b.place(mf);
      const DenseAlignment a = dense_align(q, m, truth, p);
      const DenseConsistency cq = dense_consistency(q, m, a.T_match_query, p);
      const DenseConsistency cm = dense_consistency(m, q, a.T_match_query.inverse(), p);
      const double s = std::max(cq.conflict_share(), cm.conflict_share());
      shares.push_back(s);
      std::printf("CONFLICT %s %s %.2f m: %.3f (q %zu/%zu, m %zu/%zu)\n", qf, mf, dist, s, cq.conflict, cq.visible,
                  cm.conflict, cm.visible);
    }
}
}  // namespace
}  // namespace lex3d
