#pragma once
/// \file
/// Range-image features: interest points (steder2010 §III-A), uniform coverage points
/// (ruhnke2010 §III-C), and patch descriptors with a full 6-DoF frame.

#include <cstdint>
#include <vector>

#include "lex3d/core/cloud.hpp"
#include "lex3d/range/range_image.hpp"

// The public API: exported by liblex3d.so, which hides everything else.
#pragma GCC visibility push(default)

namespace lex3d {

/// Parameters of the interest operator (steder2010 eq. 1-5 and its two filters).
struct InterestParams {
  /// Standard deviation of the Gaussian applied to the normalised gradients, pixels; [0, 5].
  double smoothing_sigma_px = 1.0;
  /// Minimum interest value of an interest point; interest values are in [0, 1]; (0, 1].
  double threshold = 0.33;
  /// Occlusion filter: a pixel is on the shadow side of a jump when the normalised
  /// range step to a nearer neighbour exceeds this (1 = jump to infinity); (0, 1].
  double occlusion_gradient = 0.9;
  /// Straight-line filter: a pixel whose neighbours along its edge direction both have
  /// an edge direction within this angle lies on a straight line and is rejected, degrees; [0, 90].
  double line_angle_deg = 20.0;
  /// Minimum 3D distance between interest points, metres; [0, 100].
  double min_distance = 0.5;
  void validate() const;
};

/// Parameters of the uniform coverage points.
struct CoverageParams {
  /// Every scan point ends within this distance of some feature point, metres; (0, 100]
  /// (0 disables coverage points).
  double distance = 0.5;
  void validate() const;
};

/// Parameters of the patch descriptor.
struct DescriptorParams {
  /// Half side of the square patch, metres (steder2010 uses 1.25 m); (0, 100].
  double support_radius = 1.25;
  /// Patch cells per side (steder2010: 10); [2, 64].
  int patch_size = 10;
  /// Radius of the neighbourhood the surface normal is fitted on, metres; it grows with
  /// range to at least 2.5 beam spacings so far surfaces keep enough points; (0, 10].
  double normal_radius = 0.2;
  /// The world's up direction expressed in the cloud frame; patches are upright with
  /// respect to it. Non-zero.
  Eigen::Vector3d up = Eigen::Vector3d::UnitZ();
  void validate() const;
};

/// All feature extraction parameters.
struct FeatureParams {
  RangeImageParams range;
  InterestParams interest;
  CoverageParams coverage;
  DescriptorParams descriptor;
  /// Worker threads for the descriptors; [1, 64]. Results do not depend on it.
  int threads = 2;
  void validate() const;
};

/// Where a feature point came from.
enum class FeatureKind : std::uint8_t { kInterest = 0, kCoverage = 1 };

/// A feature location before it has a frame and descriptor.
struct Keypoint {
  Eigen::Vector3f point_sensor = Eigen::Vector3f::Zero();  ///< sensor frame
  float x = 0.0F;       ///< image column (continuous)
  float y = 0.0F;       ///< image row (continuous)
  float interest = 0.0F;
  FeatureKind kind = FeatureKind::kInterest;
};

/// Per-pixel results of the interest operator, for inspection and drawing.
struct InterestImage {
  int width = 0;
  int height = 0;
  std::vector<float> value;  ///< interest value after the filters, [0, 1]; 0 off-surface
  std::size_t occlusion_rejected = 0;  ///< pixels above the threshold zeroed by the occlusion filter
  std::size_t line_rejected = 0;       ///< local maxima rejected by the straight-line filter
  std::size_t maxima = 0;              ///< local maxima above the threshold, before min_distance
};

/// Runs the interest operator and returns interest points sorted by decreasing
/// interest value, at least `min_distance` apart. `debug` (optional) receives the
/// interest image.
[[nodiscard]] std::vector<Keypoint> detect_interest_points(const RangeImage& image,
                                                           const InterestParams& params,
                                                           InterestImage* debug = nullptr);

/// Adds coverage keypoints so that every point of `cloud` (as seen in `image`'s
/// sensor frame) lies within `params.distance` of some keypoint in `existing` or the
/// result. Greedy in image order, deterministic.
[[nodiscard]] std::vector<Keypoint> coverage_points(const Cloud& cloud, const RangeImage& image,
                                                    const std::vector<Keypoint>& existing,
                                                    const CoverageParams& params);

/// A described feature: its 6-DoF frame and where it came from; the descriptor lives
/// in Features::descriptors.
struct Feature {
  /// Pose of the feature frame in the cloud frame: origin at the surface point,
  /// z along the surface normal (towards the sensor), y upright (world up projected
  /// onto the tangent plane; the sensor's viewing direction on near-horizontal surfaces).
  Pose T_cloud_feature = Pose::Identity();
  Keypoint keypoint;
  /// Points used for the normal; < 3 means the normal is the viewing direction.
  std::uint16_t normal_support = 0;
};

struct FeatureTimings {
  double range_image_ms = 0.0;
  double interest_ms = 0.0;
  double coverage_ms = 0.0;
  double descriptor_ms = 0.0;
  [[nodiscard]] double total_ms() const {
    return range_image_ms + interest_ms + coverage_ms + descriptor_ms;
  }
};

/// Described features of one scan.
struct Features {
  std::vector<Feature> features;
  /// Row-major, features.size() x descriptor_dim, values in [-1, 1].
  std::vector<float> descriptors;
  int descriptor_dim = 0;
  std::size_t interest_count = 0;  ///< features of kind kInterest (they come first)
  std::size_t coverage_count = 0;  ///< features of kind kCoverage

  [[nodiscard]] std::size_t size() const noexcept { return features.size(); }
  [[nodiscard]] const float* descriptor(std::size_t i) const noexcept {
    return descriptors.data() + i * static_cast<std::size_t>(descriptor_dim);
  }
};

/// Computes frames and descriptors at `keypoints` of `image`; keypoints are kept in order.
[[nodiscard]] Features describe(const RangeImage& image, const std::vector<Keypoint>& keypoints,
                                const DescriptorParams& params, int threads = 1);

/// Makes a keypoint at an arbitrary sensor-frame point of `image` (for describing a
/// given 3D spot); nullopt when the point does not project into the image.
[[nodiscard]] std::optional<Keypoint> keypoint_at(const RangeImage& image, const Eigen::Vector3f& point_sensor);

/// Squared Euclidean distance between two descriptors of length `dim`.
[[nodiscard]] float descriptor_distance_sq(const float* a, const float* b, int dim) noexcept;
/// The same from `q` to each of `count` descriptors stored one after another in `rows`,
/// into out[0..count): the same bits as descriptor_distance_sq, one call for all rows.
void descriptor_distances_sq(const float* q, const float* rows, std::size_t count, int dim, float* out) noexcept;

/// Everything `extract_features` produced, with diagnostics.
struct FeatureResult {
  RangeImage image;
  InterestImage interest;
  Features features;
  FeatureTimings timings;
};

/// Range image -> interest points -> coverage points -> descriptors, timed per stage.
[[nodiscard]] FeatureResult extract_features(const Cloud& cloud, const FeatureParams& params = {});

}  // namespace lex3d

#pragma GCC visibility pop
