#pragma once
/// \file
/// Models of scans in terms of an alphabet (ruhnke2010 §III): instances (a word placed
/// with a 6-DoF pose), reconstruction (eq. 2-3), the range-dependent Gaussian
/// likelihood and BIC (eq. 4-13), the alphabet learner, and instance pruning (§III-D).

#include <cstdint>
#include <functional>
#include <vector>

#include "lex3d/alphabet/alphabet.hpp"
#include "lex3d/core/cloud.hpp"
#include "lex3d/features/features.hpp"

// The public API: exported by liblex3d.so, which hides everything else.
#pragma GCC visibility push(default)

namespace lex3d {

/// Parameters shared by learning and encoding.
struct ModelParams {
  /// Word radius δ, metres; 0 derives it from the scan: 8 beam spacings at the median
  /// range, within [0.1, 1] m (ruhnke2010 used 0.1 m indoors, 0.25 m outdoors); else (0, 10].
  double word_radius = 0.0;
  /// Coverage points are this many word radii apart at most, so words tile the scan; (0, 10].
  double coverage_factor = 1.0;
  /// Word points are thinned to this many word radii apart; [0, 1].
  double word_spacing_factor = 0.05;
  /// λ of eq. 13: σ = λ · tan(α/2) · range, α the coarser beam spacing; (0, 100].
  double sigma_lambda = 2.0;
  /// Each instance takes, among this many words nearest by descriptor, the one that fits
  /// the scan around it best (scan points it explains minus word points nothing
  /// supports); 1 keeps the nearest descriptor alone (ruhnke2010 §III-C); [1, 64].
  int fit_candidates = 5;
  /// Rounds of point-to-point ICP that fit each kept instance's pose to the scan after
  /// pruning (0 keeps the feature frames); [0, 50]. What the rounds gain and cost:
  /// bench/README.md, "Model files".
  int refine_iterations = 2;
  /// ICP pairs a word point with a scan point at most this many word radii away; (0, 1].
  double refine_reach_factor = 0.3;
  /// Feature extraction (the coverage distance is set from the word radius).
  FeatureParams features;
  /// Worker threads; [1, 64]. Results do not depend on it.
  int threads = 2;
  /// Pruning keeps an instance that is the only one with a word point within σ of some
  /// scan point (that point's inlier), even where ruhnke2010's rule would drop it (its
  /// removal does not lower the likelihood): more inliers for larger files (measured in
  /// bench/README.md, "Model files"). false (the default): ruhnke2010's rule only.
  bool prune_keeps_sole_cover = false;
  void validate() const;
};

/// A scan made ready for modelling: points, features, per-point σ and, per feature,
/// the points near it.
struct PreparedScan {
  Cloud cloud;                 ///< the input, sensor frame
  Features features;           ///< interest + coverage features with frames and descriptors
  double word_radius = 0.0;    ///< δ used, metres
  double beam_spacing = 0.0;   ///< α of eq. 13 (the coarser spacing), radians
  std::vector<float> sigma;    ///< σ of each point, metres
  /// Indices of the points within δ + 3σ of each feature point, flat: feature f's
  /// (sorted) are nearby_index[nearby_offset[f], nearby_offset[f + 1]).
  std::vector<std::size_t> nearby_offset;
  std::vector<std::uint32_t> nearby_index;
  /// How many points are near feature f, and the first of them.
  [[nodiscard]] std::size_t nearby_count(std::size_t f) const { return nearby_offset[f + 1] - nearby_offset[f]; }
  [[nodiscard]] const std::uint32_t* nearby(std::size_t f) const { return nearby_index.data() + nearby_offset[f]; }
  FeatureTimings timings;
  double prepare_ms = 0.0;     ///< all of prepare_scan
};

/// The word radius ModelParams::word_radius = 0 stands for.
[[nodiscard]] double derive_word_radius(const Cloud& cloud);

/// The feature extraction prepare_scan runs: params.features with its thread count, the
/// coverage distance coverage_factor · δ and the descriptors' up direction from the cloud's pose.
/// `word_radius` as for prepare_scan (0: params.word_radius, 0 there too: derived).
[[nodiscard]] FeatureParams prepare_feature_params(const Cloud& cloud, const ModelParams& params, double word_radius = 0.0);

/// Extracts features (coverage distance = coverage_factor · δ), σ and neighbourhoods.
/// `word_radius` > 0 overrides params.word_radius (to share one δ across scans).
[[nodiscard]] PreparedScan prepare_scan(const Cloud& cloud, const ModelParams& params, double word_radius = 0.0);

/// One word occurrence.
struct Instance {
  std::uint32_t word = 0;                 ///< index into the alphabet
  Pose T_cloud_word = Pose::Identity();   ///< where the word's frame sits in the scan
  std::uint32_t feature = 0;              ///< the scan feature it replaced
};

/// A scan as words of an alphabet.
struct Model {
  std::vector<Instance> instances;
};

/// The union of the placed words (eq. 2) thinned to `spacing` (eq. 3; 0 keeps all),
/// with the word each point came from.
struct Reconstruction {
  Cloud cloud;
  std::vector<std::uint32_t> word_of_point;
};
[[nodiscard]] Reconstruction reconstruct(const Model& model, const Alphabet& alphabet, double spacing);

/// ln L (eq. 6-12) of a scan given a reconstruction, computed directly: for each point,
/// the Gaussians of the reconstructed points within 3σ and a uniform association prior
/// 1/M; a point nothing explains gets a background density, that of one Gaussian at 3σ
/// in a reconstruction as large as the scan (g(3σ)/N), so that an empty model is a poor
/// but finite one. The reconstruction enters unthinned (all placed word points), as in
/// the learner.
[[nodiscard]] double log_likelihood(const PreparedScan& scan, const Model& model, const Alphabet& alphabet);

/// BIC = -2 ln L + k ln N with k = 3 · (alphabet points) (eq. 4-5).
[[nodiscard]] double bic(double log_likelihood, std::size_t alphabet_points, std::size_t data_points);

/// Encodes a scan with a given alphabet: every feature takes the word with the nearest
/// descriptor (§III-C), re-chosen among the fit_candidates nearest by its fit to the scan;
/// when `prune`, instances whose removal does not lower the likelihood are dropped
/// (§III-D); then the pose of each instance kept is fitted to the scan by ICP (when
/// params.refine_iterations > 0).
/// Where encode_scan's time went, milliseconds.
struct EncodeTimings {
  double frames_ms = 0.0;  ///< the points near each feature, moved into its frame
  double words_ms = 0.0;   ///< word choice (descriptor search, fit)
  double refine_ms = 0.0;  ///< ICP fitting of the instance poses
  double prune_ms = 0.0;   ///< scoring and pruning
};

[[nodiscard]] Model encode_scan(const PreparedScan& scan, const Alphabet& alphabet, bool prune,
                                const ModelParams& params = {}, EncodeTimings* timings = nullptr);

struct LearnParams {
  ModelParams model;
  /// Candidate words drawn at most; [1, 1e6].
  int max_iterations = 400;
  /// Stop after this many candidates in a row are rejected; [1, 1e6].
  int patience = 100;
  /// Seed of the candidate order.
  std::uint64_t seed = 1;
  /// Prune instances after learning (§III-D).
  bool prune = true;
  void validate() const;
};

/// Progress of the learner, reported after every candidate.
struct LearnProgress {
  int iteration = 0;
  int max_iterations = 0;
  double bic = 0.0;
  std::size_t alphabet_size = 0;
  bool accepted = false;
};

struct LearnResult {
  Alphabet alphabet;
  std::vector<Model> models;            ///< one per scan
  std::vector<PreparedScan> scans;      ///< the prepared scans (features, σ)
  std::vector<double> bic_history;      ///< BIC after every candidate (the first entry: empty alphabet)
  std::vector<bool> accepted_history;   ///< whether each candidate was accepted
  std::size_t accepted = 0;
  std::size_t rejected = 0;
  double log_likelihood = 0.0;          ///< after pruning
  double final_bic = 0.0;               ///< after pruning
  double prepare_ms = 0.0;
  double learn_ms = 0.0;
  double prune_ms = 0.0;
};

/// Learns one alphabet for a set of scans (ruhnke2010 §III): candidate words are cut
/// around features drawn in a seeded random order and kept when they lower the BIC.
/// The likelihood is a sum over scans, each scoring only the points a change touches.
[[nodiscard]] LearnResult learn_alphabet(const std::vector<Cloud>& scans, const LearnParams& params,
                                         const std::function<void(const LearnProgress&)>& progress = {});

}  // namespace lex3d

#pragma GCC visibility pop
