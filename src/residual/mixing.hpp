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

/// squash(d) for every d in [-2047, 2047], at d + 2047: the mixer's one lookup a bit.
inline const std::array<std::int16_t, 4095>& squash_table() {
  static const std::array<std::int16_t, 4095> table = [] {
    std::array<std::int16_t, 4095> t{};
    for (std::int32_t d = -2047; d <= 2047; ++d) t[static_cast<std::size_t>(d + 2047)] = static_cast<std::int16_t>(squash(d));
    return t;
  }();
  return table;
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
/// error over its first 1, 2, 4, 8 bits and by 1/2^last_shift after 15: 1/32 by default,
/// 1/16 in the quick models of format 1.18 (formats/model.md §2.8.4).
struct YoungBitModel {
  std::uint16_t p1 = 32768;
  std::uint8_t seen = 0;
  void update(bool bit, unsigned last_shift = 5) {
    // (per `seen`, 0-15: the shift in the low 3 bits, the next `seen` above them)
    static constexpr std::uint8_t kStep[16] = {1 | 1 << 3,  2 | 2 << 3,  2 | 3 << 3,  3 | 4 << 3,  3 | 5 << 3,  3 | 6 << 3,
                                               3 | 7 << 3,  4 | 8 << 3,  4 | 9 << 3,  4 | 10 << 3, 4 | 11 << 3, 4 | 12 << 3,
                                               4 | 13 << 3, 4 | 14 << 3, 4 | 15 << 3, 5 | 15 << 3};
    // (a model past its first 15 bits, as most are, keeps moving by 1/2^last_shift: no
    // table lookup; the table's shifts are 4 or less)
    unsigned shift = last_shift;
    if (seen < 15) {
      const unsigned step = kStep[seen];
      shift = step & 7U;
      seen = static_cast<std::uint8_t>(step >> 3);
    }
    const std::uint32_t p = p1;
    p1 = static_cast<std::uint16_t>(bit ? std::min<std::uint32_t>(p + ((65536U - p) >> shift), 65280)
                                        : std::max<std::uint32_t>(p - (p >> shift), 256));
  }
};

/// How fast a mixer and its models learn: the models' last shift (YoungBitModel) and the
/// weights' (each moves by error · input >> weight_shift). The quick rates are those of
/// format 1.18's sensor-geometry layers (formats/model.md §2.8.4).
struct MixRates {
  unsigned model_shift = 5;
  unsigned weight_shift = 10;
};
constexpr MixRates kQuickMixRates{4, 12};

/// The probabilities of three YoungBitModels mixed in the logistic domain by one of several
/// weight sets (in 1/65536), which learn from each bit: p0 gives the mixed probability,
/// learn then updates the three models and the set's weights.
class Mix3 {
 public:
  Mix3(std::size_t weight_sets, std::int32_t initial_weight, MixRates rates = {})
      : weights_(3 * weight_sets, initial_weight), stretch_(stretch_table().data()), squash_(squash_table().data()),
        rates_(rates) {}
  // (learn uses the weight set p0 chose, by pointer: a move keeps the weights where they are)
  Mix3(const Mix3&) = delete;
  Mix3& operator=(const Mix3&) = delete;
  Mix3(Mix3&&) noexcept = default;
  Mix3& operator=(Mix3&&) noexcept = default;
  /// The probability of a 0, in 1/4096, of a bit modelled by a, b and c, weights of `set`.
  std::uint32_t p0(YoungBitModel& a, YoungBitModel& b, YoungBitModel& c, std::size_t set) {
    // (the tables are kept: no guard of their first use a bit)
    model_[0] = &a;
    model_[1] = &b;
    model_[2] = &c;
    w_ = weights_.data() + 3 * set;
    input_[0] = stretch_[a.p1 >> 4];
    input_[1] = stretch_[b.p1 >> 4];
    input_[2] = stretch_[c.p1 >> 4];
    const std::int64_t dot = static_cast<std::int64_t>(w_[0]) * input_[0] + static_cast<std::int64_t>(w_[1]) * input_[1] +
                             static_cast<std::int64_t>(w_[2]) * input_[2];
    p1_ = squash_[std::clamp<std::int64_t>(dot >> 16, -2047, 2047) + 2047];  // (>>: floor)
    return static_cast<std::uint32_t>(4096 - p1_);
  }
  /// Learns the bit whose probability p0 gave last.
  void learn(bool bit) {
    const std::int32_t error = (bit ? 4096 : 0) - p1_;
    for (int m = 0; m < 3; ++m) {
      model_[m]->update(bit, rates_.model_shift);
      w_[m] = std::clamp(w_[m] + ((error * input_[m]) >> rates_.weight_shift), -kMaxWeight, kMaxWeight);
    }
  }

 private:
  static constexpr std::int32_t kMaxWeight = 1 << 19;
  std::vector<std::int32_t> weights_;
  const std::int16_t* stretch_;
  const std::int16_t* squash_;
  MixRates rates_;
  YoungBitModel* model_[3] = {nullptr, nullptr, nullptr};
  std::int32_t* w_ = nullptr;
  std::int32_t input_[3] = {0, 0, 0};
  std::int32_t p1_ = 2048;
};

}  // namespace lex3d::residual::detail
