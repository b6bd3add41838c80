#pragma once
// Each decoded point's laser in a sensor-geometry layer's table (formats/model.md §2.8),
// handed from the layer to the attribute coder (§2.10, methods 3 and 4) on both sides.

#include <cstdint>
#include <vector>

#include "lex3d/core/cloud.hpp"
#include "lex3d/core/status.hpp"

namespace lex3d::residual::detail {

/// decode_layer, and with the sensor-geometry coding each decoded point's laser in the
/// layer's table in `lasers` (a kept word point: the table's laser count, a laser of its
/// own); `lasers` is left empty for the other codings.
[[nodiscard]] StatusOr<Cloud> decode_layer_lasers(const std::vector<std::uint8_t>& payload, const Cloud& words,
                                                  const Pose& T_cloud_sensor, std::uint64_t max_points,
                                                  std::vector<std::uint16_t>& lasers);

/// decode_attributes with the decoded points' layer lasers (empty without a
/// sensor-geometry layer, and a method 3 or 4 field is then an error).
[[nodiscard]] Status decode_attributes(const std::vector<std::uint8_t>& payload,
                                       const std::vector<std::uint16_t>& layer_lasers, Cloud& decoded);

}  // namespace lex3d::residual::detail
