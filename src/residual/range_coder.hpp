#pragma once
// An adaptive binary range coder (formats/model.md §2.5): 32-bit range, 12-bit
// probabilities updated by 1/32 of the error after each bit, carries propagated
// through a cached byte. Integers are binarised as a zero flag, a sign and an
// Elias-gamma magnitude whose every binary decision has its own adaptive model.
//
// The decoder reads zeros past the end of its input and never fails: the callers
// bound how many symbols they decode, so corrupt input yields wrong values, not
// unbounded work. Every operation is integer arithmetic, so the bits are identical
// on every platform.

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace lex3d::residual::detail {

constexpr int kProbBits = 12;
constexpr std::uint32_t kProbOne = 1U << kProbBits;
constexpr int kAdaptShift = 5;
constexpr std::uint32_t kTop = 1U << 24;

/// An adaptive model of one binary decision: the probability of a 0, in 1/4096.
struct BitModel {
  std::uint16_t p0 = kProbOne / 2;
};

class RangeEncoder {
 public:
  void put(BitModel& m, bool bit) {
    const std::uint32_t bound = (range_ >> kProbBits) * m.p0;
    if (!bit) {
      range_ = bound;
      m.p0 = static_cast<std::uint16_t>(m.p0 + ((kProbOne - m.p0) >> kAdaptShift));
    } else {
      low_ += bound;
      range_ -= bound;
      m.p0 = static_cast<std::uint16_t>(m.p0 - (m.p0 >> kAdaptShift));
    }
    while (range_ < kTop) {
      range_ <<= 8;
      shift_low();
    }
  }
  /// Codes `bit` with a probability of a 0 of p0 / 4096, p0 in [1, 4095], given by the
  /// caller (a model whose update is the caller's).
  void put(std::uint32_t p0, bool bit) {
    const std::uint32_t bound = (range_ >> kProbBits) * p0;
    if (!bit) {
      range_ = bound;
    } else {
      low_ += bound;
      range_ -= bound;
    }
    while (range_ < kTop) {
      range_ <<= 8;
      shift_low();
    }
  }
  /// Bytes written so far: the finished stream holds at least these.
  [[nodiscard]] std::size_t bytes_out() const { return out_.size(); }
  /// Flushes and returns the coded bytes; the encoder must not be used afterwards.
  std::vector<std::uint8_t> finish() {
    for (int i = 0; i < 5; ++i) shift_low();
    return std::move(out_);
  }

 private:
  void shift_low() {
    if (static_cast<std::uint32_t>(low_) < 0xFF000000U || (low_ >> 32) != 0) {
      const auto carry = static_cast<std::uint8_t>(low_ >> 32);
      std::uint8_t byte = cache_;
      do {
        out_.push_back(static_cast<std::uint8_t>(byte + carry));
        byte = 0xFF;
      } while (--pending_ != 0);
      cache_ = static_cast<std::uint8_t>((low_ >> 24) & 0xFFU);
    }
    ++pending_;
    low_ = (low_ & 0x00FFFFFFU) << 8;
  }

  std::uint64_t low_ = 0;
  std::uint32_t range_ = 0xFFFFFFFFU;
  std::uint8_t cache_ = 0;
  std::uint64_t pending_ = 1;
  std::vector<std::uint8_t> out_;
};

class RangeDecoder {
 public:
  RangeDecoder(const std::uint8_t* data, std::size_t size) : data_(data), size_(size) {
    for (int i = 0; i < 5; ++i) code_ = (code_ << 8) | next();
  }
  bool get(BitModel& m) {
    const std::uint32_t bound = (range_ >> kProbBits) * m.p0;
    bool bit = false;
    if (code_ < bound) {
      range_ = bound;
      m.p0 = static_cast<std::uint16_t>(m.p0 + ((kProbOne - m.p0) >> kAdaptShift));
    } else {
      code_ -= bound;
      range_ -= bound;
      m.p0 = static_cast<std::uint16_t>(m.p0 - (m.p0 >> kAdaptShift));
      bit = true;
    }
    while (range_ < kTop) {
      range_ <<= 8;
      code_ = (code_ << 8) | next();
    }
    return bit;
  }
  /// Decodes a bit coded by RangeEncoder::put(p0, bit).
  bool get(std::uint32_t p0) {
    const std::uint32_t bound = (range_ >> kProbBits) * p0;
    const bool bit = code_ >= bound;
    if (!bit) {
      range_ = bound;
    } else {
      code_ -= bound;
      range_ -= bound;
    }
    while (range_ < kTop) {
      range_ <<= 8;
      code_ = (code_ << 8) | next();
    }
    return bit;
  }
  /// Bytes consumed beyond the input (a well-formed stream needs none).
  [[nodiscard]] std::size_t overrun() const { return pos_ > size_ ? pos_ - size_ : 0; }

 private:
  std::uint32_t next() {
    const std::uint32_t b = pos_ < size_ ? data_[pos_] : 0U;
    ++pos_;
    return b;
  }
  const std::uint8_t* data_;
  std::size_t size_;
  std::size_t pos_ = 0;
  std::uint32_t code_ = 0;
  std::uint32_t range_ = 0xFFFFFFFFU;
};

/// The number of bits of a: 0 for 0, else the place of its highest 1 plus one.
inline int bit_length(std::uint64_t a) {
#if defined(__GNUC__) || defined(__clang__)
  return a == 0 ? 0 : 64 - __builtin_clzll(a);
#else
  int bits = 0;
  for (; a != 0; a >>= 1) ++bits;
  return bits;
#endif
}

/// Signed integers in [-(2^32 - 1), 2^32 - 1] under a number of conditioning contexts.
class IntModel {
 public:
  static constexpr int kClasses = 8;  ///< classes of one context value (context_of)
  static constexpr int kMaxExponent = 31;

  explicit IntModel(int contexts = kClasses) : ctx_(static_cast<std::size_t>(contexts)) {}

  /// The class of a context value: 0 for 0, else its bit length, capped at 7.
  static int context_of(std::int64_t previous) {
    const std::uint64_t a = previous < 0 ? static_cast<std::uint64_t>(-previous) : static_cast<std::uint64_t>(previous);
    return std::min(bit_length(a), kClasses - 1);
  }
  /// The context of two context values: their classes as the digits of a base-8 number.
  static int context_of(std::int64_t a, std::int64_t b) { return context_of(a) * kClasses + context_of(b); }

  void put(RangeEncoder& enc, int ctx, std::int64_t v) {
    Context& m = ctx_[static_cast<std::size_t>(ctx)];
    enc.put(m.zero, v != 0);
    if (v == 0) return;
    enc.put(m.sign, v < 0);
    const std::uint64_t mag = v < 0 ? static_cast<std::uint64_t>(-v) : static_cast<std::uint64_t>(v);
    const int e = bit_length(mag) - 1;
    for (int j = 0; j < e; ++j) enc.put(m.exponent[static_cast<std::size_t>(j)], true);
    if (e < kMaxExponent) enc.put(m.exponent[static_cast<std::size_t>(e)], false);
    for (int j = e - 1; j >= 0; --j)
      enc.put(mantissa_[static_cast<std::size_t>(e)][static_cast<std::size_t>(j)], ((mag >> j) & 1U) != 0);
  }

  std::int64_t get(RangeDecoder& dec, int ctx) {
    Context& m = ctx_[static_cast<std::size_t>(ctx)];
    if (!dec.get(m.zero)) return 0;
    const bool negative = dec.get(m.sign);
    int e = 0;
    while (e < kMaxExponent && dec.get(m.exponent[static_cast<std::size_t>(e)])) ++e;
    std::uint64_t mag = 1;
    for (int j = e - 1; j >= 0; --j)
      mag = (mag << 1) | (dec.get(mantissa_[static_cast<std::size_t>(e)][static_cast<std::size_t>(j)]) ? 1U : 0U);
    const auto v = static_cast<std::int64_t>(mag);
    return negative ? -v : v;
  }

 private:
  struct Context {
    BitModel zero, sign;
    std::array<BitModel, kMaxExponent + 1> exponent{};
  };
  std::vector<Context> ctx_;
  std::array<std::array<BitModel, kMaxExponent>, kMaxExponent + 1> mantissa_{};
};

/// Largest |value| the layers quantise, in steps.
constexpr double kMaxSteps = 1073741824.0;  // 2^30

/// a / b for b > 0, rounded half away from zero, in integers alone (so that every decoder
/// agrees): the predictions of the acquisition-order and lattice codings.
inline std::int64_t divide_rounded(std::int64_t a, std::int64_t b) {
  return a >= 0 ? (a + b / 2) / b : -((-a + b / 2) / b);
}

/// `k` = v / step rounded to the nearest integer; false when |k| would exceed kMaxSteps.
inline bool quantise(double v, double step, std::int64_t& k) {
  const double x = std::round(v / step);
  if (!(std::abs(x) <= kMaxSteps)) return false;
  k = static_cast<std::int64_t>(x);
  return true;
}

}  // namespace lex3d::residual::detail
