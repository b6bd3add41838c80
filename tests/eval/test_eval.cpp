// Tests of lex3d::eval: distances against a brute-force oracle, closed-form cases,
// determinism across thread counts, compression rates, parameter validation, and
// agreement with the independent checker ../shared/tools/pcmetrics.py.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <limits>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <zlib.h>

#include "lex3d/core/timer.hpp"
#include "lex3d/eval/metrics.hpp"
#include "lex3d/io/io.hpp"
#include "support/test_support.hpp"

namespace lex3d::eval {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

Cloud random_cloud(std::mt19937& rng, std::size_t n, float extent) {
  std::uniform_real_distribution<float> u(-extent, extent);
  Cloud c;
  for (std::size_t i = 0; i < n; ++i) c.points.emplace_back(u(rng), u(rng), u(rng));
  return c;
}

Cloud jittered(const Cloud& c, std::uint32_t seed, float amplitude, double drop_share) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-amplitude, amplitude);
  std::uniform_real_distribution<double> keep(0.0, 1.0);
  Cloud out;
  for (const auto& p : c.points) {
    const Eigen::Vector3f q = p + Eigen::Vector3f(u(rng), u(rng), u(rng));
    if (keep(rng) >= drop_share) out.points.push_back(q);
  }
  return out;
}

double sq_dist(const Eigen::Vector3f& p, const Eigen::Vector3f& q) {
  const double dx = static_cast<double>(p.x()) - static_cast<double>(q.x());
  const double dy = static_cast<double>(p.y()) - static_cast<double>(q.y());
  const double dz = static_cast<double>(p.z()) - static_cast<double>(q.z());
  return dx * dx + dy * dy + dz * dz;
}

// O(N*M) nearest squared distances from every point of `from` to `to`.
std::vector<double> brute_nearest_sq(const Cloud& from, const Cloud& to) {
  std::vector<double> out;
  for (const auto& p : from.points) {
    double best = kInf;
    for (const auto& q : to.points) best = std::min(best, sq_dist(p, q));
    out.push_back(best);
  }
  return out;
}

DistanceResult brute_compare(const Cloud& a, const Cloud& b, const DistanceParams& params) {
  const auto da = brute_nearest_sq(a, b);
  const auto db = brute_nearest_sq(b, a);
  DistanceResult r;
  r.points_a = a.size();
  r.points_b = b.size();
  double sa = 0, sb = 0, ma = 0, mb = 0, ha = 0;
  for (double q : da) sa += q, ma += std::sqrt(q), ha = std::max(ha, std::sqrt(q));
  for (double q : db) sb += q, mb += std::sqrt(q), ha = std::max(ha, std::sqrt(q));
  const auto na = static_cast<double>(a.size()), nb = static_cast<double>(b.size());
  r.mse_ab = sa / na;
  r.mse_ba = sb / nb;
  const double mse = std::max(r.mse_ab, r.mse_ba);
  r.rmse = std::sqrt(mse);
  r.d1_psnr_db = 10.0 * std::log10(3.0 * params.peak * params.peak / mse);
  r.chamfer = ma / na + mb / nb;
  r.hausdorff = ha;
  for (double tau : params.taus) {
    const auto cov = std::count_if(da.begin(), da.end(), [&](double q) { return std::sqrt(q) <= tau; });
    const auto out = std::count_if(db.begin(), db.end(), [&](double q) { return std::sqrt(q) > tau; });
    r.coverage.push_back(static_cast<double>(cov) / na);
    r.outliers.push_back(static_cast<double>(out) / nb);
  }
  return r;
}

void expect_rel(double got, double want, double rel, const char* what) {
  EXPECT_NEAR(got, want, rel * std::max(1e-300, std::abs(want))) << what;
}

void expect_same(const DistanceResult& got, const DistanceResult& want, double rel) {
  EXPECT_EQ(got.points_a, want.points_a);
  EXPECT_EQ(got.points_b, want.points_b);
  expect_rel(got.mse_ab, want.mse_ab, rel, "mse_ab");
  expect_rel(got.mse_ba, want.mse_ba, rel, "mse_ba");
  expect_rel(got.rmse, want.rmse, rel, "rmse");
  expect_rel(got.d1_psnr_db, want.d1_psnr_db, rel, "d1_psnr_db");
  expect_rel(got.chamfer, want.chamfer, rel, "chamfer");
  expect_rel(got.hausdorff, want.hausdorff, rel, "hausdorff");
  ASSERT_EQ(got.coverage.size(), want.coverage.size());
  ASSERT_EQ(got.outliers.size(), want.outliers.size());
  for (std::size_t k = 0; k < got.coverage.size(); ++k) {
    EXPECT_EQ(got.coverage[k], want.coverage[k]) << "coverage " << k;
    EXPECT_EQ(got.outliers[k], want.outliers[k]) << "outliers " << k;
  }
}

// Bit-identical results (used across thread counts).
void expect_identical(const DistanceResult& x, const DistanceResult& y) {
  EXPECT_EQ(x.points_a, y.points_a);
  EXPECT_EQ(x.points_b, y.points_b);
  EXPECT_EQ(x.mse_ab, y.mse_ab);
  EXPECT_EQ(x.mse_ba, y.mse_ba);
  EXPECT_EQ(x.d1_psnr_db, y.d1_psnr_db);
  EXPECT_EQ(x.rmse, y.rmse);
  EXPECT_EQ(x.chamfer, y.chamfer);
  EXPECT_EQ(x.hausdorff, y.hausdorff);
  EXPECT_EQ(x.coverage, y.coverage);
  EXPECT_EQ(x.outliers, y.outliers);
}

// ---------------------------------------------------------------- brute force oracle

TEST(CompareClouds, MatchesBruteForceOnRandomClouds) {
  for (std::uint32_t seed = 1; seed <= 6; ++seed) {
    std::mt19937 rng(seed);
    const Cloud a = random_cloud(rng, 200 + 37 * seed, 2.0F);
    // b: part jittered copies of a (close pairs), part unrelated points (outliers).
    Cloud b = jittered(a, seed + 100, 0.03F, 0.3);
    const Cloud extra = random_cloud(rng, 40, 3.0F);
    b.points.insert(b.points.end(), extra.points.begin(), extra.points.end());
    DistanceParams p;
    p.peak = 10.0 + seed;
    p.taus = {0.01, 0.02, 0.05, 0.3};
    p.threads = 1 + static_cast<int>(seed % 3);
    SCOPED_TRACE("seed " + std::to_string(seed));
    expect_same(compare_clouds(a, b, p), brute_compare(a, b, p), 1e-12);
    expect_same(compare_clouds(b, a, p), brute_compare(b, a, p), 1e-12);
  }
}

TEST(InliersOutliers, MatchesBruteForceOnRandomClouds) {
  for (std::uint32_t seed = 1; seed <= 6; ++seed) {
    std::mt19937 rng(seed);
    const Cloud input = random_cloud(rng, 300, 5.0F);
    Cloud rec = jittered(input, seed + 7, 0.08F, 0.2);
    const Cloud extra = random_cloud(rng, 30, 6.0F);
    rec.points.insert(rec.points.end(), extra.points.begin(), extra.points.end());
    RangeSigma s;
    s.factor = 0.01 * seed;
    s.min_sigma = 0.02;
    s.origin = Eigen::Vector3d(0.5, -1.0, 0.25);

    std::size_t in = 0, out = 0;
    for (const auto& p : input.points) {
      bool found = false;
      for (const auto& q : rec.points) found = found || std::sqrt(sq_dist(p, q)) <= s.at(p);
      in += found ? 1 : 0;
    }
    for (const auto& q : rec.points) {
      bool found = false;
      for (const auto& p : input.points) found = found || std::sqrt(sq_dist(p, q)) <= s.at(q);
      out += found ? 0 : 1;
    }
    const InlierResult r = inliers_outliers(input, rec, s, 1 + static_cast<int>(seed % 2));
    SCOPED_TRACE("seed " + std::to_string(seed));
    EXPECT_DOUBLE_EQ(r.inliers, static_cast<double>(in) / static_cast<double>(input.size()));
    EXPECT_DOUBLE_EQ(r.outliers, static_cast<double>(out) / static_cast<double>(rec.size()));
    EXPECT_GT(r.inliers, 0.0);
    EXPECT_LT(r.inliers, 1.0);
    EXPECT_GT(r.outliers, 0.0);
  }
}

// ---------------------------------------------------------------- closed forms

TEST(CompareClouds, IdenticalClouds) {
  const Cloud a = test::load_or_fail(test::sample("newer_college_00.bin"));
  ASSERT_FALSE(a.empty());
  const DistanceResult r = compare_clouds(a, a);
  EXPECT_EQ(r.points_a, a.size());
  EXPECT_EQ(r.mse_ab, 0.0);
  EXPECT_EQ(r.mse_ba, 0.0);
  EXPECT_EQ(r.rmse, 0.0);
  EXPECT_EQ(r.chamfer, 0.0);
  EXPECT_EQ(r.hausdorff, 0.0);
  EXPECT_EQ(r.d1_psnr_db, kInf);
  ASSERT_EQ(r.coverage.size(), 2U);
  for (std::size_t k = 0; k < 2; ++k) {
    EXPECT_EQ(r.coverage[k], 1.0);
    EXPECT_EQ(r.outliers[k], 0.0);
  }
}

TEST(CompareClouds, ShiftedGrid) {
  // Grid spacing 1 m > 2 d: every point's nearest neighbour is its own shifted copy.
  const double d = 0.125;  // exact in float, so every distance is exactly d
  Cloud a, b;
  for (int i = 0; i < 6; ++i)
    for (int j = 0; j < 5; ++j)
      for (int k = 0; k < 4; ++k) {
        const Eigen::Vector3f p(static_cast<float>(i) - 2.0F, static_cast<float>(j) * 1.0F, static_cast<float>(k));
        a.points.push_back(p);
        b.points.push_back(p + Eigen::Vector3f(static_cast<float>(d), 0.0F, 0.0F));
      }
  DistanceParams params;
  params.peak = 59.70;
  params.taus = {0.1, d, 0.2};
  const DistanceResult r = compare_clouds(a, b, params);
  EXPECT_EQ(r.mse_ab, d * d);
  EXPECT_EQ(r.mse_ba, d * d);
  EXPECT_EQ(r.rmse, d);
  EXPECT_EQ(r.chamfer, 2 * d);
  EXPECT_EQ(r.hausdorff, d);
  EXPECT_DOUBLE_EQ(r.d1_psnr_db, 10.0 * std::log10(3.0 * 59.70 * 59.70 / (d * d)));
  EXPECT_NEAR(r.d1_psnr_db, 58.3525, 1e-4);  // 10 log10(3 * 59.7^2 / 0.015625)
  EXPECT_EQ(r.coverage, (std::vector<double>{0.0, 1.0, 1.0}));  // "within" is inclusive
  EXPECT_EQ(r.outliers, (std::vector<double>{1.0, 0.0, 0.0}));
}

TEST(CompareClouds, EmptyAndSinglePoint) {
  Cloud empty, one, other;
  one.points.emplace_back(0.0F, 0.0F, 0.0F);
  other.points.emplace_back(3.0F, 4.0F, 0.0F);
  DistanceParams p;
  p.taus = {1.0, 5.0};

  for (const auto& [x, y] : {std::pair<const Cloud*, const Cloud*>{&empty, &one}, {&one, &empty}}) {
    const DistanceResult r = compare_clouds(*x, *y, p);
    EXPECT_EQ(r.points_a, x->size());
    EXPECT_EQ(r.points_b, y->size());
    EXPECT_EQ(r.mse_ab, kInf);
    EXPECT_EQ(r.mse_ba, kInf);
    EXPECT_EQ(r.rmse, kInf);
    EXPECT_EQ(r.chamfer, kInf);
    EXPECT_EQ(r.hausdorff, kInf);
    EXPECT_EQ(r.d1_psnr_db, -kInf);
    EXPECT_EQ(r.coverage, (std::vector<double>{0.0, 0.0}));
    EXPECT_EQ(r.outliers, (std::vector<double>{1.0, 1.0}));
  }
  {
    const DistanceResult r = compare_clouds(empty, empty, p);
    EXPECT_EQ(r.points_a, 0U);
    EXPECT_EQ(r.mse_ab, 0.0);
    EXPECT_EQ(r.chamfer, 0.0);
    EXPECT_EQ(r.hausdorff, 0.0);
    EXPECT_EQ(r.d1_psnr_db, kInf);
    EXPECT_EQ(r.coverage, (std::vector<double>{0.0, 0.0}));
    EXPECT_EQ(r.outliers, (std::vector<double>{1.0, 1.0}));
  }
  {
    const DistanceResult r = compare_clouds(one, other, p);
    EXPECT_EQ(r.mse_ab, 25.0);
    EXPECT_EQ(r.mse_ba, 25.0);
    EXPECT_EQ(r.rmse, 5.0);
    EXPECT_EQ(r.chamfer, 10.0);
    EXPECT_EQ(r.hausdorff, 5.0);
    EXPECT_DOUBLE_EQ(r.d1_psnr_db, 10.0 * std::log10(3.0 * p.peak * p.peak / 25.0));
    EXPECT_EQ(r.coverage, (std::vector<double>{0.0, 1.0}));
    EXPECT_EQ(r.outliers, (std::vector<double>{1.0, 0.0}));
  }
  {
    const DistanceResult r = compare_clouds(one, one, p);
    EXPECT_EQ(r.d1_psnr_db, kInf);
    EXPECT_EQ(r.coverage, (std::vector<double>{1.0, 1.0}));
  }
}

TEST(CompareClouds, NonFinitePointsAreLeftOut) {
  Cloud a, b;
  a.points = {{0, 0, 0}, {std::numeric_limits<float>::quiet_NaN(), 0, 0}, {1, 0, 0}};
  b.points = {{0, 0, 0.5F}, {1, 0, std::numeric_limits<float>::infinity()}, {1, 0, 0.5F}};
  const DistanceResult r = compare_clouds(a, b);
  EXPECT_EQ(r.points_a, 2U);
  EXPECT_EQ(r.points_b, 2U);
  EXPECT_EQ(r.mse_ab, 0.25);
  EXPECT_EQ(r.hausdorff, 0.5);
}

TEST(InliersOutliers, EmptyCasesAndSigma) {
  RangeSigma s;
  s.factor = 0.01;
  s.min_sigma = 0.05;
  s.origin = Eigen::Vector3d(1.0, 0.0, 0.0);
  EXPECT_DOUBLE_EQ(s.at(Eigen::Vector3f(1.0F, 0.0F, 0.0F)), 0.05);
  EXPECT_DOUBLE_EQ(s.at(Eigen::Vector3f(101.0F, 0.0F, 0.0F)), 1.0);
  EXPECT_DOUBLE_EQ(s.at(Eigen::Vector3f(1.0F, 30.0F, 40.0F)), 0.5);

  Cloud empty, one;
  one.points.emplace_back(1.0F, 2.0F, 3.0F);
  InlierResult r = inliers_outliers(empty, one, s);
  EXPECT_EQ(r.inliers, 0.0);
  EXPECT_EQ(r.outliers, 1.0);
  r = inliers_outliers(one, empty, s);
  EXPECT_EQ(r.inliers, 0.0);
  EXPECT_EQ(r.outliers, 0.0);
  r = inliers_outliers(empty, empty, s);
  EXPECT_EQ(r.inliers, 0.0);
  EXPECT_EQ(r.outliers, 0.0);
  r = inliers_outliers(one, one, s);
  EXPECT_EQ(r.inliers, 1.0);
  EXPECT_EQ(r.outliers, 0.0);

  // Range-dependent tolerance: the same 0.3 m offset is within sigma far away only.
  Cloud in, rec;
  in.points = {{2.0F, 0.0F, 0.0F}, {61.0F, 0.0F, 0.0F}};
  rec.points = {{2.0F, 0.3F, 0.0F}, {61.0F, 0.3F, 0.0F}};
  r = inliers_outliers(in, rec, s);  // sigma: 0.05 near, 0.6 far
  EXPECT_EQ(r.inliers, 0.5);
  EXPECT_EQ(r.outliers, 0.5);
}

// ---------------------------------------------------------------- determinism

TEST(CompareClouds, DeterministicAcrossThreadCounts) {
  const Cloud a = test::load_or_fail(test::sample("kitti00_000000.bin"));
  ASSERT_GT(a.size(), 100000U);
  const Cloud b = jittered(a, 7, 0.01F, 0.05);
  DistanceParams p;
  p.taus = {0.005, 0.01, 0.02, 0.05};
  p.threads = 1;
  const DistanceResult ref = compare_clouds(a, b, p);
  EXPECT_GT(ref.d1_psnr_db, 50.0);
  EXPECT_LT(ref.coverage[0], ref.coverage[3]);
  RangeSigma s;
  s.factor = 0.002;
  s.min_sigma = 0.01;
  const InlierResult ref_io = inliers_outliers(a, b, s, 1);
  for (int threads : {2, 3, 8, 64}) {
    p.threads = threads;
    const Stopwatch sw;
    const DistanceResult r = compare_clouds(a, b, p);
    if (threads == 2) {
      const double ms = sw.elapsed_ms();
      RecordProperty("compare_clouds_2_threads_ms", std::to_string(ms));
      std::printf("compare_clouds %zu vs %zu points, 2 threads: %.1f ms\n", a.size(), b.size(), ms);
    }
    SCOPED_TRACE("threads " + std::to_string(threads));
    expect_identical(r, ref);
    const InlierResult io = inliers_outliers(a, b, s, threads);
    EXPECT_EQ(io.inliers, ref_io.inliers);
    EXPECT_EQ(io.outliers, ref_io.outliers);
  }
}

// ---------------------------------------------------------------- compression rates

// The model byte stream exactly as documented in metrics.hpp, built independently.
std::uint64_t zlib9(const std::vector<std::uint8_t>& bytes) {
  uLongf n = compressBound(static_cast<uLong>(bytes.size()));
  std::vector<Bytef> out(n);
  EXPECT_EQ(compress2(out.data(), &n, bytes.data(), static_cast<uLong>(bytes.size()), 9), Z_OK);
  return n;
}
template <typename T>
void append_le(std::vector<std::uint8_t>& out, T v) {
  static_assert(sizeof(T) == 4, "4-byte values");
  std::uint8_t b[4];
  std::memcpy(b, &v, 4);  // the test machine is little-endian (checked below)
  out.insert(out.end(), b, b + 4);
}

TEST(CompressionRates, HandComputedBytes) {
  const std::uint32_t probe = 1;
  std::uint8_t first = 0;
  std::memcpy(&first, &probe, 1);
  ASSERT_EQ(first, 1) << "this test builds its reference stream on a little-endian host";

  std::mt19937 rng(3);
  const Cloud input = random_cloud(rng, 100, 10.0F);
  std::vector<std::vector<Eigen::Vector3f>> words = {random_cloud(rng, 3, 1.0F).points,
                                                     random_cloud(rng, 5, 1.0F).points};
  const std::vector<std::uint32_t> ids = {0, 1, 1, 0};
  std::vector<Pose> poses;
  for (int i = 0; i < 4; ++i) {
    Pose T = Pose::Identity();
    T.translate(Eigen::Vector3d(i, 2.0 * i, -1.0));
    T.rotate(Eigen::AngleAxisd(0.3 * i, Eigen::Vector3d(0, 0.6, 0.8)));
    poses.push_back(T);
  }
  const RateResult r = compression_rates(input, words, ids, poses);
  EXPECT_EQ(r.raw_bytes, 1200U);                    // 100 * 12
  EXPECT_EQ(r.model_bytes, 12U * 8U + 4U * 28U);  // 8 word points, 4 instances: 208
  EXPECT_DOUBLE_EQ(r.rate, 208.0 / 1200.0);
  EXPECT_GT(r.raw_gzip_bytes, 0U);
  EXPECT_GT(r.model_gzip_bytes, 0U);
  EXPECT_DOUBLE_EQ(r.gzip_rate, static_cast<double>(r.model_gzip_bytes) / static_cast<double>(r.raw_gzip_bytes));

  std::vector<std::uint8_t> raw, model;
  for (const auto& p : input.points)
    for (int k = 0; k < 3; ++k) append_le(raw, p[k]);
  for (const auto& w : words)
    for (const auto& p : w)
      for (int k = 0; k < 3; ++k) append_le(model, p[k]);
  for (std::size_t i = 0; i < ids.size(); ++i) {
    append_le(model, static_cast<std::int32_t>(ids[i]));
    for (int k = 0; k < 3; ++k) append_le(model, static_cast<float>(poses[i].translation()[k]));
    const Eigen::AngleAxisd aa(poses[i].linear());
    const Eigen::Vector3d rv = aa.angle() * aa.axis();
    EXPECT_LT((rv - 0.3 * static_cast<double>(i) * Eigen::Vector3d(0, 0.6, 0.8)).norm(), 1e-12);
    for (int k = 0; k < 3; ++k) append_le(model, static_cast<float>(rv[k]));
  }
  ASSERT_EQ(raw.size(), r.raw_bytes);
  ASSERT_EQ(model.size(), r.model_bytes);
  EXPECT_EQ(r.raw_gzip_bytes, zlib9(raw));
  EXPECT_EQ(r.model_gzip_bytes, zlib9(model));
}

TEST(CompressionRates, RepetitiveModelDeflatesWell) {
  std::mt19937 rng(5);
  const Cloud input = random_cloud(rng, 20000, 30.0F);
  const std::vector<std::vector<Eigen::Vector3f>> words = {random_cloud(rng, 40, 0.5F).points};
  const std::vector<std::uint32_t> ids(2000, 0);
  const std::vector<Pose> poses(2000, Pose::Identity());
  const RateResult r = compression_rates(input, words, ids, poses);
  EXPECT_EQ(r.raw_bytes, 240000U);
  EXPECT_EQ(r.model_bytes, 480U + 2000U * 28U);
  EXPECT_GT(r.raw_gzip_bytes, 0U);
  EXPECT_GT(r.model_gzip_bytes, 0U);
  EXPECT_LT(r.model_gzip_bytes, r.model_bytes / 10);
  EXPECT_LT(r.gzip_rate, r.rate);
}

TEST(CompressionRates, EmptyInputAndBadModel) {
  const Cloud empty;
  const std::vector<std::vector<Eigen::Vector3f>> words = {{Eigen::Vector3f(1, 2, 3)}};
  RateResult r = compression_rates(empty, words, {0}, {Pose::Identity()});
  EXPECT_EQ(r.raw_bytes, 0U);
  EXPECT_EQ(r.model_bytes, 12U + 28U);
  EXPECT_EQ(r.rate, 0.0);
  EXPECT_EQ(r.gzip_rate, 0.0);
  r = compression_rates(empty, {}, {}, {});
  EXPECT_EQ(r.model_bytes, 0U);
  EXPECT_EQ(r.rate, 0.0);
  EXPECT_THROW((void)compression_rates(empty, words, {0, 0}, {Pose::Identity()}), std::invalid_argument);
  EXPECT_THROW((void)compression_rates(empty, words, {1}, {Pose::Identity()}), std::invalid_argument);
}

// ---------------------------------------------------------------- validation

void expect_invalid(const DistanceParams& p, const std::string& field) {
  try {
    p.validate();
    ADD_FAILURE() << "no exception for " << field;
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find(field), std::string::npos) << e.what();
  }
  EXPECT_THROW((void)compare_clouds(Cloud{}, Cloud{}, p), std::invalid_argument);
}

TEST(Validate, DistanceParams) {
  EXPECT_NO_THROW(DistanceParams{}.validate());
  DistanceParams p;
  p.peak = 0.0;
  expect_invalid(p, "peak");
  p.peak = std::numeric_limits<double>::quiet_NaN();
  expect_invalid(p, "peak");
  p = {};
  p.taus = {0.02, -0.1};
  expect_invalid(p, "taus[1]");
  p.taus = {0.0};
  expect_invalid(p, "taus[0]");
  p = {};
  p.threads = 0;
  expect_invalid(p, "threads");
  p.threads = 65;
  expect_invalid(p, "threads");
  p.threads = 64;
  EXPECT_NO_THROW(p.validate());
  p.taus.clear();  // no shares asked for is fine
  EXPECT_NO_THROW(p.validate());
}

TEST(Validate, InliersOutliers) {
  const Cloud c;
  RangeSigma s;
  s.factor = -1.0;
  EXPECT_THROW((void)inliers_outliers(c, c, s), std::invalid_argument);
  s = {};
  s.min_sigma = -0.1;
  EXPECT_THROW((void)inliers_outliers(c, c, s), std::invalid_argument);
  s = {};
  EXPECT_THROW((void)inliers_outliers(c, c, s, 0), std::invalid_argument);
  EXPECT_THROW((void)inliers_outliers(c, c, s, 65), std::invalid_argument);
}

// ---------------------------------------------------------------- independent checker

// The value of `"key": number` in a one-line JSON object (Python's Infinity included).
double json_value(const std::string& json, const std::string& key) {
  const std::string needle = "\"" + key + "\":";
  const auto pos = json.find(needle);
  if (pos == std::string::npos) throw std::runtime_error("no key " + key + " in " + json);
  const char* begin = json.c_str() + pos + needle.size();
  char* end = nullptr;
  const double v = std::strtod(begin, &end);
  if (end == begin) throw std::runtime_error("no number for " + key + " in " + json);
  return v;
}

std::string run_capture(const std::string& command) {
  std::string out;
  FILE* f = ::popen(command.c_str(), "r");
  if (f == nullptr) return out;
  char buf[4096];
  std::size_t n = 0;
  while ((n = std::fread(buf, 1, sizeof buf, f)) > 0) out.append(buf, n);
  const int rc = ::pclose(f);
  if (rc != 0) return {};
  return out;
}

TEST(CompareClouds, AgreesWithPcmetrics) {
  const std::string script = std::string(LEX3D_SHARED_DATA_DIR) + "/../tools/pcmetrics.py";
  if (!std::filesystem::exists(script)) GTEST_SKIP() << "independent checker not available: " << script;
  if (std::system("/usr/bin/python3 -c \"import numpy, scipy\" >/dev/null 2>&1") != 0)
    GTEST_SKIP() << "/usr/bin/python3 with numpy and scipy not available";

  const Cloud src = test::load_or_fail(test::sample("newer_college_00.bin"));
  ASSERT_GT(src.size(), 20000U);
  const Cloud perturbed = jittered(src, 2024, 0.01F, 0.05);  // +-1 cm, 5 % dropped
  const auto dir = test::temp_dir("eval_pcmetrics");
  const std::string orig_path = (dir / "original.bin").string();
  const std::string dec_path = (dir / "decoded.bin").string();
  ASSERT_TRUE(io::write_cloud(orig_path, src).ok());  // KITTI layout: 4 float32 a point
  ASSERT_TRUE(io::write_cloud(dec_path, perturbed).ok());
  // Compare the clouds as read back from the very files pcmetrics reads.
  const Cloud a = test::load_or_fail(orig_path);
  const Cloud b = test::load_or_fail(dec_path);
  ASSERT_EQ(a.size(), src.size());
  ASSERT_EQ(b.size(), perturbed.size());

  struct Case {
    double peak, tau;
  };
  for (const Case c : {Case{59.70, 0.01}, Case{120.0, 0.005}, Case{30.0, 0.05}}) {
    char args[128];
    std::snprintf(args, sizeof args, " --peak %.17g --tau %.17g --bin-floats 4", c.peak, c.tau);
    const std::string json =
        run_capture("/usr/bin/python3 '" + script + "' '" + orig_path + "' '" + dec_path + "'" + args);
    ASSERT_FALSE(json.empty()) << "pcmetrics failed";
    DistanceParams p;
    p.peak = c.peak;
    p.taus = {c.tau};
    const DistanceResult r = compare_clouds(a, b, p);
    SCOPED_TRACE(json);
    EXPECT_EQ(json_value(json, "n_original"), static_cast<double>(r.points_a));
    EXPECT_EQ(json_value(json, "n_decoded"), static_cast<double>(r.points_b));
    EXPECT_NEAR(json_value(json, "d1_mse"), std::max(r.mse_ab, r.mse_ba), 1e-9 * std::max(r.mse_ab, r.mse_ba));
    EXPECT_NEAR(json_value(json, "d1_psnr_db"), r.d1_psnr_db, 0.01);
    EXPECT_NEAR(json_value(json, "chamfer_m"), r.chamfer, 1e-4 * r.chamfer);
    EXPECT_NEAR(json_value(json, "hausdorff_m"), r.hausdorff, 1e-4 * r.hausdorff);
    EXPECT_NEAR(json_value(json, "coverage"), r.coverage[0], 1e-6);
    EXPECT_NEAR(json_value(json, "outliers"), r.outliers[0], 1e-6);
    EXPECT_EQ(json_value(json, "tau_m"), c.tau);
    EXPECT_EQ(json_value(json, "peak_m"), c.peak);
    // Not a degenerate comparison: the shares are strictly between 0 and 1.
    EXPECT_GT(r.coverage[0], 0.0);
    EXPECT_LT(r.coverage[0], 1.0);
    std::printf("pcmetrics agreement (peak %.2f, tau %.3f): psnr %.6f vs %.6f dB, chamfer %.9g vs %.9g, "
                "hausdorff %.9g vs %.9g, coverage %.9f vs %.9f, outliers %.9f vs %.9f\n",
                c.peak, c.tau, json_value(json, "d1_psnr_db"), r.d1_psnr_db, json_value(json, "chamfer_m"),
                r.chamfer, json_value(json, "hausdorff_m"), r.hausdorff, json_value(json, "coverage"),
                r.coverage[0], json_value(json, "outliers"), r.outliers[0]);
  }
}

}  // namespace
}  // namespace lex3d::eval
