#pragma once
/// \file
/// Place recognition on word instances (steder2010 §III-B/C, collier2012 §3.2).
///
/// A scan enters the place module as a PlaceScan: the word ids of its instances (a
/// bag of words for tf-idf retrieval), its strongest interest-point features (6-DoF
/// frame, quantised descriptor) for correspondences, and a coarse, quantised range
/// image for scoring candidate transforms. A PlaceDatabase holds PlaceScans, retrieves
/// the top-K by tf-idf similarity through an inverted index, and verifies each with
/// RANSAC over feature correspondences (plus transforms that overlay the two coarse images'
/// dominant surfaces, for revisits whose interest points barely repeat) and steder2010's
/// validation-point score. The best
/// few candidates are then aligned densely (point-to-plane ICP of the points of both
/// coarse images, projective association) and scored again at the aligned transform.
///
/// Transforms: a match carries T_match_query, which maps a point from the query scan's
/// cloud frame into the matched scan's cloud frame. With world <- sensor poses T_q and
/// T_m (e.g. balm's poses.txt) the true value is T_m^-1 · T_q.
///
/// Upright frames: features are upright with respect to the world's up direction, which
/// prepare_scan takes from Cloud::T_world_cloud when has_world_pose. On a robot this
/// gravity direction would come from an IMU; without one, apply_gravity (place/gravity.hpp)
/// estimates it from the scan's points, and failing that the sensor's z axis is used.

#include <cstdint>
#include <functional>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "lex3d/alphabet/alphabet.hpp"
#include "lex3d/core/cloud.hpp"
#include "lex3d/core/status.hpp"
#include "lex3d/model/model.hpp"
#include "lex3d/range/range_image.hpp"
#include "lex3d/place/vocabulary.hpp"

// The public API: exported by liblex3d.so, which hides everything else.
#pragma GCC visibility push(default)

namespace lex3d {

/// The descriptor of a database's stored features (PHDR descriptor_kind, formats/place_db.md §3.1).
enum class PlaceDescriptor : std::uint8_t {
  kPatch = 0,  ///< the features module's range-image patch (steder2010), which the alphabet's words share
  kVdlsd = 1,  ///< VD-LSD (collier2012 §3.1; features/vdlsd.hpp): 64 values; the words stay the patch's
};
/// "patch", "vdlsd".
[[nodiscard]] const char* to_string(PlaceDescriptor d) noexcept;

/// What a database stores of each scan; fixed for a database (saved with it).
struct PlaceStorageParams {
  /// Descriptor of the stored features (what correspondences and the recognition vocabulary use).
  PlaceDescriptor descriptor = PlaceDescriptor::kPatch;
  /// Interest-point features kept per scan, strongest first; [1, 4096].
  int max_features = 160;
  /// Bits per descriptor value (values in [-1, 1], uniform quantiser); 4 or 8.
  int descriptor_bits = 4;
  /// Width of a coarse range-image pixel, degrees of azimuth; [0.05, 10].
  double coarse_azimuth_deg = 1.5;
  /// Rows of the scan's range image merged into one coarse row; [1, 16].
  int coarse_row_factor = 1;
  /// Range quantisation step of the coarse image, metres; [0.001, 1].
  double range_step = 0.02;
  void validate() const;
};

/// The first stage of a query: how candidates are ranked before verification.
enum class PlaceRetrieval {
  kDefault,         ///< kTfidfAlphabet (measured best on balm at 100-5,000 entries, bench/README.md)
  kTfidfAlphabet,   ///< tf-idf cosine over the compression alphabet's word ids (PlaceScan::words)
  kTfidf,           ///< tf-idf cosine over the recognition vocabulary's words (every tree level)
  kFabmap,          ///< FAB-MAP-style likelihood over the vocabulary's leaves (collier2012 §3)
};
/// "tfidf-alphabet", "tfidf", "fabmap" ("default" for kDefault).
[[nodiscard]] const char* to_string(PlaceRetrieval r) noexcept;

/// Parameters of matching and scoring (defaults from steder2010 and collier2012).
struct PlaceParams {
  /// Database scans retrieved by tf-idf and verified geometrically (top-K); [1, 1e6].
  /// On balm, 8 finds every true match within 4 m that 16 finds (bench/place.sh) at half the
  /// cost; of those within 8 m, 000162 -> 000108 ranks below 8 (more_candidates finds it).
  int top_k = 8;
  /// Lowe ratio test on descriptor distances: nearest < ratio · second nearest
  /// (collier2012 §3.2: 0.8); (0, 1].
  double ratio = 0.8;
  /// Minimum RANSAC inliers for a transform (collier2012 §3.2: 6); [3, 1000].
  int min_inliers = 6;
  /// A query feature is an inlier of a transform when it lands within this distance of
  /// a feature of the other scan, metres; (0, 10]. Interest points of revisits 2-5 m
  /// apart repeat only to about this (measured on balm: 15 % within 0.3 m, 30 % within 0.6 m).
  double inlier_distance = 0.5;
  /// Distance-consistency check (steder2010 §III-B): two correspondences are consistent
  /// when their distances within each scan differ by at most this, metres; (0, 10].
  double consistency_tolerance = 0.4;
  /// Candidate transforms from 1, 2 and 3 descriptor correspondences, each (steder2010: 500); [1, 1e5].
  int hypotheses_per_size = 500;
  /// Query feature pairs tried as gravity-aligned 2-correspondence hypotheses: each pair is
  /// matched to every pair of the other scan with the same horizontal distance and height
  /// difference (within consistency_tolerance), giving yaw and translation; [0, 1e5].
  /// 150 gives the same matches as 300 on balm at about 0.6 times the cost.
  int gravity_pairs = 150;
  /// Yaw candidates of the surface hypotheses (scored with the feature hypotheses): the
  /// strongest peaks of the correlation of the two scans' horizontal-normal direction
  /// histograms, each with the translations that best overlay the offsets of the walls
  /// along the two dominant directions and of the ground (2 shifts each), 4 transforms a yaw;
  /// 0 = none; [0, 36]. They find revisits whose interest points barely repeat (balm 000120
  /// -> 000008 and 000110 -> 000080: 4-7 of ~100 repeat within 0.3 m); 4 covers the
  /// 90-degree symmetry of rectangular buildings, where the right yaw need not be the first.
  int surface_yaws = 4;
  /// The best hypotheses (by inliers) that are refined and scored; [1, 100].
  int scored_hypotheses = 10;
  /// Least-squares refinement rounds on the inliers (Umeyama); [0, 50].
  int refine_iterations = 3;
  /// Seed of the RANSAC sampling; results are deterministic for a seed.
  std::uint64_t seed = 1;
  /// Validation points per scan, interest points as equidistant as possible
  /// (steder2010: 100); [1, 4096].
  int validation_points = 100;
  /// Error radius e, coarse-image pixels (steder2010 eq. 6: 2); [0, 20].
  int error_radius_px = 2;
  /// d̂, the largest range difference that still supports a validation point, metres
  /// (steder2010 eq. 7: 0.3); (0, 10].
  double max_range_difference = 0.3;
  /// p, the penalty of a visible but contradicted validation point (eq. 8: 0.3); [0, 1].
  double penalty = 0.3;
  /// Acceptance threshold on the score S (eq. 10), steder2010: 0.25; [0, 1].
  double accept_score = 0.25;
  /// Ground-vehicle check: reject transforms with a large tilt or vertical offset.
  bool ground_vehicle = false;
  /// Largest distance between the two sensor positions a transform may imply, metres; 0 =
  /// any. "Was this place seen from within R?" is a query with max_distance R: a transform
  /// that puts the scans farther apart is rejected, however well it aligns them; [0, 1e4].
  double max_distance = 0.0;
  /// Free-space check of a densely aligned match: the largest share of either scan's
  /// visible dense points that the other scan's beams passed through (DenseConsistency::
  /// conflict / visible); a larger share rejects the transform; 1 = off; (0, 1]. A beam
  /// counts as passing through a point only beyond the range the point's surface spans across
  /// one pixel at its incidence, so what remains is changed scenery and noise. Chosen on balm:
  /// right alignments (from the ground truth) of 605 scan pairs 4-10 m apart showed 0.009 in
  /// the median, 0.039 at most within 8 m and up to 0.074 at 10 m; wrong transforms the
  /// matcher scored 0.2 or more (90° turns in a symmetric courtyard, shifts along a corridor)
  /// 0.070 and more.
  double max_conflict = 0.05;
  /// Ground-vehicle check: largest angle between the two scans' up directions, degrees; [0, 180].
  double max_tilt_deg = 10.0;
  /// Ground-vehicle check: largest vertical offset, metres; [0, 100].
  double max_vertical_offset = 1.0;
  /// Dense alignment (point-to-plane ICP of the coarse images' points, both ways) of the
  /// best transform: iterations, 0 = none; [0, 100].
  int dense_iterations = 15;
  /// Dense points used from each scan at most (evenly strided); [16, 1e6]. 3000 points and
  /// 20 iterations gave 0.08 m / 0.18° against 0.08 m / 0.22° on balm's revisits, at 3x the cost.
  int dense_points = 1500;
  /// Correspondence gate of the first and the last dense iteration, metres (shrinks by 0.7 an
  /// iteration); (0, 10].
  double dense_gate_start = 1.0;
  double dense_gate_end = 0.2;
  /// PlaceDatabase::query aligns densely only its best this many candidates (by the score
  /// of the feature transform); [1, 1e6].
  int dense_candidates = 3;
  /// Transforms of a candidate that dense alignment may try, best feature-stage score first:
  /// when the aligned transform fails the free-space or distance check, the candidate's next
  /// valid transform (distinct, score above 0) is aligned and checked instead; 1 = the best
  /// only; [1, 100]. Between scans several metres apart the feature-stage score separates a
  /// right transform from a wrong one poorly (few interest points repeat, a shift along a
  /// corridor overlays walls as well), while the free-space check of the aligned scans does.
  int dense_hypotheses = 3;
  /// A transform is aligned densely only when its feature-stage score reaches this share of
  /// accept_score (a candidate whose best does not is marked invalid, rejected_score); [0, 1].
  /// Dense alignment is most of a query's cost. On balm (8 m protocol, 720 alignments made
  /// without this floor) none of the 65 that ended right had scored below 0.52 of accept_score
  /// before it; 305 of the 655 that ended wrong had scored below 0.4 of it.
  double dense_score_ratio = 0.4;
  /// When none of the top_k candidates is accepted (score >= accept_score), the next this
  /// many (by retrieval rank) are verified as well, with the surface hypotheses only (lower
  /// ranks share fewer words with the query: their interest points rarely repeat), the best
  /// dense_candidates of them aligned densely; 0 = none; [0, 1e6]. A query that found its
  /// place pays nothing more.
  int more_candidates = 8;
  /// Worker threads over candidates; [1, 64]. Results do not depend on it.
  int threads = 1;
  /// First stage (retrieval of the top_k candidates).
  PlaceRetrieval retrieval = PlaceRetrieval::kDefault;
  /// FAB-MAP detector model: p(word seen | word in the place), (0, 1) (Cummins and Newman's 0.39).
  double fabmap_p_detect = 0.39;
  /// FAB-MAP detector model: p(word seen | word not in the place), (0, fabmap_p_detect)
  /// (Cummins and Newman: 0.005).
  double fabmap_p_false = 0.005;
  /// FAB-MAP prior probability that a query shows a place not in the database; (0, 1).
  double fabmap_new_place_prior = 0.9;
  void validate() const;
};

/// One stored interest-point feature: its frame in the scan's cloud frame.
struct PlaceFeature {
  Eigen::Vector3f position = Eigen::Vector3f::Zero();                ///< cloud frame, metres
  Eigen::Quaternionf rotation = Eigen::Quaternionf::Identity();      ///< R_cloud_feature
};

/// A scan as the place module sees it (the database form; a query takes the same form).
struct PlaceScan {
  std::string name;
  /// Pose of the cloud frame in the world, when known (kept for diagnostics and the
  /// ground-vehicle check).
  Pose T_world_cloud = Pose::Identity();
  bool has_world_pose = false;
  /// Bag of words: (word id, instance count), sorted by word id.
  std::vector<std::pair<std::uint32_t, std::uint32_t>> words;
  std::vector<PlaceFeature> features;
  /// What the descriptors are (the database's PlaceStorageParams::descriptor).
  PlaceDescriptor descriptor = PlaceDescriptor::kPatch;
  /// Features whose VD-LSD support held too few points (stored with the empty descriptor;
  /// counted when the scan is described, not stored).
  std::size_t empty_descriptors = 0;
  int descriptor_dim = 0;
  int descriptor_bits = 8;
  /// Quantised descriptors, features.size() x descriptor_dim codes (one per byte in memory).
  std::vector<std::uint8_t> descriptor_codes;
  /// Dequantised descriptors (derived from the codes).
  std::vector<float> descriptors;
  /// Coarse range image: geometry and ranges (quantised) and states; points are not kept.
  RangeImage coarse;
  /// All features in farthest-point order, the strongest first (derived); the first
  /// PlaceParams::validation_points are the validation points (as equidistant as possible).
  std::vector<std::uint32_t> validation;
  /// Points of the coarse image's valid pixels that have a surface normal, cloud frame
  /// (derived from `coarse`): what dense alignment and the dense score use.
  std::vector<Eigen::Vector3f> dense_points;
  std::vector<Eigen::Vector3f> dense_normals;
  /// Per coarse pixel, the index of its dense point, or -1 (derived).
  std::vector<std::int32_t> dense_index;
  /// Feature pairs a < b at least 1 m apart horizontally in the upright frame (the cloud frame
  /// turned by T_world_cloud's rotation when has_world_pose), by horizontal distance
  /// (derived; what gravity-aligned hypotheses look up).
  struct FeaturePair {
    float horizontal = 0.0F;  ///< horizontal distance, metres
    float dz = 0.0F;          ///< height of b minus height of a, metres
    float angle = 0.0F;       ///< direction of b - a, radians
    std::uint16_t a = 0, b = 0;
  };
  std::vector<FeaturePair> pairs;
};

/// Builds the PlaceScan of a prepared scan and its model (word ids from the instances;
/// `model` may be empty, then retrieval has nothing to go on). Builds the scan's range
/// image with `range` (as feature extraction does) for the coarse image.
[[nodiscard]] PlaceScan make_place_scan(const PreparedScan& scan, const Model& model,
                                        const PlaceStorageParams& storage, const RangeImageParams& range = {},
                                        std::string name = {});

/// As above, with word ids assigned directly: every feature (interest and coverage) takes
/// the word with the nearest descriptor, which is encode_scan's assignment before its
/// pruning and pose refinement (much cheaper, same ids).
[[nodiscard]] PlaceScan make_place_scan(const PreparedScan& scan, const Alphabet& alphabet,
                                        const PlaceStorageParams& storage, const RangeImageParams& range = {},
                                        std::string name = {});

/// As above from the cloud itself: the same PlaceScan as make_place_scan(prepare_scan(cloud,
/// params, alphabet.word_radius), alphabet, storage, params.features.range, name), with one range
/// image instead of two and without the neighbourhoods prepare_scan finds for coding.
[[nodiscard]] PlaceScan make_place_scan(const Cloud& cloud, const Alphabet& alphabet, const PlaceStorageParams& storage,
                                        const ModelParams& params, std::string name = {});

/// The alphabet a place database is built with when none is given (`lex3d place build`,
/// lex3d.PlaceDatabase.build): learn_alphabet(`params`) on k = min(scan_count, learn_scans)
/// scans spread evenly over the set, scan(i * scan_count / k) for i < k, each read when
/// asked for (none when scan_count is 0: then the alphabet learn_alphabet gives for no scans).
/// Throws std::invalid_argument when learn_scans is 0 or `params` is invalid.
[[nodiscard]] Alphabet learn_place_alphabet(std::size_t scan_count, const std::function<Cloud(std::size_t)>& scan,
                                            std::size_t learn_scans, const LearnParams& params,
                                            const std::function<void(const LearnProgress&)>& progress = {});

/// Bytes of one scan in the database format (its SCAN chunk, framing included).
[[nodiscard]] std::size_t stored_bytes(const PlaceScan& scan);

/// Evidence of the dense points of one scan in the coarse image of another.
struct DenseConsistency {
  std::size_t points = 0;    ///< dense points looked at
  std::size_t visible = 0;   ///< support + conflict
  std::size_t support = 0;   ///< a pixel within ±1 sees a surface within d̂ of the point
  std::size_t conflict = 0;  ///< the other scan's beam passed through the point (free space)
  /// conflict / visible (0 when nothing is visible): what PlaceParams::max_conflict bounds.
  [[nodiscard]] double conflict_share() const noexcept {
    return visible > 0 ? static_cast<double>(conflict) / static_cast<double>(visible) : 0.0;
  }
};

/// A valid feature-stage transform of a candidate other than the best one (what dense
/// alignment tries when the best fails the free-space or distance check).
struct PlaceAlternative {
  Pose T_match_query = Pose::Identity();
  double score = 0.0;
  double score_query_in_match = 0.0;
  double score_match_in_query = 0.0;
  std::size_t inliers = 0;
  std::size_t descriptor_inliers = 0;
  double rms_inlier_m = 0.0;
  double sensor_distance_m = 0.0;
};

/// The result of matching a query against one scan.
struct PlaceMatch {
  std::size_t scan = 0;                 ///< database index
  Pose T_match_query = Pose::Identity();
  double score = 0.0;                   ///< S = min(score_query_in_match, score_match_in_query)
  double score_query_in_match = 0.0;    ///< query validation points in the match's image
  double score_match_in_query = 0.0;    ///< match validation points in the query's image
  double retrieval_similarity = 0.0;    ///< tf-idf cosine similarity
  std::size_t correspondences = 0;      ///< after the ratio test
  std::size_t inliers = 0;              ///< query features within inlier_distance of a match feature
  std::size_t descriptor_inliers = 0;   ///< ratio-test correspondences consistent with the transform
  std::size_t hypotheses = 0;           ///< candidate transforms evaluated
  double rms_inlier_m = 0.0;            ///< RMS distance of the inliers after refinement
  bool rejected_ground = false;         ///< dropped by the ground-vehicle check
  bool rejected_distance = false;       ///< dropped by PlaceParams::max_distance
  bool rejected_conflict = false;       ///< dropped by PlaceParams::max_conflict
  bool rejected_score = false;          ///< not aligned densely: score below PlaceParams::dense_score_ratio · accept_score
  double sensor_distance_m = 0.0;       ///< distance between the sensor positions T_match_query implies
  Pose T_feature = Pose::Identity();    ///< the transform before dense alignment
  double dense_rms_m = 0.0;             ///< point-to-plane RMS of the last dense iteration
  std::size_t dense_used = 0;           ///< dense correspondences in the last iteration
  DenseConsistency dense_q;             ///< query points in the match's image
  DenseConsistency dense_m;             ///< match points in the query's image
  bool dense_refined = false;           ///< T_match_query and the scores come from dense alignment
  /// Feature-stage transforms after the best, best score first (at most
  /// PlaceParams::dense_hypotheses - 1); dense alignment falls back on them in turn.
  std::vector<PlaceAlternative> alternatives;
  /// Transforms aligned densely (1 + the alternatives tried; 0 = not aligned).
  std::size_t dense_tried = 0;
  bool valid = false;                   ///< a transform with at least min_inliers was found
};

/// Matches `query` against `candidate`: correspondences (ratio test), candidate
/// transforms from 1, 2 and 3 correspondences with the distance-consistency check,
/// RANSAC inlier counting, Umeyama refinement, validation-point score. Deterministic.
[[nodiscard]] PlaceMatch match_scans(const PlaceScan& query, const PlaceScan& candidate, const PlaceParams& params);

/// Dense alignment of a valid match from m.T_feature, then its scores again (match_scans
/// does this itself when params.dense_iterations > 0).
void refine_match(const PlaceScan& query, const PlaceScan& candidate, PlaceMatch& m, const PlaceParams& params);

struct DenseAlignment {
  Pose T_match_query = Pose::Identity();
  double rms_m = 0.0;
  std::size_t used = 0;
  int iterations = 0;
};
/// Point-to-plane ICP of both scans' dense points against each other's tangent planes
/// (projective association in the coarse images), from T0.
[[nodiscard]] DenseAlignment dense_align(const PlaceScan& query, const PlaceScan& match, const Pose& T0,
                                         const PlaceParams& params);
/// Dense points of `from` moved by T_to_from into the coarse image of `to`.
[[nodiscard]] DenseConsistency dense_consistency(const PlaceScan& from, const PlaceScan& to, const Pose& T_to_from,
                                                 const PlaceParams& params);

/// Steder2010 eq. 6-10: score of the validation points of `from` moved by T_to_from into
/// the coarse range image of `to`; in [0, 1].
[[nodiscard]] double validation_score(const PlaceScan& from, const PlaceScan& to, const Pose& T_to_from,
                                      const PlaceParams& params);

struct PlaceQueryResult {
  /// Verified candidates, best score first (invalid ones last, score 0).
  std::vector<PlaceMatch> matches;
  /// True when the best score reaches PlaceParams::accept_score; false = unknown place.
  bool accepted = false;
  std::size_t retrieved = 0;  ///< candidates verified (top_k, and more_candidates more when none of those was accepted)
  double retrieval_ms = 0.0;
  double verification_ms = 0.0;  ///< includes decode_ms
  double decode_ms = 0.0;        ///< reading the candidates' stored entries (summed over threads)
  std::size_t decoded = 0;       ///< candidates read from the stored bytes (the others were cached or in memory)
  PlaceRetrieval retrieval = PlaceRetrieval::kTfidfAlphabet;  ///< the first stage used
  /// FAB-MAP: posterior probability that the query is a new place; -1 for the tf-idf stages.
  double new_place_probability = -1.0;
  [[nodiscard]] const PlaceMatch* best() const noexcept { return matches.empty() ? nullptr : &matches.front(); }
};

/// The first stage's statistics of a database: its entries and, per alphabet word id, how
/// many of them hold the word (what tf-idf's idf is made of). Summed over the shards of a
/// sharded database (databases of consecutive scan ranges) they are those of one database
/// holding all the shards' scans.
struct PlaceWordStatistics {
  std::uint64_t scans = 0;
  std::vector<std::uint64_t> df;  ///< per word id; shorter than the alphabet when the last words are unused
  PlaceWordStatistics& operator+=(const PlaceWordStatistics& other);
  [[nodiscard]] bool operator==(const PlaceWordStatistics& o) const noexcept { return scans == o.scans && df == o.df; }
};

/// One database's part of a staged query (PlaceDatabase::verify): its candidates verified with
/// the feature transform (no dense step), best first (valid, then score, then lower index), and
/// copies of the first PlaceParams::dense_candidates of them densely aligned (when
/// dense_iterations > 0). Indices are the database's own.
struct PlaceVerified {
  std::vector<PlaceMatch> matches;
  std::vector<PlaceMatch> refined;
  double decode_ms = 0.0;   ///< reading the candidates' stored entries (summed over threads)
  std::size_t decoded = 0;  ///< candidates read from the stored bytes
};

/// Merges the verified parts of databases that hold consecutive scan ranges (`offsets[i]`: the
/// index of part i's first scan in the whole): matches ordered as PlaceDatabase::query orders
/// them, the best dense_candidates of all taking their densely aligned form, so that the
/// result is that of one database holding all the scans (given candidates retrieved with the
/// global statistics). Sets matches, accepted, decode_ms and decoded. Throws
/// std::invalid_argument when the sizes differ or a part lacks a refined match it should hold.
[[nodiscard]] PlaceQueryResult merge_verified(std::vector<PlaceVerified> parts, const std::vector<std::size_t>& offsets,
                                              const PlaceParams& params);

/// Adds a second round's merged result (the next PlaceParams::more_candidates, verified with
/// `second_round` where the first top_k gave no accepted match) to the first's, ordered as
/// PlaceDatabase::query orders them; updates accepted, decode_ms and decoded.
void merge_round(PlaceQueryResult& first, PlaceQueryResult second, const PlaceParams& params);

/// A prepared query scan as bytes, to send to the shards of a database (formats/place_db.md
/// §6): the scan's SCAN chunk payload plus the unquantised feature rotations, so that
/// decode_place_query gives a scan that verifies exactly as the one encoded. `storage` must
/// be the one the scan was made with.
[[nodiscard]] std::vector<std::uint8_t> encode_place_query(const PlaceScan& scan, const PlaceStorageParams& storage);
/// The scan of encode_place_query's bytes; kBadData (with the byte offset) for bytes that do not
/// decode. `storage` as given to encode_place_query.
[[nodiscard]] StatusOr<PlaceScan> decode_place_query(const std::uint8_t* data, std::size_t size,
                                                     const PlaceStorageParams& storage);

/// Read-only bytes that stay valid while `owner` lives (a memory-mapped file, a buffer).
struct SharedBytes {
  const std::uint8_t* data = nullptr;
  std::size_t size = 0;
  std::shared_ptr<const void> owner;
  /// Owns a copy of `bytes`.
  [[nodiscard]] static SharedBytes copy_of(const std::vector<std::uint8_t>& bytes);
};

/// A stored database entry that cannot be read (CRC mismatch, bad field): thrown by
/// PlaceDatabase::query / scan / save, which decode entries only when they need them.
class PlaceDataError : public std::runtime_error {
 public:
  explicit PlaceDataError(Status status) : std::runtime_error(status.to_string()), status_(std::move(status)) {}
  [[nodiscard]] const Status& status() const noexcept { return status_; }

 private:
  Status status_;
};

/// Where a database opened from bytes came from (formats/place_db.md).
struct PlaceFileInfo {
  int major = 0, minor = 0;             ///< format version of the bytes (0.0: not opened from bytes)
  std::uint64_t commit_sequence = 0;    ///< 2.x: sequence number of the commit in force
  std::uint64_t committed_bytes = 0;    ///< 2.x: bytes of the committed state (the file's length after a clean write)
  std::uint64_t ignored_tail_bytes = 0; ///< 2.x: bytes after the committed state (an append that did not commit)
  std::uint64_t dead_bytes = 0;         ///< 2.x: bytes of earlier indexes an append left behind
  std::uint64_t index_bytes = 0;        ///< the inverted index chunk (2.x: read from the file; 1.0: built on open)
};

/// A scan database with an inverted index word id -> scans (after FAISS's Index:
/// state lasts across add/query; save/open to bytes).
///
/// A database opened from bytes (open / load) reads only what retrieval needs: the header,
/// the alphabet and the inverted index with each scan's word total and tf-idf norm, as
/// views into the bytes (a memory-mapped file stays on disk until pages are touched). A
/// scan's entry is decoded, and its CRC checked, when a query verifies it as a candidate or
/// scan() asks for it. Scans added after opening are kept in memory, decoded.
class PlaceDatabase {
 public:
  explicit PlaceDatabase(PlaceStorageParams storage = {});

  [[nodiscard]] const PlaceStorageParams& storage() const noexcept { return storage_; }
  /// The alphabet the word ids refer to (optional; stored with the database).
  void set_alphabet(Alphabet alphabet) { alphabet_ = std::move(alphabet); has_alphabet_ = true; }
  [[nodiscard]] bool has_alphabet() const noexcept { return has_alphabet_; }
  [[nodiscard]] const Alphabet& alphabet() const noexcept { return alphabet_; }
  /// Descriptor values a feature of this database's scans (0 until known).
  [[nodiscard]] int descriptor_dim() const noexcept { return descriptor_dim_; }

  /// The largest word id + 1 a database without an alphabet accepts.
  static constexpr std::size_t kMaxWordsWithoutAlphabet = std::size_t{1} << 24;
  /// Adds a scan (kept in memory); returns its index. Throws std::invalid_argument when
  /// its descriptor layout differs from the database's, or it holds a word id the database's
  /// alphabet does not have (without an alphabet: kMaxWordsWithoutAlphabet or more).
  std::size_t add(PlaceScan scan);
  [[nodiscard]] std::size_t size() const noexcept { return stored_count() + added_.size(); }
  /// Scans read from bytes (the others were added in memory).
  [[nodiscard]] std::size_t stored_count() const noexcept { return index_.scans; }
  /// The name of scan i, without decoding it.
  [[nodiscard]] std::string name(std::size_t i) const;
  /// Scan i, decoded (a stored one is read from the bytes and its CRC checked). Throws
  /// std::out_of_range for a bad index and PlaceDataError for a corrupt entry.
  [[nodiscard]] PlaceScan scan(std::size_t i) const;
  /// As scan(), with a corrupt entry as a Status (kBadData with the byte offset).
  [[nodiscard]] StatusOr<PlaceScan> read_scan(std::size_t i) const;
  /// Stored scans a query keeps decoded for the queries after it (least recently used
  /// dropped first; about 0.6 MB each on balm); 0 = none. Default 32. Results do not depend on it.
  void set_decoded_cache(std::size_t scans);

  /// tf-idf cosine similarity of `query` to every scan with a shared word, best first,
  /// at most `k` (ties by lower index). idf = ln(1 + N / n_w).
  [[nodiscard]] std::vector<std::pair<std::size_t, double>> retrieve(const PlaceScan& query, std::size_t k) const;

  /// Retrieves top_k candidates and verifies them with match_scans; when none is accepted,
  /// the next more_candidates too (a second round). Throws PlaceDataError when a candidate's
  /// stored entry is corrupt. The staged query below in one call:
  /// merge_verified({verify(query, first top_k of retrieve(...), params)}, {0}, params), then
  /// where not accepted merge_round with the next more_candidates verified with second_round.
  [[nodiscard]] PlaceQueryResult query(const PlaceScan& query, const PlaceParams& params) const;

  /// Staged query over shards (databases of consecutive scan ranges, one alphabet): sum the
  /// shards' word_statistics(), retrieve(query, top_k, global) on each, keep the top_k of all
  /// (score, then lower global index), verify() each shard's share on its shard, and
  /// merge_verified() the parts (where none is accepted, the same for the next more_candidates
  /// with second_round, merge_round() into the first); the result equals query() on one
  /// database of all the scans.
  /// Only the alphabet's tf-idf (kTfidfAlphabet) is staged.
  [[nodiscard]] PlaceWordStatistics word_statistics() const;
  /// retrieve(query, k) with idf and the entries' norms taken from `global` (the statistics of
  /// the whole a shard belongs to): the scores one database of all the scans gives; this
  /// database's indices. Throws std::invalid_argument when `global` holds fewer scans or
  /// fewer entries of a word than this database.
  [[nodiscard]] std::vector<std::pair<std::size_t, double>> retrieve(const PlaceScan& query, std::size_t k,
                                                                     const PlaceWordStatistics& global) const;
  /// Verifies `candidates` (this database's indices, with their first-stage scores): see
  /// PlaceVerified. Throws std::out_of_range for a bad index and PlaceDataError when a
  /// candidate's stored entry is corrupt. `second_round`: the candidates ranked below top_k,
  /// verified with the surface hypotheses alone (no feature or gravity-pair hypotheses).
  [[nodiscard]] PlaceVerified verify(const PlaceScan& query, const std::vector<std::pair<std::size_t, double>>& candidates,
                                     const PlaceParams& params, bool second_round = false) const;

  /// Serialises the whole database in the current format (formats/place_db.md), stored
  /// entries copied as they are (their CRC checked). Throws PlaceDataError for a corrupt one.
  [[nodiscard]] std::vector<std::uint8_t> save() const;
  /// Opens a database from its bytes (format 2.x or 1.0) without decoding its entries;
  /// corrupt, truncated or inconsistent bytes give a kBadData Status with the byte offset.
  /// A newer major version is refused with a message that says so.
  [[nodiscard]] static StatusOr<PlaceDatabase> open(SharedBytes bytes);
  /// open() of a copy of `bytes`.
  [[nodiscard]] static StatusOr<PlaceDatabase> load(const std::vector<std::uint8_t>& bytes);
  /// What open() found (version, commit, bytes left behind by appends).
  [[nodiscard]] const PlaceFileInfo& file_info() const noexcept { return info_; }
  /// The stored entry of scan i (i < stored_count()) as it is in the bytes: its whole SCAN
  /// chunk, CRC checked; kBadData when it does not check.
  [[nodiscard]] StatusOr<std::pair<const std::uint8_t*, std::size_t>> stored_chunk(std::size_t i) const;

  /// The recognition vocabulary (formats/place_db.md §3.5); set before any scan is added
  /// (throws std::logic_error otherwise, std::invalid_argument for an empty one or one whose
  /// descriptor size differs from the database's).
  void set_vocabulary(PlaceVocabulary vocabulary);
  [[nodiscard]] bool has_vocabulary() const noexcept { return vocabulary_ != nullptr; }
  /// The vocabulary (null when none).
  [[nodiscard]] const std::shared_ptr<const PlaceVocabulary>& vocabulary() const noexcept { return vocabulary_; }
  /// The first stage by `method` (kDefault resolved as PlaceParams says): scans with a shared
  /// word, best first, at most `k` (ties by lower index), with their tf-idf cosine or, for
  /// kFabmap, their posterior probability. `new_place_probability` (kFabmap) may be null.
  /// Throws std::invalid_argument for kTfidf / kFabmap without a vocabulary.
  [[nodiscard]] std::vector<std::pair<std::size_t, double>> retrieve(const PlaceScan& query, std::size_t k,
                                                                     PlaceRetrieval method, const PlaceParams& params,
                                                                     double* new_place_probability = nullptr) const;
  /// kDefault resolved for this database.
  [[nodiscard]] PlaceRetrieval resolve(PlaceRetrieval method) const noexcept;

 private:
  friend class PlaceFileWriter;
  struct Posting {
    std::uint32_t scan;
    std::uint32_t count;
  };
  /// The stored inverted index: views into the index bytes (formats/place_db.md §3.4).
  struct StoredIndex {
    std::uint32_t scans = 0;
    std::uint32_t word_slots = 0;
    const std::uint8_t* entries = nullptr;       // scans x 36 bytes
    const std::uint8_t* names = nullptr;
    std::uint64_t names_length = 0;
    const std::uint8_t* word_start = nullptr;    // (word_slots + 1) x u64
    const std::uint8_t* postings = nullptr;      // x (u32 scan, u32 count)
  };
  struct NormCache;
  struct DecodedCache;
  /// Stored scan i decoded, from the cache or read (and cached).
  [[nodiscard]] StatusOr<std::shared_ptr<const PlaceScan>> decoded(std::size_t i, double& decode_ms) const;
  [[nodiscard]] std::uint32_t word_total(std::size_t i) const;
  [[nodiscard]] std::size_t stored_postings(std::uint32_t word) const;
  [[nodiscard]] const std::vector<double>& norms() const;
  /// The k entries of highest tf-idf cosine with `query` (both retrieve()s): idf(word) is a
  /// word's inverse document frequency (0: the word is left out), norm2(i) entry i's squared
  /// tf-idf norm. Defined and used in database.cpp only.
  template <class Idf, class Norm2>
  [[nodiscard]] std::vector<std::pair<std::size_t, double>> rank_tfidf(const PlaceScan& query, std::size_t k, Idf idf,
                                                                       Norm2 norm2) const;

  PlaceStorageParams storage_;
  Alphabet alphabet_;
  bool has_alphabet_ = false;
  int descriptor_dim_ = 0;
  // Stored part (empty for a database made in memory).
  SharedBytes bytes_;
  std::shared_ptr<const std::vector<std::uint8_t>> built_index_;  // 1.0: the index built on open
  StoredIndex index_;
  PlaceFileInfo info_;
  // Added in memory.
  std::vector<PlaceScan> added_;
  std::vector<std::uint32_t> added_total_;                      // instances per added scan
  std::vector<std::vector<Posting>> added_inverted_;            // word id -> postings of added scans
  std::shared_ptr<NormCache> norm_cache_;
  std::shared_ptr<NormCache> global_norm_cache_;  // norms under the last statistics retrieve(.., global) was given
  std::shared_ptr<DecodedCache> decoded_cache_;  // shared by copies: stored entries never change
  // Recognition vocabulary and its inverted index (VOCB, VIDX chunks).
  struct StoredVocabIndex {
    std::uint32_t scans = 0;
    std::uint32_t word_slots = 0;
    const std::uint8_t* entries = nullptr;     // scans x (word_total u32, norm2 f64)
    const std::uint8_t* word_start = nullptr;  // (word_slots + 1) x u64
    const std::uint8_t* postings = nullptr;    // x (u32 scan, u32 count)
  };
  [[nodiscard]] std::uint32_t vocab_total(std::size_t i) const;
  [[nodiscard]] std::size_t vocab_stored_postings(std::uint32_t word) const;
  [[nodiscard]] const std::vector<double>& vocab_norms() const;
  std::shared_ptr<const PlaceVocabulary> vocabulary_;
  StoredVocabIndex vindex_;
  std::vector<std::uint32_t> added_vtotal_;
  std::vector<std::vector<Posting>> added_vinverted_;
  std::shared_ptr<NormCache> vnorm_cache_;
};

/// Writes a database file in format 2.0 piece by piece, holding one scan at a time (and
/// the inverted index): `begin` bytes, then one SCAN chunk a scan, then `finish`'s index
/// and commit. Each piece says where it goes; a writer that applies them in order and syncs
/// before the commit leaves either the old committed state or the new one (formats/place_db.md §5).
class PlaceFileWriter {
 public:
  struct Piece {
    std::uint64_t offset = 0;
    std::vector<std::uint8_t> bytes;
  };
  /// A new file: begin() gives the header, PHDR and ALPH at offset 0.
  PlaceFileWriter(const PlaceStorageParams& storage, const Alphabet* alphabet, int descriptor_dim);
  /// Appends to `db`, opened from a 2.x file: the new chunks go at its committed end
  /// (bytes after it are overwritten; truncate the file there first).
  explicit PlaceFileWriter(const PlaceDatabase& db);
  /// Bytes to write first (empty when appending).
  [[nodiscard]] Piece begin();
  /// The SCAN chunk of `scan`, at the end. Throws std::invalid_argument when its descriptor
  /// layout differs from the database's.
  [[nodiscard]] Piece add(const PlaceScan& scan);
  /// Copies stored scan i of `db` (its chunk CRC checked; kBadData otherwise).
  [[nodiscard]] StatusOr<Piece> copy(const PlaceDatabase& db, std::size_t i);
  /// The index chunk (write it, then sync) and the commit record (write it, then sync).
  [[nodiscard]] std::pair<Piece, Piece> finish();
  [[nodiscard]] std::size_t size() const noexcept { return names_.size(); }
  /// Offset where the first new byte goes (the committed end when appending).
  [[nodiscard]] std::uint64_t start() const noexcept { return start_; }
  /// A new file with a recognition vocabulary (before begin(); null = none): begin() writes
  /// its VOCB chunk and finish() the VIDX chunk of every scan's vocabulary words.
  void set_vocabulary(std::shared_ptr<const PlaceVocabulary> vocabulary);

 private:
  void index(std::uint64_t chunk_offset, std::uint64_t payload_length, const std::string& name,
             const std::vector<std::pair<std::uint32_t, std::uint32_t>>& words);
  PlaceStorageParams storage_;
  const Alphabet* alphabet_ = nullptr;
  int descriptor_dim_ = 0;
  std::uint64_t start_ = 0;
  std::uint64_t end_ = 0;
  std::uint64_t sequence_ = 1;
  std::vector<std::uint64_t> offsets_, lengths_;
  std::vector<std::string> names_;
  std::vector<std::uint32_t> totals_;
  std::vector<std::vector<std::pair<std::uint32_t, std::uint32_t>>> inverted_;  // word -> (scan, count)
  std::shared_ptr<const PlaceVocabulary> vocabulary_;
  std::vector<std::uint32_t> vtotals_;
  std::vector<std::vector<std::pair<std::uint32_t, std::uint32_t>>> vinverted_;  // vocabulary word -> (scan, count)
  void vocab_index(const PlaceScan& scan);
};

namespace detail {
/// Values of a stored descriptor: the alphabet's for kPatch (0 without one), 64 for kVdlsd.
int stored_descriptor_dim(const PlaceStorageParams& storage, const Alphabet* alphabet) noexcept;
/// Quantises descriptors (values in [-1, 1]) to `bits` per value and back.
std::uint8_t quantise_descriptor_value(float v, int bits) noexcept;
float dequantise_descriptor_value(std::uint8_t code, int bits) noexcept;
/// Fills `scan.descriptors` and `scan.validation` from the stored fields.
void finish_place_scan(PlaceScan& scan);
}  // namespace detail

}  // namespace lex3d

#pragma GCC visibility pop
