// Acquisition-order coding of a residual layer (formats/model.md §2.11).

#include "residual/acquisition.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "lex3d/core/parallel.hpp"
#include "residual/point_ball_grid.hpp"

namespace lex3d::residual::detail {
namespace {

using Cell = std::array<std::int64_t, 3>;

constexpr int kKinds = 4;
/// Predictions are clamped to ±2^31 cells, so that a residual fits IntModel (±(2^32 − 1)).
constexpr std::int64_t kMaxPrediction = std::int64_t{1} << 31;
/// Residuals enter the beam-slope sums clamped to ±4095 cells.
constexpr std::int64_t kSlopeClamp = 4095;
/// The beam slope is a fixed-point number of 16 fraction bits, at most ±2^20 (±16).
constexpr int kSlopeBits = 16;
constexpr std::int64_t kMaxSlope = std::int64_t{1} << 20;

std::int64_t clamp(std::int64_t v, std::int64_t limit) { return std::min(std::max(v, -limit), limit); }

/// s less s/256 rounded toward zero: the sums forget a pulse's share in about 256 pulses.
std::int64_t decay(std::int64_t s) { return s >= 0 ? s - (s >> 8) : s + ((-s) >> 8); }


/// Pulses the step to the next pulse is averaged over (formats/model.md §2.11.1): the
/// step between two consecutive pulses carries the quantisation of both, over four the
/// quarter of it. Measured on Autzen: 5.6 % fewer bits than the last step alone at
/// 1.6 cm cells, 5.4 % at 20 cm (eight pulses: the same; sixteen: 3 %).
constexpr int kStepPulses = 4;

/// The line fit (§2.11.1, format 1.13): offsets entering it are clamped to ±2^20 cells,
/// its sums to ±2^30 and its moments to ±2^40, so that its products fit signed 64-bit
/// integers with up to kMaxFitPulses pulses each up to 17 pulse numbers apart.
constexpr std::int64_t kFitClamp = std::int64_t{1} << 20;
constexpr std::int64_t kFitSumClamp = std::int64_t{1} << 30;
constexpr std::int64_t kFitMomentClamp = std::int64_t{1} << 40;
/// Pulses the state holds: the most a line fit takes.
constexpr int kHeldPulses = static_cast<int>(kMaxFitPulses);
/// Points in a block of the line fits' trial (a quarter of the blocks are coded).
constexpr std::size_t kFitTrialBlock = 4096;

/// What encoder and decoder both keep (§2.11.2): the last point, the last two pulses, the
/// kinds of the last two points, the classes of the last residuals and the beam's slope.
class AcquisitionState {
 public:
  /// `fit_pulses`: 0 for format 1.12's prediction, else the pulses of the line fit (§2.11.1).
  explicit AcquisitionState(std::uint32_t fit_pulses)
      : z_(kKinds * 8), x_(kKinds * 64), y_(kKinds * 64), gap_(1), fit_(static_cast<int>(fit_pulses)) {}

  [[nodiscard]] Cell predict(PulseKind kind, std::uint32_t skipped) const {
    Cell p = last_;
    if (kind == PulseKind::kNextPulse || kind == PulseKind::kSkipped) {
      // The last pulse plus the mean step a pulse over up to kStepPulses pulses before it.
      const int back = std::max(0, std::min(held_ - 1, kStepPulses));
      const std::int64_t ahead = static_cast<std::int64_t>(skipped) + 1;
      for (int a = fit_ > 0 ? 2 : 0; a < 3; ++a) {  // (with a fit, x and y are the fit's)
        const std::int64_t from = pulses_[0][a];
        p[a] = back == 0 ? from
                         : from + divide_rounded((from - pulses_[back][a]) * ahead, index_[0] - index_[back]);
      }
      if (fit_ > 0) {
        // x and y with the beam's slope taken off (as where z were that of the last pulse),
        // fitted with a line over up to fit_ pulses and moved back by the slope at the
        // predicted z.
        const std::int64_t z0 = pulses_[0][2];
        const std::array<std::int64_t, 2> u = fitted(back, ahead);
        for (int a = 0; a < 2; ++a)
          p[a] = pulses_[0][a] + u[static_cast<std::size_t>(a)] + slope_shift(a, clamp(p[2], kMaxPrediction) - z0);
      }
    }
    for (std::int64_t& v : p) v = clamp(v, kMaxPrediction);
    return p;
  }
  /// The x and y the beam's slope adds to a point whose z lies dz off its prediction.
  [[nodiscard]] std::int64_t slope_shift(int axis, std::int64_t dz) const {
    return divide_rounded(slope_[axis] * clamp(dz, kMaxAcquisitionCell), std::int64_t{1} << kSlopeBits);
  }
  [[nodiscard]] int kind_ctx() const { return 4 * kind2_ + kind1_; }
  [[nodiscard]] int z_ctx(PulseKind k) const { return static_cast<int>(k) * 8 + IntModel::context_of(last_dz_); }
  [[nodiscard]] int xy_ctx(PulseKind k, std::int64_t dz, int axis) const {
    return (static_cast<int>(k) * 8 + IntModel::context_of(dz)) * 8 + IntModel::context_of(last_xy_[axis]);
  }
  /// After a point `c` of kind `k` (`skipped` pulses skipped), predicted at `p`, its x and y
  /// `rx`, `ry` off the slope's shift.
  void update(PulseKind k, std::uint32_t skipped, const Cell& c, const Cell& p, std::int64_t rx, std::int64_t ry) {
    const std::int64_t dz = c[2] - p[2];
    if (k == PulseKind::kSamePulse || k == PulseKind::kNextPulse) {
      const std::int64_t z = clamp(dz, kSlopeClamp);
      for (int a = 0; a < 2; ++a) sum_[a] = decay(sum_[a]) + clamp(c[a] - p[a], kSlopeClamp) * z;
      sum_zz_ = decay(sum_zz_) + z * z;
      for (int a = 0; a < 2; ++a)
        slope_[a] = sum_zz_ > 0 ? clamp(sum_[a] * (std::int64_t{1} << kSlopeBits) / sum_zz_, kMaxSlope) : 0;
    }
    if (k == PulseKind::kRestart) {
      held_ = 1;
      pulses_[0] = c;
      index_[0] = 0;
    } else if (k != PulseKind::kSamePulse) {
      const std::int64_t index = index_[0] + static_cast<std::int64_t>(skipped) + 1;
      held_ = std::min(held_ + 1, kHeldPulses);
      for (int j = held_ - 1; j > 0; --j) {
        pulses_[static_cast<std::size_t>(j)] = pulses_[static_cast<std::size_t>(j - 1)];
        index_[static_cast<std::size_t>(j)] = index_[static_cast<std::size_t>(j - 1)];
      }
      pulses_[0] = c;
      index_[0] = index;
    }
    last_ = c;
    kind2_ = kind1_;
    kind1_ = static_cast<int>(k);
    last_dz_ = dz;
    last_xy_ = {rx, ry};
  }

  std::array<BitModel, 16> kind_high{};
  std::array<std::array<BitModel, 2>, 16> kind_low{};
  IntModel z_, x_, y_, gap_;

 private:
  /// The x and y `ahead` pulses after the latest, off the latest pulse's, with the
  /// part its height explains along the beam taken off: the least-squares line through
  /// the last min(held_, fit_) pulses' (each pulse's coordinate less the slope's part of
  /// its z, both off the latest pulse's and clamped to ±kFitClamp; the slope's part taken
  /// off the sums), or with fewer than three of them the step over `back` pulses.
  [[nodiscard]] std::array<std::int64_t, 2> fitted(int back, std::int64_t ahead) const {
    const int n = std::min(held_, fit_);
    const auto off = [&](int j, int axis) {
      return clamp(pulses_[static_cast<std::size_t>(j)][axis] - pulses_[0][axis], kFitClamp);
    };
    std::array<std::int64_t, 2> u{};
    if (n < 3) {
      if (back == 0) return u;
      const std::int64_t span = index_[0] - index_[static_cast<std::size_t>(back)];
      for (int a = 0; a < 2; ++a) {
        const std::int64_t v = off(back, a) - slope_shift(a, off(back, 2));
        u[static_cast<std::size_t>(a)] = divide_rounded(-v * ahead, span);
      }
      return u;
    }
    // (the indices' and heights' sums serve both axes)
    std::int64_t si = 0, sii = 0, sz = 0, siz = 0;
    std::array<std::int64_t, 2> sx{}, six{};
    for (int j = 1; j < n; ++j) {  // (pulse 0 adds nothing but its count: its i and offsets are 0)
      const std::int64_t i = index_[static_cast<std::size_t>(j)] - index_[0];
      const std::int64_t z = off(j, 2);
      si += i;
      sii += i * i;
      sz += z;
      siz += i * z;
      for (std::size_t a = 0; a < 2; ++a) {
        const std::int64_t x = off(j, static_cast<int>(a));
        sx[a] += x;
        six[a] += i * x;
      }
    }
    const std::int64_t d = n * sii - si * si;
    if (d <= 0) return u;
    for (std::size_t a = 0; a < 2; ++a) {
      // (|sz| < 2^25 and |siz| < 2^35 cells: their products with the slope, at most 2^20, fit)
      const std::int64_t sv = clamp(sx[a] - divide_rounded(slope_[a] * sz, std::int64_t{1} << kSlopeBits), kFitSumClamp);
      const std::int64_t siv =
          clamp(six[a] - divide_rounded(slope_[a] * siz, std::int64_t{1} << kSlopeBits), kFitMomentClamp);
      u[a] = divide_rounded(sv * d + (n * siv - si * sv) * (n * ahead - si), n * d);
    }
    return u;
  }

  Cell last_{};
  /// The last pulses (their first points), latest first, and their pulse numbers since the
  /// last restart; held_ of them are valid (0 before the first point).
  std::array<Cell, kHeldPulses> pulses_{};
  std::array<std::int64_t, kHeldPulses> index_{};
  int held_ = 0;
  int fit_ = 0;
  int kind1_ = 3, kind2_ = 3;
  std::int64_t last_dz_ = 0;
  std::array<std::int64_t, 2> last_xy_{};
  std::array<std::int64_t, 2> sum_{};
  std::int64_t sum_zz_ = 0;
  std::array<std::int64_t, 2> slope_{};
};

void encode_point(RangeEncoder& enc, AcquisitionState& s, PulseKind kind, std::uint32_t skipped, const Cell& c) {
  const int kc = s.kind_ctx();
  const auto k = static_cast<unsigned>(kind);
  enc.put(s.kind_high[static_cast<std::size_t>(kc)], (k & 2U) != 0);
  enc.put(s.kind_low[static_cast<std::size_t>(kc)][(k >> 1) & 1U], (k & 1U) != 0);
  if (kind == PulseKind::kSkipped) s.gap_.put(enc, 0, static_cast<std::int64_t>(skipped) - 1);
  const Cell p = s.predict(kind, skipped);
  const std::int64_t dz = c[2] - p[2];
  s.z_.put(enc, s.z_ctx(kind), dz);
  const std::int64_t rx = c[0] - p[0] - s.slope_shift(0, dz);
  const std::int64_t ry = c[1] - p[1] - s.slope_shift(1, dz);
  s.x_.put(enc, s.xy_ctx(kind, dz, 0), rx);
  s.y_.put(enc, s.xy_ctx(kind, dz, 1), ry);
  s.update(kind, skipped, c, p, rx, ry);
}

/// A cell's centre: x and y `step` apart, z `step_z` apart.
Eigen::Vector3f cell_centre(const Eigen::Vector3d& origin, double step, double step_z, const Cell& c) {
  return {static_cast<float>(origin.x() + static_cast<double>(c[0]) * step),
          static_cast<float>(origin.y() + static_cast<double>(c[1]) * step),
          static_cast<float>(origin.z() + static_cast<double>(c[2]) * step_z)};
}

/// The pulse period: the median of the rises between consecutive times (0 without any).
double pulse_period(const std::vector<double>& time, const std::vector<std::uint32_t>& order) {
  std::vector<double> rises;
  rises.reserve(order.size());
  for (std::size_t j = 1; j < order.size(); ++j) {
    const double dt = time[order[j]] - time[order[j - 1]];
    if (dt > 0.0 && std::isfinite(dt)) rises.push_back(dt);
  }
  if (rises.empty()) return 0.0;
  auto mid = rises.begin() + static_cast<std::ptrdiff_t>(rises.size() / 2);
  std::nth_element(rises.begin(), mid, rises.end());
  return *mid;
}

}  // namespace

bool acquisition_ordered(const std::vector<double>& time, const std::vector<std::uint32_t>& coded) {
  if (coded.size() < 2) return false;
  std::size_t rise = 0, fall = 0;
  for (std::size_t j = 1; j < coded.size(); ++j) {
    const double dt = time[coded[j]] - time[coded[j - 1]];
    if (dt > 0.0) ++rise;
    else if (!(dt == 0.0)) ++fall;
  }
  const std::size_t pairs = coded.size() - 1;
  return 10 * fall <= pairs && 10 * rise >= pairs;
}

namespace {

/// Each of the points `order`'s kind from their times (§2.11.2): equal, a return of the
/// same pulse; else the pulses between, counted in the typical rise (the pulse period).
void kinds_from_times(const std::vector<double>& time, std::size_t points, const std::vector<std::uint32_t>& order,
                      std::vector<PulseKind>& kinds, std::vector<std::uint32_t>& skips) {
  const bool timed = time.size() == points;
  const double period = timed ? pulse_period(time, order) : 0.0;
  kinds.assign(order.size(), PulseKind::kNextPulse);
  skips.assign(order.size(), 0);
  for (std::size_t j = 0; j < order.size(); ++j) {
    PulseKind& kind = kinds[j];
    if (j == 0) kind = PulseKind::kRestart;
    if (j > 0 && period > 0.0) {
      const double dt = time[order[j]] - time[order[j - 1]];
      if (dt == 0.0) {
        kind = PulseKind::kSamePulse;
      } else if (!(dt > 0.0) || !(dt / period < kMaxSkippedPulses + 1.5)) {
        kind = PulseKind::kRestart;
      } else {
        const auto pulses = static_cast<std::uint32_t>(std::lround(dt / period));
        if (pulses >= 2) {
          kind = PulseKind::kSkipped;
          skips[j] = pulses - 1;
        }
      }
    }
  }
}

/// The bytes of the cells' stream with line fit `fit`, after what `e` holds: every point,
/// or (`sample`) every fourth block of kFitTrialBlock points, each block from a restart.
std::vector<std::uint8_t> code_cells(RangeEncoder e, std::uint32_t fit, const std::vector<Cell>& cells,
                                     const std::vector<PulseKind>& kinds, const std::vector<std::uint32_t>& skips,
                                     bool sample) {
  AcquisitionState state(fit);
  for (std::size_t j = 0; j < cells.size(); ++j) {
    if (!sample) {
      encode_point(e, state, kinds[j], skips[j], cells[j]);
    } else if ((j / kFitTrialBlock) % 4 == 0) {
      const bool first = j % kFitTrialBlock == 0;
      encode_point(e, state, first ? PulseKind::kRestart : kinds[j], first ? 0 : skips[j], cells[j]);
    }
  }
  return e.finish();
}

/// The line fit of most candidates the trial takes for the cells' shapes (§2.11.2).
constexpr std::uint32_t kShapeTrialFit = 12;

}  // namespace

std::optional<AcquisitionLayer> acquisition_layer(RangeEncoder enc, const std::vector<Eigen::Vector3f>& input,
                                                  const std::vector<double>& time, const std::vector<std::uint32_t>& coded,
                                                  double bound, bool thin,
                                                  const std::vector<std::uint32_t>& fit_candidates, int threads,
                                                  const std::vector<CellShape>& shapes) {
  if (coded.empty()) return std::nullopt;
  if (fit_candidates.empty()) throw std::invalid_argument("acquisition_layer: no line fit to try");
  for (const std::uint32_t fit : fit_candidates)
    if (!valid_fit_pulses(fit))
      throw std::invalid_argument("acquisition_layer: a line fit over " + std::to_string(fit) +
                                  " pulses (0 or 3-32 allowed)");
  if (shapes.empty()) throw std::invalid_argument("acquisition_layer: no cell shape to try");
  for (const CellShape& c : shapes)
    if (!(c.height >= 1.0 && c.height <= kMaxCellHeight) || !(c.phase >= 0.0 && c.phase < 1.0))
      throw std::invalid_argument("acquisition_layer: a cell shape of height " + std::to_string(c.height) +
                                  " and phase " + std::to_string(c.phase) + " (heights 1-4, phases [0, 1))");
  Eigen::Vector3d low = input[coded[0]].cast<double>();
  for (const std::uint32_t i : coded) low = low.cwiseMin(input[i].cast<double>());
  // A shape's grid: cells `height` times taller than wide whose half-diagonal is the bound,
  // from the points' lowest corner, z planes moved down `phase` of a cell.
  const auto grid_of = [&](const CellShape& c, AcquisitionLayer& l) {
    l.step = 2.0 * bound / std::sqrt(2.0 + c.height * c.height) * (1.0 - 1e-6);
    l.step_z = c.height == 1.0 ? l.step : l.step * c.height;
    l.origin = low;
    l.origin.z() -= c.phase * l.step_z;
  };
  const auto cell_of = [](const AcquisitionLayer& l, const Eigen::Vector3d& p, Cell& c) {
    for (int a = 0; a < 3; ++a) {
      const double k = std::round((p[a] - l.origin[a]) / (a == 2 ? l.step_z : l.step));
      if (!(k <= static_cast<double>(kMaxAcquisitionCell))) return false;
      c[static_cast<std::size_t>(a)] = static_cast<std::int64_t>(k);
    }
    return true;
  };
  AcquisitionLayer layer;
  std::vector<PulseKind> kinds;
  std::vector<std::uint32_t> skips;
  std::size_t shape = 0;
  if (shapes.size() > 1) {
    // Each shape codes the sample of all the points (no thinning) with a middle fit, side by
    // side; the one of fewest bytes (the first of equals) is kept.
    kinds_from_times(time, input.size(), coded, kinds, skips);
    std::vector<std::size_t> sizes(shapes.size(), std::numeric_limits<std::size_t>::max());
    parallel_for(shapes.size(), threads, [&](std::size_t k) {
      AcquisitionLayer l;
      grid_of(shapes[k], l);
      std::vector<Cell> cells(coded.size());
      for (std::size_t j = 0; j < coded.size(); ++j)
        if ((j / kFitTrialBlock) % 4 == 0 && !cell_of(l, input[coded[j]].cast<double>(), cells[j])) return;
      const std::uint32_t fit = std::find(fit_candidates.begin(), fit_candidates.end(), kShapeTrialFit) !=
                                        fit_candidates.end() ? kShapeTrialFit : fit_candidates.front();
      sizes[k] = code_cells(RangeEncoder{}, fit, cells, kinds, skips, true).size();
    }, 1);
    shape = static_cast<std::size_t>(std::min_element(sizes.begin(), sizes.end()) - sizes.begin());
  }
  grid_of(shapes[shape], layer);
  std::vector<Cell> cells;
  std::vector<std::uint32_t>& kept = layer.sources;
  const double b2 = bound * bound;
  for (int attempt = 0;; ++attempt) {
    if (attempt == 8) return std::nullopt;  // float32 cannot hold centres this close (not seen)
    cells.clear();
    kept.clear();
    PointBallGrid decoded(bound, thin ? coded.size() : 0);
    bool miss = false;
    for (const std::uint32_t i : coded) {
      const Eigen::Vector3d p = input[i].cast<double>();
      if (thin && decoded.any_within(p)) continue;
      Cell c{};
      if (!cell_of(layer, p, c)) return std::nullopt;
      const Eigen::Vector3f centre = cell_centre(layer.origin, layer.step, layer.step_z, c);
      if (!((centre.cast<double>() - p).squaredNorm() <= b2)) {
        miss = true;
        break;
      }
      if (thin) decoded.insert(centre);
      cells.push_back(c);
      kept.push_back(i);
    }
    if (!miss) break;
    layer.step *= 1.0 - 1e-3;
    layer.step_z *= 1.0 - 1e-3;
  }
  kinds_from_times(time, input.size(), kept, kinds, skips);
  // The line fit: with several candidates, each codes the sample side by side, and the one
  // with the fewest bytes (the first of equals) codes the points.
  layer.fit_pulses = fit_candidates.front();
  if (fit_candidates.size() > 1) {
    std::vector<std::size_t> sizes(fit_candidates.size());
    parallel_for(fit_candidates.size(), threads, [&](std::size_t c) {
      sizes[c] = code_cells(RangeEncoder{}, fit_candidates[c], cells, kinds, skips, true).size();
    }, 1);
    layer.fit_pulses = fit_candidates[static_cast<std::size_t>(std::min_element(sizes.begin(), sizes.end()) - sizes.begin())];
  }
  layer.stream = code_cells(enc, layer.fit_pulses, cells, kinds, skips, false);
  return layer;
}

std::optional<std::string> decode_acquisition_points(RangeDecoder& dec, const Eigen::Vector3d& origin, double step,
                                                     double step_z, std::uint32_t fit_pulses, std::uint64_t count,
                                                     std::vector<Eigen::Vector3f>& out) {
  if (!valid_fit_pulses(fit_pulses))
    return "line fit over " + std::to_string(fit_pulses) + " pulses (0 or 3-32 allowed)";
  AcquisitionState s(fit_pulses);
  for (std::uint64_t j = 0; j < count; ++j) {
    const int kc = s.kind_ctx();
    const unsigned high = dec.get(s.kind_high[static_cast<std::size_t>(kc)]) ? 1U : 0U;
    const unsigned low = dec.get(s.kind_low[static_cast<std::size_t>(kc)][high]) ? 1U : 0U;
    const auto kind = static_cast<PulseKind>(2U * high + low);
    std::uint32_t skipped = 0;
    if (kind == PulseKind::kSkipped) {
      const std::int64_t g = s.gap_.get(dec, 0);
      if (g < 0 || g >= static_cast<std::int64_t>(kMaxSkippedPulses))
        return "point " + std::to_string(j) + " skips " + std::to_string(g + 1) + " pulses (1-16 allowed)";
      skipped = static_cast<std::uint32_t>(g) + 1;
    }
    const Cell p = s.predict(kind, skipped);
    const std::int64_t dz = s.z_.get(dec, s.z_ctx(kind));
    const std::int64_t rx = s.x_.get(dec, s.xy_ctx(kind, dz, 0));
    const std::int64_t ry = s.y_.get(dec, s.xy_ctx(kind, dz, 1));
    const Cell c{p[0] + s.slope_shift(0, dz) + rx, p[1] + s.slope_shift(1, dz) + ry, p[2] + dz};
    for (const std::int64_t v : c)
      if (v < 0 || v > kMaxAcquisitionCell)
        return "point " + std::to_string(j) + " decodes off the grid (cell " + std::to_string(v) + ")";
    const Eigen::Vector3f pc = cell_centre(origin, step, step_z, c);
    if (!pc.allFinite()) return "point " + std::to_string(j) + " decodes to a non-finite position";
    out.push_back(pc);
    s.update(kind, skipped, c, p, rx, ry);
  }
  return std::nullopt;
}

}  // namespace lex3d::residual::detail
