// Point attributes of a model file (formats/model.md §2.10, the ATTR chunk).
//
// Every field is a sequence of non-negative integers u (one a decoded point, or three for
// colour) coded in the decoded order, each field with its own range-coded stream:
//  - method 0 (context tree): u's bits, most significant first, each under a bit model of
//    the bits above it and a context of the previous value and its last change;
//  - method 1 (previous value): u minus the previous value, an integer model;
//  - method 2 (linear): u minus (2·previous − the one before), an integer model;
//  - method 3 (layer laser): u minus the last value at a point of the same laser of the
//    sensor-geometry residual layer's table, an integer model (only with such a layer);
//    after a laser's first value a flag says whether all its values are that one, and
//    then they cost nothing (a ring that is a function of the layer's laser);
//  - method 4 (mixed tree on the layer's lasers): u's bits, most significant first, over
//    method 3's history (the same laser of the sensor-geometry layer), each bit predicted
//    by three context models mixed in the logistic domain (as the voxel coding's occupancy
//    bits, §2.7.4): the previous value coarsely with its last change, the previous value
//    exactly, and the previous values of this laser and of the laser above. A laser's
//    intensities follow its calibration and its neighbours; the models learn their
//    distribution given those neighbours, not only a difference;
//  - method 5 (mixed tree): method 4 over the history of methods 0-2;
//  - method 6 (layer column): u against the value of the same measurement column of the
//    sensor-geometry layer (format 1.17). Each laser's column shift is coded first (the
//    layer's column less the measurement column: a destaggered Ouster row's pixel shift).
//    A point whose measurement column has a value already is predicted by that value
//    plus its laser's last offset from it; one that opens a column by the column before
//    plus the last step between columns. A raw log's firing times (one timestamp a
//    measurement column, each laser a fixed slot after it) then cost about one value a
//    column instead of one a point.
// Named fields (kind 5: a LAS file's classification, return number...; a PCD's other integer
// and float fields) are coded as the others, losslessly, their name after their descriptor
// and their source type in its transform bytes (format 1.15); float ones as intensity is.
// For methods 0-2 and 5 "previous" is the last value of the same laser when the chunk also
// holds the ring field (coded first), else the last value in the decoded order. The
// encoder codes each field every way that applies and keeps the smallest.

#include "lex3d/residual/attributes.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <iomanip>
#include <sstream>
#include <limits>
#include <optional>
#include <memory>
#include <numeric>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>

#include "codec/bytes.hpp"
#include "lex3d/core/parallel.hpp"
#include "residual/layer_lasers.hpp"
#include "residual/mixing.hpp"
#include "residual/range_coder.hpp"

namespace lex3d::residual {
namespace {

using detail::BitModel;
using detail::Mix3;
using detail::YoungBitModel;
using detail::IntModel;
using detail::RangeDecoder;
using detail::RangeEncoder;

enum Kind : std::uint8_t { kRing = 1, kIntensity = 2, kTime = 3, kRgb = 4, kNamed = 5 };
/// A named field's name is at most this long (is_field_name).
constexpr std::size_t kMaxNameBytes = 64;
/// `name` for a one-line message: at most 64 characters, anything but printable ASCII as '?'.
std::string shown(const std::string& name) {
  std::string out = name.substr(0, kMaxNameBytes);
  for (char& c : out)
    if (c < 0x20 || c > 0x7E) c = '?';
  return name.size() > kMaxNameBytes ? out + "..." : out;
}
/// The rgb field's `transform` (the descriptor's u32 at byte 4, format 1.10): 1 codes green,
/// then red and blue less green (each + 255, span 510), which takes the correlation of the
/// three channels out of the two coded last.
constexpr std::uint32_t kColourDifferences = 1;
/// The ring, intensity and time fields' `transform` (format 1.16): bits 0-7 the type the
/// source stored the field in (a FieldType), bit 8 set when the source's field name follows
/// the descriptor (as a named field's does).
constexpr std::uint32_t kSourceNameBit = 0x100;
constexpr std::uint64_t kColourDifferenceSpan = 510;
/// At most this many fields in a chunk (the count is a byte).
constexpr std::size_t kMaxFields = 255;
/// Fast (AttributeOptions::fast): from this many decoded points, a field's methods are
/// compared on a quarter of them, and only the smallest there is coded in full.
constexpr std::size_t kAttributeTrialPoints = 32768;
enum Repr : std::uint8_t { kQuantised = 0, kFloatBits = 1 };
constexpr std::uint8_t kMethodTree = 0, kMethodPrevious = 1, kMethodLinear = 2, kMethodLayerLaser = 3,
                       kMethodLayerTree = 4, kMethodMixedTree = 5, kMethodLayerColumn = 6;

bool is_mixed(std::uint8_t method) { return method == kMethodLayerTree || method == kMethodMixedTree; }
bool is_tree(std::uint8_t method) { return method == kMethodTree || is_mixed(method); }
/// Methods whose history is keyed by the sensor-geometry layer's lasers.
bool is_by_layer(std::uint8_t method) { return method == kMethodLayerLaser || method == kMethodLayerTree; }
/// Methods that need a sensor-geometry layer.
bool needs_layer(std::uint8_t method) { return is_by_layer(method) || method == kMethodLayerColumn; }
constexpr std::size_t kDescriptorBytes = 56;  // kind, repr, method, channels, 4 reserved, step, base, max_error, kmin, span, stream_bytes
constexpr std::uint64_t kMaxSpan = std::uint64_t{1} << 31;  // residuals stay within the integer model's 2^32 - 1
constexpr std::uint64_t kTreeMaxSpan = 255;
constexpr std::uint64_t kMixedTreeMaxSpan = 1023;  // method 4
std::uint64_t tree_max_span(std::uint8_t method) { return is_mixed(method) ? kMixedTreeMaxSpan : kTreeMaxSpan; }
constexpr int kBuckets = 16, kActivity = 4;

const char* kind_name(std::uint8_t k) {
  switch (k) {
    case kRing: return "ring";
    case kIntensity: return "intensity";
    case kTime: return "time";
    case kRgb: return "rgb";
    case kNamed: return "named field";
    default: return "unknown";
  }
}

/// How a field's values map to integers: value = T(base + (kmin + u)·step), T the field's type.
struct Quant {
  std::uint8_t repr = kQuantised;
  double step = 1.0, base = 0.0, max_error = 0.0;
  std::int64_t kmin = 0;  // (kept in `base` when stored: base + kmin·step is exact for the steps tried)
};

/// Per-laser history of the previous two values of a channel.
struct History {
  std::vector<std::int64_t> last, last2;
  std::vector<std::uint8_t> seen;
  explicit History(std::size_t lasers) : last(lasers, 0), last2(lasers, 0), seen(lasers, 0) {}
  void push(std::size_t l, std::int64_t u) {
    last2[l] = seen[l] ? last[l] : u;
    last[l] = u;
    seen[l] = 1;
  }
  /// The last value of key l − 1 (the laser above in a table's order), or `prev` when
  /// there is none.
  [[nodiscard]] std::int64_t above(std::size_t l, std::int64_t prev) const {
    return l > 0 && seen[l - 1] ? last[l - 1] : prev;
  }
};

/// The class of the last change |prev − prev2| of values in [0, n): 0 (none) to 3 (large).
int activity(std::int64_t prev, std::int64_t prev2, std::uint64_t n) {
  const std::uint64_t change = static_cast<std::uint64_t>(prev > prev2 ? prev - prev2 : prev2 - prev) * 32 / n;
  return change == 0 ? 0 : change < 2 ? 1 : change < 6 ? 2 : 3;
}

/// v · buckets / n for every value v in [0, n): a value's bucket from a table, not a
/// division a value in the coders' innermost loops.
std::vector<std::uint16_t> bucket_table(std::uint64_t n, std::uint64_t buckets) {
  std::vector<std::uint16_t> t(static_cast<std::size_t>(n));
  for (std::uint64_t v = 0; v < n; ++v) t[static_cast<std::size_t>(v)] = static_cast<std::uint16_t>(v * buckets / n);
  return t;
}

/// activity(c, 0, n) for every change c = |prev − prev2| in [0, n).
std::vector<std::uint8_t> activity_table(std::uint64_t n) {
  std::vector<std::uint8_t> t(static_cast<std::size_t>(n));
  for (std::uint64_t c = 0; c < n; ++c) t[static_cast<std::size_t>(c)] = static_cast<std::uint8_t>(activity(static_cast<std::int64_t>(c), 0, n));
  return t;
}

/// Method 4: u's bits, most significant first, each predicted by three context models
/// (young bit models) whose stretched probabilities are mixed with weights learnt per bit
/// position (formats/model.md §2.10).
class MixedTree {
 public:
  explicit MixedTree(std::uint64_t span)
      : n_(span + 1), fine_(std::min<std::uint64_t>(n_, kFine)), coarse_(bucket_table(n_, kCoarse)),
        fine_bucket_(bucket_table(n_, fine_)), near_(bucket_table(n_, kNear)), activity_(activity_table(n_)) {
    while ((std::uint64_t{1} << bits_) <= span) ++bits_;
    const std::size_t nodes = std::size_t{1} << bits_;
    models_[0].resize(static_cast<std::size_t>(kCoarse * kActivity) * nodes);
    models_[1].resize(static_cast<std::size_t>(fine_) * kActivity * nodes);
    models_[2].resize(static_cast<std::size_t>(kNear * kNear) * nodes);
    mix_ = std::make_unique<Mix3>(static_cast<std::size_t>(bits_), kInitialWeight);
  }
  void put(RangeEncoder& enc, std::int64_t u, std::int64_t prev, std::int64_t prev2, std::int64_t up) {
    start(prev, prev2, up);
    std::size_t node = 1;
    for (int j = bits_ - 1; j >= 0; --j) {
      const bool bit = ((static_cast<std::uint64_t>(u) >> j) & 1U) != 0;
      enc.put(p0(bits_ - 1 - j, node), bit);
      update(bit);
      node = 2 * node + (bit ? 1 : 0);
    }
  }
  std::int64_t get(RangeDecoder& dec, std::int64_t prev, std::int64_t prev2, std::int64_t up) {
    start(prev, prev2, up);
    std::size_t node = 1;
    for (int d = 0; d < bits_; ++d) {
      const bool bit = dec.get(p0(d, node));
      update(bit);
      node = 2 * node + (bit ? 1 : 0);
    }
    return static_cast<std::int64_t>(node - (std::size_t{1} << bits_));
  }

 private:
  static constexpr int kCoarse = 32, kNear = 16, kFine = 256;
  static constexpr std::int32_t kInitialWeight = 21845;
  std::size_t bucket(std::int64_t v, std::uint64_t buckets) const {
    return static_cast<std::size_t>(static_cast<std::uint64_t>(v) * buckets / n_);
  }
  void start(std::int64_t prev, std::int64_t prev2, std::int64_t up) {
    // (values in [0, span], as coded and decoded: from the tables; any other by division)
    const auto in = [&](std::int64_t v) { return v >= 0 && static_cast<std::uint64_t>(v) < n_; };
    const std::int64_t change = prev > prev2 ? prev - prev2 : prev2 - prev;
    const auto act = static_cast<std::size_t>(in(change) ? activity_[static_cast<std::size_t>(change)]
                                                          : activity(prev, prev2, n_));
    if (in(prev) && in(up)) {
      const auto p = static_cast<std::size_t>(prev);
      ctx_[0] = (coarse_[p] * kActivity + act) << bits_;
      ctx_[1] = (fine_bucket_[p] * kActivity + act) << bits_;  // the value itself for spans below 256
      ctx_[2] = (near_[p] * kNear + near_[static_cast<std::size_t>(up)]) << bits_;
      return;
    }
    ctx_[0] = (bucket(prev, kCoarse) * kActivity + act) << bits_;
    ctx_[1] = (bucket(prev, fine_) * kActivity + act) << bits_;
    ctx_[2] = (bucket(prev, kNear) * kNear + bucket(up, kNear)) << bits_;
  }
  /// The probability of a 0 (in 1/4096) of the bit at depth `d` (0: the most significant)
  /// under tree node `node`.
  std::uint32_t p0(int d, std::size_t node) {
    return mix_->p0(models_[0][ctx_[0] + node], models_[1][ctx_[1] + node], models_[2][ctx_[2] + node],
                    static_cast<std::size_t>(d));
  }
  void update(bool bit) { mix_->learn(bit); }

  std::uint64_t n_, fine_;
  int bits_ = 0;
  std::array<std::vector<YoungBitModel>, 3> models_;
  std::unique_ptr<Mix3> mix_;  // one weight set per bit depth
  std::array<std::size_t, 3> ctx_{};
  std::vector<std::uint16_t> coarse_, fine_bucket_, near_;  // by value
  std::vector<std::uint8_t> activity_;                     // by change |prev - prev2|
};

/// The models of one channel for one method.
struct ChannelCoder {
  std::uint8_t method;
  std::uint64_t span;
  int bits = 0;
  std::vector<BitModel> tree;  // [context][node]
  std::unique_ptr<MixedTree> mixed;  // methods 4 and 5
  IntModel ints{IntModel::kClasses * IntModel::kClasses};
  BitModel fixed;  // method 3: a laser whose values are all its first
  std::int64_t last_residual = 0;
  std::vector<std::uint16_t> tree_bucket;  // method 0: by value
  std::vector<std::uint8_t> tree_activity;  // method 0: by change
  ChannelCoder(std::uint8_t m, std::uint64_t s) : method(m), span(s) {
    if (method == kMethodTree) {
      while ((std::uint64_t{1} << bits) <= span) ++bits;
      tree.resize(static_cast<std::size_t>(kBuckets * kActivity) << bits);
      tree_bucket = bucket_table(span + 1, kBuckets);
      tree_activity = activity_table(span + 1);
    }
    if (is_mixed(method)) mixed = std::make_unique<MixedTree>(span);
  }
  [[nodiscard]] int tree_context(std::int64_t prev, std::int64_t prev2) const {
    const std::uint64_t n = span + 1;
    const std::int64_t change = prev > prev2 ? prev - prev2 : prev2 - prev;
    if (prev >= 0 && static_cast<std::uint64_t>(prev) < n && static_cast<std::uint64_t>(change) < n)
      return tree_bucket[static_cast<std::size_t>(prev)] * kActivity + tree_activity[static_cast<std::size_t>(change)];
    const int bucket = static_cast<int>(static_cast<std::uint64_t>(prev) * kBuckets / n);
    return bucket * kActivity + activity(prev, prev2, n);
  }
  [[nodiscard]] std::int64_t prediction(std::int64_t prev, std::int64_t prev2) const {
    return method == kMethodLinear ? 2 * prev - prev2 : prev;
  }
  /// `up`: the previous value of the laser above (methods 4 and 5 only).
  void put(RangeEncoder& enc, std::int64_t u, std::int64_t prev, std::int64_t prev2, std::int64_t up) {
    if (mixed) {
      mixed->put(enc, u, prev, prev2, up);
      return;
    }
    if (method == kMethodTree) {
      const std::size_t base = static_cast<std::size_t>(tree_context(prev, prev2)) << bits;
      std::size_t node = 1;
      for (int j = bits - 1; j >= 0; --j) {
        const bool bit = ((static_cast<std::uint64_t>(u) >> j) & 1U) != 0;
        enc.put(tree[base + node], bit);
        node = 2 * node + (bit ? 1 : 0);
      }
      return;
    }
    const std::int64_t r = u - prediction(prev, prev2);
    ints.put(enc, IntModel::context_of(last_residual, prev - prev2), r);
    last_residual = r;
  }
  /// Decodes one value; false when it falls outside [0, span].
  bool get(RangeDecoder& dec, std::int64_t prev, std::int64_t prev2, std::int64_t up, std::int64_t& u) {
    if (mixed) {
      u = mixed->get(dec, prev, prev2, up);
    } else if (method == kMethodTree) {
      const std::size_t base = static_cast<std::size_t>(tree_context(prev, prev2)) << bits;
      std::size_t node = 1;
      for (int j = 0; j < bits; ++j) node = 2 * node + (dec.get(tree[base + node]) ? 1 : 0);
      u = static_cast<std::int64_t>(node - (std::size_t{1} << bits));
    } else {
      const std::int64_t r = ints.get(dec, IntModel::context_of(last_residual, prev - prev2));
      last_residual = r;
      u = prediction(prev, prev2) + r;
    }
    return u >= 0 && static_cast<std::uint64_t>(u) <= span;
  }
};

/// Codes `channels` channels of values u[c][j] with `method`, the history of point j that
/// of key `laser[j]` < `lasers` (all 0 when `laser` is empty).
std::vector<std::uint8_t> code_values(const std::vector<std::vector<std::int64_t>>& u, std::uint64_t span,
                                      std::uint8_t method, const std::vector<std::uint16_t>& laser, std::size_t lasers) {
  RangeEncoder enc;
  const bool flags = method == kMethodLayerLaser;
  for (const auto& ch : u) {
    ChannelCoder coder(method, span);
    History h(lasers);
    std::vector<std::uint8_t> fixed;  // method 3: per laser, every value equals the first
    if (flags) {
      History first(lasers);
      fixed.assign(lasers, 1);
      for (std::size_t j = 0; j < ch.size(); ++j) {
        const std::size_t l = laser[j];
        if (!first.seen[l]) first.push(l, ch[j]);
        else if (ch[j] != first.last[l]) fixed[l] = 0;
      }
    }
    for (std::size_t j = 0; j < ch.size(); ++j) {
      const std::size_t l = laser.empty() ? 0 : laser[j];
      if (flags && h.seen[l] && fixed[l]) continue;  // its laser's value, known
      const std::int64_t prev = h.seen[l] ? h.last[l] : 0, prev2 = h.seen[l] ? h.last2[l] : 0;
      coder.put(enc, ch[j], prev, prev2, h.above(l, prev));
      if (flags && !h.seen[l]) enc.put(coder.fixed, fixed[l] != 0);
      h.push(l, ch[j]);
    }
  }
  return enc.finish();
}

/// Times given in whole nanoseconds (an integer time source: a driver's `t`, a raw log's
/// timestamps) on the largest step that holds them all, their greatest common divisor, where
/// it exceeds 1 ns: a sensor clock that counts in 10 ns then costs no digit of its own.
/// Decoded, base + k·step is that many nanoseconds within far less than half of one, as a
/// writer of the integer source rounds it. nullopt where a value is not a whole nanosecond
/// count or they have no common step above 1 ns (the exact steps of quantise_field then).
std::optional<Quant> whole_nanoseconds(const std::vector<double>& values) {
  std::int64_t g = 0;
  for (const double v : values) {
    const double ns = std::nearbyint(v * 1e9);
    if (!(std::abs(ns - v * 1e9) <= 1e-3 && std::abs(ns) <= 0x1p52)) return std::nullopt;
    g = std::gcd(g, std::abs(static_cast<std::int64_t>(ns)));
  }
  if (g <= 1) return std::nullopt;
  Quant q;
  q.step = static_cast<double>(g) * 1e-9;
  return q;
}

/// The history keys of methods 3, 4 and 6: the layer lasers, one key beyond the largest.
std::size_t key_count(const std::vector<std::uint16_t>& keys) {
  return keys.empty() ? 1 : static_cast<std::size_t>(*std::max_element(keys.begin(), keys.end())) + 1;
}

/// Point j's measurement column under method 6's column `shift`s: its layer column less its
/// laser's shift, on the layer's grid (a point with a column on it).
std::uint32_t measurement_column(const LayerKeys& layer, const std::vector<std::int64_t>& shift, std::size_t j) {
  const auto w = static_cast<std::int64_t>(layer.columns);
  return static_cast<std::uint32_t>((static_cast<std::int64_t>(layer.column[j]) + w - shift[layer.laser[j]]) % w);
}

/// Method 6's predictions: each laser's column shift, each measurement column's base
/// value (the value of its first point less that point's laser offset), each laser's
/// offset from the bases and the step between neighbouring columns: the last one (`mean`
/// false: firings a packet apart exactly) or the mean of all so far (`mean` true: each
/// column's own jittered timestamp). Shared by the encoder and the decoder, which update
/// it with the same values in the same order.
class ColumnHistory {
 public:
  ColumnHistory(const LayerKeys& layer, std::vector<std::int64_t> shift, bool mean)
      : layer_(layer), w_(layer.columns), mean_(mean), shift_(std::move(shift)), base_(w_, 0), set_(w_, 0),
        offset_(shift_.size(), 0), offset_seen_(shift_.size(), 0), last_(shift_.size(), 0) {}

  /// Point j's prediction and its residual's kind: 0 a known column and laser offset, 1 a
  /// known column, 2 a column opened, 3 a point without a column (a kept word point).
  struct Guess {
    std::int64_t value;
    int kind;
  };
  [[nodiscard]] Guess guess(std::size_t j) const {
    const std::size_t l = layer_.laser[j];
    if (layer_.column[j] >= w_) return {last_[l], 3};
    const std::uint32_t m = measurement(j);
    if (set_[m]) return {base_[m] + offset_[l], offset_seen_[l] ? 0 : 1};
    std::int64_t b = 0;
    const std::int64_t step = !mean_ ? step_ : steps_ > 0 ? step_sum_ / steps_ : 0;
    if (m > 0 && set_[m - 1]) b = base_[m - 1] + step;
    else if (m + 1 < w_ && set_[m + 1]) b = base_[m + 1] - step;
    else if (opened_) b = base_[last_opened_] + (static_cast<std::int64_t>(m) - static_cast<std::int64_t>(last_opened_)) * step;
    return {b + offset_[l], 2};
  }
  void update(std::size_t j, std::int64_t u) {
    const std::size_t l = layer_.laser[j];
    if (layer_.column[j] >= w_) {
      last_[l] = u;
      return;
    }
    const std::uint32_t m = measurement(j);
    if (set_[m]) {
      offset_[l] = held(u - base_[m]);
      offset_seen_[l] = 1;
      return;
    }
    base_[m] = held(u - offset_[l]);
    set_[m] = 1;
    // (the step from column to column, from whichever neighbour has a value: a layer's
    // columns may run against the measurement order)
    const bool before = m > 0 && set_[m - 1], after = m + 1 < w_ && set_[m + 1];
    if (before || after) {
      step_ = held(before ? base_[m] - base_[m - 1] : base_[m + 1] - base_[m]);
      step_sum_ += step_;  // (at most 2^20 columns of at most 2^40: no overflow)
      ++steps_;
    }
    last_opened_ = m;
    opened_ = true;
  }

 private:
  /// (bases, offsets and steps held within ±2^40, so that no prediction overflows whatever
  /// a damaged stream decodes to; values within 2^31 never reach that)
  static std::int64_t held(std::int64_t v) {
    constexpr std::int64_t kHold = std::int64_t{1} << 40;
    return std::clamp(v, -kHold, kHold);
  }
  [[nodiscard]] std::uint32_t measurement(std::size_t j) const { return measurement_column(layer_, shift_, j); }
  const LayerKeys& layer_;
  std::int64_t w_;
  bool mean_;
  std::vector<std::int64_t> shift_, base_;
  std::vector<std::uint8_t> set_;
  std::vector<std::int64_t> offset_;
  std::vector<std::uint8_t> offset_seen_;
  std::vector<std::int64_t> last_;
  std::int64_t step_ = 0, step_sum_ = 0, steps_ = 0;
  std::uint32_t last_opened_ = 0;
  bool opened_ = false;
};

/// Method 6's residual models: four kinds (ColumnHistory::Guess), each in the class of its
/// last residual; the shifts with their own model.
struct ColumnModels {
  IntModel residual{4 * IntModel::kClasses};
  IntModel shifts{1};
  std::array<std::int64_t, 4> last{};
  [[nodiscard]] int context(int kind) const {
    return kind * IntModel::kClasses + IntModel::context_of(last[static_cast<std::size_t>(kind)]);
  }
};

/// Each laser's column shift for method 6 (values in [0, columns)): against the laser with
/// the most points (shift 0), the most frequent column difference between a point and that
/// laser's latest point at or before its value, or one column either side of it, whichever
/// changes the laser's offset from that laser's values least. (A laser fired
/// before the reference within one firing finds its latest point a column back; only the
/// firing's own column keeps the offset, its slot, constant across packets.)
std::vector<std::int64_t> column_shifts(const std::vector<std::int64_t>& u, const LayerKeys& layer, std::size_t lasers) {
  const std::uint32_t w = layer.columns;
  std::vector<std::vector<std::size_t>> of(lasers);
  for (std::size_t j = 0; j < u.size(); ++j)
    if (layer.column[j] < w) of[layer.laser[j]].push_back(j);
  std::vector<std::int64_t> shift(lasers, 0);
  std::size_t ref = 0;
  for (std::size_t l = 1; l < lasers; ++l)
    if (of[l].size() > of[ref].size()) ref = l;
  if (of[ref].empty()) return shift;
  std::vector<std::pair<std::int64_t, std::uint32_t>> reference;  // (value, column), by value
  std::vector<std::int64_t> at_column(w, 0);
  std::vector<std::uint8_t> has(w, 0);
  reference.reserve(of[ref].size());
  for (const std::size_t j : of[ref]) {
    reference.emplace_back(u[j], layer.column[j]);
    at_column[layer.column[j]] = u[j];
    has[layer.column[j]] = 1;
  }
  std::sort(reference.begin(), reference.end());
  std::vector<std::uint32_t> votes(w, 0);
  std::vector<std::uint32_t> touched;
  for (std::size_t l = 0; l < lasers; ++l) {
    if (l == ref || of[l].empty()) continue;
    touched.clear();
    for (const std::size_t j : of[l]) {
      const auto at = std::upper_bound(reference.begin(), reference.end(),
                                       std::make_pair(u[j], std::numeric_limits<std::uint32_t>::max()));
      if (at == reference.begin()) continue;
      const std::uint32_t d = (layer.column[j] + w - std::prev(at)->second) % w;
      if (votes[d]++ == 0) touched.push_back(d);
    }
    std::uint32_t voted = 0, most = 0;
    for (const std::uint32_t d : touched) {
      if (votes[d] > most || (votes[d] == most && d < voted)) {
        voted = d;
        most = votes[d];
      }
      votes[d] = 0;
    }
    // (of the voted difference and its neighbours, the one whose offsets change least: the
    // sum of their changes, which a float32 time's rounding moves by a few steps a point
    // and a wrong column by a firing's jitter)
    double least = std::numeric_limits<double>::infinity();
    for (const std::uint32_t d : {voted, (voted + w - 1) % w, (voted + 1) % w}) {
      double changes = 0.0;
      std::int64_t last = 0;
      bool any = false;
      for (const std::size_t j : of[l]) {
        const std::uint32_t m = (layer.column[j] + w - d) % w;
        if (!has[m]) continue;
        const std::int64_t offset = u[j] - at_column[m];
        if (any) changes += std::abs(static_cast<double>(offset - last));
        last = offset;
        any = true;
      }
      if (any && changes < least) {
        least = changes;
        shift[l] = d;
      }
    }
  }
  return shift;
}

/// A shift less the one before, wrapped into (-columns/2, columns/2].
std::int64_t wrapped_difference(std::int64_t s, std::int64_t before, std::int64_t columns) {
  std::int64_t d = ((s - before) % columns + columns) % columns;
  return d > columns / 2 ? d - columns : d;
}

/// Codes one channel with method 6, the shifts and the step predictor given.
std::vector<std::uint8_t> code_by_column(const std::vector<std::int64_t>& u, const LayerKeys& layer,
                                         const std::vector<std::int64_t>& shift, bool mean) {
  RangeEncoder enc;
  ColumnModels models;
  models.shifts.put(enc, 0, mean ? 1 : 0);
  std::int64_t before = 0;
  for (const std::int64_t s : shift) {
    models.shifts.put(enc, 0, wrapped_difference(s, before, layer.columns));
    before = s;
  }
  ColumnHistory h(layer, shift, mean);
  for (std::size_t j = 0; j < u.size(); ++j) {
    const ColumnHistory::Guess g = h.guess(j);
    const std::int64_t r = u[j] - g.value;
    models.residual.put(enc, models.context(g.kind), r);
    models.last[static_cast<std::size_t>(g.kind)] = r;
    h.update(j, u[j]);
  }
  return enc.finish();
}

/// For a value with several keys (a float32 time: `lowest` to `highest` give it back), the
/// keys method 6 codes: each laser's offset from its measurement columns' bases (the median
/// of its key ranges' midpoints less those of the same measurement column's point of the
/// laser with the most points), then, column by column in order, the base every point of
/// the column allows (its key range less its laser's offset) nearest the line through the
/// last two bases, each point taking that base plus its offset; the points of a column
/// that allows none keep their nearest keys `u`. A raw log's firing times stored as float32
/// (a driver's `time`) then come back on their firings' grid and cost what exact ones do.
std::vector<std::int64_t> column_keys(const std::vector<std::int64_t>& u, const LayerKeys& layer,
                                      const std::vector<std::int64_t>& shift, const std::vector<std::int64_t>& lowest,
                                      const std::vector<std::int64_t>& highest) {
  const std::int64_t w = layer.columns;
  const std::size_t lasers = shift.size(), n = u.size();
  std::vector<std::vector<std::size_t>> at(static_cast<std::size_t>(w));  // points by measurement column
  std::vector<std::size_t> count(lasers, 0);
  for (std::size_t j = 0; j < n; ++j) {
    if (layer.column[j] >= w) continue;
    at[measurement_column(layer, shift, j)].push_back(j);
    ++count[layer.laser[j]];
  }
  const auto ref = static_cast<std::uint16_t>(std::max_element(count.begin(), count.end()) - count.begin());
  // Each laser's offset from the reference laser: of the offsets within 16 steps of the
  // median difference of their key ranges' midpoints (twice them, to stay in integers) in
  // one measurement column, the one that leaves the two ranges of the most such pairs
  // overlapping (the true one overlaps them all; a narrow range, near the turn's start where
  // float32 is finer than the step, rules the others out); ties: nearest the median.
  struct Pair {
    std::size_t j, r;
  };
  std::vector<std::vector<Pair>> pairs(lasers);
  for (const auto& points : at) {
    const auto r = std::find_if(points.begin(), points.end(), [&](std::size_t j) { return layer.laser[j] == ref; });
    if (r == points.end()) continue;
    for (const std::size_t j : points) pairs[layer.laser[j]].push_back({j, *r});
  }
  std::vector<std::int64_t> offset(lasers, 0);
  for (std::size_t l = 0; l < lasers; ++l) {
    if (l == ref || pairs[l].empty()) continue;
    std::vector<std::int64_t> twice;
    twice.reserve(pairs[l].size());
    for (const Pair& p : pairs[l]) twice.push_back(lowest[p.j] + highest[p.j] - lowest[p.r] - highest[p.r]);
    std::nth_element(twice.begin(), twice.begin() + static_cast<std::ptrdiff_t>(twice.size() / 2), twice.end());
    const std::int64_t t = twice[twice.size() / 2];
    const std::int64_t centre = t >= 0 ? t / 2 : -((1 - t) / 2);
    std::size_t most = 0;
    offset[l] = centre;
    for (std::int64_t d = 0; d <= 32; ++d) {
      const std::int64_t o = centre + (d % 2 == 0 ? d / 2 : -(d + 1) / 2);  // centre, +1, -1, +2, ...
      std::size_t overlap = 0;
      for (const Pair& p : pairs[l])
        overlap += std::max(lowest[p.j] - o, lowest[p.r]) <= std::min(highest[p.j] - o, highest[p.r]) ? 1 : 0;
      if (overlap > most) {
        most = overlap;
        offset[l] = o;
      }
    }
  }
  std::vector<std::int64_t> keys(u);
  std::int64_t last = 0, last_m = -1, step = 0;
  for (std::int64_t m = 0; m < w; ++m) {
    const auto& points = at[static_cast<std::size_t>(m)];
    if (points.empty()) continue;
    std::int64_t lo = std::numeric_limits<std::int64_t>::min(), hi = std::numeric_limits<std::int64_t>::max();
    for (const std::size_t j : points) {
      lo = std::max(lo, lowest[j] - offset[layer.laser[j]]);
      hi = std::min(hi, highest[j] - offset[layer.laser[j]]);
    }
    if (lo > hi) continue;
    const std::int64_t base = last_m < 0 ? lo + (hi - lo) / 2 : std::clamp(last + (m - last_m) * step, lo, hi);
    if (last_m >= 0 && m - last_m == 1) step = base - last;
    last = base;
    last_m = m;
    for (const std::size_t j : points) keys[j] = base + offset[layer.laser[j]];
  }
  return keys;
}

/// Codes one channel with method 6, with each step predictor (ColumnHistory), keeping
/// the smaller; a value with several keys (`lowest` to `highest`, else none) with those of
/// column_keys.
std::vector<std::uint8_t> code_by_column(const std::vector<std::int64_t>& u, const LayerKeys& layer,
                                         const std::vector<std::int64_t>& lowest, const std::vector<std::int64_t>& highest) {
  const std::vector<std::int64_t> shift = column_shifts(u, layer, key_count(layer.laser));
  const std::vector<std::int64_t> keys = lowest.empty() ? u : column_keys(u, layer, shift, lowest, highest);
  std::vector<std::uint8_t> best;
  for (const bool mean : {false, true}) {
    std::vector<std::uint8_t> s = code_by_column(keys, layer, shift, mean);
    if (best.empty() || s.size() < best.size()) best = std::move(s);
  }
  return best;
}

/// Decodes one channel of `out.size()` values coded with method 6; false where a value
/// falls outside [0, span] or the step predictor is neither 0 nor 1.
bool decode_by_column(RangeDecoder& dec, std::uint64_t span, const LayerKeys& layer, std::vector<std::int64_t>& out) {
  const std::size_t lasers = key_count(layer.laser);
  const auto w = static_cast<std::int64_t>(layer.columns);
  ColumnModels models;
  const std::int64_t mode = models.shifts.get(dec, 0);
  if (mode != 0 && mode != 1) return false;
  std::vector<std::int64_t> shift(lasers, 0);
  std::int64_t before = 0;
  for (std::int64_t& s : shift) {
    s = ((before + models.shifts.get(dec, 0)) % w + w) % w;
    before = s;
  }
  ColumnHistory h(layer, std::move(shift), mode == 1);
  for (std::size_t j = 0; j < out.size(); ++j) {
    const ColumnHistory::Guess g = h.guess(j);
    const std::int64_t r = models.residual.get(dec, models.context(g.kind));
    models.last[static_cast<std::size_t>(g.kind)] = r;
    const std::int64_t v = g.value + r;
    if (v < 0 || static_cast<std::uint64_t>(v) > span) return false;
    out[j] = v;
    h.update(j, v);
  }
  return true;
}

/// Finds how to represent `values` (float32 when `is_f32`) as integers.
Quant quantise_field(const std::vector<double>& values, bool is_f32, double max_error, bool allow_float_bits,
                     double fallback_error, const char* name) {
  std::vector<double> distinct(values);
  std::sort(distinct.begin(), distinct.end());
  distinct.erase(std::unique(distinct.begin(), distinct.end()), distinct.end());
  Quant q;
  if (distinct.empty()) return q;
  const double lo = distinct.front(), hi = distinct.back();
  const auto to_type = [&](double v) { return is_f32 ? static_cast<double>(static_cast<float>(v)) : v; };
  const auto fits = [&](double step, double base, double bound) {
    if (!((hi - base) / step < static_cast<double>(kMaxSpan) && (lo - base) / step > -static_cast<double>(kMaxSpan)))
      return false;
    for (const double v : distinct) {
      const double k = std::nearbyint((v - base) / step);
      const double back = to_type(base + k * step);
      if (bound == 0.0 ? back != v : !(std::abs(back - v) <= bound)) return false;
    }
    return true;
  };
  if (max_error > 0.0) {
    double step = 2.0 * max_error;
    for (int attempt = 0; attempt < 16; ++attempt, step *= 0.9)
      if (fits(step, 0.0, max_error)) {
        q.step = step;
        q.max_error = max_error;
        return q;
      }
    throw std::invalid_argument(std::string(name) + ": a bound of " + std::to_string(max_error) +
                                " is below the resolution of its values");
  }
  // Exact steps: powers of ten, then powers of two, largest first; from 0 (intensities, counts)
  // and from the smallest value (times).
  std::vector<double> steps;
  for (int e = 0; e <= 9; ++e) steps.push_back(std::pow(10.0, -e));
  for (int e = 1; e <= 24; ++e) steps.push_back(std::ldexp(1.0, -e));
  std::stable_sort(steps.begin(), steps.end(), std::greater<>());
  for (const double base : {0.0, lo})
    for (const double step : steps)
      if (fits(step, base, 0.0)) {
        q.step = step;
        q.base = base;
        return q;
      }
  if (allow_float_bits) {
    q.repr = kFloatBits;
    q.step = 0.0;
    return q;
  }
  // No exact step (double times): within fallback_error, or, where the values span more
  // than 2^31 such steps (GPS times of a LAS file over seconds, at 1 ns), within half the
  // finest step that fits them (3.1 ns over 6.5 s); the bound is stored and reported.
  double step = 2.0 * fallback_error;
  for (int attempt = 0; attempt < 64 && !fits(step, lo, 0.5 * step * 1.000001); ++attempt)
    step = std::max(step * 1.25, 1.000001 * (hi - lo) / static_cast<double>(kMaxSpan - 1));
  if (!fits(step, lo, 0.5 * step * 1.000001)) {
    std::ostringstream msg;
    msg << name << ": values span too wide a range to code (" << std::setprecision(17) << lo << " to " << hi << ")";
    throw std::invalid_argument(msg.str());
  }
  q.step = step;
  q.base = lo;
  q.max_error = 0.5 * step * 1.000001;
  return q;
}


struct FieldOut {
  std::string name;  // kNamed only
  std::uint8_t kind;
  std::uint8_t repr;
  std::uint8_t channels;
  double step, base, max_error;
  std::uint64_t span;
  std::int64_t kmin = 0;
  std::vector<std::vector<std::int64_t>> u;
  std::uint32_t type = 0;  // kNamed: the source type (FieldType), stored in `transform`
  /// A time its source holds as float32: per point the keys (less kmin) whose float32 is
  /// its value, lowest and highest; method 6 codes those of column_keys.
  std::vector<std::int64_t> lowest{}, highest{};
};

void check_size(std::size_t have, std::size_t points, const char* name) {
  if (have != 0 && have != points)
    throw std::invalid_argument("attribute " + std::string(name) + " has " + std::to_string(have) + " values for " +
                                std::to_string(points) + " points");
}

}  // namespace

void AttributeOptions::validate() const {
  if (!(intensity_error >= 0.0 && intensity_error <= 1e9))
    throw std::invalid_argument("intensity_error " + std::to_string(intensity_error) + " is outside [0, 1e9]");
  if (!(time_error > 0.0 && time_error <= 1.0))
    throw std::invalid_argument("time_error " + std::to_string(time_error) + " is outside (0, 1]");
}

std::vector<std::uint8_t> encode_attributes(const Cloud& input, const std::vector<std::uint32_t>& sources,
                                            const AttributeOptions& options, std::vector<AttributeField>* fields_out,
                                            const LayerKeys& layer, int threads) {
  options.validate();
  const std::size_t n_in = input.size(), n = sources.size();
  const std::vector<std::uint16_t>& layer_lasers = layer.laser;
  if (!layer_lasers.empty() && (layer_lasers.size() != n || layer.column.size() != n))
    throw std::invalid_argument("attribute layer keys: " + std::to_string(layer_lasers.size()) + " lasers and " +
                                std::to_string(layer.column.size()) + " columns for " + std::to_string(n) +
                                " decoded points");
  const std::size_t layer_keys = key_count(layer_lasers);
  check_size(input.intensity.size(), n_in, "intensity");
  check_size(input.time.size(), n_in, "time");
  check_size(input.ring.size(), n_in, "ring");
  check_size(input.rgb.size(), n_in, "rgb");
  for (std::size_t j = 0; j < n; ++j)
    if (sources[j] >= n_in)
      throw std::invalid_argument("attribute source " + std::to_string(sources[j]) + " of decoded point " +
                                  std::to_string(j) + " is beyond the " + std::to_string(n_in) + " input points");
  for (std::size_t i = 0; i < input.intensity.size(); ++i)
    if (!std::isfinite(input.intensity[i]))
      throw std::invalid_argument("attribute intensity of point " + std::to_string(i) + " is not finite");
  for (std::size_t i = 0; i < input.time.size(); ++i)
    if (!std::isfinite(input.time[i]))
      throw std::invalid_argument("attribute time of point " + std::to_string(i) + " is not finite");
  if (fields_out) fields_out->clear();

  std::vector<FieldOut> fields;
  std::vector<std::uint16_t> laser;  // per decoded point, when the ring field is kept
  std::size_t lasers = 1;
  const auto kept = [&options](const char* name) {
    return std::find(options.drop.begin(), options.drop.end(), name) == options.drop.end();
  };
  // (the name and type a source stored the ring, intensity or time in, where given and not
  // the writers' own: `ring` uint16, `intensity` float32, `time` float64)
  const auto source_of = [](FieldOut& f, const SourceField& src) {
    if (!src.given() || !is_field_name(src.name)) return;
    const FieldType own = f.kind == kRing ? FieldType::kUint16 : f.kind == kIntensity ? FieldType::kFloat32 : FieldType::kFloat64;
    if (src.name == kind_name(f.kind) && src.type == own) return;
    f.name = src.name;
    f.type = static_cast<std::uint32_t>(src.type);
  };
  if (options.ring && kept("ring") && input.has_rings()) {
    FieldOut f{{}, kRing, kQuantised, 1, 1.0, 0.0, 0.0, 0, 0, {}, 0, {}, {}};
    if (!is_float_type(input.ring_source.type)) source_of(f, input.ring_source);
    f.u.assign(1, std::vector<std::int64_t>(n));
    laser.resize(n);
    for (std::size_t j = 0; j < n; ++j) {
      laser[j] = input.ring[sources[j]];
      f.u[0][j] = laser[j];
      f.span = std::max<std::uint64_t>(f.span, laser[j]);
    }
    lasers = static_cast<std::size_t>(f.span) + 1;
    fields.push_back(std::move(f));
  }
  // A float or double field: its step, else (bits) its float32 bit patterns.
  const auto scalar = [&](std::uint8_t kind, const std::vector<double>& all, bool is_f32, double bound, bool bits,
                          double fallback, const std::string& name = {}, const SourceField* source = nullptr) {
    std::vector<double> vals(n);
    for (std::size_t j = 0; j < n; ++j) vals[j] = all[sources[j]];
    // (a named float field keeps every bit: NaN, infinities and -0 only as bit patterns)
    const bool only_bits = kind == kNamed && std::any_of(vals.begin(), vals.end(), [](double v) {
                             return !std::isfinite(v) || (v == 0.0 && std::signbit(v));
                           });
    // (a time its source holds in integer nanoseconds: on their common step)
    const std::optional<Quant> ns = kind == kTime && source != nullptr && source->given() && !is_float_type(source->type)
                                        ? whole_nanoseconds(vals)
                                        : std::nullopt;
    // (a time its source holds as float32: a step on which every float32 comes back)
    const bool f32_time = kind == kTime && source != nullptr && source->given() && source->type == FieldType::kFloat32 &&
                          std::all_of(vals.begin(), vals.end(), [](double v) { return static_cast<double>(static_cast<float>(v)) == v; });
    const Quant q = only_bits ? Quant{kFloatBits, 0.0, 0.0, 0.0, 0}
                    : ns      ? *ns
                              : quantise_field(vals, is_f32 || f32_time, bound, bits, fallback,
                                               kind == kNamed ? name.c_str() : kind_name(kind));
    FieldOut f{name, kind, q.repr, 1, q.step, q.repr == kFloatBits ? 0.0 : q.base, q.max_error, 0, 0, {}, 0, {}, {}};
    if (source != nullptr) source_of(f, *source);
    f.u.assign(1, std::vector<std::int64_t>(n));
    std::int64_t kmin = std::numeric_limits<std::int64_t>::max(), kmax = std::numeric_limits<std::int64_t>::min();
    for (std::size_t j = 0; j < n; ++j) {
      const std::int64_t k = q.repr == kFloatBits ? float_key(static_cast<float>(vals[j]))
                                                  : static_cast<std::int64_t>(std::nearbyint((vals[j] - q.base) / q.step));
      f.u[0][j] = k;
      kmin = std::min(kmin, k);
      kmax = std::max(kmax, k);
    }
    // Where several keys give a float32 time back (its float32 is coarser than the step),
    // each point's lowest and highest such key.
    if (f32_time && q.repr == kQuantised && q.max_error == 0.0) {
      f.lowest.resize(n);
      f.highest.resize(n);
      const auto back = [&](std::int64_t k) { return static_cast<double>(static_cast<float>(q.base + static_cast<double>(k) * q.step)); };
      for (std::size_t j = 0; j < n; ++j) {
        std::int64_t a = f.u[0][j], b = f.u[0][j];
        while (a > f.u[0][j] - 64 && back(a - 1) == vals[j]) --a;
        while (b < f.u[0][j] + 64 && back(b + 1) == vals[j]) ++b;
        f.lowest[j] = a;
        f.highest[j] = b;
        kmin = std::min(kmin, a);
        kmax = std::max(kmax, b);
      }
    }
    if (n == 0) kmin = kmax = 0;
    // Stored: kmin and u = k − kmin; a value decodes as T(base + (kmin + u)·step).
    f.kmin = kmin;
    for (auto& k : f.u[0]) k -= kmin;
    for (auto& k : f.lowest) k -= kmin;
    for (auto& k : f.highest) k -= kmin;
    f.span = static_cast<std::uint64_t>(kmax - kmin);
    fields.push_back(std::move(f));
  };
  if (options.intensity && kept("intensity") && input.has_intensity()) {
    const std::vector<double> all(input.intensity.begin(), input.intensity.end());
    scalar(kIntensity, all, true, options.intensity_error, true, 0.0, {}, &input.intensity_source);
  }
  if (options.time && kept("time") && input.has_time())
    scalar(kTime, input.time, false, 0.0, false, options.time_error, {}, &input.time_source);
  if (options.rgb && kept("rgb") && input.has_rgb()) {
    FieldOut f{{}, kRgb, kQuantised, 3, 1.0, 0.0, 0.0, 255, 0, {}, 0, {}, {}};
    f.u.assign(3, std::vector<std::int64_t>(n));
    for (std::size_t j = 0; j < n; ++j)
      for (int c = 0; c < 3; ++c) f.u[static_cast<std::size_t>(c)][j] = input.rgb[sources[j]][static_cast<std::size_t>(c)];
    fields.push_back(std::move(f));
  }
  if (options.fields) {
    for (std::size_t k = 0; k < input.fields.size(); ++k) {
      const IntegerField& x = input.fields[k];
      if (!is_field_name(x.name))
        throw std::invalid_argument("attribute field name '" + shown(x.name) + "' is not 1-64 letters, digits or underscores");
      for (std::size_t e = 0; e < k; ++e)
        if (input.fields[e].name == x.name) throw std::invalid_argument("attribute field " + x.name + " is given twice");
      check_size(x.values.size(), n_in, x.name.c_str());
      if (x.values.size() != n_in || !kept(x.name.c_str())) continue;
      if (static_cast<std::uint32_t>(x.type) > static_cast<std::uint32_t>(FieldType::kFloat64))
        throw std::invalid_argument("attribute field " + x.name + " has an unknown type");
      if (is_float_type(x.type)) {
        // (lossless: an exact step, else the bit patterns)
        std::vector<double> all(n_in);
        for (std::size_t i = 0; i < n_in; ++i) all[i] = static_cast<double>(key_float(x.values[i]));
        scalar(kNamed, all, true, 0.0, true, 0.0, x.name);
        fields.back().type = static_cast<std::uint32_t>(x.type);
        continue;
      }
      FieldOut f{x.name, kNamed, kQuantised, 1, 1.0, 0.0, 0.0, 0, 0, {}, 0, {}, {}};
      f.type = static_cast<std::uint32_t>(x.type);
      const auto [type_lo, type_hi] = field_type_range(x.type);
      f.u.assign(1, std::vector<std::int64_t>(n));
      std::int64_t lo = 0, hi = 0;
      for (std::size_t j = 0; j < n; ++j) {
        const std::int64_t v = x.values[sources[j]];
        f.u[0][j] = v;
        lo = j == 0 ? v : std::min(lo, v);
        hi = j == 0 ? v : std::max(hi, v);
      }
      if (lo < type_lo || hi > type_hi)
        throw std::invalid_argument("attribute field " + x.name + " holds " + std::to_string(lo < type_lo ? lo : hi) +
                                    ", not a " + field_type_name(x.type) + " value");
      if (static_cast<std::uint64_t>(hi - lo) > kMaxSpan)
        throw std::invalid_argument("attribute field " + x.name + " spans " + std::to_string(lo) + " to " + std::to_string(hi) +
                                    ", more than 2^31 apart");
      f.kmin = lo;
      f.span = static_cast<std::uint64_t>(hi - lo);
      for (auto& v : f.u[0]) v -= lo;
      fields.push_back(std::move(f));
    }
  }
  if (fields.empty()) return {};
  if (fields.size() > kMaxFields)
    throw std::invalid_argument("attribute fields: " + std::to_string(fields.size()) + " to keep, at most " +
                                std::to_string(kMaxFields) + " fit a model file");

  std::vector<std::uint8_t> out;
  codec::bytes::put_u64(out, n);
  out.push_back(static_cast<std::uint8_t>(fields.size()));
  for (const FieldOut& f : fields) {
    // Ring: its own history is the decoded order; the others follow their laser.
    const std::vector<std::uint16_t>& by = f.kind == kRing ? std::vector<std::uint16_t>{} : laser;
    const std::size_t hl = f.kind == kRing ? 1 : lasers;
    std::vector<std::uint8_t> best;
    std::uint8_t best_method = 0;
    std::uint32_t best_transform = 0;
    // Colour also as green, red − green and blue − green (kColourDifferences).
    std::vector<std::vector<std::int64_t>> differences;
    if (f.kind == kRgb) {
      differences = {f.u[1], f.u[0], f.u[2]};
      for (std::size_t j = 0; j < n; ++j) {
        differences[1][j] += 255 - f.u[1][j];
        differences[2][j] += 255 - f.u[1][j];
      }
    }
    // Every method that applies (each coded in full, side by side on `threads`); the
    // smallest kept, the first of equals in this order.
    std::vector<std::pair<std::uint32_t, std::uint8_t>> tries;  // (transform, method)
    for (const std::uint32_t transform : {std::uint32_t{0}, kColourDifferences}) {
      if (transform != 0 && f.kind != kRgb) continue;
      const std::uint64_t span = transform != 0 ? kColourDifferenceSpan : f.span;
      for (const std::uint8_t m : {kMethodTree, kMethodPrevious, kMethodLinear, kMethodLayerLaser, kMethodLayerTree,
                                   kMethodMixedTree, kMethodLayerColumn}) {
        if (is_tree(m) && span > tree_max_span(m)) continue;
        if (m == kMethodLinear && f.kind != kTime && f.kind != kRing) continue;
        if (needs_layer(m) && layer_lasers.empty()) continue;
        // (method 6 for times, and named fields that may hold them, of a layer with a grid)
        if (m == kMethodLayerColumn && ((f.kind != kTime && f.kind != kNamed) || layer.columns == 0)) continue;
        // With a sensor-geometry layer method 4 codes as well with the layer's lasers (on the
        // scans measured, method 5 never won there): not tried, to save its time.
        if (m == kMethodMixedTree && !layer_lasers.empty()) continue;
        tries.emplace_back(transform, m);
      }
    }
    // One method's stream on values `plain` (or their colour differences, `differences_of`)
    // and the decoded points' lasers `lasers_of` and layer lasers `layer_of` (the column
    // method, on every point only, reads `layer`).
    using Channels = std::vector<std::vector<std::int64_t>>;
    const auto code_method = [&](std::uint32_t transform, std::uint8_t m, const Channels& plain,
                                 const Channels& differences_of, const std::vector<std::uint16_t>& lasers_of,
                                 const std::vector<std::uint16_t>& layer_of) {
      const Channels& u = transform != 0 ? differences_of : plain;
      const std::uint64_t span = transform != 0 ? kColourDifferenceSpan : f.span;
      return m == kMethodLayerColumn ? code_by_column(u[0], layer, f.lowest, f.highest)
             : is_by_layer(m)        ? code_values(u, span, m, layer_of, layer_keys)
                                     : code_values(u, span, m, lasers_of, hl);
    };
    // Fast (AttributeOptions::fast), on many points: the methods other than the column one
    // each coded on a window of a quarter of the points (the middle ones), and only the
    // smallest there coded in full (beside the column method, where it applies).
    if (options.fast && n >= kAttributeTrialPoints) {
      std::vector<std::size_t> windowed;
      for (std::size_t t = 0; t < tries.size(); ++t)
        if (tries[t].second != kMethodLayerColumn) windowed.push_back(t);
      if (windowed.size() > 1) {
        const std::size_t len = n / 4, at = n / 2 - len / 2;
        const auto cut = [&](const auto& v) {
          using V = std::decay_t<decltype(v)>;
          return v.empty() ? V{} : V(v.begin() + static_cast<std::ptrdiff_t>(at), v.begin() + static_cast<std::ptrdiff_t>(at + len));
        };
        const auto cut_all = [&](const Channels& u) {
          Channels w;
          for (const auto& ch : u) w.push_back(cut(ch));
          return w;
        };
        const Channels u_window = cut_all(f.u), d_window = cut_all(differences);
        const std::vector<std::uint16_t> by_window = cut(by), layer_window = cut(layer_lasers);
        std::vector<std::size_t> sizes(windowed.size());
        parallel_for(windowed.size(), threads, [&](std::size_t k) {
          const auto [transform, m] = tries[windowed[k]];
          sizes[k] = code_method(transform, m, u_window, d_window, by_window, layer_window).size();
        }, 1);
        std::size_t pick = 0;
        for (std::size_t k = 1; k < windowed.size(); ++k)
          if (sizes[k] < sizes[pick]) pick = k;
        std::vector<std::pair<std::uint32_t, std::uint8_t>> left;
        for (std::size_t t = 0; t < tries.size(); ++t)
          if (t == windowed[pick] || tries[t].second == kMethodLayerColumn) left.push_back(tries[t]);
        tries = std::move(left);
      }
    }
    std::vector<std::vector<std::uint8_t>> coded(tries.size());
    parallel_for(tries.size(), threads, [&](std::size_t t) {
      coded[t] = code_method(tries[t].first, tries[t].second, f.u, differences, by, layer_lasers);
    }, 1);
    for (std::size_t t = 0; t < tries.size(); ++t)
      if (best.empty() || coded[t].size() < best.size()) {
        best = std::move(coded[t]);
        best_transform = tries[t].first;
        best_method = tries[t].second;
      }
    const std::size_t at = out.size();
    out.push_back(f.kind);
    out.push_back(f.repr);
    out.push_back(best_method);
    out.push_back(f.channels);
    const bool sourced = f.kind != kNamed && f.kind != kRgb && f.type != 0;
    codec::bytes::put_u32(out, f.kind == kNamed ? f.type : sourced ? f.type | kSourceNameBit : best_transform);
    codec::bytes::put_f64(out, f.step);
    codec::bytes::put_f64(out, f.base);
    codec::bytes::put_f64(out, f.max_error);
    codec::bytes::put_u64(out, static_cast<std::uint64_t>(f.kmin));
    codec::bytes::put_u64(out, best_transform != 0 ? kColourDifferenceSpan : f.span);
    codec::bytes::put_u64(out, best.size());
    if (f.kind == kNamed || sourced) {
      out.push_back(static_cast<std::uint8_t>(f.name.size()));
      out.insert(out.end(), f.name.begin(), f.name.end());
    }
    out.insert(out.end(), best.begin(), best.end());
    if (fields_out) {
      AttributeField info;
      info.name = f.kind == kNamed ? f.name : kind_name(f.kind);  // (the kind, whatever the source named it)
      info.step = f.step;
      info.max_error = f.max_error;
      info.method = best_method;
      info.bytes = out.size() - at;
      fields_out->push_back(info);
    }
  }
  if (fields_out) {
    auto described = inspect_attributes(out);
    if (described.ok())
      for (std::size_t i = 0; i < fields_out->size(); ++i) (*fields_out)[i].representation = described.value()[i].representation;
  }
  return out;
}

namespace {

struct Descriptor {
  std::string name;  // kNamed: its name; else the kind's
  std::uint8_t kind, repr, method, channels;
  std::uint32_t transform;  // rgb: kColourDifferences or 0; named: its type; ring, intensity, time: source type | kSourceNameBit
  double step, base, max_error;
  std::int64_t kmin;
  std::uint64_t span, stream_bytes, offset, stream_offset;
  SourceField source{};  // ring, intensity, time: the source's name and type (format 1.16), else not given
};

StatusOr<std::vector<Descriptor>> read_descriptors(const std::vector<std::uint8_t>& p) {
  if (p.size() < 9) return bad_data("attribute chunk is " + std::to_string(p.size()) + " bytes, at least 9 expected", 0);
  const std::uint8_t count = p[8];
  if (count == 0) return bad_data("attribute chunk field count is 0", 8);
  std::vector<Descriptor> out;
  std::uint64_t at = 9;
  std::uint8_t previous_kind = 0;
  for (int i = 0; i < count; ++i) {
    if (p.size() - at < kDescriptorBytes)
      return bad_data("attribute field " + std::to_string(i) + " is truncated", at);
    const std::uint8_t* d = p.data() + at;
    Descriptor f{kind_name(d[0]), d[0], d[1], d[2], d[3], codec::bytes::ld_u32(d + 4), codec::bytes::ld_f64(d + 8), codec::bytes::ld_f64(d + 16),
                 codec::bytes::ld_f64(d + 24), static_cast<std::int64_t>(codec::bytes::ld_u64(d + 32)),
                 codec::bytes::ld_u64(d + 40), codec::bytes::ld_u64(d + 48), at, at + kDescriptorBytes, SourceField{}};
    if (f.kind < kRing || f.kind > kNamed) return bad_data("attribute field kind " + std::to_string(f.kind) + " is unknown", at);
    if (f.kind < previous_kind || (f.kind == previous_kind && f.kind != kNamed))
      return bad_data("attribute field " + f.name + " is out of order or repeated", at);
    previous_kind = f.kind;
    // A name after the descriptor, before the stream (a named field's; a ring, intensity or
    // time source's): a byte of length, then the name; `what` names it in messages.
    const auto read_name = [&](const std::string& what, std::string& name) -> std::optional<Status> {
      if (p.size() - f.stream_offset < 1) return bad_data(what + " is truncated", f.stream_offset);
      const std::size_t len = p[f.stream_offset];
      if (p.size() - f.stream_offset - 1 < len) return bad_data(what + " is truncated", f.stream_offset);
      name.assign(reinterpret_cast<const char*>(p.data() + f.stream_offset + 1), len);
      if (!is_field_name(name)) return bad_data(what + " is not 1-64 letters, digits or underscores", f.stream_offset);
      f.stream_offset += 1 + len;
      return std::nullopt;
    };
    if (f.kind == kNamed) {
      if (auto e = read_name("attribute field name", f.name)) return *e;
      for (const Descriptor& e : out)
        if (e.kind == kNamed && e.name == f.name) return bad_data("attribute field " + f.name + " is repeated", at);
      // its type (format 1.15; 0: a 32-bit signed integer)
      if (f.transform > static_cast<std::uint32_t>(FieldType::kFloat64))
        return bad_data("attribute field " + f.name + " type " + std::to_string(f.transform) + " is unknown", at + 4);
      const auto type = static_cast<FieldType>(f.transform);
      if (is_float_type(type)) {
        if (f.max_error != 0.0) return bad_data("attribute field " + f.name + " is not lossless", at + 24);
      } else {
        if (f.repr != kQuantised || f.step != 1.0 || f.base != 0.0 || f.max_error != 0.0)
          return bad_data("attribute field " + f.name + " is not lossless integers (step 1, base 0)", at + 1);
        const auto [lo, hi] = field_type_range(type);
        if (f.kmin < lo || f.kmin + static_cast<std::int64_t>(std::min<std::uint64_t>(f.span, kMaxSpan)) > hi)
          return bad_data("attribute field " + f.name + " values are not " + field_type_name(type) + " integers", at + 32);
      }
    }
    if ((f.kind == kRing || f.kind == kIntensity || f.kind == kTime) && f.transform != 0) {
      // the source's type and name (format 1.16)
      const std::uint32_t type = f.transform & 0xFFU;
      if ((f.transform & ~(0xFFU | kSourceNameBit)) != 0 || (f.transform & kSourceNameBit) == 0 || type == 0 ||
          type > static_cast<std::uint32_t>(FieldType::kFloat64) ||
          (f.kind == kRing && is_float_type(static_cast<FieldType>(type))))
        return bad_data("attribute field " + f.name + " source type " + std::to_string(f.transform) + " is invalid", at + 4);
      if (auto e = read_name("attribute field " + f.name + " source name", f.source.name)) return *e;
      f.source.type = static_cast<FieldType>(type);
    }
    const std::string& name = f.name;
    if (f.transform != 0 && f.kind != kNamed && !(f.kind == kRgb && f.transform == kColourDifferences) &&
        !f.source.given())
      return bad_data("attribute field " + name + " has reserved bytes set", at + 4);
    if (f.repr > kFloatBits || (f.repr == kFloatBits && f.kind != kIntensity && f.kind != kNamed))
      return bad_data("attribute field " + name + " representation " + std::to_string(f.repr) + " is invalid", at + 1);
    if (f.method > kMethodLayerColumn) return bad_data("attribute field " + name + " method " + std::to_string(f.method) + " is unknown", at + 2);
    if (f.channels != (f.kind == kRgb ? 3 : 1))
      return bad_data("attribute field " + name + " has " + std::to_string(f.channels) + " channels", at + 3);
    if (f.method == kMethodLayerColumn && f.kind != kTime && f.kind != kNamed)
      return bad_data("attribute field " + name + " uses method 6, which codes times and named fields only", at + 2);
    if (f.repr == kQuantised && !(std::isfinite(f.step) && f.step > 0.0 && f.step <= 1e9))
      return bad_data("attribute field " + name + " step is not in (0, 1e9]", at + 8);
    if (!(std::isfinite(f.base) && std::abs(f.base) <= 1e18))
      return bad_data("attribute field " + name + " base is not finite", at + 16);
    if (!(std::isfinite(f.max_error) && f.max_error >= 0.0 && f.max_error <= 1e9))
      return bad_data("attribute field " + name + " max_error is out of range", at + 24);
    const std::uint64_t span_cap = f.kind == kRing ? 65535
                                   : f.kind == kRgb ? (f.transform != 0 ? kColourDifferenceSpan : 255)
                                   : f.repr == kFloatBits ? 0xFFFFFFFFULL : kMaxSpan;
    if (f.span > span_cap) return bad_data("attribute field " + name + " span " + std::to_string(f.span) + " is too large", at + 40);
    if (f.kmin < -static_cast<std::int64_t>(kMaxSpan) * 4096 || f.kmin > static_cast<std::int64_t>(kMaxSpan) * 4096 ||
        ((f.kind == kRing || f.kind == kRgb) && f.kmin != 0))
      return bad_data("attribute field " + name + " kmin " + std::to_string(f.kmin) + " is out of range", at + 32);
    if (is_tree(f.method) && f.span > tree_max_span(f.method))
      return bad_data("attribute field " + name + " uses method " + std::to_string(f.method) + " with a span above " +
                          std::to_string(tree_max_span(f.method)),
                      at + 2);
    if (f.repr == kFloatBits && (f.base != 0.0 || f.kmin < -2147483648LL || f.kmin + static_cast<std::int64_t>(f.span) > 2147483647LL))
      return bad_data("attribute field " + name + " float keys are out of range", at + 32);
    if (f.stream_bytes > p.size() - f.stream_offset)
      return bad_data("attribute field " + name + " stream of " + std::to_string(f.stream_bytes) +
                          " bytes is longer than the chunk", at + 48);
    out.push_back(f);
    at = f.stream_offset + f.stream_bytes;
  }
  if (at != p.size()) return bad_data("attribute chunk has " + std::to_string(p.size() - at) + " bytes after its last field", at);
  return out;
}

}  // namespace

StatusOr<std::vector<AttributeField>> inspect_attributes(const std::vector<std::uint8_t>& payload) {
  auto d = read_descriptors(payload);
  if (!d.ok()) return d.status();
  std::vector<AttributeField> out;
  for (const Descriptor& f : d.value()) {
    AttributeField a;
    a.name = f.name;
    a.step = f.repr == kFloatBits ? 0.0 : f.step;
    a.max_error = f.max_error;
    a.method = f.method;
    a.bytes = kDescriptorBytes + f.stream_bytes;
    std::ostringstream s;
    s << std::setprecision(6);
    const bool named_float = f.kind == kNamed && is_float_type(static_cast<FieldType>(f.transform));
    if (f.kind == kNamed && f.transform != 0) s << field_type_name(static_cast<FieldType>(f.transform)) << ": ";
    if (f.source.given()) s << "as " << f.source.name << " " << field_type_name(f.source.type) << ": ";
    if (f.repr == kFloatBits) s << "float32 bit patterns, lossless";
    else if (f.kind == kRgb && f.transform == kColourDifferences) s << "integers, lossless (green, red and blue less green)";
    else if (f.kind == kRing || f.kind == kRgb || (f.kind == kNamed && !named_float)) s << "integers, lossless";
    else {
      s << "step " << f.step;
      if (f.base != 0.0) s << " from " << std::setprecision(17) << f.base << std::setprecision(6);
      if (f.max_error > 0.0) s << ", within " << f.max_error;
      else s << ", lossless";
    }
    a.representation = s.str();
    out.push_back(a);
  }
  return out;
}

Status decode_attributes(const std::vector<std::uint8_t>& payload, Cloud& decoded) {
  return detail::decode_attributes(payload, LayerKeys{}, decoded);
}

Status detail::decode_attributes(const std::vector<std::uint8_t>& payload, const LayerKeys& layer, Cloud& decoded) {
  const std::vector<std::uint16_t>& layer_lasers = layer.laser;
  auto desc = read_descriptors(payload);
  if (!desc.ok()) return desc.status();
  const std::uint64_t n = codec::bytes::ld_u64(payload.data());
  if (n != decoded.size())
    return bad_data("attribute chunk holds " + std::to_string(n) + " points but " + std::to_string(decoded.size()) +
                        " were decoded",
                    0);
  if (!layer_lasers.empty() && (layer_lasers.size() != n || layer.column.size() != n))
    return bad_data("attribute chunk holds " + std::to_string(n) + " points but the sensor-geometry layer decoded " +
                        std::to_string(layer_lasers.size()),
                    0);
  const std::size_t layer_keys = key_count(layer_lasers);
  std::vector<std::uint16_t> laser;
  std::size_t lasers = 1;
  for (const Descriptor& f : desc.value()) {
    const std::string& name = f.name;
    const bool by_layer = is_by_layer(f.method), flags = f.method == kMethodLayerLaser;
    if (needs_layer(f.method) && (layer_lasers.empty() || (f.method == kMethodLayerColumn && layer.columns == 0)))
      return bad_data("attribute field " + name + " is coded by the lasers of a sensor-geometry layer (method " +
                          std::to_string(f.method) + "), but the file has no such layer",
                      f.offset + 2);
    // Every value coded costs at least ~1/2^12 bit in the stream: bound the points by the
    // bytes. Method 3 codes nothing for the points of a laser whose values are all its
    // first, and a tree over a span of 0 nothing at all; there the decoded points, already
    // there, bound the work.
    const bool every_point_coded = !flags && !(is_tree(f.method) && f.span == 0);
    if (every_point_coded && n > (f.stream_bytes + 16) * 4096 * 8)
      return bad_data("attribute field " + name + " stream is too short for " + std::to_string(n) + " points", f.offset + 48);
    RangeDecoder dec(payload.data() + f.stream_offset, static_cast<std::size_t>(f.stream_bytes));
    std::vector<std::vector<std::int64_t>> u(f.channels, std::vector<std::int64_t>(n));
    const bool own = f.kind == kRing;
    const std::vector<std::uint16_t>& key = by_layer ? layer_lasers : laser;
    const std::size_t hl = by_layer ? layer_keys : own ? 1 : lasers;
    if (f.method == kMethodLayerColumn) {
      if (!decode_by_column(dec, f.span, layer, u[0]))
        return bad_data("attribute field " + name + " has a value outside its span", f.stream_offset);
    }
    for (auto& ch : u) {
      if (f.method == kMethodLayerColumn) break;
      ChannelCoder coder(f.method, f.span);
      History h(hl);
      std::vector<std::uint8_t> fixed(flags ? hl : 0, 0);
      for (std::size_t j = 0; j < n; ++j) {
        const std::size_t l = (own && !by_layer) || key.empty() ? 0 : key[j];
        if (flags && h.seen[l] && fixed[l]) {
          ch[j] = h.last[l];
          continue;
        }
        const std::int64_t prev = h.seen[l] ? h.last[l] : 0, prev2 = h.seen[l] ? h.last2[l] : 0;
        std::int64_t v = 0;
        if (!coder.get(dec, prev, prev2, h.above(l, prev), v))
          return bad_data("attribute field " + name + " value of point " + std::to_string(j) + " is outside its span",
                          f.stream_offset);
        if (flags && !h.seen[l]) fixed[l] = dec.get(coder.fixed) ? 1 : 0;
        ch[j] = v;
        h.push(l, v);
      }
    }
    if (dec.overrun() > 8)
      return bad_data("attribute field " + name + " stream ends " + std::to_string(dec.overrun()) + " bytes early",
                      f.stream_offset + f.stream_bytes);
    if (f.kind == kRing) decoded.ring_source = f.source;
    if (f.kind == kIntensity) decoded.intensity_source = f.source;
    if (f.kind == kTime) decoded.time_source = f.source;
    // (a quantised value: base + (kmin + u)·step, in double; a float field rounds it once)
    const auto stepped = [&f](std::int64_t k) { return f.base + static_cast<double>(f.kmin + k) * f.step; };
    switch (f.kind) {
      case kRing:
        laser.assign(u[0].begin(), u[0].end());
        decoded.ring = laser;
        lasers = static_cast<std::size_t>(f.span) + 1;
        break;
      case kIntensity:
        decoded.intensity.resize(n);
        for (std::size_t j = 0; j < n; ++j)
          decoded.intensity[j] = f.repr == kFloatBits ? key_float(static_cast<std::int32_t>(f.kmin + u[0][j]))
                                                      : static_cast<float>(stepped(u[0][j]));
        for (std::size_t j = 0; j < n; ++j)
          if (!std::isfinite(decoded.intensity[j]))
            return bad_data("attribute field intensity of point " + std::to_string(j) + " decodes to a non-finite value",
                            f.stream_offset);
        break;
      case kTime:
        decoded.time.resize(n);
        for (std::size_t j = 0; j < n; ++j) decoded.time[j] = stepped(u[0][j]);
        break;
      case kRgb:
        decoded.rgb.resize(n);
        for (std::size_t j = 0; j < n; ++j) {
          std::int64_t v[3] = {u[0][j], u[1][j], u[2][j]};
          if (f.transform == kColourDifferences) {  // green, red − green + 255, blue − green + 255
            const std::int64_t green = u[0][j];
            v[0] = u[1][j] + green - 255;
            v[1] = green;
            v[2] = u[2][j] + green - 255;
          }
          for (std::size_t c = 0; c < 3; ++c) {
            if (v[c] < 0 || v[c] > 255)
              return bad_data("attribute field rgb of point " + std::to_string(j) + " decodes to a colour outside 0..255",
                              f.stream_offset);
            decoded.rgb[j][c] = static_cast<std::uint8_t>(v[c]);
          }
        }
        break;
      case kNamed: {
        IntegerField x{f.name, std::vector<std::int32_t>(n), static_cast<FieldType>(f.transform)};
        // (floating point: the float's key, from its bit pattern or its step)
        const bool quantised = is_float_type(x.type) && f.repr == kQuantised;
        for (std::size_t j = 0; j < n; ++j)
          x.values[j] = quantised ? float_key(static_cast<float>(stepped(u[0][j])))
                                  : static_cast<std::int32_t>(f.kmin + u[0][j]);
        decoded.fields.push_back(std::move(x));
        break;
      }
      default: break;
    }
  }
  return {};
}

}  // namespace lex3d::residual
