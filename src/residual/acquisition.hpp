#pragma once
// Acquisition-order coding of a residual layer (formats/model.md §2.11): the coded points
// in the order the scanner recorded them (an airborne or mobile-mapping scanner's pulses,
// as a LAS file stores them by GPS time), each predicted from the pulses before it. A
// scanner's mirror sweeps its beam at a steady rate, so consecutive pulses land at nearly
// equal steps along a scan line: the next pulse is the last one plus the step between the
// two before, and a later return of the same pulse lies on its beam, which the points
// coded so far give. The grid's coordinates are coded, not a sensor's spherical ones: no
// sensor position is needed, which an airborne file (a moving platform) does not have.

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "residual/range_coder.hpp"

namespace lex3d::residual::detail {

/// How a point follows the one coded before it (formats/model.md §2.11.2).
enum class PulseKind : std::uint8_t {
  kSamePulse = 0,  ///< a later return of the previous point's pulse: predicted at that point
  kNextPulse = 1,  ///< the next pulse: the last pulse plus the step between the two before
  kSkipped = 2,    ///< 1-16 pulses later (pulses without a return between): that many steps on
  kRestart = 3,    ///< no step known (the first point, a new scan line or flight line)
};
/// Most pulses a kSkipped point steps over.
constexpr std::uint32_t kMaxSkippedPulses = 16;
/// Most pulses the line fit of x and y takes (formats/model.md §2.11.1, format 1.13); a
/// fit over fewer than three is not stored.
constexpr std::uint32_t kMaxFitPulses = 32;
/// Whether `fit_pulses` is a line fit a layer may hold: 0 (none) or 3 to kMaxFitPulses.
constexpr bool valid_fit_pulses(std::uint32_t fit_pulses) {
  return fit_pulses == 0 || (fit_pulses >= 3 && fit_pulses <= kMaxFitPulses);
}
/// Bit 8 of an RESA payload's prediction field (§2.11): cells taller than wide, their
/// height an f64 after the field (format 1.13). Bits 0-7 hold fit_pulses.
constexpr std::uint32_t kTallCellsBit = 1U << 8;
/// Tallest cells, in cell widths (format 1.13).
constexpr double kMaxCellHeight = 4.0;
/// Grid coordinates lie in [0, kMaxAcquisitionCell].
constexpr std::int64_t kMaxAcquisitionCell = std::int64_t{1} << 30;

/// An acquisition-order layer: its grid and the coded stream.
struct AcquisitionLayer {
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();  ///< the grid's corner, model frame, metres
  double step = 0.0;                                 ///< cell width (x and y), metres
  double step_z = 0.0;                               ///< cell height, metres (step, or taller: format 1.13)
  /// 0: x and y predicted as format 1.12 does; else the pulses their line fit takes (1.13)
  std::uint32_t fit_pulses = 0;
  std::vector<std::uint8_t> stream;
  std::vector<std::uint32_t> sources;  ///< the input point of each coded point, in order
};

/// A grid's cells: `height` times taller than wide (1 to kMaxCellHeight; the half-diagonal
/// the bound), their z planes moved down `phase` of a cell (in [0, 1)) from the points'
/// lowest corner. Any box within the ball of the bound errs by the same E²/3 squared on
/// average; a taller one codes z in fewer bits where x and y cost little more.
struct CellShape {
  double height = 1.0;
  double phase = 0.0;
};

/// Whether `time` (one a point) orders the points `coded` as a scanner fired them: at least
/// nine in ten consecutive times rise or repeat, and one in ten rises.
[[nodiscard]] bool acquisition_ordered(const std::vector<double>& time, const std::vector<std::uint32_t>& coded);

/// Codes the input points `coded`, in their order, after what `enc` holds already (the keep
/// mask): each to the centre of its cell in a grid of cells at most 2·bound/√3 wide (every
/// decoded point within `bound` of its input point, as a float32 decoder computes it); with
/// `thin`, a point within `bound` of a point decoded before it is left out. `time` (empty,
/// or one a point) says which points are returns of one pulse and how many pulses lie
/// between the others. The grid's cells are the one of `shapes`, and x and y fitted as the
/// one of `fit_candidates` (fit_pulses values), that codes a quarter of the points smallest
/// (tried on up to `threads` threads). nullopt when there is nothing to code or the grid would be wider
/// than kMaxAcquisitionCell cells.
[[nodiscard]] std::optional<AcquisitionLayer> acquisition_layer(RangeEncoder enc, const std::vector<Eigen::Vector3f>& input,
                                                                const std::vector<double>& time,
                                                                const std::vector<std::uint32_t>& coded, double bound,
                                                                bool thin,
                                                                const std::vector<std::uint32_t>& fit_candidates = {0},
                                                                int threads = 1,
                                                                const std::vector<CellShape>& shapes = {CellShape{}});

/// Decodes `count` points of an acquisition-order stream (after its keep mask) onto `out`;
/// `step_z`, `fit_pulses` as AcquisitionLayer's.
/// A message when the stream is malformed (a gap out of range, a point off the grid).
[[nodiscard]] std::optional<std::string> decode_acquisition_points(RangeDecoder& dec, const Eigen::Vector3d& origin,
                                                                   double step, double step_z,
                                                                   std::uint32_t fit_pulses,
                                                                   std::uint64_t count,
                                                                   std::vector<Eigen::Vector3f>& out);

}  // namespace lex3d::residual::detail
