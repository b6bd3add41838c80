#pragma once
/// \file
/// The organisation a spinning lidar's points keep when a file stores them in the order
/// the sensor produced them but does not say so: firing by firing (every laser once a
/// firing, no-returns kept as placeholder points, as drivers write unorganised clouds) or
/// laser by laser (one row of a range image after another, as a row-major range image is
/// written). Detected from the points alone, so that such a cloud keeps its lasers and
/// columns even where the reader drops its no-return placeholders.

#include <cstdint>
#include <optional>
#include <vector>

#include <Eigen/Core>

// The public API: exported by liblex3d.so, which hides everything else.
#pragma GCC visibility push(default)

namespace lex3d {

struct OrderLayout {
  std::uint32_t lasers = 0;
  std::uint32_t columns = 0;
  bool firing_major = true;             ///< point i: column i / lasers (else laser i / columns)
  std::vector<std::uint16_t> laser_of;  ///< position within a firing (or row index) -> laser, top beam first

  /// The laser and column of the i-th point of the file.
  [[nodiscard]] std::uint16_t ring(std::size_t i) const {
    return laser_of[firing_major ? i % lasers : i / columns];
  }
  [[nodiscard]] std::uint32_t column(std::size_t i) const {
    return static_cast<std::uint32_t>(firing_major ? i / lasers : i % columns);
  }
};

/// The layout of `points` (a whole file's points, in file order, placeholders included):
/// lasers (2..1024) times columns must be the point count, and at least 90 % of the points
/// a firing (or row) apart must lie in about the same direction from the sensor at the
/// origin while neighbouring points mostly do not. nullopt when no layout fits.
[[nodiscard]] std::optional<OrderLayout> detect_order_layout(const std::vector<Eigen::Vector3f>& points);

}  // namespace lex3d

#pragma GCC visibility pop
