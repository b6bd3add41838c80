#pragma once
// Each decoded point's laser in a sensor-geometry layer's table (formats/model.md §2.8),
// handed from the layer to the attribute coder (§2.10, methods 3 and 4) on both sides.

#include <cstdint>
#include <vector>

#include "lex3d/core/cloud.hpp"
#include "lex3d/core/status.hpp"
#include "lex3d/residual/attributes.hpp"

namespace lex3d::residual::detail {

/// decode_layer, and with the sensor-geometry coding each decoded point's laser and column
/// in the layer's table in `keys` (a kept word point: the table's laser count, a laser of
/// its own, and the grid's column count); `keys` is left empty for the other codings.
[[nodiscard]] StatusOr<Cloud> decode_layer_lasers(const std::vector<std::uint8_t>& payload, const Cloud& words,
                                                  const Pose& T_cloud_sensor, std::uint64_t max_points,
                                                  LayerKeys& keys);

/// decode_attributes with the decoded points' layer keys (empty without a sensor-geometry
/// layer, and a method 3, 4 or 6 field is then an error).
[[nodiscard]] Status decode_attributes(const std::vector<std::uint8_t>& payload, const LayerKeys& layer, Cloud& decoded);

}  // namespace lex3d::residual::detail
