#pragma once
// Voxel coding of a residual layer (formats/model.md §2.7): the coded points are replaced
// by the centres of the cubic cells they fall in, and the occupied cells are coded as an
// octree, level by level, one occupancy byte per occupied node. It needs no sensor: it is
// what a map merged from many viewpoints, or a scan whose sensor pose is unknown, codes
// best with, where the spherical codings' predictions from one viewpoint fail.

#include <cstdint>
#include <limits>
#include <vector>

#include "residual/range_coder.hpp"

namespace lex3d::residual::detail {

/// Deepest octree: 21 levels, so that a cell's Morton code fits 63 bits.
constexpr int kMaxVoxelDepth = 21;

/// The Morton code of cell (x, y, z), each below 2^21: bit 3k holds bit k of x, bit 3k+1
/// that of y, bit 3k+2 that of z.
[[nodiscard]] std::uint64_t morton(std::uint32_t x, std::uint32_t y, std::uint32_t z);
/// The cell of a Morton code (the inverse of morton).
void unmorton(std::uint64_t code, std::uint32_t& x, std::uint32_t& y, std::uint32_t& z);

/// How the occupancy bits are modelled (the `contexts` field of an RESV payload).
enum class OccupancyContexts : std::uint8_t {
  /// One adaptive model per (child-level lower neighbours, six face neighbours, bits
  /// before): formats/model.md §2.7.1 (format 1.3).
  kFaces = 0,
  /// Three smaller context models (face neighbours on the child's side and the far side,
  /// child-level lower neighbours, siblings so far, the plane of the last node coded at
  /// the same coordinate along each axis), models that adapt fast while young, and their
  /// probabilities mixed with adaptive weights: §2.7.4 (format 1.8).
  kMixed = 1,
};

/// Codes the occupied leaves of an octree of `depth` levels (`leaves`: Morton codes below
/// 8^depth, sorted, without repeats): for every level from the root, for every occupied
/// node in Morton order, its children's occupancy byte, bit by bit (bit i: child i, whose
/// Morton code is node * 8 + i), each bit's probability in the context of which of the
/// node's neighbours are occupied and of the bits before it (`contexts`). With
/// `give_up_bytes`, stops (and returns false) once the bytes written exceed them: a coding
/// that only has to beat a size known already.
bool encode_occupancy(RangeEncoder& enc, const std::vector<std::uint64_t>& leaves, int depth,
                      OccupancyContexts contexts,
                      std::size_t give_up_bytes = std::numeric_limits<std::size_t>::max());

/// Decodes what encode_occupancy coded: the leaves in Morton order. False when the stream
/// describes more than `max_leaves` leaves (a level with more nodes than that: malformed).
[[nodiscard]] bool decode_occupancy(RangeDecoder& dec, int depth, std::uint64_t max_leaves,
                                    std::vector<std::uint64_t>& leaves, OccupancyContexts contexts);

}  // namespace lex3d::residual::detail
