#pragma once
/// \file
/// Words and alphabets (ruhnke2010 §III, eq. 1): a word is the part of a scan within
/// the word radius of a feature point, stored in that feature's frame together with
/// the feature's descriptor.

#include <cstdint>
#include <optional>
#include <vector>

#include "lex3d/core/cloud.hpp"
#include "lex3d/core/status.hpp"
#include "lex3d/features/features.hpp"

// The public API: exported by liblex3d.so, which hides everything else.
#pragma GCC visibility push(default)

namespace lex3d {

/// One word of an alphabet.
struct Word {
  /// Points in the word's own frame (the frame of the feature it was cut around),
  /// metres; all within the alphabet's word radius of the origin.
  std::vector<Eigen::Vector3f> points;
  /// The feature's descriptor, Alphabet::descriptor_dim values.
  std::vector<float> descriptor;
};

/// A set of words sharing one radius and descriptor layout.
struct Alphabet {
  std::vector<Word> words;
  int descriptor_dim = 0;
  double word_radius = 0.0;   ///< metres
  double point_spacing = 0.0; ///< minimum distance between a word's points, metres

  [[nodiscard]] std::size_t size() const noexcept { return words.size(); }
  [[nodiscard]] std::size_t total_points() const noexcept;
};

/// Cuts a word out of a scan: the points of `points_sensor` (sensor frame, as the
/// features' keypoints) within `radius` of the feature's keypoint, in the feature
/// frame, thinned so that no two are closer than `spacing` (0 keeps all).
/// `T_sensor_feature` is the feature's pose in the sensor frame.
[[nodiscard]] Word cut_word(const std::vector<Eigen::Vector3f>& points_sensor, const std::vector<std::uint32_t>& nearby,
                            const Eigen::Isometry3f& T_sensor_feature, const float* descriptor, int descriptor_dim,
                            double radius, double spacing);

/// Nearest word by descriptor distance (exact; FLANN kd-trees when the alphabet is
/// large, brute force otherwise); deterministic.
class WordIndex {
 public:
  explicit WordIndex(const Alphabet& alphabet);
  ~WordIndex();
  WordIndex(const WordIndex&) = delete;
  WordIndex& operator=(const WordIndex&) = delete;

  struct Match {
    std::uint32_t word = 0;
    float distance_sq = 0.0F;
  };
  /// Nearest word of each of `count` descriptors (row-major, descriptor_dim each);
  /// empty when the alphabet is empty.
  [[nodiscard]] std::vector<Match> nearest(const float* descriptors, std::size_t count, int threads = 1) const;

 private:
  const Alphabet& alphabet_;
  std::vector<float> packed_;  // words' descriptors, row-major
};

}  // namespace lex3d

#pragma GCC visibility pop
