// Lattice coding of a residual layer (formats/model.md §2.12).

#include "residual/lattice.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <complex>
#include <limits>
#include <utility>

#include "residual/counting.hpp"

namespace lex3d::residual::detail {
namespace {

constexpr double kTwoPi = 6.283185307179586;
/// Points sampled to find the lattice.
constexpr std::size_t kLatticeSample = 2048;
/// Pitches tried either side of the neighbours' mean distance (2 % each way).
constexpr int kPitchSteps = 100;
/// Least concentration (the modulus of the mean phase, for x and y) that makes a lattice.
/// White offsets of σ a side give exp(−2π²σ²/pitch²): 0.5 at σ = 0.19 pitch.
constexpr double kMinConcentration = 0.5;
/// A lattice layer has at most this many cells a coded point (and 64 more).
constexpr std::uint64_t kMaxCellsPerPoint = 4;
/// Offsets and heights lie within ±2^30 steps.
constexpr std::int64_t kMaxOffset = std::int64_t{1} << 30;


/// The modulus and phase (radians) of the mean of exp(2πi v / pitch) over `values`.
std::complex<double> mean_phase(const std::vector<double>& values, double pitch) {
  std::complex<double> sum(0.0, 0.0);
  const double k = kTwoPi / pitch;
  for (const double v : values) sum += std::polar(1.0, k * v);
  return sum / static_cast<double>(values.size());
}

/// One cell's neighbours as a decoder knows them, row by row: whether a cell of the row
/// above and of this row so far holds points, and its first point's height.
class LatticeState {
 public:
  explicit LatticeState(std::uint32_t columns)
      : above_(columns), here_(columns), x_(8), y_(8), z_(9 * 4), extra_(5), x2_(1), y2_(1), z2_(2) {}

  struct Cell {
    bool occupied = false;
    std::int64_t z = 0;
    bool several = false;  ///< it holds more than one point
    std::int64_t gap = 0;  ///< stacked cells: its second point's height over its first's
  };

  [[nodiscard]] int occupancy_ctx(std::uint32_t i) const {
    const bool w = i > 0 && here_[i - 1].occupied;
    const bool n = above_[i].occupied;
    const bool nw = i > 0 && above_[i - 1].occupied;
    const bool ne = i + 1 < above_.size() && above_[i + 1].occupied;
    return (w ? 1 : 0) | (n ? 2 : 0) | (nw ? 4 : 0) | (ne ? 8 : 0);
  }
  /// The height a cell's first point is predicted at, and the context of its residual.
  void predict_z(std::uint32_t i, std::int64_t& pred, int& ctx) const {
    const Cell* w = i > 0 ? &here_[i - 1] : nullptr;
    const Cell* n = &above_[i];
    const Cell* nw = i > 0 ? &above_[i - 1] : nullptr;
    const Cell* ne = i + 1 < above_.size() ? &above_[i + 1] : nullptr;
    std::int64_t sum = 0, lo = 0, hi = 0;
    int count = 0;
    for (const Cell* c : {w, n, nw, ne}) {
      if (c == nullptr || !c->occupied) continue;
      lo = count == 0 ? c->z : std::min(lo, c->z);
      hi = count == 0 ? c->z : std::max(hi, c->z);
      sum += c->z;
      ++count;
    }
    if (count == 0) {
      pred = last_z_;
      ctx = 8;
      return;
    }
    ctx = IntModel::context_of(hi - lo);
    const bool planes = w != nullptr && w->occupied && n->occupied && nw != nullptr && nw->occupied;
    if (planes && ne != nullptr && ne->occupied) {
      // the mean of the planes through W, N, NW and through W, N, NE: W + (NE - NW) / 2
      pred = w->z + divide_rounded(ne->z - nw->z, 2);
    } else if (planes) {
      pred = w->z + n->z - nw->z;  // the plane through W, N and NW
    } else {
      pred = divide_rounded(sum, count);
    }
  }
  /// The context of a cell's count: how many of W, N, NW and NE hold more than one point
  /// (such cells cluster: vegetation, walls). On hexbin 0.39 -> 0.23 bits a point.
  [[nodiscard]] int extra_ctx(std::uint32_t i) const {
    int n = above_[i].several ? 1 : 0;
    if (i > 0) n += (here_[i - 1].several ? 1 : 0) + (above_[i - 1].several ? 1 : 0);
    if (i + 1 < above_.size()) n += above_[i + 1].several ? 1 : 0;
    return n;
  }
  /// The height residual's context: the neighbours' spread (`spread_ctx`, 0-8) and how large
  /// the last residual was (0, 1-15, 16 or more steps).
  [[nodiscard]] int z_ctx(int spread_ctx) const {
    const std::int64_t a = last_rz_ < 0 ? -last_rz_ : last_rz_;
    const int c = IntModel::context_of(a);
    return spread_ctx * 4 + (c < 3 ? 0 : c < 5 ? 1 : c < 7 ? 2 : 3);
  }
  void last_residual(std::int64_t r) { last_rz_ = r; }
  /// Stacked cells (§2.12.1, format 1.13): the mean gap of those of W, N, NW and NE that
  /// hold several points, false where none does.
  [[nodiscard]] bool neighbour_gap(std::uint32_t i, std::int64_t& gap) const {
    std::int64_t sum = 0;
    std::int64_t count = 0;
    for (const Cell* c : {i > 0 ? &here_[i - 1] : nullptr, &above_[i], i > 0 ? &above_[i - 1] : nullptr,
                          i + 1 < above_.size() ? &above_[i + 1] : nullptr}) {
      if (c == nullptr || !c->several) continue;
      sum += c->gap;
      ++count;
    }
    if (count == 0) return false;
    gap = divide_rounded(sum, count);
    return true;
  }
  [[nodiscard]] int x_ctx() const { return IntModel::context_of(last_dx_); }
  [[nodiscard]] int y_ctx() const { return IntModel::context_of(last_dy_); }
  void set(std::uint32_t i, bool occupied, std::int64_t z, bool several, std::int64_t gap = 0) {
    here_[i] = {occupied, z, several, gap};
    if (occupied) last_z_ = z;
  }
  void first_offsets(std::int64_t dx, std::int64_t dy) {
    last_dx_ = dx;
    last_dy_ = dy;
  }
  void next_row() {
    std::swap(above_, here_);
    std::fill(here_.begin(), here_.end(), Cell{});
  }

  std::array<BitModel, 16> occupancy{};
  IntModel& x() { return x_; }
  IntModel& y() { return y_; }
  IntModel& z() { return z_; }
  IntModel& extra() { return extra_; }
  IntModel& x2() { return x2_; }
  IntModel& y2() { return y2_; }
  IntModel& z2() { return z2_; }

 private:
  std::vector<Cell> above_, here_;
  std::int64_t last_z_ = 0, last_dx_ = 0, last_dy_ = 0, last_rz_ = 0;
  IntModel x_, y_, z_, extra_, x2_, y2_, z2_;
};

/// A coded point: its cell and its offsets and height in steps.
struct LatticePoint {
  std::uint32_t i = 0, j = 0;
  std::int64_t dx = 0, dy = 0, z = 0;
  std::uint32_t source = 0;
};

Eigen::Vector3f lattice_position(const Eigen::Vector3d& origin, double pitch, double step, std::uint32_t i,
                                 std::uint32_t j, std::int64_t dx, std::int64_t dy, std::int64_t z) {
  return {static_cast<float>(origin.x() + static_cast<double>(i) * pitch + static_cast<double>(dx) * step),
          static_cast<float>(origin.y() + static_cast<double>(j) * pitch + static_cast<double>(dy) * step),
          static_cast<float>(origin.z() + static_cast<double>(z) * step)};
}

}  // namespace

std::optional<Lattice> find_lattice(const std::vector<Eigen::Vector3f>& input, const std::vector<std::uint32_t>& coded) {
  if (coded.size() < 64) return std::nullopt;
  double x_lo = input[coded[0]].x(), x_hi = x_lo, y_lo = input[coded[0]].y(), y_hi = y_lo;
  for (const std::uint32_t k : coded) {
    x_lo = std::min(x_lo, static_cast<double>(input[k].x()));
    x_hi = std::max(x_hi, static_cast<double>(input[k].x()));
    y_lo = std::min(y_lo, static_cast<double>(input[k].y()));
    y_hi = std::max(y_hi, static_cast<double>(input[k].y()));
  }
  const double area = (x_hi - x_lo) * (y_hi - y_lo);
  if (!(area > 0.0) || !std::isfinite(area)) return std::nullopt;
  const double spacing = std::sqrt(area / static_cast<double>(coded.size()));
  // (cells of the neighbour search within 2^30 a side: not for a cloud flat as a line)
  if (!((x_hi - x_lo) / spacing < 1073741824.0 && (y_hi - y_lo) / spacing < 1073741824.0)) return std::nullopt;
  // The points in cells `spacing` wide (x and y), to find each sampled point's neighbours.
  // (cells of at most 2^31 a side: the bounding box over `spacing` is below sqrt(n) + 1)
  const auto key = [&](double x, double y) {
    return std::make_pair(static_cast<std::int64_t>(std::floor((x - x_lo) / spacing)),
                          static_cast<std::int64_t>(std::floor((y - y_lo) / spacing)));
  };
  std::vector<std::pair<std::uint64_t, std::uint32_t>> cells;  // (cell key, point), sorted
  const auto packed = [](std::int64_t cx, std::int64_t cy) {
    return (static_cast<std::uint64_t>(cx + 2) << 32) | static_cast<std::uint64_t>(cy + 2);
  };
  cells.reserve(coded.size());
  for (const std::uint32_t k : coded) {
    const auto [cx, cy] = key(input[k].x(), input[k].y());
    cells.emplace_back(packed(cx, cy), k);
  }
  // (sorted by cell, then point: by a counting sort over the cells where they are few and
  // `coded` ascends, so that its order within a cell is the points' order)
  const auto [nx, ny] = key(x_hi, y_hi);
  const auto grid = static_cast<std::uint64_t>(nx + 1) * static_cast<std::uint64_t>(ny + 1);
  if (counting_pays(grid, coded.size()) && std::is_sorted(coded.begin(), coded.end())) {
    const auto ny1 = static_cast<std::uint64_t>(ny + 1);
    const auto dense = [&](std::size_t j) {
      const std::uint64_t c = cells[j].first;
      return static_cast<std::size_t>(((c >> 32) - 2) * ny1 + ((c & 0xFFFFFFFFU) - 2));
    };
    const std::vector<std::uint32_t> order = counting_order(cells.size(), static_cast<std::size_t>(grid), dense);
    std::vector<std::pair<std::uint64_t, std::uint32_t>> sorted(cells.size());
    for (std::size_t j = 0; j < order.size(); ++j) sorted[j] = cells[order[j]];
    cells.swap(sorted);
  } else {
    std::sort(cells.begin(), cells.end());
  }
  const auto in_cell = [&](std::int64_t cx, std::int64_t cy, auto&& visit) {
    if (cx < -2 || cy < -2) return;
    const std::uint64_t k = packed(cx, cy);
    auto it = std::lower_bound(cells.begin(), cells.end(), std::make_pair(k, std::uint32_t{0}));
    for (; it != cells.end() && it->first == k; ++it) visit(it->second);
  };
  const std::size_t stride = std::max<std::size_t>(1, coded.size() / kLatticeSample);
  std::vector<std::uint32_t> sample;
  for (std::size_t k = 0; k < coded.size(); k += stride) sample.push_back(coded[k]);
  // Each sampled point's nearest neighbour: on a lattice, mostly along x or y.
  // (stopped once more than a quarter of the sample is not aligned: the test below fails)
  std::vector<double> nearest;
  std::size_t aligned = 0;
  for (const std::uint32_t k : sample) {
    if (4 * (nearest.size() - aligned) > sample.size()) return std::nullopt;
    const auto [cx, cy] = key(input[k].x(), input[k].y());
    // (by squared distance, its root taken once: a lidar scan crowds thousands of points into
    // the cells near its sensor)
    double best = std::numeric_limits<double>::infinity(), bx = 0.0, by = 0.0;
    for (std::int64_t dx = -1; dx <= 1; ++dx)
      for (std::int64_t dy = -1; dy <= 1; ++dy)
        in_cell(cx + dx, cy + dy, [&](std::uint32_t m) {
          const double vx = static_cast<double>(input[m].x()) - input[k].x();
          const double vy = static_cast<double>(input[m].y()) - input[k].y();
          const double d2 = vx * vx + vy * vy;
          if ((vx != 0.0 || vy != 0.0) && d2 < best) {
            best = d2;
            bx = vx;
            by = vy;
          }
        });
    if (!std::isfinite(best)) continue;
    nearest.push_back(std::hypot(bx, by));
    aligned += std::min(std::abs(bx), std::abs(by)) < 0.25 * std::max(std::abs(bx), std::abs(by)) ? 1 : 0;
  }
  if (nearest.size() < 32 || 4 * aligned < 3 * nearest.size()) return std::nullopt;
  std::nth_element(nearest.begin(), nearest.begin() + static_cast<std::ptrdiff_t>(nearest.size() / 2), nearest.end());
  const double near = nearest[nearest.size() / 2];
  // The pitch: the mean distance along x (y) between neighbours in one row (column), which
  // the offsets do not bias as they bias the nearest neighbour's.
  double sum = 0.0;
  std::size_t pairs = 0;
  for (const std::uint32_t k : sample) {
    const auto [cx, cy] = key(input[k].x(), input[k].y());
    for (std::int64_t dx = -2; dx <= 2; ++dx)
      for (std::int64_t dy = -2; dy <= 2; ++dy)
        in_cell(cx + dx, cy + dy, [&](std::uint32_t m) {
          const double vx = std::abs(static_cast<double>(input[m].x()) - input[k].x());
          const double vy = std::abs(static_cast<double>(input[m].y()) - input[k].y());
          const double along = std::max(vx, vy), across = std::min(vx, vy);
          if (across < 0.4 * near && along > 0.5 * near && along < 1.6 * near) {
            sum += along;
            ++pairs;
          }
        });
  }
  if (pairs < 32) return std::nullopt;
  const double guess = sum / static_cast<double>(pairs);
  // Then the pitch within 2 % of it at which the points gather most tightly at the lattice
  // points (of equal ones the largest: an exact lattice gathers as tightly at fractions).
  std::vector<double> xs, ys;
  for (const std::uint32_t k : sample) {
    xs.push_back(input[k].x());
    ys.push_back(input[k].y());
  }
  const auto concentration = [&](double pitch) {
    return std::min(std::abs(mean_phase(xs, pitch)), std::abs(mean_phase(ys, pitch)));
  };
  Lattice best;
  for (int s = -kPitchSteps; s <= kPitchSteps; ++s) {
    const double pitch = guess * (1.0 + 0.02 * static_cast<double>(s) / kPitchSteps);
    const double c = concentration(pitch);
    if (c >= best.concentration * (1.0 - 1e-9)) best = {Eigen::Vector2d::Zero(), pitch, c};
  }
  if (best.concentration < kMinConcentration) return std::nullopt;
  best.origin = {std::arg(mean_phase(xs, best.pitch)) / kTwoPi * best.pitch,
                 std::arg(mean_phase(ys, best.pitch)) / kTwoPi * best.pitch};
  return best;
}

namespace {

/// The stream of `points` (row by row, cell by cell) after what `enc` holds. `stacked`
/// (format 1.13): a cell's points come lowest first, each extra one's height against the
/// one below it, the second's against the gap its neighbours hold (§2.12.1).
std::vector<std::uint8_t> code_cells(RangeEncoder enc, const LatticeLayer& layer, const std::vector<LatticePoint>& points,
                                     bool stacked) {
  LatticeState s(layer.columns);
  std::size_t at = 0;
  for (std::uint32_t j = 0; j < layer.rows; ++j) {
    for (std::uint32_t i = 0; i < layer.columns; ++i) {
      std::size_t end = at;
      while (end < points.size() && points[end].j == j && points[end].i == i) ++end;
      const bool occupied = end > at;
      enc.put(s.occupancy[static_cast<std::size_t>(s.occupancy_ctx(i))], occupied);
      if (!occupied) {
        s.set(i, false, 0, false);
        continue;
      }
      s.extra().put(enc, s.extra_ctx(i), static_cast<std::int64_t>(end - at - 1));
      const LatticePoint& first = points[at];
      s.x().put(enc, s.x_ctx(), first.dx);
      s.y().put(enc, s.y_ctx(), first.dy);
      std::int64_t pred = 0;
      int ctx = 0;
      s.predict_z(i, pred, ctx);
      s.z().put(enc, s.z_ctx(ctx), first.z - pred);
      s.last_residual(first.z - pred);
      s.first_offsets(first.dx, first.dy);
      std::int64_t gap = 0;
      const bool known = stacked && s.neighbour_gap(i, gap);
      for (std::size_t k = at + 1; k < end; ++k) {  // each its own offsets; its height as the order says
        s.x2().put(enc, 0, points[k].dx);
        s.y2().put(enc, 0, points[k].dy);
        if (!stacked) s.z2().put(enc, 0, points[k].z - first.z);
        else if (k == at + 1 && known) s.z2().put(enc, 1, points[k].z - first.z - gap);
        else s.z2().put(enc, 0, points[k].z - points[k - 1].z);
      }
      s.set(i, true, first.z, end - at > 1, end - at > 1 ? points[at + 1].z - first.z : 0);
      at = end;
    }
    s.next_row();
  }
  return enc.finish();
}

}  // namespace

std::optional<LatticeLayer> lattice_layer(RangeEncoder enc, const std::vector<Eigen::Vector3f>& input,
                                          const std::vector<std::uint32_t>& coded, const Lattice& lattice, double bound,
                                          bool try_stacked) {
  if (coded.empty() || !(lattice.pitch > 0.0)) return std::nullopt;
  LatticeLayer layer;
  layer.pitch = lattice.pitch;
  // The cells, from the lowest lattice point the points reach.
  std::int64_t i_lo = 0, j_lo = 0, i_hi = 0, j_hi = 0;
  double z_lo = 0.0;
  std::vector<std::int64_t> ci(coded.size()), cj(coded.size());
  for (std::size_t k = 0; k < coded.size(); ++k) {
    const Eigen::Vector3f& p = input[coded[k]];
    const double fi = std::round((static_cast<double>(p.x()) - lattice.origin.x()) / lattice.pitch);
    const double fj = std::round((static_cast<double>(p.y()) - lattice.origin.y()) / lattice.pitch);
    if (!(std::abs(fi) < 1e12 && std::abs(fj) < 1e12)) return std::nullopt;
    ci[k] = static_cast<std::int64_t>(fi);
    cj[k] = static_cast<std::int64_t>(fj);
    if (k == 0 || ci[k] < i_lo) i_lo = ci[k];
    if (k == 0 || cj[k] < j_lo) j_lo = cj[k];
    if (k == 0 || ci[k] > i_hi) i_hi = ci[k];
    if (k == 0 || cj[k] > j_hi) j_hi = cj[k];
    if (k == 0 || p.z() < z_lo) z_lo = p.z();
  }
  const std::uint64_t columns = static_cast<std::uint64_t>(i_hi - i_lo) + 1, rows = static_cast<std::uint64_t>(j_hi - j_lo) + 1;
  if (columns > (1U << 30) || rows > (1U << 30) || columns * rows > kMaxCellsPerPoint * coded.size() + 64)
    return std::nullopt;
  layer.columns = static_cast<std::uint32_t>(columns);
  layer.rows = static_cast<std::uint32_t>(rows);
  layer.origin = {lattice.origin.x() + static_cast<double>(i_lo) * lattice.pitch,
                  lattice.origin.y() + static_cast<double>(j_lo) * lattice.pitch, z_lo};
  layer.step = 2.0 * bound / std::sqrt(3.0) * (1.0 - 1e-6);
  std::vector<LatticePoint> points(coded.size());
  const double b2 = bound * bound;
  for (int attempt = 0;; ++attempt) {
    if (attempt == 8) return std::nullopt;  // float32 cannot hold positions this close (not seen)
    bool miss = false;
    for (std::size_t k = 0; k < coded.size() && !miss; ++k) {
      const Eigen::Vector3d p = input[coded[k]].cast<double>();
      LatticePoint& lp = points[k];
      lp.i = static_cast<std::uint32_t>(ci[k] - i_lo);
      lp.j = static_cast<std::uint32_t>(cj[k] - j_lo);
      lp.source = coded[k];
      const double ox = std::round((p.x() - (layer.origin.x() + static_cast<double>(lp.i) * layer.pitch)) / layer.step);
      const double oy = std::round((p.y() - (layer.origin.y() + static_cast<double>(lp.j) * layer.pitch)) / layer.step);
      const double oz = std::round((p.z() - layer.origin.z()) / layer.step);
      const auto limit = static_cast<double>(kMaxOffset);
      if (!(std::abs(ox) <= limit && std::abs(oy) <= limit && oz <= limit)) return std::nullopt;
      lp.dx = static_cast<std::int64_t>(ox);
      lp.dy = static_cast<std::int64_t>(oy);
      lp.z = static_cast<std::int64_t>(oz);
      const Eigen::Vector3f d = lattice_position(layer.origin, layer.pitch, layer.step, lp.i, lp.j, lp.dx, lp.dy, lp.z);
      miss = !((d.cast<double>() - p).squaredNorm() <= b2);
    }
    if (!miss) break;
    layer.step *= 1.0 - 1e-3;
  }
  // Row by row, cell by cell; the points of a cell in input order, or stacked (lowest
  // first), whichever codes smaller (the first of equals).
  std::stable_sort(points.begin(), points.end(), [](const LatticePoint& a, const LatticePoint& b) {
    return a.j != b.j ? a.j < b.j : a.i < b.i;
  });
  std::vector<std::uint8_t> plain_stream = code_cells(enc, layer, points, false);
  std::vector<LatticePoint> stacked;
  std::vector<std::uint8_t> stacked_stream;
  if (try_stacked) {
    stacked = points;
    std::stable_sort(stacked.begin(), stacked.end(), [](const LatticePoint& a, const LatticePoint& b) {
      return a.j != b.j ? a.j < b.j : a.i != b.i ? a.i < b.i : a.z < b.z;
    });
    stacked_stream = code_cells(enc, layer, stacked, true);
  }
  layer.stacked = try_stacked && stacked_stream.size() < plain_stream.size();
  layer.stream = std::move(layer.stacked ? stacked_stream : plain_stream);
  for (const LatticePoint& p : layer.stacked ? stacked : points) layer.sources.push_back(p.source);
  return layer;
}

std::optional<std::string> decode_lattice_points(RangeDecoder& dec, const Eigen::Vector3d& origin, double pitch,
                                                 double step, std::uint32_t columns, std::uint32_t rows, bool stacked,
                                                 std::uint64_t count, std::vector<Eigen::Vector3f>& out) {
  LatticeState s(columns);
  std::uint64_t decoded = 0;
  for (std::uint32_t j = 0; j < rows; ++j) {
    for (std::uint32_t i = 0; i < columns; ++i) {
      const bool occupied = dec.get(s.occupancy[static_cast<std::size_t>(s.occupancy_ctx(i))]);
      if (!occupied) {
        s.set(i, false, 0, false);
        continue;
      }
      const std::int64_t extra = s.extra().get(dec, s.extra_ctx(i));
      if (extra < 0 || static_cast<std::uint64_t>(extra) >= count - decoded)
        return "cell (" + std::to_string(i) + ", " + std::to_string(j) + ") holds more points than the layer's " +
               std::to_string(count);
      const std::int64_t dx = s.x().get(dec, s.x_ctx());
      const std::int64_t dy = s.y().get(dec, s.y_ctx());
      std::int64_t pred = 0;
      int ctx = 0;
      s.predict_z(i, pred, ctx);
      const std::int64_t rz = s.z().get(dec, s.z_ctx(ctx));
      s.last_residual(rz);
      const std::int64_t z = pred + rz;
      s.first_offsets(dx, dy);
      std::int64_t gap = 0;
      const bool known = stacked && s.neighbour_gap(i, gap);
      std::int64_t below = z, second = z;
      for (std::int64_t k = 0; k <= extra; ++k) {
        std::int64_t px = dx, py = dy, pz = z;
        if (k > 0) {
          px = s.x2().get(dec, 0);
          py = s.y2().get(dec, 0);
          if (!stacked) pz = z + s.z2().get(dec, 0);
          else if (k == 1 && known) pz = z + gap + s.z2().get(dec, 1);
          else pz = below + s.z2().get(dec, 0);
          below = pz;
          if (k == 1) second = pz;
        }
        if (std::max({std::abs(px), std::abs(py), std::abs(pz)}) > kMaxOffset)
          return "point " + std::to_string(decoded) + " lies beyond 2^30 steps of its lattice point";
        const Eigen::Vector3f p = lattice_position(origin, pitch, step, i, j, px, py, pz);
        if (!p.allFinite()) return "point " + std::to_string(decoded) + " decodes to a non-finite position";
        out.push_back(p);
        ++decoded;
      }
      s.set(i, true, z, extra > 0, extra > 0 ? second - z : 0);
    }
    s.next_row();
  }
  if (decoded != count)
    return "the lattice holds " + std::to_string(decoded) + " points, not the " + std::to_string(count) + " its header states";
  return std::nullopt;
}

}  // namespace lex3d::residual::detail
