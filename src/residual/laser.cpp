// Sensor-geometry coding of a residual layer (formats/model.md §2.8, laser.hpp).
//
// Every coded point is given a laser l and a column c of the sensor's azimuth grid; the
// table then gives the beam it travelled along (origin o, direction u) and the point is
// coded as its beam length, quantised with a step up to 2E (the whole error budget lies
// along the beam), plus a tangential correction in the two directions across the beam
// that is zero wherever the table reproduces the point within the bound. Points are
// coded column by column, lasers in order within a column, as occupancy bits; a beam
// length is predicted from the same laser's previous column and the laser above in the
// same column (the median edge detector of LOCO-I on the range image).

#include "residual/laser.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <memory>
#include <complex>
#include <functional>
#include <future>
#include <initializer_list>
#include <iomanip>
#include <sstream>
#include <cstring>
#include <limits>
#include <map>
#include <numeric>

#include "codec/bytes.hpp"
#include "lex3d/core/parallel.hpp"
#include "lex3d/core/layout.hpp"
#include "core/fast_atan2.hpp"
#include "residual/angles.hpp"
#include "residual/counting.hpp"
#include "residual/mixing.hpp"
#include "residual/point_ball_grid.hpp"

namespace lex3d::residual::detail {
using lex3d::detail::fast_atan2;
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kTwoPi = 2.0 * kPi;
/// Stored table values lie within these many units (angles: 2π; lengths: 64 m).
constexpr std::int64_t kMaxAngleUnits = 105414357;   // ceil(2π / 2^-24)
constexpr std::int64_t kMaxLengthUnits = 64 * 65536;
/// Predictors 2 and 3: left and upper pixels more than this many range steps apart mark
/// an edge, where a flag says which of them predicts (formats/model.md §2.8.2).
constexpr std::int64_t kEdgeSteps = 16;
/// The share of a layer's points sharing a pixel with the point before above which a
/// pixel's points keep the input order (order_pixels_along_scan).
constexpr double kSharedPixels = 0.25;
/// Layers of this many points or more choose their range-step share and predictor on a
/// quarter of the turn's columns and code only the winner in full.
constexpr std::size_t kLaserTrialMinPoints = 32768;
/// A column's azimuth shift is rounded to a unit that moves a point at the layer's RMS
/// horizontal distance by this many E (on the VLP-16 and HDL-32E captures at 14 and 30 mm
/// the smallest files at equal PSNR came from 0.3-0.5; 1/64 of a column before).
constexpr double kShiftRounding = 0.3;
/// A left neighbour further than this many columns back does not predict.
constexpr std::uint32_t kMaxColumnGap = 4;

/// The table as doubles, with the per-laser trigonometry the beams need.
struct Beams {
  std::vector<double> sin_el, cos_el, beam_az, col_az, z, radial;
  /// Cosines and sines of each laser's azimuth offsets: its origin's (col_az) and its
  /// direction's (col_az + beam_az), turned by a column's azimuth (ColumnTrig) per beam.
  std::vector<double> cos_o, sin_o, cos_d, sin_d;
  double azimuth0 = 0.0, column_angle = 0.0;  // column_angle: direction · 2π / columns
  double shift_unit = 0.0;
  Pose T_cloud_head = Pose::Identity();
  // The table's motion over a turn (metres, head frame), the column it starts at and the
  // column count: a beam's origin moves by motion · tau(column).
  Eigen::Vector3d motion = Eigen::Vector3d::Zero();
  std::uint32_t motion_cut = 0, grid_columns = 1;
  bool moves = false;

  Beams(const LaserTable& t, const Pose& T_cloud_sensor) {
    const std::size_t n = t.elevation.size();
    sin_el.resize(n);
    cos_el.resize(n);
    beam_az.resize(n);
    col_az.resize(n);
    z.resize(n);
    radial.resize(n);
    cos_o.resize(n);
    sin_o.resize(n);
    cos_d.resize(n);
    sin_d.resize(n);
    for (std::size_t l = 0; l < n; ++l) {
      const double el = static_cast<double>(t.elevation[l]) * kLaserAngleUnit;
      sin_el[l] = std::sin(el);
      cos_el[l] = std::cos(el);
      beam_az[l] = static_cast<double>(t.beam_azimuth[l]) * kLaserAngleUnit;
      col_az[l] = static_cast<double>(t.column_azimuth[l]) * kLaserAngleUnit;
      z[l] = static_cast<double>(t.z_offset[l]) * kLaserLengthUnit;
      radial[l] = static_cast<double>(t.radial_offset[l]) * kLaserLengthUnit;
      cos_o[l] = std::cos(col_az[l]);
      sin_o[l] = std::sin(col_az[l]);
      cos_d[l] = std::cos(col_az[l] + beam_az[l]);
      sin_d[l] = std::sin(col_az[l] + beam_az[l]);
    }
    azimuth0 = t.azimuth0;
    column_angle = static_cast<double>(t.direction) * (kTwoPi / static_cast<double>(t.columns));
    shift_unit = t.shift_unit;
    T_cloud_head = T_cloud_sensor * t.T_sensor_head;
    grid_columns = std::max<std::uint32_t>(1, t.columns);
    moves = t.has_motion();
    motion = Eigen::Vector3d(static_cast<double>(t.motion[0]), static_cast<double>(t.motion[1]),
                             static_cast<double>(t.motion[2])) * kLaserLengthUnit;
    motion_cut = t.motion_cut % grid_columns;
  }

  struct Beam {
    Eigen::Vector3d o, u, e1, e2;
  };
  /// The beam of laser l in column c shifted by `shift` units, head frame: origin,
  /// direction and two unit vectors across it (e1 horizontal, e2 = u × e1 pointing up).
  [[nodiscard]] Beam beam(std::uint32_t l, std::uint32_t c, std::int64_t shift) const {
    return beam(l, trig(l, c, shift));
  }
  /// The cosines and sines of a beam's two azimuths (its origin's and its direction's): all
  /// a beam needs besides its laser, 32 bytes where the beam takes 96.
  struct Trig {
    double ca, sa, cb, sb;
    double mx, my, mz;  // the column's origin moved by the table's motion
  };
  /// The cosine and sine of a column's azimuth (shifted by `shift` units), shared by its
  /// lasers: one sine and cosine a column, not two a point; and where the sensor was at
  /// that column (the table's motion times tau(c), formats/model.md §2.8.5).
  struct ColumnTrig {
    double c, s;
    double mx = 0.0, my = 0.0, mz = 0.0;
  };
  [[nodiscard]] ColumnTrig column_trig(std::uint32_t c, std::int64_t shift) const {
    const double a = azimuth0 + column_angle * static_cast<double>(c) + static_cast<double>(shift) * shift_unit;
    ColumnTrig k{std::cos(a), std::sin(a)};
    if (moves) {
      const double tau = motion_tau(c);
      k.mx = motion.x() * tau;
      k.my = motion.y() * tau;
      k.mz = motion.z() * tau;
    }
    return k;
  }
  /// tau(c) = ((c - cut) mod columns + 1/2) / columns - 1/2: the column's time in the turn,
  /// in turns from its middle.
  [[nodiscard]] double motion_tau(std::uint32_t c) const {
    const std::uint32_t k = (c % grid_columns + grid_columns - motion_cut) % grid_columns;
    return (static_cast<double>(k) + 0.5) / static_cast<double>(grid_columns) - 0.5;
  }
  [[nodiscard]] Trig trig(std::uint32_t l, const ColumnTrig& k) const {
    return {k.c * cos_o[l] - k.s * sin_o[l], k.s * cos_o[l] + k.c * sin_o[l], k.c * cos_d[l] - k.s * sin_d[l],
            k.s * cos_d[l] + k.c * sin_d[l], k.mx, k.my, k.mz};
  }
  [[nodiscard]] Trig trig(std::uint32_t l, std::uint32_t c, std::int64_t shift) const {
    return trig(l, column_trig(c, shift));
  }
  /// Every column's unshifted azimuth (cosine and sine) of a grid of `columns`: for a pass
  /// over many points, one sine and cosine a column.
  [[nodiscard]] std::vector<ColumnTrig> column_trigs(std::uint32_t columns) const {
    std::vector<ColumnTrig> t(columns);
    for (std::uint32_t c = 0; c < columns; ++c) t[c] = column_trig(c, 0);
    return t;
  }
  [[nodiscard]] Beam beam(std::uint32_t l, const Trig& t) const {
    const double ca = t.ca, sa = t.sa, cb = t.cb, sb = t.sb;
    Beam b;
    b.o = Eigen::Vector3d(radial[l] * ca + t.mx, radial[l] * sa + t.my, z[l] + t.mz);
    b.u = Eigen::Vector3d(cb * cos_el[l], sb * cos_el[l], sin_el[l]);
    b.e1 = Eigen::Vector3d(-sb, cb, 0.0);
    b.e2 = Eigen::Vector3d(-cb * sin_el[l], -sb * sin_el[l], cos_el[l]);
    return b;
  }
  /// The beam of laser l in column c unshifted, given column_trigs (a column beyond them computed here).
  [[nodiscard]] Beam beam(std::uint32_t l, std::uint32_t c, const std::vector<ColumnTrig>& columns) const {
    return beam(l, trig(l, c < columns.size() ? columns[c] : column_trig(c, 0)));
  }
  /// The decoded point of beam length index k and corrections (k1, k2), cloud frame.
  [[nodiscard]] Eigen::Vector3f point(const Beam& b, std::int64_t k, std::int64_t k1, std::int64_t k2, double qr,
                                      double qt) const {
    const Eigen::Vector3d p = b.o + (static_cast<double>(k) * qr) * b.u + (static_cast<double>(k1) * qt) * b.e1 +
                              (static_cast<double>(k2) * qt) * b.e2;
    return (T_cloud_head * p).cast<float>();
  }
};

/// The mantissa bits of a magnitude (below its leading 1, most significant first), a bit
/// model per (set, exponent, bit).
class MantissaModels {
 public:
  static constexpr int kMaxExponent = IntModel::kMaxExponent;
  explicit MantissaModels(int sets) : m_(static_cast<std::size_t>(sets)) {}
  void put(RangeEncoder& enc, int set, int e, std::uint64_t mag) {
    auto& m = m_[static_cast<std::size_t>(set)][static_cast<std::size_t>(e)];
    for (int j = e - 1; j >= 0; --j) enc.put(m[static_cast<std::size_t>(j)], ((mag >> j) & 1U) != 0);
  }
  /// The magnitude of exponent e.
  std::uint64_t get(RangeDecoder& dec, int set, int e) {
    auto& m = m_[static_cast<std::size_t>(set)][static_cast<std::size_t>(e)];
    std::uint64_t mag = 1;
    for (int j = e - 1; j >= 0; --j) mag = (mag << 1) | (dec.get(m[static_cast<std::size_t>(j)]) ? 1U : 0U);
    return mag;
  }

 private:
  std::vector<std::array<std::array<BitModel, kMaxExponent>, kMaxExponent + 1>> m_;
};

/// Signed integers as IntModel codes them (zero flag, sign, Elias-gamma exponent, mantissa),
/// except that the sign is conditioned on a sign context and the mantissa bits on the
/// context's first class too (beam lengths: their magnitude's low bits still follow how
/// rough the neighbourhood is).
class RangeModel {
 public:
  static constexpr int kClasses = IntModel::kClasses;
  static constexpr int kMaxExponent = IntModel::kMaxExponent;
  RangeModel() : ctx_(kClasses * kClasses), mant_(kClasses) {}
  void put(RangeEncoder& enc, int ctx, int sign_ctx, std::int64_t v) {
    Context& m = ctx_[static_cast<std::size_t>(ctx)];
    enc.put(m.zero, v != 0);
    if (v == 0) return;
    enc.put(m.sign[sign_ctx], v < 0);
    const std::uint64_t mag = v < 0 ? static_cast<std::uint64_t>(-v) : static_cast<std::uint64_t>(v);
    const int e = bit_length(mag) - 1;
    for (int j = 0; j < e; ++j) enc.put(m.exponent[static_cast<std::size_t>(j)], true);
    if (e < kMaxExponent) enc.put(m.exponent[static_cast<std::size_t>(e)], false);
    mant_.put(enc, ctx / kClasses, e, mag);
  }
  std::int64_t get(RangeDecoder& dec, int ctx, int sign_ctx) {
    Context& m = ctx_[static_cast<std::size_t>(ctx)];
    if (!dec.get(m.zero)) return 0;
    const bool negative = dec.get(m.sign[sign_ctx]);
    int e = 0;
    while (e < kMaxExponent && dec.get(m.exponent[static_cast<std::size_t>(e)])) ++e;
    const auto v = static_cast<std::int64_t>(mant_.get(dec, ctx / kClasses, e));
    return negative ? -v : v;
  }

 private:
  struct Context {
    BitModel zero;
    BitModel sign[3];
    std::array<BitModel, kMaxExponent + 1> exponent{};
  };
  std::vector<Context> ctx_;
  MantissaModels mant_;
};

/// The beam-length residuals of predictors 4 and 5 (formats/model.md §2.8.4): RangeModel's
/// binarisation, with the probability of each zero, sign and exponent decision mixed in the
/// logistic domain from three context models (YoungBitModel) by weights that learn per
/// decision; the mantissa bits are RangeModel's.
class MixedRangeModel {
 public:
  static constexpr int kClasses = IntModel::kClasses;
  static constexpr int kMaxExponent = IntModel::kMaxExponent;
  /// Contexts of the three models: recent errors (as RangeModel's), the predicted beam
  /// length's size with the recent errors, the local gradient with the laser's last
  /// residual and the laser's place in the table.
  static constexpr int kContexts[3] = {kClasses * kClasses, 16 * kClasses, kClasses * kClasses * 8};
  struct Contexts {
    int at[3];
    int sign;      ///< 0, 1, 2: the laser's last residual zero, positive, negative
    int mantissa;  ///< the class of the recent errors
  };
  explicit MixedRangeModel(MixRates rates) : mix_{kWeightSets, kInitialWeight, rates}, mant_(kClasses) {
    for (int m = 0; m < 3; ++m) models_[m].resize(static_cast<std::size_t>(kContexts[m]) * kSlots);
  }
  void put(RangeEncoder& enc, const Contexts& x, std::int64_t v) {
    const Slots s = slots(x);
    bit(enc, s, 0, 0, v != 0);
    if (v == 0) return;
    bit(enc, s, 1 + x.sign, 1, v < 0);
    const std::uint64_t mag = v < 0 ? static_cast<std::uint64_t>(-v) : static_cast<std::uint64_t>(v);
    const int e = bit_length(mag) - 1;
    for (int j = 0; j < e; ++j) bit(enc, s, 4 + j, 2 + std::min(j, 3), true);
    if (e < kMaxExponent) bit(enc, s, 4 + e, 2 + std::min(e, 3), false);
    mant_.put(enc, x.mantissa, e, mag);
  }
  std::int64_t get(RangeDecoder& dec, const Contexts& x) {
    const Slots s = slots(x);
    if (!bit(dec, s, 0, 0)) return 0;
    const bool negative = bit(dec, s, 1 + x.sign, 1);
    int e = 0;
    while (e < kMaxExponent && bit(dec, s, 4 + e, 2 + std::min(e, 3))) ++e;
    const auto v = static_cast<std::int64_t>(mant_.get(dec, x.mantissa, e));
    return negative ? -v : v;
  }

 private:
  static constexpr int kSlots = 4 + kMaxExponent + 1;  // zero, sign in 3 contexts, exponent bits
  static constexpr int kWeightSets = 6;                // zero, sign, exponent bits 0, 1, 2, 3 and on
  static constexpr std::int32_t kInitialWeight = 19661;  // 0.3 in 1/65536
  /// The three models' slots of one value's contexts.
  struct Slots {
    YoungBitModel* m[3];
  };
  Slots slots(const Contexts& x) {
    Slots s{};
    for (int m = 0; m < 3; ++m) s.m[m] = models_[m].data() + static_cast<std::size_t>(x.at[m]) * kSlots;
    return s;
  }
  std::uint32_t p0(const Slots& s, int slot, int set) {
    return mix_.p0(s.m[0][slot], s.m[1][slot], s.m[2][slot], static_cast<std::size_t>(set));
  }
  void bit(RangeEncoder& enc, const Slots& s, int slot, int set, bool b) {
    enc.put(p0(s, slot, set), b);
    mix_.learn(b);
  }
  bool bit(RangeDecoder& dec, const Slots& s, int slot, int set) {
    const bool b = dec.get(p0(s, slot, set));
    mix_.learn(b);
    return b;
  }

  std::array<std::vector<YoungBitModel>, 3> models_;
  Mix3 mix_;
  MantissaModels mant_;
};

/// The models and predictor state shared by encoder and decoder (formats/model.md §2.8.3).
class PointCoder {
 public:
  static constexpr int kClasses = IntModel::kClasses;
  /// `spacing`: range step · grid step / E, so that a beam length index times it is the gap,
  /// in units of E, between neighbouring columns' points at that range.
  /// `quick`: with predictors 4 and 5, the mixed models learn at the quick rates (format 1.18).
  PointCoder(std::uint32_t lasers, double spacing, std::uint32_t predictor, bool quick)
      : med_(predictor == 1 || predictor == 2 || predictor == 4), edges_(predictor >= 2),
        mixed_(predictor >= 4 ? std::make_unique<MixedRangeModel>(quick ? kQuickMixRates : MixRates{}) : nullptr),
        occ_mix_(predictor >= 4 ? std::make_unique<OccupancyMix>(lasers, quick ? kQuickMixRates : MixRates{}) : nullptr),
        lasers_(lasers), spacing_(spacing), sel_(lasers, 0),
        last_k_(lasers, 0), last_c_(lasers, kNone), prev_k_(lasers, 0), prev_c_(lasers, kNone), last_res_(lasers, 0),
        last_k1_(lasers, 0), last_k2_(lasers, 0), occ_prev_(lasers + 1, 0), occ_now_(lasers + 1, 0),
        occ_prev2_(lasers + 1, 0), err_(lasers, 0), eighth_(lasers) {
    // (each laser's eighth of the table once, not a division a point)
    for (std::uint32_t l = 0; l < lasers; ++l)
      eighth_[l] = static_cast<std::uint8_t>((static_cast<std::uint64_t>(l) * 8) / lasers);
  }

  // --- structure ---
  int column_ctx() const { return IntModel::context_of(last_dc_); }
  /// The column shift's context: the class of the last shift change, or with predictors 4
  /// and 5 that change itself, signed, within -3..3 (a shift that jitters about its mean
  /// changes sign from one column to the next).
  int shift_ctx() const {
    if (mixed_) return static_cast<int>(std::clamp<std::int64_t>(last_shift_delta_, -3, 3) + 3);
    return IntModel::context_of(last_shift_delta_);
  }
  std::int64_t last_shift() const { return last_shift_; }
  void set_shift(std::int64_t shift) {
    last_shift_delta_ = shift - last_shift_;
    last_shift_ = shift;
  }
  void start_column(std::uint32_t column, std::int64_t dc) {
    if (started_) {
      std::swap(occ_prev2_, occ_prev_);
      std::swap(occ_prev_, occ_now_);
    }
    std::fill(occ_now_.begin(), occ_now_.end(), 0);
    started_ = true;
    column_ = column;
    last_dc_ = dc;
    up_ = kNone;
  }
  /// With predictors 2 and 3 the context also holds the pixel two coded columns back and
  /// the upper-left one.
  /// How far laser l's pixel in this column lies from the laser's last point, in E, as a
  /// class 0-3: under E, thinning has likely dropped it.
  int near(std::uint32_t l) const {
    if (last_c_[l] == kNone) return 3;
    const double gap = static_cast<double>(std::abs(last_k_[l])) * spacing_ * static_cast<double>(column_ - last_c_[l]);
    return gap < 0.8 ? 0 : gap < 1.0 ? 1 : gap < 1.25 ? 2 : 3;
  }
  int occupancy_ctx(std::uint32_t l) const { return occupancy_ctx(l, near(l)); }
  /// The same, given near(l).
  int occupancy_ctx(std::uint32_t l, int near) const {
    const int up = l == 0 ? 1 : occ_now_[l - 1];
    const int base = occ_prev_[l] + 2 * occ_prev_[l + 1] + 4 * up + 8 * (last_dc_ == 0 ? 1 : 0) + 16 * near;
    if (!edges_) return base;
    return base + 64 * occ_prev2_[l] + 128 * (l == 0 ? 1 : occ_prev_[l - 1]);
  }
  void occupied(std::uint32_t l) { occ_now_[l] = 1; }
  /// Codes (or decodes) whether laser l has a point in this column: with `occupancy`, or
  /// with predictors 4 and 5 mixed from three models (formats/model.md §2.8.4).
  void put_occupancy(RangeEncoder& enc, std::uint32_t l, bool occ) {
    if (!mixed_) return enc.put(occupancy[occupancy_ctx(l)], occ);
    enc.put(occupancy_p0(l), occ);
    occ_mix_->mix.learn(occ);
  }
  bool get_occupancy(RangeDecoder& dec, std::uint32_t l) {
    if (!mixed_) return dec.get(occupancy[occupancy_ctx(l)]);
    const bool occ = dec.get(occupancy_p0(l));
    occ_mix_->mix.learn(occ);
    return occ;
  }

  // --- one point of laser l in the current column ---
  /// A beam length is predicted by the laser's left neighbour (the same laser's last point
  /// within kMaxColumnGap columns) or, with `med`, by the median edge detector over the
  /// left, upper and upper-left pixels where all three exist; else by the laser above in
  /// this column, else by the last point. Its context is the size of the recent prediction
  /// errors at the left and upper pixels and the class of the laser's last residual.
  struct Prediction {
    std::int64_t k;
    int ctx;
    bool edge = false;     ///< predictors 2-5: left and upper pixels far apart, a flag picks one
    std::int64_t alt = 0;  ///< the upper pixel's value, picked by flag 1 (k: the left one, flag 0)
    int flag_ctx = 0;
    std::int64_t gradient = 0;  ///< |a - c| + |b - c| where the left, upper and upper-left pixels exist
  };
  Prediction predict(std::uint32_t l) const {
    const bool has_a = last_c_[l] != kNone && column_ - last_c_[l] <= kMaxColumnGap;
    const bool has_b = up_ != kNone && l - up_ <= 2;
    const int second = IntModel::context_of(last_res_[l]);
    if (!has_a && !has_b) return {last_any_, (kClasses - 1) * kClasses + second};
    std::int64_t score = err_[l];
    if (has_b) score += err_[up_];
    else score *= 2;
    const int activity = std::min(IntModel::context_of(score / 4), kClasses - 1);
    if ((med_ || edges_) && has_a && has_b && prev_c_[up_] != kNone && prev_c_[up_] == last_c_[l]) {
      const std::int64_t a = last_k_[l], b = last_k_[up_], c = prev_k_[up_];
      const std::int64_t gradient = std::min<std::int64_t>(std::abs(a - c) + std::abs(b - c), std::int64_t{1} << 40);
      if (edges_ && std::abs(a - b) > kEdgeSteps) {
        const int fc = sel_[l] + 3 * sel_[up_] + 9 * (a < b ? 1 : 0);
        return {a, activity * kClasses + second, true, b, fc, gradient};
      }
      return {med_ ? med(l) : a, activity * kClasses + second, false, 0, 0, gradient};
    }
    return {has_a ? last_k_[l] : last_k_[up_], activity * kClasses + second};
  }
  /// The median edge detector of the left (a), upper (b) and upper-left (c) pixels.
  std::int64_t med(std::uint32_t l) const {
    const std::int64_t a = last_k_[l], b = last_k_[up_], c = prev_k_[up_];
    return c >= std::max(a, b) ? std::min(a, b) : c <= std::min(a, b) ? std::max(a, b) : a + b - c;
  }
  /// Codes (or decodes) laser l's residual from prediction `pk`: with RangeModel, or with
  /// predictors 4 and 5 with MixedRangeModel.
  void put_residual(RangeEncoder& enc, std::uint32_t l, const Prediction& p, std::int64_t pk, std::int64_t res) {
    if (mixed_) mixed_->put(enc, mixed_contexts(l, p, pk), res);
    else range.put(enc, p.ctx, sign_ctx(l), res);
  }
  std::int64_t get_residual(RangeDecoder& dec, std::uint32_t l, const Prediction& p, std::int64_t pk) {
    return mixed_ ? mixed_->get(dec, mixed_contexts(l, p, pk)) : range.get(dec, p.ctx, sign_ctx(l));
  }
  int k1_ctx(std::uint32_t l) const { return IntModel::context_of(last_k1_[l], last_k1_any_); }
  int k2_ctx(std::uint32_t l, std::int64_t k1) const { return IntModel::context_of(last_k2_[l], k1); }
  /// Which neighbour laser l's point took (0: not at an edge, 1: left, 2: upper).
  void picked(std::uint32_t l, int which) { sel_[l] = static_cast<std::uint8_t>(which); }
  void update(std::uint32_t l, std::int64_t k, std::int64_t res, std::int64_t k1, std::int64_t k2) {
    err_[l] = 2 * std::min<std::int64_t>(std::abs(res), 1 << 20) + (err_[l] >> 1);
    if (last_c_[l] != column_) {
      prev_k_[l] = last_k_[l];
      prev_c_[l] = last_c_[l];
    }
    last_k_[l] = k;
    last_c_[l] = column_;
    last_res_[l] = res;
    last_k1_[l] = k1;
    last_k2_[l] = k2;
    last_k1_any_ = k1;
    last_any_ = k;
    up_ = l;
  }

  BitModel occupancy[256];
  BitModel more[2];
  BitModel edge[18];
  IntModel column_delta{kClasses};
  IntModel column_shift{kClasses};
  RangeModel range;
  /// The sign context of laser l's next residual: its last residual's sign (0, +, -).
  int sign_ctx(std::uint32_t l) const { return last_res_[l] == 0 ? 0 : last_res_[l] > 0 ? 1 : 2; }
  IntModel tangential1{kClasses * kClasses}, tangential2{kClasses * kClasses};

 private:
  static constexpr std::uint32_t kNone = 0xFFFFFFFFU;
  /// The three contexts of MixedRangeModel: `ctx`; the bit length of the predicted beam
  /// length index (less 4, in 0..15) with the recent errors' class; the gradient's class
  /// with the class of the laser's last residual and the laser's eighth of the table.
  MixedRangeModel::Contexts mixed_contexts(std::uint32_t l, const Prediction& p, std::int64_t pk) const {
    const int activity = p.ctx / kClasses, second = p.ctx % kClasses;
    const std::uint64_t a = pk < 0 ? static_cast<std::uint64_t>(-pk) : static_cast<std::uint64_t>(pk);
    const int size = std::clamp(bit_length(a) - 4, 0, 15);
    const int eighth = eighth_[l];
    const int gradient = IntModel::context_of(p.gradient);
    return {{p.ctx, size * kClasses + activity, (gradient * kClasses + second) * 8 + eighth}, sign_ctx(l), activity};
  }
  /// The occupancy models of predictors 4 and 5: occupancy_ctx; the laser with its own
  /// last two columns and the pixel above; the previous column from the laser above to two
  /// below, the two pixels above in this column and `near`. Weights per (pixel above,
  /// laser's last column).
  struct OccupancyMix {
    OccupancyMix(std::uint32_t lasers, MixRates rates) : by_laser(static_cast<std::size_t>(lasers) * 8), mix{4, 21845, rates} {}
    std::vector<YoungBitModel> by_ctx = std::vector<YoungBitModel>(256);
    std::vector<YoungBitModel> by_laser;
    std::vector<YoungBitModel> by_window = std::vector<YoungBitModel>(64 * 4);
    Mix3 mix;
  };
  std::uint32_t occupancy_p0(std::uint32_t l) {
    OccupancyMix& m = *occ_mix_;
    const unsigned up = l == 0 ? 1U : occ_now_[l - 1];
    const unsigned up2 = l < 2 ? 1U : occ_now_[l - 2];
    const unsigned left = occ_prev_[l];
    const std::size_t by_laser = static_cast<std::size_t>(l) * 8 + left + 2U * occ_prev2_[l] + 4U * up;
    const unsigned below2 = l + 2 < lasers_ ? occ_prev_[l + 2] : 0U;
    const int near_l = near(l);
    const std::size_t window = ((((l == 0 ? 1U : occ_prev_[l - 1]) + 2U * left + 4U * occ_prev_[l + 1] + 8U * below2 +
                                  16U * up + 32U * up2) << 2) | static_cast<unsigned>(near_l));
    return m.mix.p0(m.by_ctx[static_cast<std::size_t>(occupancy_ctx(l, near_l))], m.by_laser[by_laser], m.by_window[window],
                    up * 2 + left);
  }
  bool med_, edges_;
  std::unique_ptr<MixedRangeModel> mixed_;
  std::unique_ptr<OccupancyMix> occ_mix_;
  std::uint32_t lasers_;
  double spacing_;
  std::vector<std::uint8_t> sel_;  // per laser: the neighbour its last point took (picked)
  std::vector<std::int64_t> last_k_;
  std::vector<std::uint32_t> last_c_;
  std::vector<std::int64_t> prev_k_;    // a laser's value before its last column's
  std::vector<std::uint32_t> prev_c_;
  std::vector<std::int64_t> last_res_, last_k1_, last_k2_;
  std::vector<std::uint8_t> occ_prev_, occ_now_, occ_prev2_;  // one extra laser, never occupied
  std::vector<std::int64_t> err_;                  // per laser: recent prediction errors
  std::vector<std::uint8_t> eighth_;               // per laser: l · 8 / lasers
  std::int64_t last_dc_ = 0, last_any_ = 0, last_k1_any_ = 0, last_shift_ = 0, last_shift_delta_ = 0;
  std::uint32_t column_ = 0, up_ = kNone;
  bool started_ = false;
};

/// About the bits the range model spends on a residual r (zero flag, sign, exponent, mantissa).
double residual_bits(std::int64_t r) {
  if (r == 0) return 1.0;
  const auto m = static_cast<std::uint64_t>(r < 0 ? -r : r);
  int e = 0;
  while ((m >> (e + 1)) != 0) ++e;
  return 3.0 + 2.0 * e;
}

/// The table's five per-laser fields, in the order they are stored.
std::array<std::vector<std::int64_t>*, 5> table_fields(LaserTable& t) {
  return {&t.elevation, &t.beam_azimuth, &t.column_azimuth, &t.z_offset, &t.radial_offset};
}

/// The prediction of value i of a table field by predictor `kind` (§2.8.1): 0 the
/// previous value, 1 the line through the two previous, 2 the value four back; 0 before
/// there are enough values, and 0 for the first.
std::int64_t table_prediction(const std::vector<std::int64_t>& v, std::size_t i, int kind) {
  if (kind == 1 && i >= 2) return 2 * v[i - 1] - v[i - 2];
  if (kind == 2 && i >= 4) return v[i - 4];
  return i > 0 ? v[i - 1] : 0;
}

/// Codes one table field against predictor `kind` with the table's integer model.
void put_table_field(RangeEncoder& enc, IntModel& m, const std::vector<std::int64_t>& v, int kind) {
  std::int64_t prev_d = 0;
  for (std::size_t i = 0; i < v.size(); ++i) {
    const std::int64_t d = v[i] - table_prediction(v, i, kind);
    m.put(enc, IntModel::context_of(prev_d), d);
    prev_d = d;
  }
}

/// With t.table_predictors each field picks, before its values, the predictor that codes it
/// smallest on its own (two flags; format 1.11); else every field is coded against the
/// previous value. The integer model is shared by the fields.
void put_table(RangeEncoder& enc, const LaserTable& t) {
  IntModel m{IntModel::kClasses};
  BitModel pick[2];
  for (const auto* f : {&t.elevation, &t.beam_azimuth, &t.column_azimuth, &t.z_offset, &t.radial_offset}) {
    int kind = 0;
    if (t.table_predictors) {
      std::size_t best = 0;
      for (int k = 0; k < 3; ++k) {
        RangeEncoder alone;
        IntModel fresh{IntModel::kClasses};
        put_table_field(alone, fresh, *f, k);
        const std::size_t bytes = alone.finish().size();
        if (k == 0 || bytes < best) {
          best = bytes;
          kind = k;
        }
      }
      enc.put(pick[0], kind != 0);
      if (kind != 0) enc.put(pick[1], kind == 2);
    }
    put_table_field(enc, m, *f, kind);
  }
  if (t.has_motion()) {
    m.put(enc, 0, static_cast<std::int64_t>(t.motion_cut));
    for (const std::int64_t v : t.motion) m.put(enc, 0, v);
  }
}

/// The bytes the table costs coded alone as put_table codes it (not in the layer's stream).
std::size_t table_bytes(const LaserTable& t) {
  RangeEncoder alone;
  put_table(alone, t);
  return alone.finish().size();
}

// ---------------------------------------------------------------------------------------
// The table from the input
// ---------------------------------------------------------------------------------------

std::int64_t angle_units(double a) { return static_cast<std::int64_t>(std::llround(a / kLaserAngleUnit)); }
std::int64_t length_units(double v) { return static_cast<std::int64_t>(std::llround(v / kLaserLengthUnit)); }

/// Whether the table's values are within what a payload may store.
bool storable(const LaserTable& t) {
  if (t.lasers() < 1 || t.lasers() > kMaxLasers || t.columns < 1 || t.columns > kMaxLaserColumns) return false;
  if (!std::isfinite(t.azimuth0) || std::abs(t.azimuth0) > kTwoPi) return false;
  if (t.direction != 1 && t.direction != -1) return false;
  if (!(t.shift_unit >= 0.0 && t.shift_unit <= kPi / 64.0)) return false;
  if (!t.T_sensor_head.matrix().allFinite()) return false;
  const auto within = [](const std::vector<std::int64_t>& v, std::int64_t bound) {
    return std::all_of(v.begin(), v.end(), [&](std::int64_t x) { return x >= -bound && x <= bound; });
  };
  return within(t.elevation, kMaxAngleUnits) && within(t.beam_azimuth, kMaxAngleUnits) &&
         within(t.column_azimuth, kMaxAngleUnits) && within(t.z_offset, kMaxLengthUnits) &&
         within(t.radial_offset, kMaxLengthUnits) &&
         std::all_of(t.motion.begin(), t.motion.end(), [](std::int64_t v) { return std::abs(v) <= kMaxLengthUnits; });
}

LaserTable quantise_geometry(const SensorGeometry& g) {
  LaserTable t;
  const std::size_t n = g.lasers();
  const auto field = [&](const std::vector<double>& v, std::size_t l) { return l < v.size() ? v[l] : 0.0; };
  for (std::size_t l = 0; l < n; ++l) {
    t.elevation.push_back(angle_units(field(g.elevation, l)));
    t.beam_azimuth.push_back(angle_units(field(g.beam_azimuth, l)));
    t.column_azimuth.push_back(angle_units(field(g.column_azimuth, l)));
    t.z_offset.push_back(length_units(field(g.z_offset, l)));
    t.radial_offset.push_back(length_units(field(g.radial_offset, l)));
  }
  t.columns = g.columns;
  t.direction = g.direction >= 0 ? 1 : -1;
  t.azimuth0 = std::isfinite(g.azimuth0) ? std::remainder(g.azimuth0, kTwoPi) : 0.0;
  t.T_sensor_head = g.T_sensor_head;
  return t;
}

/// Mean direction of angles (radians) and its resultant length in [0, 1].
std::pair<double, double> circular_mean(double sum_cos, double sum_sin, std::size_t n) {
  if (n == 0) return {0.0, 0.0};
  return {std::atan2(sum_sin, sum_cos), std::hypot(sum_cos, sum_sin) / static_cast<double>(n)};
}

/// A scan's points in the sensor frame with each one's horizontal range and azimuth,
/// computed once for all the estimates below (each reads them several times).
struct ScanPoints {
  std::vector<Eigen::Vector3d> p;
  std::vector<double> rho, azimuth;

  explicit ScanPoints(std::vector<Eigen::Vector3d> points) : p(std::move(points)), rho(p.size()), azimuth(p.size()) {
    for (std::size_t i = 0; i < p.size(); ++i) {
      rho[i] = std::sqrt(p[i].x() * p[i].x() + p[i].y() * p[i].y());
      azimuth[i] = fast_atan2(p[i].y(), p[i].x());
    }
  }
};

/// Estimates a table for points whose lasers and columns are known: per laser, the height
/// of the beam origin and the elevation by a line fit of z against the horizontal range
/// (twice, the second time without the points more than 3 median deviations off), and the
/// azimuth of its columns by a circular mean; the direction of the grid is the one whose
/// means are the tighter.
std::optional<LaserTable> estimate_table(const ScanPoints& scan, const std::vector<std::uint16_t>& ring,
                                         const std::vector<std::uint32_t>& column, std::uint32_t lasers,
                                         std::uint32_t columns, const std::vector<double>& tangential = {}) {
  if (lasers < 1 || lasers > kMaxLasers || columns < 1 || columns > kMaxLaserColumns) return std::nullopt;
  // A beam d sideways of the spin axis reaches a point at horizontal range ρ with its
  // direction asin(d / ρ) off the point's azimuth, and sqrt(ρ² - d²) along it.
  const auto sideways = [&](std::uint16_t l) { return l < tangential.size() ? tangential[l] : 0.0; };
  // Per point (once: the passes below read them several times): its horizontal range, the
  // beam's length to it and the beam's azimuth.
  const std::vector<Eigen::Vector3d>& p = scan.p;
  const std::vector<double>& rho_of = scan.rho;
  const std::size_t n_points = p.size();
  // (the beam's azimuth as its cosine and sine: x / ρ and y / ρ turned back by asin(d / ρ))
  std::vector<double> beam_rho_of(n_points), beam_cos_of(n_points), beam_sin_of(n_points);
  for (std::size_t i = 0; i < n_points; ++i) {
    const double d = sideways(ring[i]), r = rho_of[i];
    beam_rho_of[i] = d == 0.0 ? r : std::sqrt(std::max(0.0, r * r - d * d));
    if (!(r > 0.0)) continue;
    const double c = p[i].x() / r, sn = p[i].y() / r;
    if (d == 0.0) {
      beam_cos_of[i] = c;
      beam_sin_of[i] = sn;
    } else {
      const double ss = std::clamp(d / r, -1.0, 1.0), cs = std::sqrt(1.0 - ss * ss);
      beam_cos_of[i] = c * cs + sn * ss;
      beam_sin_of[i] = sn * cs - c * ss;
    }
  }
  const auto beam_rho = [&](std::uint32_t i) { return beam_rho_of[i]; };
  std::vector<std::vector<std::uint32_t>> of(lasers);
  for (std::size_t i = 0; i < p.size(); ++i) of[ring[i]].push_back(static_cast<std::uint32_t>(i));
  LaserTable t;
  t.columns = columns;
  t.elevation.assign(lasers, 0);
  t.beam_azimuth.assign(lasers, 0);
  t.column_azimuth.assign(lasers, 0);
  t.z_offset.assign(lasers, 0);
  t.radial_offset.assign(lasers, 0);
  // Direction of the grid: the one that explains the azimuths better over all lasers.
  // (the points' beam azimuths less their columns', as cosine and sine: the columns'
  // cosines and sines once, the differences by the angle-difference identities)
  std::vector<double> column_cos(columns), column_sin(columns);
  for (std::uint32_t c = 0; c < columns; ++c) {
    const double g = kTwoPi * static_cast<double>(c) / columns;
    column_cos[c] = std::cos(g);
    column_sin[c] = std::sin(g);
  }
  double best_r = -1.0;
  for (int dir : {1, -1}) {
    double total = 0.0;
    std::size_t count = 0;
    std::vector<std::int64_t> offsets(lasers, 0);
    for (std::uint32_t l = 0; l < lasers; ++l) {
      double sc = 0.0, ss = 0.0;
      std::size_t n = 0;
      for (std::uint32_t i : of[l]) {
        if (!(rho_of[i] > 1e-3)) continue;
        const std::uint32_t c = column[i] < columns ? column[i] : column[i] % columns;
        const double gc = column_cos[c], gs = dir * column_sin[c];
        sc += beam_cos_of[i] * gc + beam_sin_of[i] * gs;
        ss += beam_sin_of[i] * gc - beam_cos_of[i] * gs;
        ++n;
      }
      const auto [mean, r] = circular_mean(sc, ss, n);
      offsets[l] = angle_units(mean);
      total += r * static_cast<double>(n);
      count += n;
    }
    const double r = count ? total / static_cast<double>(count) : 0.0;
    if (r > best_r) {
      best_r = r;
      t.direction = dir;
      t.column_azimuth = offsets;
    }
  }
  // Elevation and height of each laser's beam origin.
  for (std::uint32_t l = 0; l < lasers; ++l) {
    std::vector<std::uint32_t> use;
    for (std::uint32_t i : of[l])
      if (beam_rho(i) > 1e-3) use.push_back(i);
    double z0 = 0.0, slope = 0.0;
    for (int pass = 0; pass < 2 && !use.empty(); ++pass) {
      double sr = 0, sz = 0, srr = 0, srz = 0;
      for (std::uint32_t i : use) {
        const double r = beam_rho(i);
        sr += r;
        sz += p[i].z();
        srr += r * r;
        srz += r * p[i].z();
      }
      const double n = static_cast<double>(use.size());
      const double den = n * srr - sr * sr;
      if (use.size() >= 8 && den > 1e-9 * n * srr) {
        slope = (n * srz - sr * sz) / den;
        z0 = (sz - slope * sr) / n;
      } else {
        // too few points or one range: the elevation through the sensor origin
        double s = 0;
        for (std::uint32_t i : use) s += p[i].z() / beam_rho(i);
        slope = s / n;
        z0 = 0.0;
      }
      if (std::abs(z0) > 10.0) {  // a wild fit: through the origin instead
        z0 = 0.0;
        double s = 0;
        for (std::uint32_t i : use) s += p[i].z() / beam_rho(i);
        slope = s / n;
      }
      if (pass == 1) break;
      std::vector<double> dev(use.size());
      for (std::size_t j = 0; j < use.size(); ++j) {
        const Eigen::Vector3d& q = p[use[j]];
        dev[j] = std::abs(q.z() - z0 - slope * beam_rho(use[j]));
      }
      std::vector<double> sorted = dev;
      std::nth_element(sorted.begin(), sorted.begin() + static_cast<std::ptrdiff_t>(sorted.size() / 2), sorted.end());
      const double mad = sorted[sorted.size() / 2];
      std::vector<std::uint32_t> kept;
      for (std::size_t j = 0; j < use.size(); ++j)
        if (dev[j] <= 3.0 * mad + 1e-6) kept.push_back(use[j]);
      if (kept.size() >= 8) use.swap(kept);
    }
    // z = z0 + tan(φ) ρ: a beam from (0, 0, z0) at elevation φ.
    t.elevation[l] = angle_units(std::atan(slope));
    t.z_offset[l] = length_units(z0);
    // A sideways offset: the origin d across the beam, as §2.8 stores it (the origin at
    // the column's azimuth + π/2, radial offset d, the beam turned back by π/2).
    if (sideways(static_cast<std::uint16_t>(l)) != 0.0) {
      t.column_azimuth[l] += angle_units(kPi / 2.0);
      t.beam_azimuth[l] = angle_units(-kPi / 2.0);
      t.radial_offset[l] = length_units(sideways(static_cast<std::uint16_t>(l)));
    }
  }
  return t;
}

/// sums[k] += exp(i (a[j] + k b[j])) for every k and every j in order (by rotation, in plain
/// arithmetic). Two terms at a time: their rotations are independent, and each sum still
/// takes term j before term j + 1, so the sums are those of one term at a time.
void rotate_sums(const std::vector<double>& a, const std::vector<double>& b, std::vector<std::complex<double>>& sums) {
  std::size_t j = 0;
  for (; j + 1 < a.size(); j += 2) {
    double er = std::cos(a[j]), ei = std::sin(a[j]), fr = std::cos(a[j + 1]), fi = std::sin(a[j + 1]);
    const double rr = std::cos(b[j]), ri = std::sin(b[j]), qr = std::cos(b[j + 1]), qi = std::sin(b[j + 1]);
    for (auto& s : sums) {
      s = {s.real() + er + fr, s.imag() + ei + fi};
      const double t = er * rr - ei * ri;
      ei = er * ri + ei * rr;
      er = t;
      const double u = fr * qr - fi * qi;
      fi = fr * qi + fi * qr;
      fr = u;
    }
  }
  if (j < a.size()) {
    double er = std::cos(a[j]), ei = std::sin(a[j]);
    const double rr = std::cos(b[j]), ri = std::sin(b[j]);
    for (auto& s : sums) {
      s = {s.real() + er, s.imag() + ei};
      const double t = er * rr - ei * ri;
      ei = er * ri + ei * rr;
      er = t;
    }
  }
}

/// The azimuth grid of points whose lasers are known but not their columns. The step first
/// from the median gap between azimuth-neighbouring points of a laser (the firing
/// interval), then the column count near it whose grid the lasers' farthest points follow
/// best (the largest sum over lasers of the resultant length of their azimuths' phases on
/// the grid: reported azimuths rounded to a coarser unit than the step make the median
/// gap a few per cent off). Per laser, the beam's sideways offset d from the spin axis
/// (a tangential offset moves a point's azimuth by asin(d / ρ), more the nearer it is) is
/// the d whose corrected phases are the most coherent, taken where that beats no offset by
/// more than chance would over the candidates tried; the grid's phase per laser is their
/// circular mean and each point's column its nearest grid step. False when the lasers hold
/// too few points.
bool estimate_columns(const ScanPoints& scan, const std::vector<std::uint16_t>& ring, std::uint32_t lasers,
                      std::vector<std::uint32_t>& column, std::uint32_t& columns, std::vector<double>& tangential,
                      bool refine = true) {
  const std::vector<Eigen::Vector3d>& p = scan.p;
  const std::vector<double>& rho = scan.rho;
  const std::vector<double>& az = scan.azimuth;
  std::vector<std::vector<std::uint32_t>> of(lasers);
  for (std::size_t i = 0; i < p.size(); ++i) of[ring[i]].push_back(static_cast<std::uint32_t>(i));
  std::vector<double> gaps;
  for (const auto& idx : of) {
    std::vector<double> s;
    for (std::uint32_t i : idx) s.push_back(az[i]);
    std::sort(s.begin(), s.end());
    for (std::size_t k = 1; k < s.size(); ++k)
      if (s[k] - s[k - 1] > 1e-7) gaps.push_back(s[k] - s[k - 1]);
  }
  if (gaps.size() < 64) return false;
  std::nth_element(gaps.begin(), gaps.begin() + static_cast<std::ptrdiff_t>(gaps.size() / 2), gaps.end());
  const double w0 = std::round(kTwoPi / gaps[gaps.size() / 2]);
  if (!(w0 >= 16 && w0 <= kMaxLaserColumns)) return false;
  using Complex = std::complex<double>;
  // The column count: within 6 % of the median gap's, on each laser's farthest quarter
  // (4096 points over all the lasers; a sideways offset moves them least).
  std::uint32_t w = static_cast<std::uint32_t>(w0);
  if (refine) {
    const auto w_lo = static_cast<std::uint32_t>(std::max(16.0, std::floor(0.94 * w0)));
    const auto w_hi = static_cast<std::uint32_t>(std::min<double>(kMaxLaserColumns, std::ceil(1.06 * w0)));
    std::vector<double> score(w_hi - w_lo + 1, 0.0);
    std::vector<Complex> sums(score.size());
    for (const auto& idx : of) {
      std::vector<std::uint32_t> far = idx;
      const std::size_t quarter = far.size() / 4;
      if (quarter < 8) continue;
      std::nth_element(far.begin(), far.begin() + static_cast<std::ptrdiff_t>(quarter), far.end(),
                       [&](std::uint32_t x, std::uint32_t y) { return rho[x] > rho[y]; });
      far.resize(quarter);
      std::sort(far.begin(), far.end());
      const double stride = std::max(1.0, static_cast<double>(far.size()) / std::max(16.0, 4096.0 / lasers));
      std::fill(sums.begin(), sums.end(), Complex(0.0, 0.0));
      std::vector<double> starts, steps;
      for (double k = 0; k < static_cast<double>(far.size()); k += stride) {
        const double a = az[far[static_cast<std::size_t>(k)]];
        starts.push_back(static_cast<double>(w_lo) * a);
        steps.push_back(a);
      }
      rotate_sums(starts, steps, sums);
      for (std::size_t k = 0; k < sums.size(); ++k) score[k] += std::abs(sums[k]);
    }
    const auto best = static_cast<std::size_t>(std::max_element(score.begin(), score.end()) - score.begin());
    if (score[best] > 0.0 && refine) w = w_lo + static_cast<std::uint32_t>(best);
  }
  columns = w;
  const double step = kTwoPi / static_cast<double>(w);
  // Per laser: the sideways offset (4 mm steps within 0.2 m, then 0.1 mm steps around the
  // best) and the grid's phase, on at most 256 of its points 1 m or more from the axis.
  tangential.assign(lasers, 0.0);
  std::vector<double> phase(lasers, 0.0);
  const auto coherence = [&](const std::vector<double>& phi, const std::vector<double>& x, double d0, double dd,
                             std::size_t count, std::vector<Complex>& sums) {
    sums.assign(count, Complex(0.0, 0.0));
    std::vector<double> starts(phi.size()), steps(phi.size());
    for (std::size_t k = 0; k < phi.size(); ++k) {
      starts[k] = phi[k] - static_cast<double>(w) * d0 * x[k];
      steps[k] = -static_cast<double>(w) * dd * x[k];
    }
    rotate_sums(starts, steps, sums);
  };
  for (std::uint32_t l = 0; l < lasers; ++l) {
    std::vector<double> phi, x;
    std::vector<std::uint32_t> use;
    for (std::uint32_t i : of[l])
      if (rho[i] >= 1.0) use.push_back(i);
    const double stride = std::max(1.0, static_cast<double>(use.size()) / 256.0);
    for (double k = 0; k < static_cast<double>(use.size()); k += stride) {
      const std::uint32_t i = use[static_cast<std::size_t>(k)];
      phi.push_back(static_cast<double>(w) * az[i]);
      x.push_back(1.0 / rho[i]);
    }
    if (phi.empty()) {
      double sc = 0, ss = 0;
      for (std::uint32_t i : of[l]) {
        sc += std::cos(static_cast<double>(w) * az[i]);
        ss += std::sin(static_cast<double>(w) * az[i]);
      }
      phase[l] = std::atan2(ss, sc) / static_cast<double>(w);
      continue;
    }
    std::vector<Complex> none;
    coherence(phi, x, 0.0, 0.0, 1, none);
    if (!refine) {
      phase[l] = std::arg(none[0]) / static_cast<double>(w);
      continue;
    }
    constexpr double kMaxOffset = 0.2, kCoarse = 0.004, kFine = 0.0001;
    constexpr std::size_t kCoarseCount = 101, kFineCount = 81;
    std::vector<Complex> sums;
    coherence(phi, x, -kMaxOffset, kCoarse, kCoarseCount, sums);
    std::size_t best = 0;
    for (std::size_t k = 1; k < sums.size(); ++k)
      if (std::norm(sums[k]) > std::norm(sums[best])) best = k;
    const double coarse = -kMaxOffset + kCoarse * static_cast<double>(best);
    coherence(phi, x, coarse - kFine * 40.0, kFine, kFineCount, sums);
    best = 0;
    for (std::size_t k = 1; k < sums.size(); ++k)
      if (std::norm(sums[k]) > std::norm(sums[best])) best = k;
    const double d = coarse - kFine * 40.0 + kFine * static_cast<double>(best);
    // n R² of random phases is about exponential with mean 1: the best of the candidates
    // tried beats no offset by chance by about ln(candidates).
    const double m = static_cast<double>(phi.size());
    const double gain = (std::norm(sums[best]) - std::norm(none[0])) / m;
    const bool offset = gain > 2.0 * std::log(static_cast<double>(kCoarseCount * kFineCount));
    tangential[l] = offset && refine ? d : 0.0;
    phase[l] = std::arg(tangential[l] != 0.0 ? sums[best] : none[0]) / static_cast<double>(w);
  }
  column.resize(p.size());
  for (std::size_t i = 0; i < p.size(); ++i) {
    const double d = tangential[ring[i]];
    double a = az[i] - phase[ring[i]];
    if (d != 0.0 && rho[i] > 0.0) a -= std::asin(std::clamp(d / rho[i], -1.0, 1.0));
    a -= kTwoPi * std::floor(a / kTwoPi);  // [0, 2π)
    auto c = static_cast<std::int64_t>(std::llround(a / step));
    if (c >= static_cast<std::int64_t>(columns)) c -= columns;
    column[i] = static_cast<std::uint32_t>(std::clamp<std::int64_t>(c, 0, columns - 1));
  }
  return true;
}

/// The columns of points whose lasers and firing times are known (a driver's unorganised
/// cloud with `ring` and `time`): a spinning lidar fires all its lasers once a column, so
/// the points' times count the firings. Along each laser, each gap between consecutive
/// times is a whole number of firing periods (the mean period: the median gap, refined),
/// so that the timestamps' jitter does not add up over the turn; each laser's count is then aligned with the laser
/// with the most points by the offset most of its points agree with (to that laser's point
/// nearest in time); a point's column is its firing from the turn's first plus its laser's
/// stagger, the whole columns by which it looks ahead of its firing. The columns a turn: 2π
/// over the azimuth a laser advances a firing (between its points at most 4 firings apart),
/// or the turn's firings where they exceed that by at most 1 %. False where the times do not fall on firings (fewer than 90 % of the
/// gaps within 10 % of a whole number of periods) or the firings do not fit in one turn.
constexpr double kTimeColumnsCost = 1.25;

bool columns_from_times(const ScanPoints& scan, const std::vector<double>& time, const std::vector<std::uint16_t>& ring,
                        std::uint32_t lasers, std::vector<std::uint32_t>& column, std::uint32_t& columns) {
  const std::size_t n = time.size();
  if (n < 64 || ring.size() != n || scan.azimuth.size() != n) return false;
  std::vector<std::vector<std::uint32_t>> of(lasers);
  for (std::size_t i = 0; i < n; ++i)
    if (ring[i] < lasers) of[ring[i]].push_back(static_cast<std::uint32_t>(i));
  std::vector<double> gaps;
  for (auto& idx : of) {
    std::stable_sort(idx.begin(), idx.end(), [&](std::uint32_t x, std::uint32_t y) { return time[x] < time[y]; });
    for (std::size_t k = 1; k < idx.size(); ++k)
      if (time[idx[k]] > time[idx[k - 1]]) gaps.push_back(time[idx[k]] - time[idx[k - 1]]);
  }
  if (gaps.size() < 32) return false;
  std::vector<double> sorted(gaps);
  std::nth_element(sorted.begin(), sorted.begin() + static_cast<std::ptrdiff_t>(sorted.size() / 2), sorted.end());
  const double period = sorted[sorted.size() / 2];
  if (!(period > 0.0)) return false;
  std::size_t whole = 0;
  for (const double g : gaps) {
    const double f = g / period;
    whole += std::abs(f - std::round(f)) < 0.1 ? 1 : 0;
  }
  if (10 * whole < 9 * gaps.size()) return false;
  // Each laser's firings counted along its own times. The median gap is off the mean
  // period by a share of the timestamps' jitter, which a gap of hundreds of firings (a
  // laser's stretch of sky) multiplies: the period is refined first by the gaps of at most
  // 4 firings, then by the slope of every laser's times over its firings.
  std::vector<std::int64_t> firing(n, 0);
  const auto count = [&](double p) {
    for (const auto& idx : of)
      for (std::size_t k = 1; k < idx.size(); ++k) {
        const double f = std::round((time[idx[k]] - time[idx[k - 1]]) / p);
        if (!(f <= static_cast<double>(kMaxLaserColumns))) return false;
        firing[idx[k]] = firing[idx[k - 1]] + static_cast<std::int64_t>(f);
      }
    return true;
  };
  double short_span = 0.0, short_firings = 0.0;
  for (const double g : gaps) {
    const double f = std::round(g / period);
    if (f >= 1.0 && f <= 4.0) {
      short_span += g;
      short_firings += f;
    }
  }
  if (!(short_firings > 0.0) || !count(short_span / short_firings)) return false;
  double sxy = 0.0, sxx = 0.0;
  for (const auto& idx : of) {
    if (idx.size() < 2) continue;
    double mk = 0.0, mt = 0.0;
    for (const std::uint32_t i : idx) {
      mk += static_cast<double>(firing[i]);
      mt += time[i];
    }
    mk /= static_cast<double>(idx.size());
    mt /= static_cast<double>(idx.size());
    for (const std::uint32_t i : idx) {
      sxy += (static_cast<double>(firing[i]) - mk) * (time[i] - mt);
      sxx += (static_cast<double>(firing[i]) - mk) * (static_cast<double>(firing[i]) - mk);
    }
  }
  if (!(sxx > 0.0 && sxy > 0.0) || !count(sxy / sxx)) return false;
  std::size_t ref = 0;
  for (std::uint32_t l = 1; l < lasers; ++l)
    if (of[l].size() > of[ref].size()) ref = l;
  // aligned with the reference laser's count: the offset to its point nearest in time
  const auto& reference = of[ref];
  for (std::uint32_t l = 0; l < lasers; ++l) {
    if (l == ref || of[l].empty()) continue;
    std::map<std::int64_t, std::size_t> votes;
    std::size_t at = 0;
    for (const std::uint32_t i : of[l]) {
      while (at + 1 < reference.size() && time[reference[at + 1]] <= time[i]) ++at;
      std::size_t near = at;
      if (at + 1 < reference.size() && time[reference[at + 1]] - time[i] < time[i] - time[reference[at]]) near = at + 1;
      ++votes[firing[reference[near]] - firing[i]];
    }
    std::int64_t offset = 0;
    std::size_t most = 0;
    for (const auto& [d, agreeing] : votes)
      if (agreeing > most) {
        most = agreeing;
        offset = d;
      }
    for (const std::uint32_t i : of[l]) firing[i] += offset;
  }
  const auto [first_it, last_it] = std::minmax_element(firing.begin(), firing.end());
  const std::int64_t first = *first_it, last = *last_it;
  // the columns a turn: 2π over the azimuth a laser advances a firing, the mean over its
  // points at most 4 firings apart whose advance is within a factor 2 of the median (the
  // median alone takes the azimuths' rounding: a Velodyne's 0.01° units)
  struct Step {
    double azimuth;
    std::int64_t firings;
  };
  std::vector<Step> steps;
  std::vector<double> advance;
  for (const auto& idx : of)
    for (std::size_t k = 1; k < idx.size(); ++k) {
      const std::int64_t df = firing[idx[k]] - firing[idx[k - 1]];
      if (df < 1 || df > 4 || scan.rho[idx[k]] < 0.3 || scan.rho[idx[k - 1]] < 0.3) continue;
      steps.push_back({std::abs(wrap_angle(scan.azimuth[idx[k]] - scan.azimuth[idx[k - 1]])), df});
      advance.push_back(steps.back().azimuth / static_cast<double>(df));
    }
  if (advance.size() < 32) return false;
  std::nth_element(advance.begin(), advance.begin() + static_cast<std::ptrdiff_t>(advance.size() / 2), advance.end());
  const double typical = advance[advance.size() / 2];
  double azimuth = 0.0, fired = 0.0;
  for (const Step& st : steps) {
    const double a = st.azimuth / static_cast<double>(st.firings);
    if (!(a > 0.5 * typical && a < 2.0 * typical)) continue;
    azimuth += st.azimuth;
    fired += static_cast<double>(st.firings);
  }
  if (!(azimuth > 0.0)) return false;
  // (a turn cut a firing or two past 360°, as a driver may cut it, takes its firings as
  // its columns, as a raw log's turn does)
  const auto firings = static_cast<double>(last - first + 1);
  double w = std::round(kTwoPi * fired / azimuth);
  if (firings > w && firings <= 1.01 * w + 1.0) w = firings;
  if (!(w >= 16 && w <= kMaxLaserColumns && firings <= w)) return false;
  columns = static_cast<std::uint32_t>(w);
  // Each laser's stagger: how many columns ahead of its firing it looks (the circular mean
  // of its points' azimuths less their firings' turn, against the laser with the most
  // points), so that a column's points look the same way, as a destaggered image's do (an
  // Ouster's or a VLP-32C's lasers look degrees apart within one firing).
  const double step = kTwoPi / w;
  double turning = 0.0;  // the azimuths' direction: the sign of their advance a firing
  for (const auto& idx : of)
    for (std::size_t k = 1; k < idx.size(); ++k)
      if (firing[idx[k]] > firing[idx[k - 1]] && scan.rho[idx[k]] >= 0.3 && scan.rho[idx[k - 1]] >= 0.3)
        turning += wrap_angle(scan.azimuth[idx[k]] - scan.azimuth[idx[k - 1]]) > 0.0 ? 1.0 : -1.0;
  const double dir = turning >= 0.0 ? 1.0 : -1.0;
  std::vector<std::complex<double>> look(lasers, std::complex<double>(0.0, 0.0));
  for (std::size_t i = 0; i < n; ++i)
    if (scan.rho[i] >= 0.3) look[ring[i]] += std::polar(1.0, scan.azimuth[i] - dir * step * static_cast<double>(firing[i]));
  std::vector<std::int64_t> stagger(lasers, 0);
  for (std::uint32_t l = 0; l < lasers; ++l)
    if (std::abs(look[l]) > 0.0 && std::abs(look[ref]) > 0.0) {
      // (within a column of the reference: none; a sequence's lasers fired across one
      // firing, as a Velodyne's, look up to half a column either side)
      const double ahead = dir * wrap_angle(std::arg(look[l]) - std::arg(look[ref])) / step;
      stagger[l] = std::abs(ahead) < 1.0 ? 0 : std::llround(ahead);
    }
  const auto wide = static_cast<std::int64_t>(w);
  column.resize(n);
  for (std::size_t i = 0; i < n; ++i)
    column[i] = static_cast<std::uint32_t>(((firing[i] - first + stagger[ring[i]]) % wide + wide) % wide);
  return true;
}

/// Each laser's beam as a line z = h + t ρ: least squares over its points that `use(i)`
/// accepts, where it has 8 or more and their ranges are not all alike (`fitted`).
struct LaserLines {
  std::vector<double> h, t;
  std::vector<std::uint8_t> fitted;
};
template <typename Use>
LaserLines fit_laser_lines(const ScanPoints& scan, const std::vector<std::uint16_t>& ring, std::uint32_t lasers,
                           Use use) {
  std::vector<double> sr(lasers, 0), sz(lasers, 0), srr(lasers, 0), srz(lasers, 0), cnt(lasers, 0);
  for (std::size_t i = 0; i < scan.p.size(); ++i) {
    if (ring[i] >= lasers || !use(i)) continue;
    const std::uint16_t l = ring[i];
    const double r = scan.rho[i], z = scan.p[i].z();
    sr[l] += r;
    sz[l] += z;
    srr[l] += r * r;
    srz[l] += r * z;
    cnt[l] += 1;
  }
  LaserLines lines{std::vector<double>(lasers, 0.0), std::vector<double>(lasers, 0.0), std::vector<std::uint8_t>(lasers, 0)};
  for (std::uint32_t l = 0; l < lasers; ++l) {
    const double den = cnt[l] * srr[l] - sr[l] * sr[l];
    if (!(cnt[l] >= 8 && den > 1e-6 * cnt[l] * srr[l])) continue;
    lines.t[l] = (cnt[l] * srz[l] - sr[l] * sz[l]) / den;
    lines.h[l] = (sz[l] - lines.t[l] * sr[l]) / cnt[l];
    lines.fitted[l] = 1;
  }
  return lines;
}

/// Lasers of points that know none: the elevations (seen from the height that makes them
/// sharpest) of the points beyond the nearest quarter form one peak a laser; each point
/// goes to the nearest peak, and then to the laser whose fitted beam passes nearest it.
bool estimate_rings(const ScanPoints& scan, std::vector<std::uint16_t>& ring, std::uint32_t& lasers) {
  const std::vector<Eigen::Vector3d>& p = scan.p;
  const std::vector<double>& rho = scan.rho;
  const std::size_t n = p.size();
  if (n < 256) return false;
  const double near = 1.0;
  std::vector<std::uint32_t> far;
  for (std::size_t i = 0; i < n; ++i)
    if (rho[i] >= near) far.push_back(static_cast<std::uint32_t>(i));
  if (far.size() < 128) return false;
  // Histogram of elevations, 0.01 degree bins over what the points span.
  constexpr double kBin = 0.01 * kPi / 180.0;
  std::vector<double> elevation;  // (of the points in `far`, one atan2 a point a height)
  const auto histogram = [&](double h, std::vector<double>& hist, double& lo) {
    double mn = 10, mx = -10;
    elevation.resize(far.size());
    for (std::size_t k = 0; k < far.size(); ++k) {
      const std::uint32_t i = far[k];
      const double e = fast_atan2(p[i].z() - h, rho[i]);
      elevation[k] = e;
      mn = std::min(mn, e);
      mx = std::max(mx, e);
    }
    lo = mn - 4 * kBin;
    hist.assign(static_cast<std::size_t>((mx - lo) / kBin) + 8, 0.0);
    for (const double e : elevation) hist[static_cast<std::size_t>((e - lo) / kBin)] += 1.0;
  };
  // The height whose elevations are sharpest: the largest sum of squared bin counts, on at
  // most 16384 of the points, searched every 5 cm and then every centimetre around the best.
  const std::vector<std::uint32_t> all_far = far;
  if (far.size() > 16384) {
    std::vector<std::uint32_t> sample;
    const double step = static_cast<double>(far.size()) / 16384.0;
    for (std::size_t k = 0; k < 16384; ++k) sample.push_back(far[static_cast<std::size_t>(static_cast<double>(k) * step)]);
    far.swap(sample);
  }
  double best_h = 0.0, best_sharp = -1.0;
  // (the search bins the elevations' tangents, kBin wide: as fine as kBin at the horizon and
  // finer above and below it, with no arc tangent a point; points steeper than kSteep, no
  // spinning lidar's beams, left out)
  constexpr double kSteep = 6.0;  // tan 80.5°
  std::vector<double> tan_hist;
  const auto sharpness = [&](double h) {
    double mn = kSteep, mx = -kSteep;
    elevation.clear();
    for (const std::uint32_t i : far) {
      const double t = (p[i].z() - h) / rho[i];
      if (!(std::abs(t) <= kSteep)) continue;
      elevation.push_back(t);
      mn = std::min(mn, t);
      mx = std::max(mx, t);
    }
    if (elevation.empty()) return;
    const double lo = mn - 4 * kBin;
    tan_hist.assign(static_cast<std::size_t>((mx - lo) / kBin) + 8, 0.0);
    for (const double t : elevation) tan_hist[static_cast<std::size_t>((t - lo) / kBin)] += 1.0;
    double sharp = 0;
    for (double c : tan_hist) sharp += c * c;
    if (sharp > best_sharp) {
      best_sharp = sharp;
      best_h = h;
    }
  };
  for (int k = -6; k <= 6; ++k) sharpness(0.05 * k);
  const double coarse = best_h;
  for (int k = -4; k <= 4; ++k)
    if (k != 0) sharpness(coarse + 0.01 * k);
  far = all_far;
  std::vector<double> hist;
  double lo = 0;
  histogram(best_h, hist, lo);
  // (the elevations of the points in `far` from best_h, kept for their lasers below)
  const std::vector<double> far_elevation = std::move(elevation);
  // Smooth over 5 bins; peaks are local maxima above a share of the mean occupied count,
  // at least 0.08 degrees apart (the closest beams of the sensors known, 0.11 degrees).
  std::vector<double> sm(hist.size(), 0.0);
  for (std::size_t b = 2; b + 2 < hist.size(); ++b)
    sm[b] = (hist[b - 2] + 2 * hist[b - 1] + 3 * hist[b] + 2 * hist[b + 1] + hist[b + 2]) / 9.0;
  double occupied = 0, sum = 0;
  for (double c : sm)
    if (c > 0) {
      occupied += 1;
      sum += c;
    }
  const double floor_count = 0.25 * sum / std::max(1.0, occupied);
  std::vector<double> peaks;
  const auto min_sep = static_cast<std::size_t>(0.08 * kPi / 180.0 / kBin);
  std::size_t last = 0;
  for (std::size_t b = 1; b + 1 < sm.size(); ++b) {
    if (!(sm[b] >= floor_count && sm[b] >= sm[b - 1] && sm[b] > sm[b + 1])) continue;
    const double e = lo + (static_cast<double>(b) + 0.5) * kBin;
    if (!peaks.empty() && b - last < min_sep) {
      if (sm[b] > sm[last]) {
        peaks.back() = e;
        last = b;
      }
      continue;
    }
    peaks.push_back(e);
    last = b;
  }
  if (peaks.size() < 2 || peaks.size() > kMaxLasers) return false;
  lasers = static_cast<std::uint32_t>(peaks.size());
  ring.resize(n);
  for (std::size_t i = 0, k = 0; i < n; ++i) {
    const bool in_far = k < far.size() && far[k] == i;
    const double e = in_far ? far_elevation[k++] : fast_atan2(p[i].z() - best_h, rho[i]);
    const auto it = std::lower_bound(peaks.begin(), peaks.end(), e);
    std::size_t l = static_cast<std::size_t>(it - peaks.begin());
    if (l == peaks.size() || (l > 0 && e - peaks[l - 1] < *it - e)) l = l == 0 ? 0 : l - 1;
    ring[i] = static_cast<std::uint16_t>(l);
  }
  // Refinement: each laser's beam as a line z = h + t ρ fitted to its points, and every
  // point moved to the laser whose line passes nearest in elevation (beams whose origins
  // sit at different heights, as a HDL-64E's do).
  for (int round = 0; round < 3; ++round) {
    LaserLines lines = fit_laser_lines(scan, ring, lasers, [&rho, near](std::size_t i) { return rho[i] >= near; });
    std::vector<double>& h = lines.h;
    std::vector<double>& t = lines.t;
    for (std::uint32_t l = 0; l < lasers; ++l)
      if (lines.fitted[l] == 0 || std::abs(h[l] - best_h) > 0.5) {
        t[l] = std::tan(peaks[l]);
        h[l] = best_h;
      }
    for (std::size_t i = 0; i < n; ++i) {
      // (the nearest line in elevation: the smallest height difference at the point's range)
      const double r = std::max(rho[i], 1e-3);
      std::size_t best = ring[i];
      double best_d = std::abs(p[i].z() - h[best] - t[best] * r);
      for (std::size_t l = best > 2 ? best - 2 : 0; l < std::min<std::size_t>(lasers, best + 3); ++l) {
        const double d = std::abs(p[i].z() - h[l] - t[l] * r);
        if (d < best_d) {
          best_d = d;
          best = l;
        }
      }
      ring[i] = static_cast<std::uint16_t>(best);
    }
  }
  // (ring numbers from the top, as sensors number their beams)
  for (auto& r : ring) r = static_cast<std::uint16_t>(lasers - 1 - r);
  return true;
}


/// Lasers too sparse for the estimates' peaks, beyond the edge of the field of view the
/// others span (a top beam that sees mostly sky: on a VLP-16 made from a KITTI scan, 11
/// points of the +3.3° beam, which the cones gave to the +2° one). Each laser's points are
/// fitted with a line z = h + t ρ (beyond 1 m); a point of the top laser more than
/// kStrayAngle or 8 median deviations above its line (of the bottom laser, below it) is a
/// stray. Strays whose elevations gather within kSparseWidth of one another, at least
/// kSparseMin of them and at least half the strays within kSparseBackground, become a
/// laser of their own (numbered after the others; finish_assignment orders the table).
/// Within the field of view strays gathering at one elevation are rather the turns of a
/// motion-compensated scan's lasers (KITTI's), not lasers of their own. Returns how many
/// lasers were added.
std::uint32_t recover_sparse_lasers(const ScanPoints& scan, std::vector<std::uint16_t>& ring, std::uint32_t& lasers) {
  static constexpr double kStrayAngle = 0.05 * kPi / 180.0;
  constexpr double kSparseWidth = 0.02 * kPi / 180.0;
  constexpr std::size_t kSparseMin = 8;
  constexpr double kSparseBackground = 0.2 * kPi / 180.0;
  const std::size_t n = scan.p.size();
  if (lasers < 2 || n != ring.size()) return 0;
  const LaserLines lines =
      fit_laser_lines(scan, ring, lasers, [&scan](std::size_t i) { return scan.rho[i] >= 1.0 && std::isfinite(scan.p[i].z()); });
  const std::vector<double>& h = lines.h;
  const std::vector<double>& t = lines.t;
  const std::vector<std::uint8_t>& fitted = lines.fitted;
  // The top and bottom lasers (the steepest lines up and down): a sparse laser beyond the
  // edge of the field of view gave them its points. Their points' angles off their lines,
  // each laser's limit, and the strays beyond it, outward.
  std::uint32_t top = lasers, bottom = lasers;
  for (std::uint32_t l = 0; l < lasers; ++l) {
    if (fitted[l] == 0) continue;
    if (top == lasers || t[l] > t[top]) top = l;
    if (bottom == lasers || t[l] < t[bottom]) bottom = l;
  }
  if (top == lasers || top == bottom) return 0;
  std::vector<double> dev_top, dev_bottom;
  std::vector<std::pair<double, std::uint32_t>> outward;  // (angle off the line, point)
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint16_t l = ring[i];
    const double r = scan.rho[i];
    if ((l != top && l != bottom) || !(r >= 1.0) || !std::isfinite(scan.p[i].z())) continue;
    const double off = (scan.p[i].z() - h[l] - t[l] * r) / r;
    (l == top ? dev_top : dev_bottom).push_back(std::abs(off));
    if (l == top ? off > kStrayAngle : off < -kStrayAngle) outward.emplace_back(std::abs(off), static_cast<std::uint32_t>(i));
  }
  const auto limit_of = [](std::vector<double>& d) {
    if (d.empty()) return std::numeric_limits<double>::infinity();
    std::nth_element(d.begin(), d.begin() + static_cast<std::ptrdiff_t>(d.size() / 2), d.end());
    return std::max(kStrayAngle, 8.0 * d[d.size() / 2]);
  };
  const double limit_top = limit_of(dev_top), limit_bottom = limit_of(dev_bottom);
  // the strays' elevations seen from their laser's origin height, in order
  std::vector<std::pair<double, std::uint32_t>> strays;
  for (const auto& [off, i] : outward) {
    const std::uint16_t l = ring[i];
    if (off > (l == top ? limit_top : limit_bottom)) strays.emplace_back(std::atan2(scan.p[i].z() - h[l], scan.rho[i]), i);
  }
  if (strays.size() < kSparseMin) return 0;
  std::sort(strays.begin(), strays.end());
  std::uint32_t added = 0;
  for (std::size_t a = 0; a < strays.size() && lasers < kMaxLasers;) {
    // the run of strays within kSparseWidth of the first
    std::size_t b = a;
    while (b < strays.size() && strays[b].first - strays[a].first <= kSparseWidth) ++b;
    if (b - a < kSparseMin) {
      ++a;
      continue;
    }
    const double e = strays[(a + b) / 2].first;
    // (a laser's own, not a chance cluster of scattered strays: at least half the strays
    // within kSparseBackground of it)
    const auto lo = std::lower_bound(strays.begin(), strays.end(), std::make_pair(e - kSparseBackground, 0U));
    const auto hi = std::upper_bound(strays.begin(), strays.end(), std::make_pair(e + kSparseBackground, ~0U));
    if (2 * (b - a) < static_cast<std::size_t>(hi - lo)) {
      ++a;
      continue;
    }
    for (std::size_t k = a; k < b; ++k) ring[strays[k].second] = static_cast<std::uint16_t>(lasers);
    ++lasers;
    ++added;
    a = b;
  }
  return added;
}

/// The sensor's travel over a turn, for a scan whose points were motion-compensated: each
/// point moved to where it lies from the sensor's pose at one instant, so that seen from
/// the head its beams no longer keep their elevations (KITTI's scans: ~0.85 m a turn at
/// 8.5 m/s). When the sensor looked along `azimuth` it stood travel · tau(azimuth) from
/// where it was at the turn's middle, tau(azimuth) = ((azimuth - cut) mod 2π) / 2π - 1/2.
struct TurnMotion {
  double cut = 0.0;                        // azimuth where the turn starts, radians
  Eigen::Vector2d travel = Eigen::Vector2d::Zero();  // metres a turn, horizontal
  [[nodiscard]] double tau(double azimuth) const {
    double a = azimuth - cut;
    a -= kTwoPi * std::floor(a / kTwoPi);
    return a / kTwoPi - 0.5;
  }
};

/// The motion that makes the points' elevations (seen from the height that makes them
/// sharpest) fall into the sharpest peaks: the sum of squared counts of bins of their
/// tangents 0.01° wide at the horizon, on at most 4096 points beyond 1 m, searched over 8
/// start azimuths and travels up to 2 m a turn in x and y (every 0.5 m, on a quarter of
/// the points), then refined by steps of 0.25, 0.1 and 0.05 m, and the start within 7π/64
/// by halving steps (6 starts: trying all 16 within π/8, as before, gave the same files on
/// the 300 codings of bench/fast.sh and the 105 of the encoder's byte checks).
/// nullopt where no travel within the search
/// sharpens the elevations by kMotionGain or more: a scan as the sensor took it, one too
/// still to tell, or one whose sharpest travel lies at the edge of the search.
std::optional<TurnMotion> estimate_motion(const std::vector<Eigen::Vector3d>& points) {
  // (the gain a travel must bring: scans taken as the sensor saw them gain up to 8 % by
  // fitting the four parameters to their noise, balm's non-spinning scans included;
  // KITTI's, at 8 m/s, 110-120 %)
  constexpr double kMotionGain = 1.25;
  // (the travel searched in x and y: 2 m a turn is 20 m/s at 10 turns a second)
  constexpr double kMaxTravel = 2.0;
  constexpr std::size_t kSample = 4096;
  constexpr double kBin = 0.01 * kPi / 180.0;
  std::vector<std::uint32_t> far;
  for (std::size_t i = 0; i < points.size(); ++i)
    if (points[i].x() * points[i].x() + points[i].y() * points[i].y() >= 1.0) far.push_back(static_cast<std::uint32_t>(i));
  if (far.size() < 256) return std::nullopt;
  struct Sample {
    double x, y, z, azimuth;
  };
  std::vector<Sample> sample;
  const std::size_t count = std::min(kSample, far.size());
  sample.reserve(count);
  for (std::size_t k = 0; k < count; ++k) {
    const Eigen::Vector3d& q = points[far[k * far.size() / count]];
    sample.push_back({q.x(), q.y(), q.z(), fast_atan2(q.y(), q.x())});
  }
  // (tangents within ±kTangentBins bins: elevations within ±60°, beyond any spinning lidar's beams)
  const double kTangentBins = std::ceil(std::sqrt(3.0) / kBin);
  std::vector<double> hist(static_cast<std::size_t>(2.0 * kTangentBins) + 2, 0.0);
  std::vector<std::uint32_t> touched(sample.size());
  // (each sample point's tau for the start azimuth last asked for: the searches below try
  // many travels from each start; none where the travel is zero)
  std::vector<double> tau(sample.size(), 0.0);
  double tau_cut = std::numeric_limits<double>::quiet_NaN();
  // (every fourth sample point where `coarse`)
  const auto compute_sharpness = [&](double h, const TurnMotion& m, bool coarse) {
    const bool moves = !m.travel.isZero();
    if (moves && !(m.cut == tau_cut)) {
      for (std::size_t k = 0; k < sample.size(); ++k) tau[k] = m.tau(sample[k].azimuth);
      tau_cut = m.cut;
    }
    std::size_t used = 0;
    for (std::size_t k = 0; k < sample.size(); k += coarse ? 4 : 1) {
      const Sample& q = sample[k];
      const double t = moves ? tau[k] : 0.0;
      const double dx = q.x - m.travel.x() * t, dy = q.y - m.travel.y() * t;
      const double rho2 = dx * dx + dy * dy;
      if (!(rho2 >= 1e-4)) continue;  // (moved onto the spin axis: no elevation)
      // (bins of the elevation's tangent, as fine as kBin near the horizon: no arc tangent;
      // each point shared by its two nearest bins, so that the sum does not jump as points
      // cross bin edges)
      const double x = std::clamp((q.z - h) / std::sqrt(rho2) / kBin + kTangentBins, 0.0,
                                  static_cast<double>(hist.size() - 2));
      const auto b = static_cast<std::uint32_t>(x);
      const double f = x - static_cast<double>(b);
      hist[b] += 1.0 - f;
      hist[b + 1] += f;
      touched[used++] = b;
    }
    double sum = 0.0;
    for (std::size_t k = 0; k < used; ++k) {
      const std::uint32_t b = touched[k];
      sum += hist[b] * hist[b] + hist[b + 1] * hist[b + 1];
      hist[b] = 0.0;
      hist[b + 1] = 0.0;
    }
    return sum;
  };
  // (each value on all the sample points kept by its exact height, start and travel: the
  // searches below step back onto points they have been, and try the same travels again
  // from a new start azimuth's first steps)
  std::map<std::array<double, 4>, double> seen;
  const auto sharpness = [&](double h, const TurnMotion& m, bool coarse) {
    if (coarse) return compute_sharpness(h, m, coarse);
    const std::array<double, 4> key{h, m.cut, m.travel.x(), m.travel.y()};
    const auto it = seen.find(key);
    if (it != seen.end()) return it->second;
    const double v = compute_sharpness(h, m, false);
    seen.emplace(key, v);
    return v;
  };
  const TurnMotion still;
  double h = 0.0, best = -1.0;
  for (int k = -6; k <= 6; ++k) {
    const double v = sharpness(0.05 * k, still, false);
    if (v > best) {
      best = v;
      h = 0.05 * k;
    }
  }
  // Coarse: 8 start azimuths, travels on a 0.5 m grid.
  TurnMotion m;
  best = -1.0;
  for (int c = 0; c < 8; ++c)
    for (int ix = -4; ix <= 4; ++ix)
      for (int iy = -4; iy <= 4; ++iy) {
        const TurnMotion t{-kPi + c * kPi / 4.0, Eigen::Vector2d(kMaxTravel / 4.0 * ix, kMaxTravel / 4.0 * iy)};
        const double v = sharpness(h, t, true);
        if (v > best) {
          best = v;
          m = t;
        }
      }
  // (no travel on the grid sharpens the elevations by kMotionGain: not refined)
  if (m.travel.isZero() || !(best >= kMotionGain * sharpness(h, still, true))) return std::nullopt;
  // Refined: the travel and the height by steps of 0.25, 0.1 and 0.05 m (the height by a
  // fifth of them) at the coarse start azimuth, then the start azimuth within π/8 of it in
  // steps of π/64, each tried with that travel refined again by 0.05 m. (Moving the start
  // step by step strays: the start and the travel across it trade off.)
  // A refinement stops where it takes a travel at the edge of the search (`edge`): the
  // estimate is then no estimate (as below). Scans not from a spinning lidar (balm's) climbed
  // there in 1,400-1,800 evaluations, and were refused for it after 2,100.
  bool edge = false;
  const auto refine = [&](TurnMotion& t, double& height, double value, std::initializer_list<double> steps) {
    for (const double step : steps) {
      for (bool moved = true; moved;) {
        moved = false;
        for (const Eigen::Vector2d& d : {Eigen::Vector2d(step, 0), Eigen::Vector2d(-step, 0), Eigen::Vector2d(0, step),
                                         Eigen::Vector2d(0, -step)}) {
          const TurnMotion u{t.cut, t.travel + d};
          if (u.travel.cwiseAbs().maxCoeff() > kMaxTravel + 1e-9) continue;
          const double v = sharpness(height, u, false);
          if (v > value) {
            value = v;
            t = u;
            moved = true;
            if (t.travel.cwiseAbs().maxCoeff() >= kMaxTravel - 1e-9) {
              edge = true;
              return value;
            }
          }
        }
        for (const double dh : {step / 5.0, -step / 5.0}) {
          const double v = sharpness(height + dh, t, false);
          if (v > value) {
            value = v;
            height += dh;
            moved = true;
          }
        }
      }
    }
    return value;
  };
  best = refine(m, h, sharpness(h, m, false), {0.25, 0.1, 0.05});
  if (edge) return std::nullopt;
  const TurnMotion coarse_motion = m;
  const double coarse_h = h;
  // (the start k·π/64 from the coarse one, tried with its travel refined; false at the edge)
  const auto try_start = [&](int k) {
    TurnMotion t{coarse_motion.cut + k * kPi / 64.0, coarse_motion.travel};
    double th = coarse_h;
    const double v = refine(t, th, sharpness(th, t, false), {0.05});
    if (edge) return false;
    if (v > best) {
      best = v;
      m = t;
      h = th;
    }
    return true;
  };
  // (halving steps of 4, 2 and 1 around the best start so far)
  int centre = 0;
  for (const int step : {4, 2, 1}) {
    const int from = centre;
    for (const int k : {from - step, from + step}) {
      const double before = best;
      if (!try_start(k)) return std::nullopt;
      if (best > before) centre = k;
    }
  }
  // Against no motion at its own sharpest height, both within 10 cm of the first (1 cm steps).
  double moving = best, none = -1.0;
  for (int k = -10; k <= 10; ++k) {
    moving = std::max(moving, sharpness(h + 0.01 * k, m, false));
    none = std::max(none, sharpness(h + 0.01 * k, still, false));
  }
  // (a travel at the edge of the search is no estimate: the sharpest lies beyond it, or the
  // points have no beams to sharpen)
  if (m.travel.isZero() || m.travel.cwiseAbs().maxCoeff() >= kMaxTravel - 1e-9 || !(moving >= kMotionGain * none))
    return std::nullopt;
  return m;
}

/// Sets `t`'s motion (formats/model.md §2.8.5) to `m`, estimated in the sensor frame (the
/// head's, for an estimated table): the column nearest its start azimuth, and its travel
/// turned to the columns' direction.
void set_motion(LaserTable& t, const TurnMotion& m) {
  const auto w = static_cast<std::int64_t>(std::max<std::uint32_t>(1, t.columns));
  const double step = static_cast<double>(t.direction) * kTwoPi / static_cast<double>(w);
  std::int64_t c = std::llround((m.cut - t.azimuth0) / step) % w;
  if (c < 0) c += w;
  t.motion_cut = static_cast<std::uint32_t>(c);
  const double sign = t.direction > 0 ? 1.0 : -1.0;
  t.motion = {std::llround(sign * m.travel.x() / kLaserLengthUnit), std::llround(sign * m.travel.y() / kLaserLengthUnit), 0};
}

/// Lasers of points that know none, as cones: laser l's beams start at height h_l on the
/// spin axis and rise at tan t_l, so its points lie on z = h_l + t_l·ρ. Seeds: every point
/// votes, for each origin height h in [-0.5, 0.5] m, for the slope (z - h) / ρ it would
/// have from there; the slopes (0.01° bins) that most points share at their best height
/// are the seeds, far more of them than there are lasers (a wall at one range votes along
/// a whole diagonal). Rounds of giving every point to the cone that passes nearest it (in
/// z at its range) and refitting each cone to its points then pull the seeds of one laser
/// onto the same cone; cones that coincide over their points' ranges (within three times
/// their points' RMS distance) are merged, cones left with too few points dropped. This
/// keeps lasers whose beams start at different heights (a HDL-64E's two blocks) whole where
/// elevations seen from one height split or merge them. `z_rms`: the points' RMS distance
/// (in z) from their cones. False where the rounds have not settled after kConeRounds and
/// there are more cones than `elevation_lasers()` (the lasers seen as elevation peaks,
/// estimate_rings, 0 where it found none; asked only then and after kConeEarlyRound): cones
/// that keep splitting and merging beyond the lasers the elevations show are not the beams;
/// with no more cones than that (or no peaks) the rounds go on to kMaxConeRounds.
/// (On the shared scans and the lidars re-sampled from them, the rounds settled within 2-5
/// rounds where the points lie on cones; on scans that the sensor's motion moved off them
/// (KITTI's: 146-179 cones against 89-127 elevation peaks), balm's non-spinning scans
/// (389-531 against 71-477) and the VLS-128 re-sampled from KITTI (97 against 98) they did
/// not settle in 12, and the lasers by elevation were coded instead, or as small, at
/// 5-14 mm. newer_college/raw_00's unsettled cones (151 against 195 peaks, 67 mm off them)
/// coded 0.5 % and 1.0 % smaller at 5 and 7 cm. Giving up at 8 rounds takes 0.19 of
/// kitti00/000000's encoding instructions.)
constexpr int kConeRounds = 8;
constexpr int kMaxConeRounds = 12;
/// The rounds give up already after kConeEarlyRound rounds where there are more than
/// kConeEarlyExcess times as many cones as elevation peaks. On the 76 scans of bench/fast.sh's
/// inputs and more (every shared set, the indoor scans, every re-sampled lidar) the cones
/// given up at kConeRounds were 1.48-2.1 times the peaks after two rounds, those kept at most
/// 1.07 times: the same decisions, and 0.15 G fewer of the 1.58 G instructions that
/// kitti00/000000 took.
constexpr int kConeEarlyRound = 2;
constexpr double kConeEarlyExcess = 1.25;

bool estimate_cones(const ScanPoints& scan, std::vector<std::uint16_t>& ring, std::uint32_t& lasers, double& z_rms,
                    const std::function<std::uint32_t()>& elevation_lasers, bool fast = false) {
  // (the points that vote and those the rounds assign: a quarter as many `fast`)
  const std::size_t voters = fast ? 4096 : 16384, workers = fast ? 8192 : 32768;
  const std::vector<Eigen::Vector3d>& p = scan.p;
  const std::vector<double>& rho = scan.rho;
  const std::size_t n = p.size();
  if (n < 256) return false;
  constexpr double kNear = 1.0;
  std::vector<std::uint32_t> far;
  for (std::size_t i = 0; i < n; ++i)
    if (rho[i] >= kNear) far.push_back(static_cast<std::uint32_t>(i));
  if (far.size() < 128) return false;
  if (far.size() > voters) {
    std::vector<std::uint32_t> sample;
    const double stride = static_cast<double>(far.size()) / static_cast<double>(voters);
    for (std::size_t k = 0; k < voters; ++k) sample.push_back(far[static_cast<std::size_t>(static_cast<double>(k) * stride)]);
    far.swap(sample);
  }
  // The vote: heights every 2 cm, slopes in bins of 0.01° (in tan) within ±60°.
  constexpr int kHeights = 51;
  constexpr double kHeightStep = 0.02, kHeightLow = -0.5;
  const double bin = std::tan(0.01 * kPi / 180.0);
  const double t_max = std::tan(60.0 * kPi / 180.0);
  double lo = t_max, hi = -t_max;
  for (std::uint32_t i : far)
    for (double h : {kHeightLow, -kHeightLow}) {
      const double t = std::clamp((p[i].z() - h) / rho[i], -t_max, t_max);
      lo = std::min(lo, t);
      hi = std::max(hi, t);
    }
  lo -= 4 * bin;
  const auto bins = static_cast<std::size_t>((hi - lo) / bin) + 8;
  std::vector<float> votes(kHeights * bins, 0.0F);
  for (int k = 0; k < kHeights; ++k) {
    const double h = kHeightLow + kHeightStep * k;
    float* row = votes.data() + static_cast<std::size_t>(k) * bins;
    for (std::uint32_t i : far) {
      const double t = (p[i].z() - h) / rho[i];
      if (t < -t_max || t > t_max) continue;
      row[static_cast<std::size_t>((t - lo) / bin)] += 1.0F;
    }
  }
  // Each slope's best height (votes smoothed over 5 bins), then peaks as in estimate_rings.
  std::vector<double> profile(bins, 0.0), height(bins, 0.0);
  for (int k = 0; k < kHeights; ++k) {
    const float* row = votes.data() + static_cast<std::size_t>(k) * bins;
    for (std::size_t b = 2; b + 2 < bins; ++b) {
      const double s = (row[b - 2] + 2.0 * row[b - 1] + 3.0 * row[b] + 2.0 * row[b + 1] + row[b + 2]) / 9.0;
      if (s > profile[b]) {
        profile[b] = s;
        height[b] = kHeightLow + kHeightStep * k;
      }
    }
  }
  double occupied = 0, sum = 0;
  for (double c : profile)
    if (c > 0) {
      occupied += 1;
      sum += c;
    }
  const double floor_count = 0.25 * sum / std::max(1.0, occupied);
  std::vector<double> T, H;
  std::size_t last = 0;
  for (std::size_t b = 1; b + 1 < bins; ++b) {
    if (!(profile[b] >= floor_count && profile[b] >= profile[b - 1] && profile[b] > profile[b + 1])) continue;
    const double t = lo + (static_cast<double>(b) + 0.5) * bin;
    if (!T.empty() && b - last < 8) {
      if (profile[b] > profile[last]) {
        T.back() = t;
        H.back() = height[b];
        last = b;
      }
      continue;
    }
    T.push_back(t);
    H.push_back(height[b]);
    last = b;
  }
  if (T.size() < 2) return false;

  // Rounds: nearest cone, refit, merge, drop (on at most 32768 of the points, evenly
  // spread; the last assignment on all of them).
  ring.assign(n, 0);
  std::vector<double> dist(n, 0.0);
  std::vector<std::uint32_t> work, all(n);
  std::iota(all.begin(), all.end(), 0U);
  {
    const double stride = std::max(1.0, static_cast<double>(n) / static_cast<double>(workers));
    for (double k = 0; k < static_cast<double>(n); k += stride) work.push_back(static_cast<std::uint32_t>(k));
  }
  const auto assign = [&](bool first, const std::vector<std::uint32_t>& points) {
    // cones in slope order; a point looks near where its slope from its cone's height falls
    const std::size_t m = T.size();
    double h_ref = 0.0;
    if (first) {
      std::vector<double> hs = H;
      std::nth_element(hs.begin(), hs.begin() + static_cast<std::ptrdiff_t>(m / 2), hs.end());
      h_ref = hs[m / 2];
    }
    for (std::uint32_t i : points) {
      const double r = std::max(rho[i], 1e-3);
      const std::size_t prev = std::min<std::size_t>(ring[i], m - 1);
      const double h = first ? h_ref : H[prev];
      const auto pos = static_cast<std::size_t>(std::lower_bound(T.begin(), T.end(), (p[i].z() - h) / r) - T.begin());
      const std::size_t w = first ? 12 : 4;
      std::size_t best = first ? std::min(pos, m - 1) : prev;
      double best_d = std::abs(p[i].z() - H[best] - T[best] * r);
      const double z = p[i].z();
      for (std::size_t l = pos > w ? pos - w : 0; l < std::min(m, pos + w); ++l) {
        // (selects, not a branch: which cone is nearer is a coin toss to the predictor)
        const double d = std::abs(z - H[l] - T[l] * r);
        const bool nearer = d < best_d;
        best_d = nearer ? d : best_d;
        best = nearer ? l : best;
      }
      ring[i] = static_cast<std::uint16_t>(best);
      dist[i] = best_d;
    }
  };
  assign(true, work);
  bool given_up = false;
  for (int round = 0; round < kMaxConeRounds; ++round) {
    const std::size_t m = T.size();
    if (round == kConeEarlyRound || round == kConeRounds) {
      const std::uint32_t peaks = elevation_lasers();
      const double excess = round == kConeRounds ? 1.0 : kConeEarlyExcess;
      given_up = peaks > 0 && static_cast<double>(m) > excess * static_cast<double>(peaks);
      if (given_up) break;
    }
    std::vector<double> sr(m, 0), sz(m, 0), srr(m, 0), srz(m, 0), cnt(m, 0), r0(m, 1e30), r1(m, 0);
    for (std::uint32_t i : work) {
      if (!(rho[i] >= kNear)) continue;
      const std::uint16_t l = ring[i];
      sr[l] += rho[i];
      sz[l] += p[i].z();
      srr[l] += rho[i] * rho[i];
      srz[l] += rho[i] * p[i].z();
      cnt[l] += 1;
      r0[l] = std::min(r0[l], rho[i]);
      r1[l] = std::max(r1[l], rho[i]);
    }
    const double min_points = std::max(16.0 * static_cast<double>(work.size()) / static_cast<double>(n), 0.01 * static_cast<double>(work.size()) / static_cast<double>(m));
    std::vector<double> s(m, 0.0);
    std::vector<std::size_t> keep;
    for (std::size_t l = 0; l < m; ++l) {
      if (cnt[l] < min_points) continue;
      const double den = cnt[l] * srr[l] - sr[l] * sr[l];
      if (den > 1e-6 * cnt[l] * srr[l]) {
        T[l] = (cnt[l] * srz[l] - sr[l] * sz[l]) / den;
        H[l] = (sz[l] - T[l] * sr[l]) / cnt[l];
      }
      if (!(std::abs(H[l]) <= 1.0 && std::abs(T[l]) <= t_max)) continue;
      keep.push_back(l);
    }
    if (keep.size() < 2) return false;
    // each kept cone's RMS distance (in z) from its points
    std::vector<double> se(m, 0.0);
    for (std::uint32_t i : work) {
      if (!(rho[i] >= kNear)) continue;
      const std::uint16_t l = ring[i];
      const double d = p[i].z() - H[l] - T[l] * rho[i];
      se[l] += d * d;
    }
    for (std::size_t l : keep) s[l] = std::sqrt(se[l] / cnt[l]);
    std::stable_sort(keep.begin(), keep.end(), [&](std::size_t x, std::size_t y) { return T[x] < T[y]; });
    std::vector<double> nT, nH, ns, n0, n1;
    for (std::size_t l : keep) {
      if (!nT.empty()) {
        const double a = std::min(n0.back(), r0[l]), b = std::max(n1.back(), r1[l]);
        const double dt = T[l] - nT.back(), dh = H[l] - nH.back();
        const double apart = std::max(std::abs(dt * a + dh), std::abs(dt * b + dh));
        if (apart < 3.0 * std::max(ns.back(), s[l]) + 1e-4) {
          n0.back() = a;
          n1.back() = b;
          continue;
        }
      }
      nT.push_back(T[l]);
      nH.push_back(H[l]);
      ns.push_back(s[l]);
      n0.push_back(r0[l]);
      n1.push_back(r1[l]);
    }
    const bool merged = nT.size() != m;
    T.swap(nT);
    H.swap(nH);
    if (T.size() > kMaxLasers) return false;
    std::vector<std::uint16_t> before(work.size());
    for (std::size_t k = 0; k < work.size(); ++k) before[k] = ring[work[k]];
    assign(true, work);
    assign(false, work);
    std::size_t changed = 0;
    for (std::size_t k = 0; k < work.size(); ++k) changed += before[k] != ring[work[k]] ? 1 : 0;
    if (!merged && changed == 0) break;
  }
  if (given_up) return false;
  assign(true, all);
  assign(false, all);
  lasers = static_cast<std::uint32_t>(T.size());
  if (lasers < 2) return false;
  double se = 0.0;
  for (std::size_t i = 0; i < n; ++i) se += dist[i] * dist[i];
  z_rms = std::sqrt(se / static_cast<double>(n));
  // (ring numbers from the top, as sensors number their beams)
  for (auto& r : ring) r = static_cast<std::uint16_t>(lasers - 1 - r);
  return true;
}

/// Roughly what a laser assignment and its table would cost the coder: per point,
/// log2(1 + x / 1 cm) of its distance off its beam and of the change of its beam length
/// from its laser's previous point (in column order, up to kMaxColumnGap columns back; a
/// point that starts a scan line pays for its whole beam length), plus the occupancy of
/// the range image (lasers × columns pixels, each filled or not: their binary entropy).
double assignment_cost(const std::vector<Eigen::Vector3d>& p, const std::vector<std::uint16_t>& ring,
                       const std::vector<std::uint32_t>& column, const LaserTable& table) {
  const Beams beams(table, Pose::Identity());
  const std::size_t n = p.size();
  std::vector<double> along(n), cost(n);
  constexpr double kScale = 0.01;
  const std::vector<Beams::ColumnTrig> columns = beams.column_trigs(table.columns);
  for (std::size_t i = 0; i < n; ++i) {
    const auto b = beams.beam(ring[i], column[i], columns);
    const Eigen::Vector3d v = p[i] - b.o;
    along[i] = v.dot(b.u);
    cost[i] = std::log2(1.0 + (v - along[i] * b.u).norm() / kScale);
  }
  // The points laser by laser, columns in order, then by index: a counting sort over the
  // pixels where every laser and column lies in the table (as the estimates make them),
  // else a comparison sort to the same order.
  std::vector<std::uint32_t> order;
  const std::uint64_t lasers = table.lasers(), grid = table.columns;
  bool counting = counting_pays(lasers * grid, n);
  for (std::size_t i = 0; i < n && counting; ++i) counting = ring[i] < lasers && column[i] < grid;
  if (counting) {
    order = counting_order(n, static_cast<std::size_t>(lasers * grid),
                           [&](std::size_t i) { return static_cast<std::size_t>(ring[i] * grid + column[i]); });
  } else {
    order.resize(n);
    std::iota(order.begin(), order.end(), 0U);
    std::sort(order.begin(), order.end(), [&](std::uint32_t x, std::uint32_t y) {
      return ring[x] != ring[y] ? ring[x] < ring[y] : column[x] != column[y] ? column[x] < column[y] : x < y;
    });
  }
  double total = 0.0;
  for (std::size_t k = 0; k < n; ++k) {
    const std::uint32_t i = order[k];
    const bool follows = k > 0 && ring[order[k - 1]] == ring[i] && column[i] - column[order[k - 1]] <= kMaxColumnGap;
    const double change = follows ? along[i] - along[order[k - 1]] : along[i];
    total += cost[i] + std::log2(1.0 + std::abs(change) / kScale);
  }
  const double pixels = static_cast<double>(table.lasers()) * static_cast<double>(table.columns);
  const double fill = std::min(1.0, static_cast<double>(n) / std::max(1.0, pixels));
  if (fill > 0.0 && fill < 1.0)
    total += pixels * -(fill * std::log2(fill) + (1.0 - fill) * std::log2(1.0 - fill));
  return total;
}

/// The table's shift unit (the grid's step / 64: a positive unit marks a table whose
/// columns may shift; the unit a layer codes with follows from its bound, prepare_layer),
/// its lasers in elevation order (top first) and the points' RMS distance from their
/// beams. False when the table cannot be stored.
bool finish_assignment(const Cloud& input, const Pose& T_cloud_sensor, LaserAssignment& a) {
  const std::size_t n = input.size();
  a.table.shift_unit = kTwoPi / static_cast<double>(std::max<std::uint32_t>(1, a.table.columns)) / 64.0;
  // Lasers in the order of their elevations, top first, so that a laser's neighbour in the
  // table is its neighbour in the range image.
  {
    const std::uint32_t nl = a.table.lasers();
    std::vector<std::uint32_t> by(nl);
    std::iota(by.begin(), by.end(), 0U);
    std::stable_sort(by.begin(), by.end(),
                     [&](std::uint32_t x, std::uint32_t y) { return a.table.elevation[x] > a.table.elevation[y]; });
    std::vector<std::uint16_t> rank(nl);
    for (std::uint32_t k = 0; k < nl; ++k) rank[by[k]] = static_cast<std::uint16_t>(k);
    for (auto* f : table_fields(a.table)) {
      std::vector<std::int64_t> sorted(nl);
      for (std::uint32_t k = 0; k < nl; ++k) sorted[k] = (*f)[by[k]];
      *f = std::move(sorted);
    }
    for (auto& r : a.ring) r = r < nl ? rank[r] : r;
  }
  if (!storable(a.table)) return false;
  // How far the points lie from their beams.
  const Beams beams(a.table, T_cloud_sensor);
  const Pose T_head_cloud = beams.T_cloud_head.inverse();
  const std::vector<Beams::ColumnTrig> columns = beams.column_trigs(a.table.columns);
  double sum = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    const auto b = beams.beam(a.ring[i], a.column[i], columns);
    const Eigen::Vector3d v = T_head_cloud * input.points[i].cast<double>() - b.o;
    sum += (v - v.dot(b.u) * b.u).squaredNorm();
  }
  a.fit_rms = std::sqrt(sum / static_cast<double>(n));
  return true;
}

}  // namespace

// ---------------------------------------------------------------------------------------
// assign_lasers
// ---------------------------------------------------------------------------------------

std::optional<LaserAssignment> assign_lasers(const Cloud& input, const Pose& T_cloud_sensor, bool estimate, int threads,
                                             bool fast) {
  const std::size_t n = input.size();
  if (n == 0) return std::nullopt;
  LaserAssignment a;
  std::uint32_t lasers = 0, columns = 0;
  if (input.has_rings()) {
    a.ring = input.ring;
    for (std::size_t i = 0; i < n; ++i) lasers = std::max<std::uint32_t>(lasers, a.ring[i] + 1U);
  }
  if (input.has_rings() && input.has_columns()) {
    a.column = input.column;
    for (std::size_t i = 0; i < n; ++i) columns = std::max<std::uint32_t>(columns, a.column[i] + 1U);
  }
  if (!a.column.empty() && input.geometry && input.geometry->lasers() >= lasers && input.geometry->columns >= columns &&
      input.geometry->columns > 0) {
    a.table = quantise_geometry(*input.geometry);
    a.source = input.geometry->source.empty() ? "sensor metadata" : input.geometry->source;
  } else {
    if (a.ring.empty() && !estimate) return std::nullopt;
    const Pose T_sensor_cloud = T_cloud_sensor.inverse();
    std::vector<Eigen::Vector3d> sensor_points(n);
    for (std::size_t i = 0; i < n; ++i) sensor_points[i] = T_sensor_cloud * input.points[i].cast<double>();
    std::optional<OrderLayout> layout;
    if (a.ring.empty()) layout = detect_order_layout(input.points);
    // A motion-compensated scan (estimate_motion; with its lasers given or not, but not one
    // in firing or row order, which is as the sensor saw it): the lasers, columns and table
    // are estimated from the points as the sensor saw them, and the table carries the motion.
    std::optional<TurnMotion> motion;
    if (!layout) motion = estimate_motion(sensor_points);
    if (motion)
      for (Eigen::Vector3d& q : sensor_points) {
        const double t = motion->tau(fast_atan2(q.y(), q.x()));
        q.x() -= motion->travel.x() * t;
        q.y() -= motion->travel.y() * t;
      }
    // (an estimated table takes the motion, and its source says so, before its fit is measured)
    const auto carry_motion = [&motion](LaserAssignment& x) {
      if (!motion) return;
      set_motion(x.table, *motion);
      std::ostringstream note;
      note << std::fixed << std::setprecision(2) << "; motion-compensated points: the sensor moved ("
           << motion->travel.x() << ", " << motion->travel.y() << ") m over the turn from azimuth " << std::setprecision(1)
           << motion->cut * 180.0 / kPi << " deg";
      x.source += note.str();
    };
    const ScanPoints scan(std::move(sensor_points));
    if (layout) {
      // Stored firing by firing or row by row: the order gives lasers and columns; the
      // grid's step is the median azimuth step of a laser from one column to the next.
      lasers = layout->lasers;
      std::vector<double> steps;
      const std::size_t apart = layout->firing_major ? layout->lasers : 1;
      for (std::size_t i = 0; i + apart < n; i += std::max<std::size_t>(1, n / 20000)) {
        if (!layout->firing_major && layout->column(i) + 1 >= layout->columns) continue;
        if (scan.rho[i] < 0.3 || scan.rho[i + apart] < 0.3) continue;
        const double d = std::abs(wrap_angle(scan.azimuth[i + apart] - scan.azimuth[i]));
        if (d > 1e-7) steps.push_back(d);
      }
      if (steps.size() < 16) return std::nullopt;
      std::nth_element(steps.begin(), steps.begin() + static_cast<std::ptrdiff_t>(steps.size() / 2), steps.end());
      const double w = std::round(kTwoPi / steps[steps.size() / 2]);
      if (!(w >= 16 && w <= kMaxLaserColumns)) return std::nullopt;
      columns = static_cast<std::uint32_t>(w);
      a.ring.resize(n);
      a.column.resize(n);
      for (std::size_t i = 0; i < n; ++i) {
        a.ring[i] = layout->ring(i);
        a.column[i] = layout->column(i) % columns;
      }
      a.source = std::string("estimated from the points' order (") + (layout->firing_major ? "firing" : "row") +
                 " by " + (layout->firing_major ? "firing" : "row") + ", " + std::to_string(layout->lasers) + " lasers)";
    } else if (a.ring.empty()) {
      // Two estimates of the lasers: as cones (estimate_cones: beams from different
      // heights, as a HDL-64E's; the grid's step by coherence, sideways offsets fitted) and
      // as elevation peaks seen from one height (estimate_rings; the median gap's step, no
      // sideways offsets); each with its grid and table, and the one whose scan lines the
      // coder would find cheaper (assignment_cost) is kept.
      struct Candidate {
        std::vector<std::uint16_t> ring;
        std::vector<std::uint32_t> column;
        std::uint32_t lasers = 0, columns = 0;
        LaserTable table;
        bool found = false;
        double cost = std::numeric_limits<double>::infinity();
      };
      // (the two side by side where there are two threads, the elevation peaks first: the
      // cones may ask for their laser count)
      std::array<Candidate, 2> cand;
      std::promise<std::uint32_t> peaks;
      std::shared_future<std::uint32_t> peak_lasers = peaks.get_future().share();
      parallel_for(cand.size(), threads, [&](std::size_t job) {
        const std::size_t k = 1 - job;
        Candidate& c = cand[k];
        bool found = false;
        double z_rms = 0.0;
        if (k == 0) {
          found = estimate_cones(scan, c.ring, c.lasers, z_rms, [&peak_lasers] { return peak_lasers.get(); }, fast);
        } else {
          try {
            found = estimate_rings(scan, c.ring, c.lasers);
          } catch (...) {
            peaks.set_value(0);
            throw;
          }
          peaks.set_value(found ? c.lasers : 0);
        }
        std::vector<double> tangential;
        if (found) (void)recover_sparse_lasers(scan, c.ring, c.lasers);
        if (!found || !estimate_columns(scan, c.ring, c.lasers, c.column, c.columns, tangential, k == 0)) return;
        auto t = estimate_table(scan, c.ring, c.column, c.lasers, c.columns, tangential);
        if (!t || !storable(*t)) return;
        c.table = std::move(*t);
        c.found = true;
      }, 1);
      // Each estimate's rough cost, where there are two to choose from; one alone is kept
      // whatever its cost, unless that cost is not finite (a point that is not: the cost is
      // finite for finite points), as the choice below would then refuse it (kitti00 in
      // `--fast`, whose cones are given up: 37 M of 1.10 G instructions).
      const bool costs = (cand[0].found && cand[1].found) ||
                         !std::all_of(scan.p.begin(), scan.p.end(), [](const Eigen::Vector3d& q) { return q.allFinite(); });
      parallel_for(cand.size(), threads, [&](std::size_t k) {
        Candidate& c = cand[k];
        if (!c.found) return;
        c.cost = costs ? assignment_cost(scan.p, c.ring, c.column, c.table) : 0.0;
      }, 1);
      std::size_t pick = 0;
      for (std::size_t k = 1; k < cand.size(); ++k)
        if (cand[k].cost < cand[pick].cost) pick = k;
      if (!std::isfinite(cand[pick].cost)) return std::nullopt;
      const std::size_t other = 1 - pick;
      // The runner-up is coded too (and the smaller file kept) only where the rough costs are
      // within kCloseCosts of each other but not equal (equal costs: the same lasers). Gaps
      // measured at 14 mm: 25-60 % on balm and 45 % on the HDL-64E re-sampled scans, where the
      // rough cost picked the smaller file; 5-8 % on a VLP-32C and a PandarXT-32 scan, where it
      // did not (the runner-up was 0.3-3 % smaller); 0.2-1.4 % on kitti00. A second coding of
      // the layer costs about 40 % more encoding.
      constexpr double kCloseCosts = 0.15;
      const double gap = std::abs(cand[other].cost - cand[pick].cost) / cand[pick].cost;
      if (std::isfinite(cand[other].cost) && gap > 1e-9 && gap < kCloseCosts) {
        // the runner-up, finished as below (lasers in elevation order, its fit)
        LaserAssignment b;
        b.ring = std::move(cand[other].ring);
        b.column = std::move(cand[other].column);
        b.table = std::move(cand[other].table);
        b.source = other == 0 ? "estimated from the points (lasers as cones, columns by azimuth)"
                              : "estimated from the points (lasers by elevation, columns by azimuth)";
        carry_motion(b);
        b.from_elevations = true;
        if (finish_assignment(input, T_cloud_sensor, b))
          a.alternative = std::make_shared<const LaserAssignment>(std::move(b));
      }
      a.ring = std::move(cand[pick].ring);
      a.column = std::move(cand[pick].column);
      a.table = std::move(cand[pick].table);
      a.source = pick == 0 ? "estimated from the points (lasers as cones, columns by azimuth)"
                           : "estimated from the points (lasers by elevation, columns by azimuth)";
      a.from_elevations = true;
    } else if (a.column.empty()) {
      a.source = "estimated from the input's lasers (columns by azimuth)";
    } else {
      a.source = "estimated from the input's lasers and columns";
    }
    if (!a.from_elevations) {
      std::vector<double> tangential;
      const bool by_azimuth = a.column.empty();
      if (by_azimuth && !estimate_columns(scan, a.ring, lasers, a.column, columns, tangential)) return std::nullopt;
      // With firing times (a driver's `time`), the columns from them where they fall on
      // firings (columns_from_times), unless the coder would find them kTimeColumnsCost
      // times as costly as the azimuths' (that rough cost leaves out the times, which the
      // firings' columns code nearly free). The shared captures written as unorganised PLY
      // with their ring and time, at 14 mm, by the azimuths' columns → by the firings':
      // VLP-16 22,999 → 21,704 bytes (the capture itself: 21,686), an HDL-32E turn 35,470 →
      // 34,888 (34,674), OS-1-32 87,864 → 87,750 (87,369), OS-2-128 378,850 → 378,736
      // (377,004); the VLP-16's rough cost was 1.08 times the azimuths'.
      std::vector<std::uint32_t> by_time;
      std::uint32_t time_columns = 0;
      // (the table of the columns kept, for the lasers and columns it was estimated with)
      std::optional<LaserTable> kept;
      const std::uint32_t compared_lasers = lasers;
      if (by_azimuth && input.has_time() && columns_from_times(scan, input.time, a.ring, lasers, by_time, time_columns)) {
        const std::vector<double> none(lasers, 0.0);
        auto azimuth_table = estimate_table(scan, a.ring, a.column, lasers, columns, tangential);
        auto time_table = estimate_table(scan, a.ring, by_time, lasers, time_columns, none);
        if (time_table && (!azimuth_table || assignment_cost(scan.p, a.ring, by_time, *time_table) <
                                                 kTimeColumnsCost * assignment_cost(scan.p, a.ring, a.column, *azimuth_table))) {
          a.column = std::move(by_time);
          columns = time_columns;
          tangential = none;
          a.source = "estimated from the input's lasers (columns by firing time)";
          kept = std::move(time_table);
        } else {
          kept = std::move(azimuth_table);
        }
      }
      const std::uint32_t compared_columns = columns;
      if (input.rows > 0 && input.has_rings()) lasers = std::max(lasers, input.rows);
      if (input.columns > 0 && input.has_columns()) columns = std::max(columns, input.columns);
      auto t = kept && lasers == compared_lasers && columns == compared_columns
                   ? std::move(kept)
                   : estimate_table(scan, a.ring, a.column, lasers, columns, tangential);
      if (!t) return std::nullopt;
      a.table = std::move(*t);
    }
    carry_motion(a);
  }
  if (!finish_assignment(input, T_cloud_sensor, a)) return std::nullopt;
  return a;
}

// ---------------------------------------------------------------------------------------
// Encoder
// ---------------------------------------------------------------------------------------

namespace {

/// A point's beam length and corrections as the encoder rounds them, and the point they
/// decode to.
struct Coded {
  std::int64_t k = 0, k1 = 0, k2 = 0;
  Eigen::Vector3f decoded;
  float rounding = 0.0F;  ///< the beam length's distance past step k, in steps (-1/2..1/2)
  double err = 0.0;       ///< the decoded point's squared distance from the input point
};

/// Rate-distortion choice of the beam lengths (formats/model.md §2.8.3). A point may take
/// the step its length rounds to or a neighbouring one that still decodes within the bound
/// (`decode_at(t, k, p)` gives point t's decoded point p with step k and its squared error,
/// which must not pass e2; with a range step of two thirds of the bound or more, as every
/// share the encoder tries gives, no step further away can). Along each laser, in coding
/// order, the steps are chosen together: those that minimise the sum of the squared errors
/// and λ times the bits of each step's change from the laser's step before it (a Viterbi
/// pass, a state for each step a point may take). The bits are −log2 of each change's share among the rounded steps' (the scan's
/// own residuals against the left neighbour, as the coder mostly predicts); λ =
/// lambda_scale · 2 ln 2 / 12 · q_r² a bit, an entropy-coded uniform quantiser's slope
/// (D = q_r² / 12 falling by 2 ln 2 · D a bit).
template <class Decode>
void choose_beam_lengths(std::vector<Coded>& q, const std::vector<std::uint32_t>& laser_at, std::uint32_t lasers,
                         double qr, double bound, double e2, double lambda_scale, const Decode& decode_at) {
  static constexpr std::int64_t kSpan = 64;  // changes beyond ±kSpan share the end bins
  const std::size_t m = q.size();
  const auto bin = [](std::int64_t r) { return static_cast<std::size_t>(std::clamp(r, -kSpan, kSpan) + kSpan); };
  std::vector<double> bits(2 * kSpan + 1, 0.5);
  {
    std::vector<std::int64_t> last(lasers, 0);
    std::vector<std::uint8_t> any(lasers, 0);
    double total = 0.5 * static_cast<double>(bits.size());
    for (std::size_t t = 0; t < m; ++t) {
      const std::uint32_t l = laser_at[t];
      if (any[l] != 0) {
        bits[bin(q[t].k - last[l])] += 1.0;
        total += 1.0;
      }
      last[l] = q[t].k;
      any[l] = 1;
    }
    for (double& b : bits) b = -std::log2(b / total);
  }
  const double lambda = lambda_scale * 2.0 * std::log(2.0) / 12.0 * qr * qr;
  // A point's steps: from q[t].k − 1 (where `below`) to q[t].k + 1 (where `above`); state x
  // is step q[t].k + x − 1. A laser's open stretch: its points since the last that had one
  // step only (all paths pass there, so what lies before it is settled), each with the best
  // state of the point before it for each of its own.
  struct Node {
    std::uint32_t t;
    std::uint8_t first, last;  // its states
    std::array<std::uint8_t, 3> back;
  };
  std::vector<std::vector<Node>> open(lasers);
  std::vector<std::array<double, 3>> cost(lasers);  // path costs to each state of the laser's last point
  // (the steps of an open stretch from state x of its last node back to its start)
  const auto settle = [&](std::vector<Node>& stretch, int x) {
    for (std::size_t i = stretch.size(); i-- > 0;) {
      const Node& nd = stretch[i];
      if (x != 1) {
        q[nd.t].k += x - 1;
        q[nd.t].err = decode_at(nd.t, q[nd.t].k, q[nd.t].decoded);
      }
      x = nd.back[x];
    }
    stretch.clear();
  };
  Eigen::Vector3f p;
  for (std::size_t t = 0; t < m; ++t) {
    const std::uint32_t l = laser_at[t];
    const Coded& c = q[t];
    std::array<double, 3> err{0.0, c.err, 0.0};
    Node nd{static_cast<std::uint32_t>(t), 1, 1, {1, 1, 1}};
    for (const int d : {-1, 1}) {
      if (std::abs(static_cast<double>(c.rounding) - d) * qr > bound) continue;
      const double e = decode_at(t, c.k + d, p);
      if (e > e2) continue;
      err[static_cast<std::size_t>(1 + d)] = e;
      (d < 0 ? nd.first : nd.last) = static_cast<std::uint8_t>(1 + d);
    }
    std::vector<Node>& stretch = open[l];
    std::array<double, 3> next{};
    for (int x = nd.first; x <= nd.last; ++x) {
      const auto xs = static_cast<std::size_t>(x);
      double best = 0.0;
      if (!stretch.empty()) {
        const Node& pn = stretch.back();
        const std::int64_t pk = q[pn.t].k;
        best = std::numeric_limits<double>::infinity();
        for (int y = pn.first; y <= pn.last; ++y) {
          const double v = cost[l][static_cast<std::size_t>(y)] + lambda * bits[bin(c.k + x - (pk + y))];
          if (v < best) {
            best = v;
            nd.back[xs] = static_cast<std::uint8_t>(y);
          }
        }
      }
      next[xs] = best + err[xs];
    }
    cost[l] = next;
    if (nd.first == nd.last && !stretch.empty()) settle(stretch, nd.back[1]);
    stretch.push_back(nd);
  }
  for (std::uint32_t l = 0; l < lasers; ++l) {
    std::vector<Node>& stretch = open[l];
    if (stretch.empty()) continue;
    int x = stretch.back().first;
    for (int y = x + 1; y <= stretch.back().last; ++y)
      if (cost[l][static_cast<std::size_t>(y)] < cost[l][static_cast<std::size_t>(x)]) x = y;
    settle(stretch, x);
  }
}

std::optional<LaserLayer> code_laser(const RangeEncoder& head, const std::vector<Eigen::Vector3f>& input,
                                     const std::vector<std::uint32_t>& coded, const LaserAssignment& a,
                                     const Beams& beams, const std::vector<std::uint32_t>& order,
                                     const std::vector<std::int64_t>& shift, const std::vector<Beams::Trig>& beam_of,
                                     const std::vector<Eigen::Vector3d>& offset, double max_error, double bound,
                                     bool thin, double share, double lambda_scale,
                                     const std::vector<std::uint32_t>& predictors,
                                     int threads, const std::vector<std::uint32_t>* js = nullptr,
                                     std::vector<std::size_t>* sizes = nullptr) {
  // The points coded: positions `js` in `order` (a trial on some columns), else all of them.
  const std::size_t m = js ? js->size() : order.size();
  const auto J = [js](std::size_t t) -> std::size_t { return js ? (*js)[t] : t; };
  const double qr = 2.0 * share * bound;
  const double qt = std::sqrt(std::max(0.0, 2.0 * (1.0 - share * share))) * bound * 0.99;
  if (!(qt > 0.0)) return std::nullopt;
  const double e2 = bound * bound;

  std::vector<Coded> q(m);  // by position t among the points coded (J(t) in `order`)
  std::vector<std::uint8_t> failed(m, 0);
  parallel_for(m, threads, [&](std::size_t t) {
    const std::size_t j = J(t);
    const std::uint32_t i = coded[order[j]];
    const Eigen::Vector3d truth = input[i].cast<double>();
    const Beams::Beam b = beams.beam(a.ring[i], beam_of[j]);
    const Eigen::Vector3d& v = offset[j];
    Coded& c = q[t];
    const double along = v.dot(b.u);
    if (!quantise(along, qr, c.k)) {
      failed[t] = 1;
      return;
    }
    c.rounding = static_cast<float>(along / qr - static_cast<double>(c.k));
    c.decoded = beams.point(b, c.k, 0, 0, qr, qt);
    c.err = (c.decoded.cast<double>() - truth).squaredNorm();
    if (c.err <= e2) return;
    if (!quantise(v.dot(b.e1), qt, c.k1) || !quantise(v.dot(b.e2), qt, c.k2)) {
      failed[t] = 1;
      return;
    }
    c.decoded = beams.point(b, c.k, c.k1, c.k2, qr, qt);
    c.err = (c.decoded.cast<double>() - truth).squaredNorm();
    if (c.err <= e2) return;
    // rounding at the edge of the bound: the neighbouring steps
    const Coded base = c;
    bool found = false;
    for (int dk = -1; dk <= 1 && !found; ++dk)
      for (int d1 = -1; d1 <= 1 && !found; ++d1)
        for (int d2 = -1; d2 <= 1 && !found; ++d2) {
          const Eigen::Vector3f d = beams.point(b, base.k + dk, base.k1 + d1, base.k2 + d2, qr, qt);
          const double err = (d.cast<double>() - truth).squaredNorm();
          if (err <= e2) {
            c = {base.k + dk, base.k1 + d1, base.k2 + d2, d, 0.0F, err};
            found = true;
          }
        }
    if (!found) failed[t] = 1;
  }, 4096);
  if (std::any_of(failed.begin(), failed.end(), [](std::uint8_t f) { return f != 0; })) return std::nullopt;

  // Rate-distortion choice of the beam lengths (choose_beam_lengths): each point may take
  // any step that keeps it within the bound; each laser's steps are chosen together.
  {
    std::vector<std::uint32_t> laser_at(m);
    for (std::size_t t = 0; t < m; ++t) laser_at[t] = a.ring[coded[order[J(t)]]];
    const auto decode_at = [&](std::size_t t, std::int64_t k, Eigen::Vector3f& p) {
      const std::size_t j = J(t);
      const std::uint32_t i = coded[order[j]];
      p = beams.point(beams.beam(laser_at[t], beam_of[j]), k, q[t].k1, q[t].k2, qr, qt);
      return (p.cast<double>() - input[i].cast<double>()).squaredNorm();
    };
    choose_beam_lengths(q, laser_at, a.table.lasers(), qr, bound, e2, lambda_scale, decode_at);
  }

  // Thinning (with `thin`): a point that a point decoded before it explains is not coded
  // where coding it would cost more than its neighbours (laser_layer): it needs a
  // correction across its beam, it is its laser's first, or its beam length lies more than
  // kEdgeSteps from its laser's last coded point's.
  std::vector<std::uint32_t> kept(m);  // positions t
  std::iota(kept.begin(), kept.end(), 0U);
  if (thin) {
    PointBallGrid seen(bound, m);
    std::vector<std::int64_t> last_k(a.table.lasers(), 0);
    std::vector<std::uint8_t> any(a.table.lasers(), 0);
    kept.clear();
    for (std::uint32_t t = 0; t < m; ++t) {
      const std::uint32_t i = coded[order[J(t)]];
      const std::uint32_t l = a.ring[i];
      const Coded& c = q[t];
      const bool costly = c.k1 != 0 || c.k2 != 0 || any[l] == 0 || std::abs(c.k - last_k[l]) > kEdgeSteps;
      if (costly && seen.any_within(input[i].cast<double>())) continue;
      seen.insert(c.decoded);
      kept.push_back(t);
      last_k[l] = c.k;
      any[l] = 1;
    }
  }

  // The kept points' lasers and columns side by side, read by every predictor's pass.
  std::vector<std::uint16_t> kept_ring(kept.size());
  std::vector<std::uint32_t> kept_column(kept.size());
  for (std::size_t k = 0; k < kept.size(); ++k) {
    const std::uint32_t i = coded[order[J(kept[k])]];
    kept_ring[k] = a.ring[i];
    kept_column[k] = a.column[i];
  }
  // The table's fields each against its own predictor where that codes the table smaller
  // (format 1.11): the same for every range predictor.
  bool table_predictors = false;
  {
    LaserTable picked = a.table;
    picked.table_predictors = true;
    table_predictors = table_bytes(picked) < table_bytes(a.table);
  }
  // T_sensor_head is stored only where it is not the identity (format 1.11).
  const bool head_pose = !a.table.T_sensor_head.matrix().isIdentity(0.0);
  // The stream, once for each predictor (side by side); the smallest is kept.
  std::vector<std::optional<LaserLayer>> streams(predictors.size());
  parallel_for(predictors.size(), threads, [&](std::size_t pi) {
    const std::uint32_t predictor = predictors[pi];
    LaserTable table = a.table;
    table.predictor = predictor;
    table.shift_unit = beams.shift_unit;
    table.table_predictors = table_predictors;
    table.quick_models = predictor >= 4;
    LaserLayer out;
    out.head_pose = head_pose;
    out.range_step = qr;
    out.coded = kept.size();
    out.sources.resize(kept.size());
    for (std::size_t k = 0; k < kept.size(); ++k) out.sources[k] = coded[order[J(kept[k])]];
    RangeEncoder enc = head;
    const auto ring_at = [&](std::size_t k) { return kept_ring[k]; };
    const auto column_at = [&](std::size_t k) { return kept_column[k]; };
    put_table(enc, table);
    // Predictors 2 and 3: whether any point has a correction and whether any pixel holds
    // more than one point; without them those symbols are not coded.
    bool any_correction = true, any_more = true;
    if (predictor >= 2) {
      any_correction = any_more = false;
      for (std::size_t k = 0; k < kept.size(); ++k) {
        const Coded& c = q[kept[k]];
        any_correction = any_correction || c.k1 != 0 || c.k2 != 0;
        any_more = any_more || (k + 1 < kept.size() && ring_at(k + 1) == ring_at(k) && column_at(k + 1) == column_at(k));
      }
      BitModel flag;
      enc.put(flag, any_correction);
      enc.put(flag, any_more);
    }
    PointCoder pc(table.lasers(), qr * (kTwoPi / static_cast<double>(table.columns)) / max_error, table.predictor,
                  table.quick_models);
    std::size_t at = 0;
    std::int64_t prev_column = -1;
    std::uint64_t remaining = kept.size();
    while (at < kept.size()) {
      const std::uint32_t column = column_at(at);
      std::size_t end = at;
      while (end < kept.size() && column_at(end) == column) ++end;
      const std::int64_t dc = static_cast<std::int64_t>(column) - prev_column - 1;
      pc.column_delta.put(enc, pc.column_ctx(), dc);
      const std::int64_t s = shift[J(kept[at])];
      pc.column_shift.put(enc, pc.shift_ctx(), s - pc.last_shift());
      pc.set_shift(s);
      pc.start_column(column, dc);
      std::size_t j = at;
      for (std::uint32_t l = 0; l < table.lasers() && remaining > 0; ++l) {
        const bool occ = j < end && ring_at(j) == l;
        pc.put_occupancy(enc, l, occ);
        if (!occ) continue;
        pc.occupied(l);
        for (;;) {
          const Coded& c = q[kept[j]];
          const auto pred = pc.predict(l);
          std::int64_t pk = pred.k;
          if (pred.edge) {
            // the neighbour whose residual and flag together cost fewer bits (estimated)
            const double p0 = static_cast<double>(pc.edge[pred.flag_ctx].p0) / kProbOne;
            const bool upper =
                residual_bits(c.k - pred.alt) - std::log2(1.0 - p0) < residual_bits(c.k - pred.k) - std::log2(p0);
            enc.put(pc.edge[pred.flag_ctx], upper);
            if (upper) pk = pred.alt;
            pc.picked(l, upper ? 2 : 1);
          } else {
            pc.picked(l, 0);
          }
          const std::int64_t res = c.k - pk;
          pc.put_residual(enc, l, pred, pk, res);
          if (any_correction) {
            pc.tangential1.put(enc, pc.k1_ctx(l), c.k1);
            pc.tangential2.put(enc, pc.k2_ctx(l, c.k1), c.k2);
          }
          pc.update(l, c.k, res, c.k1, c.k2);
          ++j;
          --remaining;
          if (remaining == 0) break;
          const bool more = j < end && ring_at(j) == l;
          if (any_more) enc.put(pc.more[0], more);
          if (!more) break;
        }
      }
      prev_column = column;
      at = end;
    }
    out.stream = enc.finish();

    codec::bytes::put_f64(out.fields, qt);
    codec::bytes::put_f64(out.fields, table.shift_unit);
    codec::bytes::put_u32(out.fields, table.lasers());
    codec::bytes::put_u32(out.fields, table.columns);
    codec::bytes::put_u32(out.fields, static_cast<std::uint32_t>(table.direction));
    codec::bytes::put_u32(out.fields, table.predictor | (table.table_predictors ? kTablePredictorsBit : 0U) |
                                          (table.has_motion() ? kMotionBit : 0U) |
                                          (table.quick_models ? kQuickModelsBit : 0U));
    codec::bytes::put_f64(out.fields, table.azimuth0);
    if (head_pose) {
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) codec::bytes::put_f64(out.fields, table.T_sensor_head.linear()(r, c));
      for (int r = 0; r < 3; ++r) codec::bytes::put_f64(out.fields, table.T_sensor_head.translation()(r));
    }
    streams[pi] = std::move(out);
  }, 1);
  if (sizes)
    for (const auto& o : streams) sizes->push_back(o ? o->stream.size() : std::numeric_limits<std::size_t>::max());
  std::optional<LaserLayer> best;
  for (auto& o : streams)
    if (o && (!best || o->stream.size() < best->stream.size())) best = std::move(o);
  if (best) {
    best->laser_of = std::move(kept_ring);
    best->column_of = std::move(kept_column);
    best->lasers = a.table.lasers();
    best->columns = a.table.columns;
  }
  return best;
}

/// The positions in `coded` column by column, lasers in order, then input order: a counting
/// sort over the pixels where `coded` ascends and every laser and column is in the table
/// (as the assignment makes them), else a comparison sort to the same order.
std::vector<std::uint32_t> pixel_order(const std::vector<std::uint32_t>& coded, const LaserAssignment& a) {
  const std::size_t n = coded.size();
  const std::uint64_t lasers = a.table.lasers(), columns = a.table.columns;
  const std::uint64_t pixels = lasers * columns;
  bool counting = counting_pays(pixels, n);
  for (std::size_t k = 0; k < n && counting; ++k) {
    const std::uint32_t i = coded[k];
    counting = (k == 0 || coded[k - 1] < i) && a.ring[i] < lasers && a.column[i] < columns;
  }
  if (!counting) {
    std::vector<std::uint32_t> order(n);
    std::iota(order.begin(), order.end(), 0U);
    std::sort(order.begin(), order.end(), [&](std::uint32_t x, std::uint32_t y) {
      const std::uint32_t ix = coded[x], iy = coded[y];
      if (a.column[ix] != a.column[iy]) return a.column[ix] < a.column[iy];
      if (a.ring[ix] != a.ring[iy]) return a.ring[ix] < a.ring[iy];
      return ix < iy;
    });
    return order;
  }
  return counting_order(n, static_cast<std::size_t>(pixels), [&](std::size_t k) {
    const std::uint32_t i = coded[k];
    return static_cast<std::size_t>(a.column[i]) * lasers + a.ring[i];
  });
}

}  // namespace

namespace {

/// One laser assignment made ready to code: its beams, the pixel order, each column's
/// azimuth shift and every point's beam and offset from the beam's origin.
struct Prepared {
  const LaserAssignment* a = nullptr;
  Beams beams;
  std::vector<std::uint32_t> order;
  std::vector<std::int64_t> shift;
  std::vector<Beams::Trig> beam_of;
  std::vector<Eigen::Vector3d> offset;
  Prepared(const LaserAssignment& assignment, const Pose& T_cloud_sensor)
      : a(&assignment), beams(assignment.table, T_cloud_sensor) {}
};

/// Reorders the points of each pixel in `order` (pixel_order's) along the scan: by their
/// azimuth in the grid's direction, then range, then input order, so that the file does not
/// depend on the order of the input's points (kitti00/000000 at 14 mm: 77,902 bytes in its
/// own order, 79,897 shuffled and 81,718 reversed when a pixel's points kept the input
/// order; now 77,970, 77,769 and 77,915). Not where more than kSharedPixels of the points
/// share a pixel with the point before: there the table is coarse for the points (an indoor
/// scanner's room, 70 %) and the input order, a scanner's sweep, codes smaller (room_scan2
/// at 5 mm: 45,378 bytes against 53,148 along the azimuth).
void order_pixels_along_scan(const std::vector<Eigen::Vector3f>& input, const std::vector<std::uint32_t>& coded,
                             const LaserAssignment& a, const Pose& T_head_cloud, std::vector<std::uint32_t>& order) {
  const auto same_pixel = [&](std::size_t x, std::size_t y) {
    const std::uint32_t i = coded[order[x]], k = coded[order[y]];
    return a.column[i] == a.column[k] && a.ring[i] == a.ring[k];
  };
  std::size_t shared = 0;
  for (std::size_t at = 0; at + 1 < order.size(); ++at) shared += same_pixel(at, at + 1) ? 1 : 0;
  if (static_cast<double>(shared) > kSharedPixels * static_cast<double>(order.size())) return;
  struct Key {
    double along, range;
    std::uint32_t k;
  };
  std::vector<Key> run;
  for (std::size_t at = 0; at < order.size();) {
    std::size_t end = at + 1;
    while (end < order.size() && same_pixel(at, end)) ++end;
    if (end - at > 1) {
      run.clear();
      const Eigen::Vector3d p0 = T_head_cloud * input[coded[order[at]]].cast<double>();
      const double az0 = fast_atan2(p0.y(), p0.x());
      for (std::size_t j = at; j < end; ++j) {
        const Eigen::Vector3d p = T_head_cloud * input[coded[order[j]]].cast<double>();
        const double along = static_cast<double>(a.table.direction) * wrap_angle(fast_atan2(p.y(), p.x()) - az0);
        run.push_back({std::isfinite(along) ? along : 0.0, p.allFinite() ? p.norm() : 0.0, order[j]});
      }
      std::sort(run.begin(), run.end(), [](const Key& x, const Key& y) {
        if (x.along != y.along) return x.along < y.along;
        if (x.range != y.range) return x.range < y.range;
        return x.k < y.k;
      });
      for (std::size_t j = at; j < end; ++j) order[j] = run[j - at].k;
    }
    at = end;
  }
}

std::unique_ptr<Prepared> prepare_layer(const std::vector<Eigen::Vector3f>& input, const std::vector<std::uint32_t>& coded,
                                        const LaserAssignment& a, const Pose& T_cloud_sensor, double bound, int threads) {
  const LaserTable& table = a.table;
  if (!storable(table)) return nullptr;
  auto prepared = std::make_unique<Prepared>(a, T_cloud_sensor);
  const Beams& beams = prepared->beams;
  const Pose T_head_cloud = beams.T_cloud_head.inverse();

  // Column by column, lasers in order (several points of one pixel along the scan).
  std::vector<std::uint32_t>& order = prepared->order;
  order = pixel_order(coded, a);
  order_pixels_along_scan(input, coded, a, T_head_cloud, order);
  // Each column's azimuth shift: the median of its points' azimuths off their beams (a
  // sensor whose firings do not fall on an even grid), in the table's shift units.
  // Every point's beam (its azimuths' cosines and sines) and its offset from the beam's
  // origin (head frame), first unshifted: a column whose shift comes out 0 keeps them.
  std::vector<std::int64_t>& shift = prepared->shift;  // by position in `order`
  std::vector<Beams::Trig>& beam_of = prepared->beam_of;
  std::vector<Eigen::Vector3d>& offset = prepared->offset;
  shift.assign(coded.size(), 0);
  beam_of.resize(order.size());
  offset.resize(order.size());
  // (a column's azimuth, shared by its lasers: one sine and cosine a column)
  const std::vector<Beams::ColumnTrig> unshifted = beams.column_trigs(table.columns);
  parallel_for(order.size(), threads, [&](std::size_t j) {
    const std::uint32_t i = coded[order[j]];
    beam_of[j] = beams.trig(a.ring[i], unshifted[a.column[i]]);
    offset[j] = T_head_cloud * input[i].cast<double>() - beams.beam(a.ring[i], beam_of[j]).o;
  }, 4096);
  if (table.shift_unit > 0.0 && !order.empty()) {
    // The shift unit: an azimuth step whose rounding moves a point at the layer's RMS
    // horizontal distance by kShiftRounding E (a finer unit costs bits a column and barely
    // changes the error).
    double sum = 0.0;
    for (const Eigen::Vector3d& v : offset) sum += v.x() * v.x() + v.y() * v.y();
    const double rms = std::sqrt(sum / static_cast<double>(offset.size()));
    const double step = kTwoPi / static_cast<double>(table.columns);
    prepared->beams.shift_unit =
        std::clamp(rms > 0.0 ? kShiftRounding * bound / rms : step / 2.0, step / 256.0, std::min(step / 2.0, kPi / 64.0));
    std::vector<double> off;
    std::int64_t last = 0;
    for (std::size_t at = 0; at < order.size();) {
      const std::uint32_t column = a.column[coded[order[at]]];
      std::size_t end = at;
      off.clear();
      // (a point's azimuth off its beam's unshifted direction, whose cosine and sine its
      // Trig holds: the angle of the offset turned back by the beam's azimuth)
      for (; end < order.size() && a.column[coded[order[end]]] == column; ++end) {
        const Eigen::Vector3d& v = offset[end];
        if (v.x() * v.x() + v.y() * v.y() < 1.0) continue;
        const Beams::Trig& b = beam_of[end];
        off.push_back(fast_atan2(b.cb * v.y() - b.sb * v.x(), b.cb * v.x() + b.sb * v.y()));
      }
      std::int64_t s = last;
      if (!off.empty()) {
        std::nth_element(off.begin(), off.begin() + static_cast<std::ptrdiff_t>(off.size() / 2), off.end());
        s = static_cast<std::int64_t>(std::llround(off[off.size() / 2] / beams.shift_unit));
      }
      for (std::size_t k = at; k < end; ++k) shift[k] = s;
      last = s;
      at = end;
    }
    // (each shifted column's azimuth once, at its first point in `order`)
    std::vector<Beams::ColumnTrig> shifted(order.size());
    for (std::size_t j = 0; j < order.size(); ++j) {
      if (shift[j] == 0) continue;
      const bool first = j == 0 || a.column[coded[order[j - 1]]] != a.column[coded[order[j]]];
      shifted[j] = first ? beams.column_trig(a.column[coded[order[j]]], shift[j]) : shifted[j - 1];
    }
    parallel_for(order.size(), threads, [&](std::size_t j) {
      if (shift[j] == 0) return;
      const std::uint32_t i = coded[order[j]];
      beam_of[j] = beams.trig(a.ring[i], shifted[j]);
      offset[j] = T_head_cloud * input[i].cast<double>() - beams.beam(a.ring[i], beam_of[j]).o;
    }, 4096);
  }
  return prepared;
}

}  // namespace

std::optional<LaserLayer> laser_layer(const RangeEncoder& head, const std::vector<Eigen::Vector3f>& input,
                                      const std::vector<std::uint32_t>& coded,
                                      const std::vector<const LaserAssignment*>& candidates, const Pose& T_cloud_sensor,
                                      double max_error, double bound, bool thin, const std::vector<double>& shares,
                                      double lambda_scale, int threads, std::size_t* chosen, bool fast) {
  std::vector<std::unique_ptr<Prepared>> prepared;
  for (const LaserAssignment* a : candidates) prepared.push_back(prepare_layer(input, coded, *a, T_cloud_sensor, bound, threads));
  const auto code = [&](const Prepared& p, double share, std::vector<std::uint32_t> predictors, int inner,
                        const std::vector<std::uint32_t>* js = nullptr, std::vector<std::size_t>* sizes = nullptr) {
    return code_laser(head, input, coded, *p.a, p.beams, p.order, p.shift, p.beam_of, p.offset, max_error, bound, thin,
                      share, lambda_scale, predictors, inner, js, sizes);
  };
  // Each share with predictor 5 (left neighbour, a flag at edges), the first also with
  // predictor 4 (median edge detector, a flag at edges), both with mixed contexts: at 14 mm
  // the median edge detector coded the OS-2-128 scan 8 % and the OS-1-32 scan 4 % smaller
  // than the left neighbour, the OS-0-128, OS-0-32, HDL-32E and VLP-16 scans 1-6 % larger.
  // Predictors 0-3 are still decoded; 2 or 3 coded each of these scans and a KITTI and
  // balm scan smaller than 0 or 1, and 4 or 5 (the same with mixed contexts) 2-7 %
  // smaller than 2 or 3.
  const auto predictors_of = [](std::size_t share) {
    return share == 0 ? std::vector<std::uint32_t>{4, 5} : std::vector<std::uint32_t>{5};
  };
  // A large layer makes the choice of candidate assignment, share and predictor on a
  // quarter of the turn (every fourth of 32 column blocks; every eighth `fast`): each is coded there, and only
  // the one with the fewest bits a sampled point is coded in full. A small layer codes
  // every share of every candidate with each of its predictors in full (the shares side
  // by side, one thread each).
  if (coded.size() >= kLaserTrialMinPoints) {
    struct Pick {
      double bits = std::numeric_limits<double>::infinity();
      std::size_t candidate = 0, share = 0;
      std::uint32_t predictor = 0;
    } pick;
    for (std::size_t c = 0; c < prepared.size(); ++c) {
      if (!prepared[c] || prepared[c]->a->table.columns < 32) continue;
      const Prepared& p = *prepared[c];
      std::vector<std::uint32_t> js;  // positions in `order` of the trial's columns
      const std::uint32_t block = p.a->table.columns / 32;
      for (std::size_t j = 0; j < p.order.size(); ++j)
        if ((p.a->column[coded[p.order[j]]] / block) % (fast ? 8 : 4) == 0) js.push_back(static_cast<std::uint32_t>(j));
      if (js.empty()) continue;
      std::vector<std::vector<std::size_t>> bytes(shares.size());
      parallel_for(shares.size(), threads, [&](std::size_t t) {
        (void)code(p, shares[t], predictors_of(t), shares.size() > 1 ? 1 : threads, &js, &bytes[t]);
      }, 1);
      for (std::size_t t = 0; t < shares.size(); ++t)
        for (std::size_t k = 0; k < bytes[t].size(); ++k) {
          if (bytes[t][k] == std::numeric_limits<std::size_t>::max()) continue;
          const double bits = 8.0 * static_cast<double>(bytes[t][k]) / static_cast<double>(js.size());
          if (bits < pick.bits) pick = {bits, c, t, predictors_of(t)[k]};
        }
    }
    if (std::isfinite(pick.bits)) {
      auto best = code(*prepared[pick.candidate], shares[pick.share], {pick.predictor}, threads);
      if (best) {
        if (chosen) *chosen = pick.candidate;
        return best;
      }
    }
    // (no sample coded, or the whole turn did not: a point beyond what a share can code)
  }
  std::optional<LaserLayer> best;
  for (std::size_t c = 0; c < prepared.size(); ++c) {
    if (!prepared[c]) continue;
    std::vector<std::optional<LaserLayer>> tries(shares.size());
    const int inner = shares.size() > 1 ? 1 : threads;
    parallel_for(tries.size(), threads, [&](std::size_t t) {
      tries[t] = code(*prepared[c], shares[t], predictors_of(t), inner);
    }, 1);
    for (auto& t : tries)
      if (t && (!best || t->stream.size() < best->stream.size())) {
        best = std::move(t);
        if (chosen) *chosen = c;
      }
  }
  return best;
}

// ---------------------------------------------------------------------------------------
// Decoder
// ---------------------------------------------------------------------------------------

std::optional<LaserDecodeError> read_laser_fields(const std::uint8_t* f, std::uint64_t size, double max_error,
                                                  LaserTable& table, double& tangential_step, bool head_pose) {
  if (size < (head_pose ? kLaserFieldBytes : kLaserShortFieldBytes))
    return LaserDecodeError{"sensor-geometry layer fields are truncated", 0};
  tangential_step = codec::bytes::ld_f64(f);
  if (!(tangential_step > 0.0 && tangential_step <= 2.0 * max_error))
    return LaserDecodeError{"cross step " + std::to_string(tangential_step) + " is not in (0, 2*max_error]", 0};
  table.shift_unit = codec::bytes::ld_f64(f + 8);
  if (!(table.shift_unit >= 0.0 && table.shift_unit <= kPi / 64.0))
    return LaserDecodeError{"azimuth shift unit " + std::to_string(table.shift_unit) + " is not in [0, pi/64]", 8};
  const std::uint32_t lasers = codec::bytes::ld_u32(f + 16);
  table.columns = codec::bytes::ld_u32(f + 20);
  const std::uint32_t dir = codec::bytes::ld_u32(f + 24);
  const std::uint32_t predictor_field = codec::bytes::ld_u32(f + 28);
  table.predictor = predictor_field & 0xFFU;
  table.table_predictors = (predictor_field & kTablePredictorsBit) != 0;
  table.motion_coded = (predictor_field & kMotionBit) != 0;
  table.quick_models = (predictor_field & kQuickModelsBit) != 0;
  if ((predictor_field & ~(0xFFU | kTablePredictorsBit | kMotionBit | kQuickModelsBit)) != 0)
    return LaserDecodeError{"predictor field " + std::to_string(predictor_field) + " has reserved bits set", 28};
  table.azimuth0 = codec::bytes::ld_f64(f + 32);
  if (lasers < 1 || lasers > kMaxLasers)
    return LaserDecodeError{"laser count " + std::to_string(lasers) + " is not in [1, 1024]", 16};
  if (table.columns < 1 || table.columns > kMaxLaserColumns)
    return LaserDecodeError{"column count " + std::to_string(table.columns) + " is not in [1, 2^20]", 20};
  if (dir != 1U && dir != 0xFFFFFFFFU) return LaserDecodeError{"column direction is neither +1 nor -1", 24};
  table.direction = dir == 1U ? 1 : -1;
  if (table.predictor > 5) return LaserDecodeError{"range predictor " + std::to_string(table.predictor) + " is not in 0..5", 28};
  if (table.quick_models && table.predictor < 4)
    return LaserDecodeError{"quick models (bit 10 of the predictor field) with range predictor " +
                                std::to_string(table.predictor) + ", which has no mixed models",
                            28};
  if (!(std::isfinite(table.azimuth0) && std::abs(table.azimuth0) <= kTwoPi))
    return LaserDecodeError{"azimuth of column 0 is not in [-2pi, 2pi]", 32};
  table.T_sensor_head = Pose::Identity();
  for (auto* field : table_fields(table)) field->assign(lasers, 0);
  if (!head_pose) return std::nullopt;
  Eigen::Matrix3d R;
  Eigen::Vector3d t;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) R(r, c) = codec::bytes::ld_f64(f + 40 + 8 * (3 * r + c));
  for (int r = 0; r < 3; ++r) t[r] = codec::bytes::ld_f64(f + 112 + 8 * r);
  if (!R.allFinite() || !t.allFinite() || (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() > 1e-6 ||
      !(R.determinant() > 0.0) || !(t.cwiseAbs().maxCoeff() <= 1e3))
    return LaserDecodeError{"T_sensor_head is not a rigid transform within 1 km", 40};
  table.T_sensor_head.linear() = R;
  table.T_sensor_head.translation() = t;
  return std::nullopt;
}

std::optional<LaserDecodeError> decode_laser_points(RangeDecoder& dec, LaserTable& table, double max_error, double qr,
                                                    double qt, std::uint64_t coded_points, const Pose& T_cloud_sensor,
                                                    std::vector<Eigen::Vector3f>& out, LayerKeys* keys) {
  {
    IntModel m{IntModel::kClasses};
    BitModel pick[2];
    const std::array<std::int64_t, 5> bounds = {kMaxAngleUnits, kMaxAngleUnits, kMaxAngleUnits, kMaxLengthUnits,
                                                kMaxLengthUnits};
    std::size_t f_index = 0;
    for (auto* f : table_fields(table)) {
      int kind = 0;
      if (table.table_predictors && dec.get(pick[0])) kind = dec.get(pick[1]) ? 2 : 1;
      std::int64_t prev_d = 0;
      for (std::size_t i = 0; i < f->size(); ++i) {
        const std::int64_t d = m.get(dec, IntModel::context_of(prev_d));
        // (values within bounds: the prediction, at most 3 of them, cannot overflow)
        const std::int64_t v = table_prediction(*f, i, kind) + d;
        if (v < -bounds[f_index] || v > bounds[f_index])
          return LaserDecodeError{"laser table value out of range", 0};
        (*f)[i] = v;
        prev_d = d;
      }
      ++f_index;
    }
    if (table.motion_coded) {
      const std::int64_t cut = m.get(dec, 0);
      if (cut < 0 || cut >= static_cast<std::int64_t>(table.columns))
        return LaserDecodeError{"motion's first column " + std::to_string(cut) + " is outside the grid", 0};
      table.motion_cut = static_cast<std::uint32_t>(cut);
      for (std::int64_t& v : table.motion) {
        v = m.get(dec, 0);
        if (std::abs(v) > kMaxLengthUnits) return LaserDecodeError{"motion over a turn beyond 64 m", 0};
      }
    }
  }
  const Beams beams(table, T_cloud_sensor);
  PointCoder pc(table.lasers(), qr * (kTwoPi / static_cast<double>(table.columns)) / max_error, table.predictor,
                table.quick_models);
  bool any_correction = true, any_more = true;
  if (table.predictor >= 2) {
    BitModel flag;
    any_correction = dec.get(flag);
    any_more = dec.get(flag);
  }
  std::uint64_t remaining = coded_points;
  std::int64_t prev_column = -1;
  while (remaining > 0) {
    if (dec.overrun() > 8) return LaserDecodeError{"stream ends early", 0};
    const std::int64_t dc = pc.column_delta.get(dec, pc.column_ctx());
    const std::int64_t column = prev_column + 1 + dc;
    if (dc < 0 || column >= static_cast<std::int64_t>(table.columns))
      return LaserDecodeError{"column " + std::to_string(column) + " is outside the grid of " +
                                  std::to_string(table.columns),
                              0};
    const auto c = static_cast<std::uint32_t>(column);
    const std::int64_t shift = pc.last_shift() + pc.column_shift.get(dec, pc.shift_ctx());
    if (std::abs(shift) > static_cast<std::int64_t>(kMaxSteps))
      return LaserDecodeError{"column azimuth shift beyond 2^30 units", 0};
    pc.set_shift(shift);
    pc.start_column(c, dc);
    const Beams::ColumnTrig column_trig = beams.column_trig(c, shift);
    for (std::uint32_t l = 0; l < table.lasers() && remaining > 0; ++l) {
      if (!pc.get_occupancy(dec, l)) continue;
      pc.occupied(l);
      const auto b = beams.beam(l, beams.trig(l, column_trig));
      for (;;) {
        const auto pred = pc.predict(l);
        std::int64_t pk = pred.k;
        if (pred.edge) {
          const bool upper = dec.get(pc.edge[pred.flag_ctx]);
          if (upper) pk = pred.alt;
          pc.picked(l, upper ? 2 : 1);
        } else {
          pc.picked(l, 0);
        }
        const std::int64_t res = pc.get_residual(dec, l, pred, pk);
        const std::int64_t k1 = any_correction ? pc.tangential1.get(dec, pc.k1_ctx(l)) : 0;
        const std::int64_t k2 = any_correction ? pc.tangential2.get(dec, pc.k2_ctx(l, k1)) : 0;
        const std::int64_t k = pk + res;
        if (std::abs(k) > static_cast<std::int64_t>(kMaxSteps) || std::abs(k1) > static_cast<std::int64_t>(kMaxSteps) ||
            std::abs(k2) > static_cast<std::int64_t>(kMaxSteps))
          return LaserDecodeError{"point " + std::to_string(out.size()) + " lies beyond 2^30 steps", 0};
        const Eigen::Vector3f p = beams.point(b, k, k1, k2, qr, qt);
        if (!p.allFinite()) return LaserDecodeError{"point decodes to a non-finite position", 0};
        out.push_back(p);
        if (keys) {
          keys->laser.push_back(static_cast<std::uint16_t>(l));
          keys->column.push_back(c);
        }
        pc.update(l, k, res, k1, k2);
        --remaining;
        if (remaining == 0 || !any_more || !dec.get(pc.more[0])) break;
      }
    }
    prev_column = column;
  }
  if (dec.overrun() > 8) return LaserDecodeError{"stream ends " + std::to_string(dec.overrun()) + " bytes early", 0};
  return std::nullopt;
}

}  // namespace lex3d::residual::detail
