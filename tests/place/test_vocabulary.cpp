// The recognition vocabulary (formats/place_db.md 2.1, VOCB and VIDX): learning is
// deterministic for a seed, the vocabulary and its index round-trip through the file and
// through an append, corrupt or truncated vocabulary bytes are rejected as bad data, and
// retrieval over it finds a scan's own copy and a real balm revisit.

#include <cstring>
#include <random>
#include <string>

#include <gtest/gtest.h>

#include "lex3d/io/io.hpp"
#include "lex3d/place/place.hpp"
#include "lex3d/place/vocabulary.hpp"
#include "place/internal.hpp"
#include "support/test_support.hpp"

namespace lex3d {
namespace {

using Bytes = std::vector<std::uint8_t>;
constexpr int kDim = 8;

// A synthetic scan whose descriptors are noisy copies of `place`'s prototypes, so scans of
// the same place share words and scans of different places mostly do not.
PlaceScan scan_of_place(std::uint32_t place, std::uint32_t seed) {
  std::mt19937 proto(place * 7919u + 1u), rng(seed * 104729u + place);
  std::uniform_real_distribution<float> u(-0.9F, 0.9F);
  std::normal_distribution<float> noise(0.0F, 0.05F);
  PlaceScan s;
  s.name = "p" + std::to_string(place) + "_" + std::to_string(seed);
  s.descriptor_dim = kDim;
  s.descriptor_bits = 8;
  s.words = {{0, 3}, {1 + place % 5, 2}};
  for (int i = 0; i < 40; ++i) {
    PlaceFeature f;
    f.position = Eigen::Vector3f(u(rng) * 10, u(rng) * 10, u(rng));
    s.features.push_back(f);
    for (int k = 0; k < kDim; ++k) {
      const float v = u(proto) + noise(rng);
      s.descriptor_codes.push_back(detail::quantise_descriptor_value(v, 8));
    }
  }
  detail::finish_place_scan(s);
  return s;
}

std::vector<PlaceScan> training(std::uint32_t places) {
  std::vector<PlaceScan> t;
  for (std::uint32_t p = 0; p < places; ++p) t.push_back(scan_of_place(p, 0));
  return t;
}

PlaceVocabulary learn(const std::vector<PlaceScan>& scans, std::uint64_t seed = 1) {
  std::vector<const PlaceScan*> ptrs;
  for (const auto& s : scans) ptrs.push_back(&s);
  VocabularyParams p;
  p.words = 256;
  p.branching = 8;
  p.seed = seed;
  return learn_vocabulary(ptrs, p);
}

PlaceStorageParams storage8() {
  PlaceStorageParams s;
  s.descriptor_bits = 8;
  return s;
}

void put_piece(Bytes& file, const PlaceFileWriter::Piece& p) {
  if (file.size() < p.offset + p.bytes.size()) file.resize(static_cast<std::size_t>(p.offset + p.bytes.size()));
  std::memcpy(file.data() + p.offset, p.bytes.data(), p.bytes.size());
}

TEST(PlaceVocabulary, LearningIsDeterministicForASeed) {
  const auto t = training(30);
  const PlaceVocabulary a = learn(t), b = learn(t);
  EXPECT_GT(a.leaves(), 8U);
  EXPECT_EQ(encode_vocabulary(a), encode_vocabulary(b));
  // Every training descriptor descends to a leaf; the words of a scan are sorted path nodes.
  const auto w = a.words(t[0]);
  ASSERT_FALSE(w.empty());
  for (std::size_t i = 1; i < w.size(); ++i) EXPECT_LT(w[i - 1].first, w[i].first);
  std::uint32_t leaf_total = 0;
  for (const auto& [node, count] : w) {
    EXPECT_NE(node, 0U);  // the root is never a word
    if (a.is_leaf(node)) leaf_total += count;
  }
  EXPECT_EQ(leaf_total, t[0].features.size());
  // The Chow–Liu forest links leaves only.
  for (std::uint32_t i = 0; i < a.nodes(); ++i)
    if (a.parent[i] != PlaceVocabulary::kNoParent) {
      EXPECT_TRUE(a.is_leaf(i));
      EXPECT_TRUE(a.is_leaf(a.parent[i]));
    }
}

TEST(PlaceVocabulary, BadParamsAndNoDescriptorsAreRefused) {
  VocabularyParams p;
  p.branching = 1;
  EXPECT_THROW(p.validate(), std::invalid_argument);
  EXPECT_THROW((void)learn_vocabulary({}, VocabularyParams{}), std::invalid_argument);
}

TEST(PlaceVocabulary, RetrievalFindsTheSamePlaceWithEveryMethod) {
  const auto t = training(30);
  PlaceDatabase db(storage8());
  db.set_vocabulary(learn(t));
  for (const auto& s : t) db.add(s);
  EXPECT_THROW(db.set_vocabulary(learn(t)), std::logic_error);
  PlaceParams params;
  for (const std::uint32_t place : {3u, 11u, 27u}) {
    const PlaceScan q = scan_of_place(place, 5);  // another visit of the place: new noise
    for (const auto m : {PlaceRetrieval::kTfidf, PlaceRetrieval::kFabmap}) {
      double pnew = -1;
      const auto r = db.retrieve(q, 5, m, params, &pnew);
      ASSERT_FALSE(r.empty());
      EXPECT_EQ(r[0].first, place) << to_string(m);
      if (m == PlaceRetrieval::kFabmap) {
        EXPECT_GE(pnew, 0.0);
        EXPECT_LT(pnew, 0.5) << "a known place";
      }
    }
  }
  // A place never seen: FAB-MAP says it is new.
  double pnew = -1;
  (void)db.retrieve(scan_of_place(1000, 1), 5, PlaceRetrieval::kFabmap, params, &pnew);
  EXPECT_GT(pnew, 0.5);
  // Without a vocabulary the vocabulary methods are refused.
  PlaceDatabase plain(storage8());
  plain.add(t[0]);
  EXPECT_THROW((void)plain.retrieve(t[0], 5, PlaceRetrieval::kTfidf, params), std::invalid_argument);
  EXPECT_EQ(plain.resolve(PlaceRetrieval::kDefault), PlaceRetrieval::kTfidfAlphabet);
  EXPECT_EQ(db.resolve(PlaceRetrieval::kDefault), PlaceRetrieval::kTfidfAlphabet);
}

void expect_same(const PlaceDatabase& a, const PlaceDatabase& b, const std::vector<PlaceScan>& queries) {
  PlaceParams params;
  for (const auto m : {PlaceRetrieval::kTfidfAlphabet, PlaceRetrieval::kTfidf, PlaceRetrieval::kFabmap})
    for (const auto& q : queries) {
      const auto ra = a.retrieve(q, 1000, m, params), rb = b.retrieve(q, 1000, m, params);
      ASSERT_EQ(ra.size(), rb.size()) << to_string(m);
      for (std::size_t i = 0; i < ra.size(); ++i) {
        EXPECT_EQ(ra[i].first, rb[i].first) << to_string(m) << " rank " << i;
        EXPECT_EQ(ra[i].second, rb[i].second) << to_string(m) << " rank " << i;  // bit for bit
      }
    }
}

TEST(PlaceVocabulary, RoundTripsThroughTheFileAndAnAppend) {
  const auto t = training(20);
  PlaceDatabase mem(storage8());
  mem.set_vocabulary(learn(t));
  for (std::size_t i = 0; i < 12; ++i) mem.add(t[i]);
  const Bytes bytes = mem.save();
  EXPECT_EQ(bytes[10], 1) << "format 2.1";
  auto file = PlaceDatabase::load(bytes);
  ASSERT_TRUE(file.ok()) << file.status().to_string();
  ASSERT_TRUE(file.value().has_vocabulary());
  EXPECT_EQ(encode_vocabulary(*file.value().vocabulary()), encode_vocabulary(*mem.vocabulary()));
  std::vector<PlaceScan> qs{scan_of_place(2, 9), scan_of_place(15, 9), scan_of_place(500, 9)};
  expect_same(mem, file.value(), qs);
  // Append the other scans in place: the new VIDX is found from the new commit.
  PlaceFileWriter w(file.value());
  Bytes appended = bytes;
  appended.resize(static_cast<std::size_t>(w.start()));
  for (std::size_t i = 12; i < t.size(); ++i) {
    put_piece(appended, w.add(t[i]));
    mem.add(t[i]);
  }
  const auto [idx, commit] = w.finish();
  put_piece(appended, idx);
  put_piece(appended, commit);
  auto again = PlaceDatabase::load(appended);
  ASSERT_TRUE(again.ok()) << again.status().to_string();
  EXPECT_EQ(again.value().size(), t.size());
  EXPECT_GT(again.value().file_info().dead_bytes, 0U);
  expect_same(mem, again.value(), qs);
  // A database written without a vocabulary opens as before (no VOCB: tf-idf over the alphabet).
  PlaceDatabase plain(storage8());
  plain.add(t[0]);
  auto p = PlaceDatabase::load(plain.save());
  ASSERT_TRUE(p.ok());
  EXPECT_FALSE(p.value().has_vocabulary());
}

TEST(PlaceVocabulary, CorruptOrTruncatedVocabularyIsBadData) {
  const auto t = training(10);
  PlaceDatabase mem(storage8());
  mem.set_vocabulary(learn(t));
  for (std::size_t i = 0; i < 3; ++i) mem.add(t[i]);
  const Bytes file = mem.save();
  ASSERT_TRUE(PlaceDatabase::load(file).ok());
  for (std::size_t n = 0; n < file.size(); n += 7) {
    const auto r = PlaceDatabase::load(Bytes(file.begin(), file.begin() + static_cast<std::ptrdiff_t>(n)));
    ASSERT_FALSE(r.ok()) << n;
    EXPECT_EQ(r.status().code(), ErrorCode::kBadData);
  }
  // Every flipped byte of the file is rejected on open or when its scan is read, except in
  // the spare commit record.
  for (std::size_t i = 0; i < file.size(); i += 3) {
    if (i >= 20 && i < 76) continue;
    Bytes bad = file;
    bad[i] ^= 0x10;
    const auto r = PlaceDatabase::load(bad);
    bool caught = !r.ok();
    for (std::size_t s = 0; !caught && s < r.value().size(); ++s) caught = !r.value().read_scan(s).ok();
    EXPECT_TRUE(caught) << "flip at byte " << i;
  }
  // The VOCB payload's own checks (behind the CRC): truncations and bad fields.
  const Bytes v = encode_vocabulary(*mem.vocabulary());
  for (std::size_t n = 0; n < v.size(); n += 5) EXPECT_FALSE(decode_vocabulary(v.data(), n, 0).ok()) << n;
  ASSERT_TRUE(decode_vocabulary(v.data(), v.size(), 0).ok());
  auto with = [&](std::size_t at, std::uint32_t value) {
    Bytes b = v;
    std::memcpy(b.data() + at, &value, 4);  // little-endian hosts (x86, ARM)
    return decode_vocabulary(b.data(), b.size(), 100);
  };
  EXPECT_FALSE(with(0, 0).ok());            // descriptor size 0
  EXPECT_FALSE(with(4, 1).ok());            // branching 1
  EXPECT_FALSE(with(8, 0xFFFFFFF0u).ok());  // node count: sizes checked before allocating
  EXPECT_FALSE(with(24, 0).ok());           // the root without children: not a tree
  const auto bad = with(24 + 4 * 1, 200);   // a child count beyond the branching
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), ErrorCode::kBadData);
  EXPECT_GE(bad.status().offset().value_or(0), 100U) << "offsets are file offsets";
  const std::size_t stats_at = v.size() - 16 * mem.vocabulary()->nodes();
  float two = 2.0F;
  std::uint32_t bits = 0;
  std::memcpy(&bits, &two, 4);
  EXPECT_FALSE(with(stats_at, bits).ok());  // a probability of 2
  EXPECT_FALSE(with(stats_at + 4, 0xFFFFFFF0u).ok());  // a Chow–Liu parent out of range
}

TEST(PlaceVocabulary, BalmRevisitRankedFirst) {
  LEX3D_REQUIRE_SHARED("balm/poses.txt");
  auto poses = io::read_pose_list(test::shared_data("balm/poses.txt"));
  ASSERT_TRUE(poses.ok());
  Alphabet alphabet;
  auto place = [&](const std::string& frame) {
    Cloud c = test::load_or_fail(test::shared_data("balm/" + frame + ".bin"));
    c.T_world_cloud = poses.value().at(static_cast<std::size_t>(std::stoi(frame) / 2));
    c.has_world_pose = true;
    const PreparedScan s = prepare_scan(c, ModelParams{}, 0.39);
    if (alphabet.size() == 0) {
      alphabet.descriptor_dim = s.features.descriptor_dim;
      alphabet.word_radius = s.word_radius;
      for (std::size_t i = 0; i < s.features.size(); i += 60) {
        Word w;
        w.descriptor.assign(s.features.descriptor(i), s.features.descriptor(i) + s.features.descriptor_dim);
        alphabet.words.push_back(std::move(w));
      }
    }
    return make_place_scan(s, alphabet, PlaceStorageParams{}, ModelParams{}.features.range, frame);
  };
  // 000176 revisits 000114 (2.3 m apart, heading ~101 degrees different).
  std::vector<PlaceScan> scans;
  for (const char* f : {"000000", "000008", "000016", "000024", "000040", "000060", "000080", "000090", "000114"})
    scans.push_back(place(f));
  std::vector<const PlaceScan*> ptrs;
  for (const auto& s : scans) ptrs.push_back(&s);
  PlaceDatabase db;
  db.set_alphabet(alphabet);
  db.set_vocabulary(learn_vocabulary(ptrs, VocabularyParams{}));
  for (const auto& s : scans) db.add(s);
  const auto r = db.retrieve(place("000176"), 3, PlaceRetrieval::kTfidf, PlaceParams{});
  ASSERT_FALSE(r.empty());
  EXPECT_EQ(db.name(r[0].first), "000114");
}

}  // namespace
}  // namespace lex3d
