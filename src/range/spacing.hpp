#pragma once
// Beam-spacing estimation on precomputed directions, shared by
// estimate_angular_resolution and make_range_image (which already has them).

#include <optional>
#include <vector>

#include "lex3d/range/range_image.hpp"

namespace lex3d::detail {

struct Direction {
  float az;  // radians, (-pi, pi]
  float el;  // radians, [-pi/2, pi/2]
};

/// Spacing of the first `count` directions of `dirs`.
std::optional<AngularResolution> estimate_spacing(const Direction* dirs, std::size_t count, std::size_t max_samples);

}  // namespace lex3d::detail
