#pragma once
// Sensor-geometry coding of a residual layer (formats/model.md §2.8): a spinning lidar's
// points coded as (column, laser, beam length), the direction of every beam implied by a
// laser table stored in the layer, so that only the range — and, where the table does not
// reproduce a point within the bound, a small tangential correction — costs bits.

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "lex3d/core/cloud.hpp"
#include "lex3d/residual/attributes.hpp"
#include "residual/range_coder.hpp"

namespace lex3d::residual::detail {

/// Stored units of the laser table: angles in 2^-24 rad, lengths in 2^-16 m.
constexpr double kLaserAngleUnit = 1.0 / 16777216.0;
constexpr double kLaserLengthUnit = 1.0 / 65536.0;
constexpr std::uint32_t kMaxLasers = 1024;
/// Bit 8 of a layer's stored predictor field: the table's fields each coded against the
/// predictor it picks (formats/model.md §2.8.1, format 1.11); bits 0-7 the range predictor.
constexpr std::uint32_t kTablePredictorsBit = 1U << 8;
/// Bit 9 of the stored predictor field: the table's motion follows its fields in the stream (format 1.14).
constexpr std::uint32_t kMotionBit = 1U << 9;
/// Bit 10 of the stored predictor field, with range predictor 4 or 5: the mixed models learn
/// at the quick rates (kQuickMixRates, formats/model.md §2.8.4, format 1.18).
constexpr std::uint32_t kQuickModelsBit = 1U << 10;
constexpr std::uint32_t kMaxLaserColumns = 1U << 20;

/// A laser table as a layer stores it: quantised per-laser fields and the azimuth grid.
struct LaserTable {
  std::vector<std::int64_t> elevation, beam_azimuth, column_azimuth, z_offset, radial_offset;  // stored units
  std::uint32_t columns = 0;
  /// Unit of the per-column azimuth shifts, radians: in an estimate, the grid's step / 64
  /// (columns may shift); in a layer, chosen from its bound (formats/model.md §2.8).
  double shift_unit = 0.0;
  std::int32_t direction = 1;
  /// Beam lengths predicted by 0: the left neighbour; 1: the median edge detector; 2 and 3:
  /// 1 and 0 with a flag at edges picking the left or upper pixel (formats/model.md §2.8.2).
  std::uint32_t predictor = 0;
  /// The table's fields each coded against the predictor it picks (the previous laser, the
  /// line through the two previous, the laser four back), signalled by bit 8 of the stored
  /// predictor field (formats/model.md §2.8.1, format 1.11); else all against the previous.
  bool table_predictors = false;
  /// With predictor 4 or 5: the mixed models learn at the quick rates (bit 10, format 1.18).
  bool quick_models = false;
  double azimuth0 = 0.0;
  Pose T_sensor_head = Pose::Identity();
  /// The sensor's travel over one turn (head frame, kLaserLengthUnit) and the column the
  /// turn starts at, for a scan whose points were motion-compensated (each moved to where
  /// it lies from the sensor's pose at one instant): a beam of column c starts
  /// motion·tau(c) from the head's origin, tau(c) = ((c - motion_cut) mod columns + 1/2) /
  /// columns - 1/2 (formats/model.md §2.8.5, format 1.14). All zero: no motion.
  std::array<std::int64_t, 3> motion{0, 0, 0};
  std::uint32_t motion_cut = 0;
  /// Decoding: the stored fields say the motion follows the table in the stream (bit 9).
  bool motion_coded = false;

  [[nodiscard]] std::uint32_t lasers() const { return static_cast<std::uint32_t>(elevation.size()); }
  [[nodiscard]] bool has_motion() const { return motion[0] != 0 || motion[1] != 0 || motion[2] != 0; }
};

/// Where each input point sits in a laser table: its laser and column.
struct LaserAssignment {
  LaserTable table;
  std::vector<std::uint16_t> ring;     ///< per input point
  std::vector<std::uint32_t> column;   ///< per input point
  std::string source;                  ///< "sensor metadata", "rings and columns of the input", "estimated"
  double fit_rms = 0.0;                ///< RMS distance of the points from their beams, metres
  bool from_elevations = false;        ///< lasers estimated from the points' elevations alone
  /// Lasers estimated from the points: the other estimate (cones or elevation peaks), for
  /// the caller to code too and keep the smaller.
  std::shared_ptr<const LaserAssignment> alternative;
};

/// The laser table and every point's laser and column: from the cloud's geometry, rings and
/// columns when it has them, else estimated from its points (in the sensor frame given by
/// `T_cloud_sensor`): columns from the azimuths of a laser's points, and, with `estimate`,
/// lasers from the points' elevations. nullopt when the cloud does not look like a spinning
/// lidar's scan. `threads`: the two estimates side by side with 2 or more (the result does
/// not depend on it). `fast` (LayerOptions::fast): the cones estimated on a quarter as many
/// points.
[[nodiscard]] std::optional<LaserAssignment> assign_lasers(const Cloud& input, const Pose& T_cloud_sensor,
                                                           bool estimate, int threads = 1, bool fast = false);

/// A coded sensor-geometry layer: the fields after the ones every coding has, and the stream.
struct LaserLayer {
  std::vector<std::uint8_t> fields;  ///< cross step, shift unit, lasers, columns, direction, azimuth0, T_sensor_head (if head_pose)
  /// T_sensor_head is in `fields`: it is not the identity (else the payload's marker is
  /// 0xFFFFFFFE and the fields end before it, format 1.11).
  bool head_pose = true;
  std::vector<std::uint8_t> stream;  ///< the keep mask (as `head` holds it), the table, the points
  double range_step = 0.0;
  std::uint64_t coded = 0;           ///< points coded (after thinning)
  std::vector<std::uint32_t> sources;  ///< the input point of each coded point, in stream order
  /// Each coded point's laser and column, in stream order (what a decoder's LayerKeys gives
  /// after the kept word points), and the table's lasers and columns a turn.
  std::vector<std::uint16_t> laser_of;
  std::vector<std::uint32_t> column_of;
  std::uint32_t lasers = 0, columns = 0;
};

/// Size of `fields` in a payload.
constexpr std::uint64_t kLaserFieldBytes = 8 + 8 + 4 + 4 + 4 + 4 + 8 + 96;
/// The same without T_sensor_head, the identity (the layer's marker 0xFFFFFFFE, format 1.11).
constexpr std::uint64_t kLaserShortFieldBytes = kLaserFieldBytes - 96;

/// Codes the input points `coded` with the table of an assignment for error bound `bound`
/// (E'), continuing `head` (which holds the keep mask), for each range-step share in
/// `shares` (the range step is 2·share·E', the rest of the budget goes to corrections
/// across the beams) and each candidate assignment (two estimates of a scan's lasers), and
/// returns the smallest (a large layer: the smallest on a quarter of its columns, coded in
/// full); `chosen` gets its candidate's index. nullopt when no candidate codes (a point
/// beyond float32 resolution, table values out of the stored range). With `thin`, a point
/// within E' of a point decoded before it is left out only where coding it would cost
/// more than its neighbours (a correction across its beam, its laser's first point, or a
/// beam length far off its laser's last): leaving out every such point broke the lasers' runs of neighbours, and
/// the occupancy bits and predictions that cost outweighed the points (VLP-16 and HDL-32E
/// turns at E = 6 cm: 14 % fewer bytes and 1 dB more PSNR coding them). `fast`
/// (LayerOptions::fast): the choice on an eighth of the columns.
[[nodiscard]] std::optional<LaserLayer> laser_layer(const RangeEncoder& head, const std::vector<Eigen::Vector3f>& input,
                                                    const std::vector<std::uint32_t>& coded,
                                                    const std::vector<const LaserAssignment*>& candidates,
                                                    const Pose& T_cloud_sensor, double max_error, double bound,
                                                    bool thin, const std::vector<double>& shares,
                                                    double lambda_scale, int threads, std::size_t* chosen = nullptr,
                                                    bool fast = false);

/// Decodes the points of a sensor-geometry layer whose `fields` start at `fields` (`size`
/// bytes from there to the payload's end) after the keep mask was read from `dec`.
/// Appends `coded_points` points to `out` (and, with `lasers`, each point's laser in the
/// table to `lasers`). Returns an error message (empty on success)
/// and the byte offset (relative to `fields`) it refers to.
struct LaserDecodeError {
  std::string message;
  std::uint64_t offset = 0;
};
/// `head_pose`: the fields end with T_sensor_head (else it is the identity).
[[nodiscard]] std::optional<LaserDecodeError> read_laser_fields(const std::uint8_t* fields, std::uint64_t size,
                                                                double max_error, LaserTable& table, double& tangential_step,
                                                                bool head_pose = true);
[[nodiscard]] std::optional<LaserDecodeError> decode_laser_points(RangeDecoder& dec, LaserTable& table, double max_error,
                                                                  double range_step,
                                                                  double tangential_step, std::uint64_t coded_points,
                                                                  const Pose& T_cloud_sensor,
                                                                  std::vector<Eigen::Vector3f>& out,
                                                                  LayerKeys* keys = nullptr);

}  // namespace lex3d::residual::detail
