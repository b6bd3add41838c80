#pragma once
// Logistic mixing of adaptive binary models (formats/model.md §2.7.4), shared by the voxel
// coding's occupancy contexts and the attribute coder's mixed context tree (§2.10): the
// squash function and its inverse as integer tables, and a bit model that adapts fast
// while young. Integer arithmetic only, so the bits are the same on every platform.

#include <algorithm>
#include <array>
#include <cstdint>

namespace lex3d::residual::detail {

/// squash(d) = 4096 / (1 + e^(-d/256)) at d = -2048, -1920, ..., 2048 (formats/model.md
/// §2.7.4): the mixer's logistic function, interpolated between these knots.
inline constexpr std::int32_t kSquashKnots[33] = {1,    2,    4,    6,    10,   17,   27,   45,   74,   120,  194,
                                                  311,  488,  747,  1102, 1546, 2048, 2550, 2994, 3349, 3608, 3785,
                                                  3902, 3976, 4022, 4051, 4069, 4079, 4086, 4090, 4092, 4094, 4095};

/// The probability of a 1, in 1/4096 and within [1, 4095], of a logit d in 1/256.
inline std::int32_t squash(std::int32_t d) {
  d = std::clamp(d, -2047, 2047) + 2048;
  const std::int32_t k = d >> 7, f = d & 127;
  return std::clamp((kSquashKnots[k] * (128 - f) + kSquashKnots[k + 1] * f + 64) >> 7, 1, 4095);
}

/// stretch(p): the least d in [-2047, 2047] with squash(d) >= p, for p in [0, 4095] (the
/// inverse of squash, as a table).
inline const std::array<std::int16_t, 4096>& stretch_table() {
  static const std::array<std::int16_t, 4096> table = [] {
    std::array<std::int16_t, 4096> t{};
    std::int32_t d = -2047;
    for (std::int32_t p = 0; p < 4096; ++p) {
      while (d < 2047 && squash(d) < p) ++d;
      t[static_cast<std::size_t>(p)] = static_cast<std::int16_t>(d);
    }
    return t;
  }();
  return table;
}

/// An adaptive probability of a 1 (in 1/65536) that moves by 1/2, 1/4, 1/8, 1/16 of the
/// error over its first 1, 2, 4, 8 bits and by 1/32 after 15.
struct YoungBitModel {
  std::uint16_t p1 = 32768;
  std::uint8_t seen = 0;
  void update(bool bit) {
    const int shift = seen < 1 ? 1 : seen < 3 ? 2 : seen < 7 ? 3 : seen < 15 ? 4 : 5;
    if (seen < 15) ++seen;
    if (bit) p1 = static_cast<std::uint16_t>(p1 + ((65536U - p1) >> shift));
    else p1 = static_cast<std::uint16_t>(p1 - (p1 >> shift));
    p1 = std::clamp<std::uint16_t>(p1, 256, 65280);
  }
};

}  // namespace lex3d::residual::detail
