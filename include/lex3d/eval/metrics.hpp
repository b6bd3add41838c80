#pragma once
/// \file
/// Quality and size metrics shared by the commands and benchmarks: point-to-point
/// distances (D1 PSNR as in MPEG, RMSE, Chamfer, Hausdorff, coverage within a
/// tolerance), inliers/outliers with a range-dependent tolerance (ruhnke2010 §IV),
/// and compression rates with the byte costs of ruhnke2010 §IV.

#include <cstdint>
#include <vector>

#include "lex3d/core/cloud.hpp"

// The public API: exported by liblex3d.so, which hides everything else.
#pragma GCC visibility push(default)

namespace lex3d::eval {

struct DistanceParams {
  /// Peak value of the D1 PSNR, metres (MPEG uses the bounding-box diagonal; 59.70 m is
  /// the value used for KITTI-like scans); > 0.
  double peak = 59.70;
  /// Tolerances for the coverage / outlier shares, metres; each > 0.
  std::vector<double> taus = {0.02, 0.05};
  /// Worker threads; [1, 64]. Results do not depend on it.
  int threads = 2;
  void validate() const;
};

struct DistanceResult {
  std::size_t points_a = 0;      ///< original
  std::size_t points_b = 0;      ///< decoded
  double mse_ab = 0.0;           ///< mean squared distance from each a to its nearest b, m^2
  double mse_ba = 0.0;           ///< mean squared distance from each b to its nearest a, m^2
  double d1_psnr_db = 0.0;       ///< 10 log10(3 peak^2 / max(mse_ab, mse_ba)); +inf when identical
  double rmse = 0.0;             ///< sqrt(max(mse_ab, mse_ba)), m
  double chamfer = 0.0;          ///< mean_a d(a,B) + mean_b d(b,A), m
  double hausdorff = 0.0;        ///< max(max_a d(a,B), max_b d(b,A)), m
  std::vector<double> coverage;  ///< per tau: share of a with a b within tau
  std::vector<double> outliers;  ///< per tau: share of b with no a within tau
};

/// Compares an original cloud `a` with a decoded one `b` (exact nearest neighbours).
/// Either cloud empty: distances are +inf (0 when both are empty), shares are 0 / 1.
/// As /work/shared/tools/pcmetrics.py: points with a non-finite coordinate are left out
/// (points_a / points_b count the others), distances are computed in double precision,
/// coverage counts d(a, B) <= tau and outliers d(b, A) > tau; the D1 PSNR is -inf when
/// exactly one cloud is empty. Throws std::invalid_argument on invalid params.
[[nodiscard]] DistanceResult compare_clouds(const Cloud& a, const Cloud& b, const DistanceParams& params = {});

/// A tolerance that grows with range: sigma(p) = max(min_sigma, factor * |p - origin|).
/// With factor = lambda * tan(alpha / 2) this is ruhnke2010 eq. 13.
struct RangeSigma {
  double factor = 0.0;                               ///< >= 0
  double min_sigma = 0.0;                            ///< metres, >= 0
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();  ///< the sensor, in the clouds' frame
  [[nodiscard]] double at(const Eigen::Vector3f& p) const noexcept;
};

struct InlierResult {
  double inliers = 0.0;   ///< share of input points with a reconstructed point within sigma(input point)
  double outliers = 0.0;  ///< share of reconstructed points with no input point within sigma(reconstructed point)
};

/// ruhnke2010 §IV inliers and outliers. Empty input: inliers 0; empty reconstruction: outliers 0.
/// "Within" is inclusive (d <= sigma); with an empty input every reconstructed point is an
/// outlier (outliers 1). Non-finite points are left out. Throws std::invalid_argument when
/// sigma has a negative or non-finite field or threads is outside [1, 64].
[[nodiscard]] InlierResult inliers_outliers(const Cloud& input, const Cloud& reconstruction,
                                            const RangeSigma& sigma, int threads = 2);

/// What a model costs, in the units of ruhnke2010 §IV.
struct ModelSize {
  std::uint64_t input_points = 0;     ///< points of the (original) input
  std::uint64_t alphabet_points = 0;  ///< sum of word sizes
  std::uint64_t instances = 0;        ///< word occurrences
};

struct RateResult {
  std::uint64_t raw_bytes = 0;         ///< 12 bytes a point
  std::uint64_t model_bytes = 0;       ///< 12 a word point + 24 a transform + 4 a word reference
  double rate = 0.0;                   ///< model_bytes / raw_bytes
  std::uint64_t raw_gzip_bytes = 0;    ///< deflate (level 9) of the raw float32 points
  std::uint64_t model_gzip_bytes = 0;  ///< deflate (level 9) of the model's float32/int32 arrays
  double gzip_rate = 0.0;              ///< model_gzip_bytes / raw_gzip_bytes
};

/// Compression rate (ruhnke2010 §IV, the alphabet included) and the same after
/// deflating both sides. `words` are the alphabet's points (any frame), `instance_word`
/// and `instance_pose` the model.
/// Deflated sizes: zlib compress2 level 9 of little-endian arrays: the input as float32
/// x y z a point; the model as every word point (word by word) as float32 x y z, then
/// per instance int32 word id + float32 translation x y z + float32 rotation vector
/// (axis times angle, radians) x y z. No input points: rate and gzip_rate are 0.
/// Throws std::invalid_argument when instance_word and instance_pose differ in size or
/// a word id is not below words.size().
[[nodiscard]] RateResult compression_rates(const Cloud& input,
                                           const std::vector<std::vector<Eigen::Vector3f>>& words,
                                           const std::vector<std::uint32_t>& instance_word,
                                           const std::vector<Pose>& instance_pose);

}  // namespace lex3d::eval

#pragma GCC visibility pop
