// A database split into shards (consecutive scan ranges, one alphabet) and queried in stages
// (word statistics summed, retrieval under the global idf, the top-K merged, verification on
// the owning shard, merge_verified) answers exactly as one database of all the scans: the
// same entries, scores and transforms, bit for bit. The query goes to the shards as bytes
// (encode_place_query) and verifies as the scan it was made from.

#include <algorithm>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "lex3d/io/io.hpp"
#include "lex3d/place/place.hpp"
#include "support/test_support.hpp"

namespace lex3d {
namespace {

// An alphabet of every `stride`-th feature descriptor of a prepared scan (a stand-in for a
// learned one: the word ids only have to be shared by all the databases).
Alphabet alphabet_of(const PreparedScan& s, std::size_t stride) {
  Alphabet a;
  a.descriptor_dim = s.features.descriptor_dim;
  a.word_radius = s.word_radius;
  for (std::size_t i = 0; i < s.features.size(); i += stride) {
    Word w;
    w.descriptor.assign(s.features.descriptor(i), s.features.descriptor(i) + s.features.descriptor_dim);
    a.words.push_back(std::move(w));
  }
  return a;
}

// Shards [cuts[i], cuts[i+1]) of `scans`, each saved and opened again as a file is.
std::vector<PlaceDatabase> shards_of(const std::vector<PlaceScan>& scans, const Alphabet& a,
                                     const std::vector<std::size_t>& cuts) {
  std::vector<PlaceDatabase> out;
  for (std::size_t i = 0; i + 1 < cuts.size(); ++i) {
    PlaceDatabase db;
    db.set_alphabet(a);
    for (std::size_t k = cuts[i]; k < cuts[i + 1]; ++k) db.add(scans[k]);
    auto file = PlaceDatabase::load(db.save());
    EXPECT_TRUE(file.ok()) << file.status().to_string();
    out.push_back(std::move(file).value());
  }
  return out;
}

// The staged query over `shards` as a distributed driver runs it: the query travels as bytes.
PlaceQueryResult staged_query(const std::vector<PlaceDatabase>& shards, const PlaceScan& query, const PlaceParams& params) {
  const std::vector<std::uint8_t> bytes = encode_place_query(query, shards.front().storage());
  PlaceWordStatistics global;
  std::vector<std::size_t> offsets;
  for (const auto& s : shards) {
    offsets.push_back(static_cast<std::size_t>(global.scans));
    global += s.word_statistics();
  }
  struct Cand {
    std::size_t shard, local;
    double score;
  };
  std::vector<Cand> all;
  for (std::size_t i = 0; i < shards.size(); ++i) {
    auto q = decode_place_query(bytes.data(), bytes.size(), shards[i].storage());
    EXPECT_TRUE(q.ok()) << q.status().to_string();
    for (const auto& [local, score] : shards[i].retrieve(q.value(), static_cast<std::size_t>(params.top_k), global))
      all.push_back({i, local, score});
  }
  std::sort(all.begin(), all.end(), [&](const Cand& a, const Cand& b) {
    if (a.score != b.score) return a.score > b.score;
    return offsets[a.shard] + a.local < offsets[b.shard] + b.local;
  });
  all.resize(std::min(all.size(), static_cast<std::size_t>(params.top_k)));
  std::vector<PlaceVerified> parts;
  for (std::size_t i = 0; i < shards.size(); ++i) {
    std::vector<std::pair<std::size_t, double>> mine;
    for (const auto& c : all)
      if (c.shard == i) mine.emplace_back(c.local, c.score);
    auto q = decode_place_query(bytes.data(), bytes.size(), shards[i].storage());
    parts.push_back(shards[i].verify(q.value(), mine, params));
  }
  PlaceQueryResult r = merge_verified(std::move(parts), offsets, params);
  r.retrieved = all.size();
  return r;
}

void expect_same_result(const PlaceQueryResult& a, const PlaceQueryResult& b, const std::string& what) {
  EXPECT_EQ(a.retrieved, b.retrieved) << what;
  EXPECT_EQ(a.accepted, b.accepted) << what;
  ASSERT_EQ(a.matches.size(), b.matches.size()) << what;
  for (std::size_t i = 0; i < a.matches.size(); ++i) {
    const PlaceMatch &x = a.matches[i], &y = b.matches[i];
    EXPECT_EQ(x.scan, y.scan) << what << " rank " << i;
    EXPECT_EQ(x.valid, y.valid) << what << " rank " << i;
    EXPECT_EQ(x.score, y.score) << what << " rank " << i;  // bit for bit
    EXPECT_EQ(x.retrieval_similarity, y.retrieval_similarity) << what << " rank " << i;
    EXPECT_EQ(x.dense_refined, y.dense_refined) << what << " rank " << i;
    EXPECT_EQ(x.inliers, y.inliers) << what << " rank " << i;
    EXPECT_TRUE(x.T_match_query.isApprox(y.T_match_query, 0.0)) << what << " rank " << i;
  }
}

Cloud moved(Cloud c, double yaw_deg, const Eigen::Vector3d& t) {
  Pose T = Pose::Identity();
  T.linear() = Eigen::AngleAxisd(yaw_deg * M_PI / 180.0, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T.translation() = t;
  for (auto& p : c.points) p = (T * p.cast<double>()).cast<float>();
  return c;
}

TEST(PlaceShards, QueryBytesVerifyAsTheScan) {
  const Cloud c = test::load_or_fail(test::sample("newer_college_00.bin"));
  const PreparedScan s = prepare_scan(c, ModelParams{}, 0.39);
  const Alphabet a = alphabet_of(s, 40);
  const PlaceScan q = make_place_scan(c, a, PlaceStorageParams{}, ModelParams{}, "q");
  const auto bytes = encode_place_query(q, PlaceStorageParams{});
  auto back = decode_place_query(bytes.data(), bytes.size(), PlaceStorageParams{});
  ASSERT_TRUE(back.ok()) << back.status().to_string();
  EXPECT_EQ(back.value().words, q.words);
  EXPECT_EQ(back.value().descriptor_codes, q.descriptor_codes);
  EXPECT_EQ(back.value().validation, q.validation);
  ASSERT_EQ(back.value().features.size(), q.features.size());
  for (std::size_t i = 0; i < q.features.size(); ++i) {
    EXPECT_EQ(back.value().features[i].position, q.features[i].position);
    EXPECT_EQ(back.value().features[i].rotation.coeffs(), q.features[i].rotation.coeffs());
  }
  EXPECT_EQ(back.value().coarse.state, q.coarse.state);
  EXPECT_EQ(back.value().dense_points.size(), q.dense_points.size());
  // Against a moved copy of itself the two forms give the same match.
  const PlaceScan other = make_place_scan(moved(c, 20.0, {1.0, 0.5, 0.0}), a, PlaceStorageParams{}, ModelParams{}, "m");
  const PlaceMatch m1 = match_scans(q, other, PlaceParams{}), m2 = match_scans(back.value(), other, PlaceParams{});
  EXPECT_TRUE(m1.valid);
  EXPECT_EQ(m1.score, m2.score);
  EXPECT_TRUE(m1.T_match_query.isApprox(m2.T_match_query, 0.0));
  // Damaged bytes are refused, not decoded.
  for (const std::size_t at : {std::size_t{0}, std::size_t{5}, bytes.size() / 2, bytes.size() - 1}) {
    auto bad = bytes;
    bad[at] ^= 0x10;
    EXPECT_FALSE(decode_place_query(bad.data(), bad.size(), PlaceStorageParams{}).ok()) << at;
  }
  EXPECT_FALSE(decode_place_query(bytes.data(), bytes.size() - 7, PlaceStorageParams{}).ok());
  PlaceStorageParams eight;
  eight.descriptor_bits = 8;
  EXPECT_FALSE(decode_place_query(bytes.data(), bytes.size(), eight).ok());
}

TEST(PlaceShards, AddRefusesWordsPastTheAlphabet) {
  // A query's bytes carry word ids that decode_place_query cannot check (it has no alphabet);
  // a database given one refuses ids past it instead of growing its inverted lists to them.
  const Cloud c = test::load_or_fail(test::sample("newer_college_00.bin"));
  const PreparedScan s = prepare_scan(c, ModelParams{}, 0.39);
  const Alphabet a = alphabet_of(s, 40);
  PlaceScan q = make_place_scan(c, a, PlaceStorageParams{}, ModelParams{}, "q");
  ASSERT_FALSE(q.words.empty());
  PlaceDatabase db(PlaceStorageParams{});
  db.set_alphabet(a);
  PlaceScan past = q;
  past.words.back().first = static_cast<std::uint32_t>(a.size());
  EXPECT_THROW(db.add(past), std::invalid_argument);
  EXPECT_EQ(db.size(), 0U);
  PlaceDatabase bare(PlaceStorageParams{});
  past.words.back().first = 0xFFFFFFF0U;
  EXPECT_THROW(bare.add(past), std::invalid_argument);
  EXPECT_EQ(bare.size(), 0U);
  EXPECT_EQ(db.add(q), 0U);
  EXPECT_EQ(bare.add(q), 0U);
}

TEST(PlaceShards, SamplesShardedEqualWhole) {
  std::vector<Cloud> clouds;
  for (const char* f : {"newer_college_00.bin", "kitti00_000000.bin", "room_scan1.pcd"})
    clouds.push_back(test::load_or_fail(test::sample(f)));
  const Alphabet a = alphabet_of(prepare_scan(clouds[0], ModelParams{}, 0.39), 40);
  std::vector<PlaceScan> scans;
  for (std::size_t i = 0; i < clouds.size(); ++i)
    scans.push_back(make_place_scan(clouds[i], a, PlaceStorageParams{}, ModelParams{}, "s" + std::to_string(i)));
  const auto whole = shards_of(scans, a, {0, scans.size()});
  PlaceWordStatistics sum;
  const auto shards = shards_of(scans, a, {0, 1, 3});
  for (const auto& s : shards) sum += s.word_statistics();
  EXPECT_TRUE(sum == whole[0].word_statistics());
  PlaceParams p;
  p.top_k = 2;  // fewer than the scans: the merge of the shards' top-K decides
  for (std::size_t i = 0; i < clouds.size(); ++i) {
    const PlaceScan q = make_place_scan(moved(clouds[i], 15.0, {0.8, -0.4, 0.0}), a, PlaceStorageParams{}, ModelParams{}, "q");
    const PlaceQueryResult one = whole[0].query(q, p);
    ASSERT_FALSE(one.matches.empty());
    EXPECT_EQ(one.matches[0].scan, i) << "the moved copy finds its scan";
    expect_same_result(one, staged_query(shards, q, p), "sample " + std::to_string(i));
    expect_same_result(one, staged_query(whole, q, p), "sample " + std::to_string(i) + ", one shard");
  }
}

TEST(PlaceShards, BalmShardedEqualWhole) {
  LEX3D_REQUIRE_SHARED("balm/poses.txt");
  auto poses = io::read_pose_list(test::shared_data("balm/poses.txt"));
  ASSERT_TRUE(poses.ok());
  auto cloud = [&](int frame) {
    Cloud c = test::load_or_fail(test::shared_data("balm/" + std::string(6 - std::to_string(frame).size(), '0') +
                                                   std::to_string(frame) + ".bin"));
    c.T_world_cloud = poses.value().at(static_cast<std::size_t>(frame / 2));
    c.has_world_pose = true;
    return c;
  };
  const Alphabet a = alphabet_of(prepare_scan(cloud(0), ModelParams{}, 0.39), 60);
  std::vector<PlaceScan> scans;
  for (const int f : {0, 8, 20, 40, 60, 80, 90, 100, 106, 114, 130, 150})
    scans.push_back(make_place_scan(cloud(f), a, PlaceStorageParams{}, ModelParams{}, std::to_string(f)));
  PlaceDatabase mem;
  mem.set_alphabet(a);
  for (const auto& s : scans) mem.add(s);
  const auto whole = shards_of(scans, a, {0, scans.size()});
  const auto two = shards_of(scans, a, {0, 6, 12});
  const auto three = shards_of(scans, a, {0, 3, 7, 12});
  PlaceWordStatistics global;
  for (const auto& s : three) global += s.word_statistics();
  PlaceParams p;
  p.threads = 2;
  bool own_idf_differs = false;
  for (const int f : {124, 176, 110, 170, 8}) {
    const PlaceScan q = make_place_scan(cloud(f), a, PlaceStorageParams{}, ModelParams{}, "q");
    // A shard's own statistics rank differently: the test would see a merge that ignored the global idf.
    own_idf_differs |= three[1].retrieve(q, 8) != three[1].retrieve(q, 8, global);
    const PlaceQueryResult one = whole[0].query(q, p);
    expect_same_result(one, mem.query(q, p), "balm " + std::to_string(f) + " in memory");
    expect_same_result(one, staged_query(two, q, p), "balm " + std::to_string(f) + " on 2 shards");
    expect_same_result(one, staged_query(three, q, p), "balm " + std::to_string(f) + " on 3 shards");
  }
  EXPECT_TRUE(own_idf_differs);
  // Statistics that do not cover a shard are refused.
  PlaceWordStatistics part = two[0].word_statistics();
  EXPECT_THROW((void)two[1].retrieve(scans[0], 4, part), std::invalid_argument);
  EXPECT_THROW((void)two[0].verify(scans[0], {{99, 0.5}}, p), std::out_of_range);
}

}  // namespace
}  // namespace lex3d
