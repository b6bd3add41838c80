#pragma once
/// \file
/// The residual layer (formats/model.md §2.5): what the placed words do not explain
/// within a chosen error E is coded too, so that the decoded cloud meets E both ways.
///
/// Guarantee, for a model file with a residual layer of error E, the input cloud P
/// it was made from and the decoded cloud D (`decode_cloud`), all coordinates as the
/// float32 values they are stored in and distances computed in double precision:
///  - every point of P has a point of D within E, and
///  - every point of D has a point of P within E.
/// D is the reconstructed word points that have an input point within E (a keep mask
/// over the reconstruction) plus the input points no kept word point explains (thinned:
/// a point within E of one decoded before it is skipped), quantised in sensor-centred
/// spherical coordinates and range coded; or, in the voxel coding, the centres of the
/// cubic cells (2E/sqrt(3) wide, less a margin) that hold the input points no kept word
/// point explains, coded as an octree.

#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "lex3d/codec/codec.hpp"
#include "lex3d/core/cloud.hpp"
#include "lex3d/core/status.hpp"
#include "lex3d/residual/attributes.hpp"

// The public API: exported by liblex3d.so, which hides everything else.
#pragma GCC visibility push(default)

namespace lex3d::residual {

/// Smallest and largest error bound a residual layer accepts, metres.
inline constexpr double kMinMaxError = 1e-4;
inline constexpr double kMaxMaxError = 10.0;

/// How the encoder codes a layer (the decoder needs none of it).
struct LayerOptions {
  /// Skip an input point that a point decoded before it already explains within E
  /// (the bound still holds both ways; fewer points are coded where they are denser
  /// than E). Off: every unexplained input point gets its own decoded point.
  bool thin = true;
  /// Also try the sweep coding (formats/model.md §2.6: a file of format 1.2) and keep it
  /// when it codes smaller; off: the layer is always a RESD one (format 1.1).
  bool sweep = true;
  /// Also try the voxel coding (formats/model.md §2.7: a file of format 1.3), which needs
  /// no sensor (maps merged from many viewpoints), and keep it when it codes smaller.
  /// Only with `thin`: a voxel stands for all the points in it.
  bool voxel = true;
  /// Try the spherical codings (RESD, and RESW with `sweep`); off with `voxel` on: the
  /// voxel coding alone (the spherical ones still code a layer the voxel one cannot).
  bool spherical = true;
  /// Also try the sensor-geometry coding (formats/model.md §2.8: a file of format 1.4) where
  /// the scan's lasers and columns are known (an organised cloud, a `ring` field, a raw
  /// sensor log) and keep it when it codes smaller.
  bool laser = true;
  /// Also try the acquisition-order coding (formats/model.md §2.11: a file of format 1.12)
  /// where the points carry times that rise in their order (a LAS file's GPS times) and keep
  /// it when it codes smaller.
  bool acquisition = true;
  /// Also try the lattice coding (formats/model.md §2.12: a file of format 1.12) where the
  /// points gather one or a few a cell at the points of a square lattice in x and y (a
  /// gridded product) and keep it when it codes smaller.
  bool lattice = true;
  /// Sensor-rate encoding: lasers estimated from the points as cones on a quarter as many
  /// points; the sensor-geometry coding chooses its range step and predictor on an eighth of
  /// the columns (not a quarter); and beside it a spherical coding (no sweep) or the voxel coding is
  /// coded in full only where its trial window beats it (the voxel trial on a quarter of the
  /// default's window) or the points lie closer together than a voxel cell. A KITTI scan in
  /// 0.6 of the time; of 300 files, 230 the same, 90 % within 0.5 % and the largest 1.06 times
  /// the default's (bench/README.md, "Fast encoding").
  bool fast = false;
  /// The mean-squared-error objective: the fewest bits for the mean squared error, within
  /// the bound. The sensor-geometry coding takes a range step of E (not about 1.8 E) and
  /// lets each point take either step within E, chosen by rate and distortion; the other
  /// codings code to 5/9 E. At the same E a file is larger and its mean squared error
  /// lower (about a third where the laser table fits the points); at the same PSNR files
  /// are smaller than the default's (bench/README.md, "Beam lengths chosen a laser at a
  /// time, and the mean-squared-error objective").
  bool mse = false;
  /// Worker threads; the output does not depend on it.
  int threads = 2;
  /// Fill LayerStats::sources (the input point each decoded point stands for, which the
  /// attribute chunk needs); off, it stays empty.
  bool track_sources = false;
};

/// What encoding a residual layer did.
struct LayerStats {
  double max_error = 0.0;              ///< E, metres
  std::size_t word_points = 0;         ///< points of the word reconstruction
  std::size_t kept_word_points = 0;    ///< of those, kept (an input point within E)
  std::size_t explained_points = 0;    ///< input points a kept word point explains
  std::size_t residual_points = 0;     ///< points coded by the layer (input points, thinned)
  std::size_t escaped_points = 0;      ///< of those, coded in Cartesian form (near the sensor or a pole)
  std::size_t bytes = 0;               ///< payload bytes of the layer
  bool sweep = false;                  ///< coded with the sweep coding (an RESW chunk)
  bool voxel = false;                  ///< coded with the voxel coding (an RESV chunk)
  bool laser = false;                  ///< coded with the sensor-geometry coding (an RESL chunk)
  bool acquisition = false;            ///< coded in acquisition order (an RESA chunk)
  bool lattice = false;                ///< coded on a lattice (an RESG chunk)
  /// A spherical coding was coded over the whole layer (until it could no longer be the
  /// smallest, beside a coding in hand); not where its trials ruled it out. Encoder work
  /// only: the file does not say.
  bool spherical_in_full = false;
  /// Where the laser table came from when the sensor-geometry coding was tried (empty
  /// when it was not), and the RMS distance of the points from their table's beams.
  std::string laser_table_source;
  double laser_table_rms = 0.0;
  std::uint32_t lasers = 0, columns = 0;  ///< the table's lasers and columns a turn
  /// With LayerOptions::track_sources: for each decoded point (kept word points, then
  /// coded points, in the decoded order) the input point it stands for: a coded point's
  /// own input point; for a kept word point or a voxel centre the input point nearest
  /// to it (ties: the lowest index).
  std::vector<std::uint32_t> sources;
  /// With LayerOptions::track_sources and the sensor-geometry coding: each decoded point's
  /// laser and column in the layer's table (LayerKeys), as the decoder finds them; the
  /// attribute coder's keys (formats/model.md §2.10). Empty for the other codings.
  LayerKeys layer;
};

/// The fixed fields at the start of a residual layer's payload (formats/model.md §2.5,
/// RESW: §2.6).
struct LayerHeader {
  double max_error = 0.0;          ///< E, metres
  double step = 0.0;               ///< q, metres
  std::uint64_t word_points = 0;   ///< reconstruction points the keep mask covers
  std::uint64_t coded_points = 0;  ///< points coded by the layer
  std::uint32_t coding = 0;        ///< 0: previous-point (RESD); 1: sweep (RESW); 2: voxel (RESV); 3: sensor geometry (RESL); 4: acquisition order (RESA); 5: lattice (RESG)
  double cell = 0.0;               ///< sweep coding: direction cell, radians
  std::array<double, 3> origin{};  ///< voxel and acquisition-order codings: the grid's corner, model frame, metres
  std::uint32_t depth = 0;         ///< voxel coding: octree levels
  std::uint32_t octree_contexts = 0;  ///< voxel coding: 0 face contexts (§2.7.1), 1 mixed contexts (§2.7.4, format 1.8)
  std::uint32_t voxel_reserved = 0;   ///< voxel coding: the reserved u16 after depth and contexts; lattice coding: its order field (0 input order, 1 stacked: format 1.13)
  std::uint32_t fit_pulses = 0;    ///< acquisition-order coding: pulses of the line fit of x and y, 0 for format 1.12's step (formats/model.md §2.11.1)
  double step_z = 0.0;             ///< acquisition-order coding: the cells' height where taller than wide (format 1.13), else 0 (cubes of `step`)
  double tangential_step = 0.0;    ///< sensor-geometry coding: step across the beams, metres
  std::uint32_t lasers = 0;        ///< sensor-geometry coding: lasers of the table
  std::uint32_t columns = 0;       ///< sensor-geometry coding: columns a turn; lattice coding: the lattice's columns
  std::uint32_t rows = 0;          ///< lattice coding: the lattice's rows
  double pitch = 0.0;              ///< lattice coding: the lattice's pitch, metres
  std::uint32_t predictor = 0;     ///< sensor-geometry coding: range predictor 0-5 (formats/model.md §2.8.2, §2.8.4)
  bool table_predictors = false;   ///< sensor-geometry coding: the laser table's fields each against its own predictor (format 1.11)
  bool motion = false;             ///< sensor-geometry coding: the beams' origins move over the turn (a motion-compensated scan, format 1.14)
  bool quick_models = false;       ///< sensor-geometry coding: predictor 4 or 5's mixed models learn at the quick rates (format 1.18)
  bool head_pose = true;           ///< sensor-geometry coding: T_sensor_head stored (marker 0xFFFFFFFF), else the identity (0xFFFFFFFE, format 1.11)
  std::uint64_t fields_offset = 0; ///< where max_error starts (8 in an RESW payload)
  std::uint64_t stream_offset = 0; ///< where the range-coded stream starts
};
/// Whether a payload starts with a coding u32 and the marker 0xFFFFFFFF (the sweep, voxel
/// and sensor-geometry codings), or 3 and 0xFFFFFFFE (the sensor-geometry coding without
/// its head pose); codec::layer_coding names its chunk.
[[nodiscard]] bool has_coding_field(const std::uint8_t* payload, std::size_t size);
/// Reads the header of a residual payload (no checks beyond its length and coding).
[[nodiscard]] StatusOr<LayerHeader> read_layer_header(const std::uint8_t* payload, std::size_t size);

/// The word reconstruction a decoder of `data` computes: the instances placed and
/// thinned to the alphabet's point spacing (`reconstruct`), in the model's frame.
/// `data.alphabet` must be set (decode_model sets it).
[[nodiscard]] Cloud word_cloud(const codec::ModelData& data);

/// Encodes the residual payload for `input` (the scan, model frame) against `words`
/// (exactly what `word_cloud` gives the decoder) with error bound `max_error`
/// ([kMinMaxError, kMaxMaxError]); `T_cloud_sensor` centres the spherical coding.
/// Throws std::invalid_argument for a bound out of range or a point beyond 2^30
/// quantisation steps from the sensor.
[[nodiscard]] std::vector<std::uint8_t> encode_layer(const Cloud& input, const Cloud& words, const Pose& T_cloud_sensor,
                                                     double max_error, LayerStats* stats = nullptr,
                                                     const LayerOptions& options = {});

/// Decodes a residual payload against `words`: the kept word points, then the coded
/// points, in the model's frame. Fails with kBadData when the payload is malformed or
/// does not belong to this reconstruction; `max_points` bounds the coded points
/// (the model's input point count).
[[nodiscard]] StatusOr<Cloud> decode_layer(const std::vector<std::uint8_t>& payload, const Cloud& words,
                                           const Pose& T_cloud_sensor, std::uint64_t max_points);

/// The word reconstruction the decoder of `data` will compute, with `alphabet` exactly as
/// the decoder will see it (decoded from its file: for a learned alphabet,
/// `decode_alphabet(encode_alphabet(a))`): the instances are quantised as `encode_model`
/// stores them with steps `q` (those the file will be written with), then placed
/// (`word_cloud`). `data.alphabet` is not used.
[[nodiscard]] Cloud decoder_word_cloud(const codec::ModelData& data, const Alphabet& alphabet,
                                       const codec::Quantization& q = {});

/// Adds a residual layer of bound `max_error` to `data` for the scan `input`. `alphabet`
/// must be the alphabet exactly as the decoder will see it (decoded from its file: for a
/// learned one, `decode_alphabet(encode_alphabet(a))`). The instances are quantised as
/// `encode_model` stores them, reconstructed, and the layer coded against that
/// reconstruction. `q`: the steps the file will be written with. Replaces any layer
/// `data` had.
LayerStats add_layer(codec::ModelData& data, const Alphabet& alphabet, const Cloud& input, double max_error,
                     const LayerOptions& options = {}, const codec::Quantization& q = {});

/// Rate control: the smallest error bound in [kMinMaxError, kMaxMaxError] whose coded size
/// `size_of(E)` fits `target_bytes`, by bisection on log E until the bracket is narrower
/// than `relative_tolerance` (its upper end is returned, so the result fits). nullopt
/// when even kMaxMaxError does not fit. Sizes are assumed to shrink as E grows.
[[nodiscard]] std::optional<double> fit_max_error(const std::function<std::size_t(double)>& size_of,
                                                  std::size_t target_bytes, double relative_tolerance = 0.02);

/// The decoded cloud of a model file: the word reconstruction, with the residual layer
/// applied when the file has one. The sensor pose is set from the model.
[[nodiscard]] StatusOr<Cloud> decode_cloud(const codec::ModelData& data);

}  // namespace lex3d::residual

#pragma GCC visibility pop
