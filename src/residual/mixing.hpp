#pragma once
// Logistic mixing of adaptive bit models (formats/model.md §2.7.4, §2.8.4): the logistic
// function and its inverse as integer tables, and a bit model that adapts fast while
// young. Integer arithmetic only, so that every platform codes the same bits.

#include <algorithm>
#include <array>
#include <cstdint>
#include <vector>

namespace lex3d::residual::detail {

/// squash(d) = 4096 / (1 + e^(-d/256)) at d = -2048, -1920, ..., 2048 (formats/model.md
/// §2.7.4): the mixer's logistic function, interpolated between these knots.
constexpr std::int32_t kSquashKnots[33] = {1,    2,    4,    6,    10,   17,   27,   45,   74,   120,  194,
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
    static constexpr std::uint8_t kShift[16] = {1, 2, 2, 3, 3, 3, 3, 4, 4, 4, 4, 4, 4, 4, 4, 5};
    static constexpr std::uint8_t kNext[16] = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 15};
    const unsigned shift = kShift[seen & 15U];
    seen = kNext[seen & 15U];
    const std::uint32_t p = p1;
    const std::uint32_t moved = bit ? p + ((65536U - p) >> shift) : p - (p >> shift);
    p1 = static_cast<std::uint16_t>(std::clamp<std::uint32_t>(moved, 256, 65280));
  }
};

/// The probabilities of three YoungBitModels mixed in the logistic domain by one of several
/// weight sets (in 1/65536), which learn from each bit: p0 gives the mixed probability,
/// learn then updates the three models and the set's weights.
class Mix3 {
 public:
  Mix3(std::size_t weight_sets, std::int32_t initial_weight)
      : weights_(3 * weight_sets, initial_weight), stretch_(stretch_table().data()) {}
  /// The probability of a 0, in 1/4096, of a bit modelled by a, b and c, weights of `set`.
  std::uint32_t p0(YoungBitModel& a, YoungBitModel& b, YoungBitModel& c, std::size_t set) {
    const std::int16_t* st = stretch_;  // (kept: no guard of the table's first use a bit)
    model_[0] = &a;
    model_[1] = &b;
    model_[2] = &c;
    at_ = 3 * set;
    std::int64_t dot = 0;
    for (int m = 0; m < 3; ++m) {
      input_[m] = st[model_[m]->p1 >> 4];
      dot += static_cast<std::int64_t>(weights_[at_ + static_cast<std::size_t>(m)]) * input_[m];
    }
    p1_ = squash(static_cast<std::int32_t>(std::clamp<std::int64_t>(dot >> 16, -2047, 2047)));  // (>>: floor)
    return static_cast<std::uint32_t>(4096 - p1_);
  }
  /// Learns the bit whose probability p0 gave last.
  void learn(bool bit) {
    const std::int32_t error = (bit ? 4096 : 0) - p1_;
    for (int m = 0; m < 3; ++m) {
      model_[m]->update(bit);
      std::int32_t& w = weights_[at_ + static_cast<std::size_t>(m)];
      w = std::clamp(w + ((error * input_[m]) >> 10), -kMaxWeight, kMaxWeight);
    }
  }

 private:
  static constexpr std::int32_t kMaxWeight = 1 << 19;
  std::vector<std::int32_t> weights_;
  const std::int16_t* stretch_;
  YoungBitModel* model_[3] = {nullptr, nullptr, nullptr};
  std::int32_t input_[3] = {0, 0, 0};
  std::int32_t p1_ = 2048;
  std::size_t at_ = 0;
};

}  // namespace lex3d::residual::detail
