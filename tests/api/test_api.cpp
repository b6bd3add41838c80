// The one-call API (lex3d/lex3d.hpp) and the PCL adapters: round trips within the bound,
// the same bytes as the `lex3d` command, determinism, and the error paths.

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <limits>
#include <string>

#include <unistd.h>

#include <pcl/point_types.h>

#include "lex3d/codec/codec.hpp"
#include "lex3d/core/pcl_conversions.hpp"
#include "lex3d/eval/metrics.hpp"
#include "lex3d/io/io.hpp"
#include "lex3d/lex3d.hpp"
#include "test_config.hpp"

namespace fs = std::filesystem;

namespace {

lex3d::Cloud sample(const std::string& name) {
  auto r = lex3d::io::read_cloud(std::string(LEX3D_SAMPLES_DIR) + "/" + name);
  EXPECT_TRUE(r.ok()) << r.status().to_string();
  return std::move(r).value().cloud;
}

std::vector<std::uint8_t> read(const fs::path& p) {
  auto r = lex3d::io::read_file(p.string());
  EXPECT_TRUE(r.ok()) << r.status().to_string();
  return r.ok() ? std::move(r).value() : std::vector<std::uint8_t>{};
}

/// Runs the `lex3d` command with `args`; its exit code.
int run_cli(const std::string& args) {
  const std::string cmd = std::string("\"") + LEX3D_CLI + "\" " + args + " > /dev/null 2>&1";
  return std::system(cmd.c_str());
}

fs::path work_dir(const std::string& name) {
  const fs::path d = fs::temp_directory_path() / ("lex3d_test_api_" + name + "_" + std::to_string(::getpid()));
  fs::create_directories(d);
  return d;
}

}  // namespace

TEST(Api, VersionMatchesTheHeaders) { EXPECT_STREQ(lex3d::version(), LEX3D_VERSION_STRING); }

TEST(Api, LayeredRoundTripOfARealScanMeetsTheBoundBothWays) {
  const lex3d::Cloud cloud = sample("kitti00_000000.bin");
  ASSERT_GT(cloud.size(), 100000U);
  lex3d::CompressOptions o;
  o.max_error = 0.03;
  auto c = lex3d::compress(cloud, o);
  ASSERT_TRUE(c.ok()) << c.status().to_string();
  EXPECT_FALSE(c.value().words);  // with a layer, words are off by default
  EXPECT_EQ(c.value().input_points, cloud.size());
  EXPECT_LT(c.value().bits_per_point(), 32.0);
  EXPECT_TRUE(c.value().dropped_attributes.empty());  // the KITTI intensity is kept
  ASSERT_EQ(c.value().attributes.size(), 1U);
  EXPECT_EQ(c.value().attributes[0].name, "intensity");
  EXPECT_EQ(c.value().attributes[0].max_error, 0.0);
  auto d = lex3d::decompress(c.value().bytes);
  ASSERT_TRUE(d.ok()) << d.status().to_string();
  EXPECT_TRUE(d.value().residual_layer);
  EXPECT_EQ(d.value().input_points, cloud.size());
  const auto dist = lex3d::eval::compare_clouds(cloud, d.value().cloud);
  EXPECT_LE(dist.hausdorff, 0.03 * (1 + 1e-6));
  EXPECT_TRUE(d.value().cloud.has_intensity());
}

TEST(Api, ScanStampAndFrameComeBackFromTheModelFile) {
  lex3d::Cloud cloud = sample("newer_college_00.bin");
  lex3d::CompressOptions o;
  o.max_error = 0.05;
  auto plain = lex3d::compress(cloud, o);
  ASSERT_TRUE(plain.ok()) << plain.status().to_string();
  cloud.stamp = lex3d::ScanStamp{lex3d::ScanStamp::Source::kMessage, 1700000000, 250000000, "os_sensor"};
  auto c = lex3d::compress(cloud, o);
  ASSERT_TRUE(c.ok()) << c.status().to_string();
  EXPECT_EQ(c.value().bytes.size(), plain.value().bytes.size() + 12 + 15 + 9 + 4);  // the `scan` chunk alone
  auto d = lex3d::decompress(c.value().bytes);
  ASSERT_TRUE(d.ok()) << d.status().to_string();
  ASSERT_TRUE(d.value().cloud.stamp.has_value());
  EXPECT_EQ(d.value().cloud.stamp->sec, 1700000000U);
  EXPECT_EQ(d.value().cloud.stamp->nsec, 250000000U);
  EXPECT_EQ(d.value().cloud.stamp->frame_id, "os_sensor");
  EXPECT_EQ(d.value().cloud.stamp->source, lex3d::ScanStamp::Source::kMessage);
  EXPECT_FALSE(lex3d::decompress(plain.value().bytes).value().cloud.stamp.has_value());
}

TEST(Api, SameBytesAsTheCommandWithALayerAndWithWords) {
  const fs::path dir = work_dir("cli");
  const std::string scan = std::string(LEX3D_SAMPLES_DIR) + "/newer_college_00.bin";
  const lex3d::Cloud cloud = sample("newer_college_00.bin");
  // A layer of 14 mm (words off), and words only (an alphabet learned on the scan).
  ASSERT_EQ(run_cli("compress " + scan + " -o " + (dir / "layer.lex3dm").string() + " --max-error 0.014"), 0);
  ASSERT_EQ(run_cli("compress " + scan + " -o " + (dir / "words.lex3dm").string() + " --iterations 60 --max-error none"), 0);
  lex3d::CompressOptions layer;
  layer.max_error = 0.014;
  auto a = lex3d::compress(cloud, layer);
  ASSERT_TRUE(a.ok()) << a.status().to_string();
  EXPECT_EQ(a.value().bytes, read(dir / "layer.lex3dm"));
  lex3d::CompressOptions words;
  words.max_iterations = 60;
  auto b = lex3d::compress(cloud, words);
  ASSERT_TRUE(b.ok()) << b.status().to_string();
  EXPECT_TRUE(b.value().words);
  EXPECT_GT(b.value().instances, 0U);
  EXPECT_EQ(b.value().bytes, read(dir / "words.lex3dm"));
  // And the command decompresses what the library wrote, to the same points.
  auto d = lex3d::decompress(b.value().bytes);
  ASSERT_TRUE(d.ok()) << d.status().to_string();
  EXPECT_GT(d.value().cloud.size(), 0U);
  fs::remove_all(dir);
}

TEST(Api, ReusedAlphabetIsReferencedAndNeededToDecode) {
  const lex3d::Cloud cloud = sample("newer_college_00.bin");
  lex3d::AlphabetOptions ao;
  ao.max_iterations = 40;
  const lex3d::AlphabetResult learnt = lex3d::learn_alphabet({cloud}, ao);
  ASSERT_GT(learnt.learning.alphabet.size(), 0U);
  EXPECT_EQ(learnt.learning.bic_history.size(), learnt.learning.accepted + learnt.learning.rejected + 1);
  lex3d::CompressOptions o;
  o.alphabet = learnt.bytes;
  auto c = lex3d::compress(cloud, o);
  ASSERT_TRUE(c.ok()) << c.status().to_string();
  EXPECT_EQ(c.value().alphabet_words, learnt.learning.alphabet.size());
  auto without = lex3d::decompress(c.value().bytes);
  ASSERT_FALSE(without.ok());
  EXPECT_EQ(without.status().code(), lex3d::ErrorCode::kInvalidArgument);
  auto with = lex3d::decompress(c.value().bytes, &learnt.bytes);
  ASSERT_TRUE(with.ok()) << with.status().to_string();
  EXPECT_EQ(with.value().instances, c.value().instances);
  // An alphabet file that does not decode is bad data, named as the alphabet.
  lex3d::CompressOptions bad;
  bad.alphabet = {'n', 'o', 't'};
  auto e = lex3d::compress(cloud, bad);
  ASSERT_FALSE(e.ok());
  EXPECT_EQ(e.status().code(), lex3d::ErrorCode::kBadData);
  EXPECT_NE(e.status().message().find("alphabet"), std::string::npos) << e.status().to_string();
}

TEST(Api, ALayerOnlyFileDecodesWithoutTheSharedAlphabetUnlessASequenceNeedsIt) {
  const lex3d::Cloud cloud = sample("newer_college_00.bin");
  lex3d::AlphabetOptions ao;
  ao.max_iterations = 20;
  const lex3d::AlphabetResult learnt = lex3d::learn_alphabet({cloud}, ao);
  auto alphabet = lex3d::codec::decode_alphabet(learnt.bytes);
  ASSERT_TRUE(alphabet.ok()) << alphabet.status().to_string();
  lex3d::CodingOptions co;
  co.max_error = 0.02;
  co.words = lex3d::WordsMode::kOff;  // the layer alone, whatever the words would save
  for (const bool in_sequence : {false, true}) {
    co.layer_only_references_alphabet = in_sequence;
    const lex3d::ScanCoder coder(alphabet.value(), co, false, learnt.bytes);
    auto c = coder.code(cloud, lex3d::Model{}, 1);
    ASSERT_TRUE(c.ok()) << c.status().to_string();
    EXPECT_FALSE(c.value().words);
    auto alone = lex3d::decompress(c.value().bytes);
    auto with = lex3d::decompress(c.value().bytes, &learnt.bytes);
    ASSERT_TRUE(with.ok()) << with.status().to_string();
    EXPECT_EQ(with.value().references_alphabet, in_sequence);
    if (in_sequence) {
      ASSERT_FALSE(alone.ok());
      EXPECT_EQ(alone.status().code(), lex3d::ErrorCode::kInvalidArgument);
    } else {
      ASSERT_TRUE(alone.ok()) << alone.status().to_string();
      ASSERT_EQ(alone.value().cloud.size(), with.value().cloud.size());
      EXPECT_EQ(lex3d::eval::compare_clouds(alone.value().cloud, with.value().cloud).hausdorff, 0.0);
    }
  }
}

TEST(Api, DeterministicAcrossRunsAndThreadCounts) {
  const lex3d::Cloud cloud = sample("newer_college_00.bin");
  lex3d::CompressOptions o;
  o.max_error = 0.01;
  o.threads = 1;
  auto a = lex3d::compress(cloud, o);
  auto b = lex3d::compress(cloud, o);
  o.threads = 2;
  auto c = lex3d::compress(cloud, o);
  ASSERT_TRUE(a.ok() && b.ok() && c.ok());
  EXPECT_EQ(a.value().bytes, b.value().bytes);
  EXPECT_EQ(a.value().bytes, c.value().bytes);
}

TEST(Api, EmptyCloudRoundTripsToAnEmptyCloud) {
  lex3d::CompressOptions o;
  o.max_error = 0.01;
  auto c = lex3d::compress(lex3d::Cloud{}, o);
  ASSERT_TRUE(c.ok()) << c.status().to_string();
  auto d = lex3d::decompress(c.value().bytes);
  ASSERT_TRUE(d.ok()) << d.status().to_string();
  EXPECT_TRUE(d.value().cloud.empty());
}

TEST(Api, NonFinitePointsAndBadOptionsThrowNamingWhatIsWrong) {
  lex3d::Cloud cloud;
  cloud.points = {{1, 2, 3}, {std::numeric_limits<float>::quiet_NaN(), 0, 0}};
  try {
    (void)lex3d::compress(cloud, {});
    FAIL() << "no exception";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("point 1 is not finite"), std::string::npos) << e.what();
  }
  cloud.points.pop_back();
  cloud.intensity = {1.f, 2.f};
  EXPECT_THROW((void)lex3d::compress(cloud, {}), std::invalid_argument);
  cloud.intensity.clear();
  lex3d::CompressOptions o;
  o.max_error = 50.0;
  try {
    (void)lex3d::compress(cloud, o);
    FAIL() << "no exception";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("max_error"), std::string::npos) << e.what();
  }
  o.max_error.reset();
  o.words = lex3d::WordsMode::kOff;
  EXPECT_THROW((void)lex3d::compress(cloud, o), std::invalid_argument);
  EXPECT_THROW((void)lex3d::learn_alphabet({}, lex3d::AlphabetOptions{}), std::invalid_argument);
}

TEST(Api, CorruptAndTruncatedFilesAreBadDataNotCrashes) {
  const lex3d::Cloud cloud = sample("newer_college_00.bin");
  lex3d::CompressOptions o;
  o.max_error = 0.02;
  auto c = lex3d::compress(cloud, o);
  ASSERT_TRUE(c.ok());
  const std::vector<std::uint8_t>& bytes = c.value().bytes;
  for (std::size_t n : {std::size_t{0}, std::size_t{3}, bytes.size() / 2, bytes.size() - 1}) {
    auto d = lex3d::decompress(std::vector<std::uint8_t>(bytes.begin(), bytes.begin() + static_cast<std::ptrdiff_t>(n)));
    ASSERT_FALSE(d.ok()) << "truncated to " << n;
    EXPECT_EQ(d.status().code(), lex3d::ErrorCode::kBadData);
  }
  std::vector<std::uint8_t> flipped = bytes;
  flipped[bytes.size() / 2] ^= 0x40;
  auto d = lex3d::decompress(flipped);
  EXPECT_FALSE(d.ok());  // the chunk's crc32
}

TEST(Api, TargetBitsPerPointPicksABoundThatFits) {
  const lex3d::Cloud cloud = sample("newer_college_00.bin");
  lex3d::CompressOptions o;
  o.target_bpp = 6.0;
  auto c = lex3d::compress(cloud, o);
  ASSERT_TRUE(c.ok()) << c.status().to_string();
  ASSERT_TRUE(c.value().max_error.has_value());
  EXPECT_LE(c.value().bits_per_point(), 6.0);
  // With the mean-squared-error objective the search fits the same budget: a bound at least
  // as large (the objective codes finer at a given bound), every point within it.
  o.mse = true;
  auto m = lex3d::compress(cloud, o);
  ASSERT_TRUE(m.ok()) << m.status().to_string();
  ASSERT_TRUE(m.value().max_error.has_value());
  EXPECT_LE(m.value().bits_per_point(), 6.0);
  EXPECT_GE(*m.value().max_error, *c.value().max_error);
  auto back = lex3d::decompress(m.value().bytes);
  ASSERT_TRUE(back.ok()) << back.status().to_string();
  EXPECT_LE(lex3d::eval::compare_clouds(cloud, back.value().cloud).hausdorff, *m.value().max_error);
}

TEST(PclConversions, CarryIntensityAndPoseAndCountNonFinitePoints) {
  pcl::PointCloud<pcl::PointXYZI> in;
  for (int i = 0; i < 6; ++i) {
    pcl::PointXYZI p;
    p.x = static_cast<float>(i);
    p.y = 1.f;
    p.z = 2.f;
    p.intensity = 10.f * static_cast<float>(i);
    in.push_back(p);
  }
  in[2].x = std::numeric_limits<float>::quiet_NaN();
  in.sensor_origin_ = Eigen::Vector4f(1, 2, 3, 0);
  lex3d::PclConversionStats stats;
  const lex3d::Cloud cloud = lex3d::from_pcl(in, &stats);
  EXPECT_EQ(stats.non_finite, 1U);
  ASSERT_EQ(cloud.size(), 5U);
  ASSERT_TRUE(cloud.has_intensity());
  EXPECT_FLOAT_EQ(cloud.intensity[2], 30.f);  // the NaN point's neighbour moved up
  EXPECT_FLOAT_EQ(cloud.points[2].x(), 3.f);
  EXPECT_TRUE(cloud.T_cloud_sensor.translation().isApprox(Eigen::Vector3d(1, 2, 3)));
  EXPECT_FALSE(cloud.has_rings());

  const auto xyz = lex3d::to_pcl<pcl::PointXYZ>(cloud);
  ASSERT_EQ(xyz.size(), 5U);
  EXPECT_FLOAT_EQ(xyz[4].x, 5.f);
  EXPECT_TRUE(xyz.sensor_origin_.head<3>().isApprox(Eigen::Vector3f(1, 2, 3)));
  const auto xyzi = lex3d::to_pcl<pcl::PointXYZI>(cloud);
  EXPECT_FLOAT_EQ(xyzi[4].intensity, 50.f);
  const lex3d::Cloud plain = lex3d::from_pcl(xyz);
  EXPECT_FALSE(plain.has_intensity());
}

TEST(PclConversions, OrganisedCloudKeepsRowsAsRings) {
  pcl::PointCloud<pcl::PointXYZ> in(4, 3);  // 4 columns, 3 rows
  for (std::size_t i = 0; i < in.size(); ++i) in[i] = pcl::PointXYZ(1.f + static_cast<float>(i), 0.f, 0.f);
  in.at(1, 2).x = std::numeric_limits<float>::quiet_NaN();  // column 1, row 2: a no-return
  const lex3d::Cloud cloud = lex3d::from_pcl(in);
  ASSERT_EQ(cloud.size(), 11U);
  ASSERT_TRUE(cloud.has_rings());
  ASSERT_TRUE(cloud.has_columns());
  EXPECT_EQ(cloud.rows, 3U);
  EXPECT_EQ(cloud.columns, 4U);
  EXPECT_EQ(cloud.ring[10], 2U);
  EXPECT_EQ(cloud.column[10], 3U);
  EXPECT_EQ(cloud.ring[9], 2U);
  EXPECT_EQ(cloud.column[9], 2U);
}
