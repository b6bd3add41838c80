#pragma once
// Lattice coding of a residual layer (formats/model.md §2.12): points that sit one (or a
// few) to a cell of a square lattice in x and y, each near its lattice point, as gridded
// products store them (a Geiger-mode scanner's gridded points, a surface model exported
// as points). The lattice's cells are visited row by row: whether a cell holds points,
// how many, each point's offset from its lattice point and its height against the heights
// of the neighbouring cells. Nothing is predicted from a viewpoint or an order.

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "residual/range_coder.hpp"

namespace lex3d::residual::detail {

/// A square lattice in x and y: point (i, j) at origin + (i, j) · pitch.
struct Lattice {
  Eigen::Vector2d origin = Eigen::Vector2d::Zero();
  double pitch = 0.0;
  double concentration = 0.0;  ///< how tightly the points gather at the lattice points, 0-1
};

/// The lattice the points `coded` lie on, found from their x and y: the pitch (between half
/// and twice the spacing their density implies) and phase at which they gather most
/// tightly at the lattice points (the modulus of the mean of exp(2πi x / pitch), the lesser
/// of x's and y's, at least 0.5). nullopt where they do not.
[[nodiscard]] std::optional<Lattice> find_lattice(const std::vector<Eigen::Vector3f>& input,
                                                  const std::vector<std::uint32_t>& coded);

/// A lattice layer: its grid and the coded stream.
struct LatticeLayer {
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();  ///< lattice point (0, 0) and z 0, model frame, metres
  double pitch = 0.0;                                ///< lattice pitch, metres
  double step = 0.0;                                 ///< offsets' and heights' step, metres
  std::uint32_t columns = 0, rows = 0;
  /// a cell's points lowest first, each against the one below (format 1.13, §2.12.1)
  bool stacked = false;
  std::vector<std::uint8_t> stream;
  std::vector<std::uint32_t> sources;  ///< the input point of each coded point, in order
};

/// Codes the input points `coded` on `lattice` after what `enc` holds already (the keep
/// mask), every point within `bound` of its decoded position (float32). nullopt when
/// there is nothing to code or the lattice has more than four cells a point. A cell's
/// points are coded in input order or (with `try_stacked`) stacked, whichever codes smaller.
[[nodiscard]] std::optional<LatticeLayer> lattice_layer(RangeEncoder enc, const std::vector<Eigen::Vector3f>& input,
                                                        const std::vector<std::uint32_t>& coded, const Lattice& lattice,
                                                        double bound, bool try_stacked = true);

/// Decodes `count` points of a lattice stream (after its keep mask) onto `out`. A message
/// when the stream is malformed (more points than `count`, a height off the grid).
[[nodiscard]] std::optional<std::string> decode_lattice_points(RangeDecoder& dec, const Eigen::Vector3d& origin,
                                                               double pitch, double step, std::uint32_t columns,
                                                               std::uint32_t rows, bool stacked, std::uint64_t count,
                                                               std::vector<Eigen::Vector3f>& out);

}  // namespace lex3d::residual::detail
