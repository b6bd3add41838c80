#include "lex3d/core/layout.hpp"

#include "core/fast_atan2.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>

namespace lex3d {
namespace {

constexpr double kPi = 3.14159265358979323846;
/// Two returns of one laser in neighbouring firings lie within these angles of each other.
constexpr double kSameElevation = 0.3 * kPi / 180.0;
constexpr double kSameAzimuth = 2.0 * kPi / 180.0;
constexpr std::size_t kMaxPairs = 20000;
/// The share of a layout's points that must lie within kSameElevation of their laser's
/// median elevation (number_lasers).
constexpr double kKeptToLaser = 0.5;

struct Direction {
  float elevation = 0, azimuth = 0;
  bool valid = false;
};

/// The points' directions, each worked out the first time it is asked for: the tests
/// below sample a few tens of thousands of pairs, and most clouds fail them.
class Directions {
 public:
  explicit Directions(const std::vector<Eigen::Vector3f>& points) : points_(points), d_(points.size()), done_(points.size(), 0) {}
  [[nodiscard]] std::size_t size() const { return d_.size(); }
  const Direction& operator[](std::size_t i) {
    if (done_[i] == 0) {
      done_[i] = 1;
      const Eigen::Vector3d p = points_[i].cast<double>();
      const double rho = std::sqrt(p.x() * p.x() + p.y() * p.y());
      if (rho > 0.3 && p.allFinite())
        d_[i] = {static_cast<float>(detail::fast_atan2(p.z(), rho)), static_cast<float>(detail::fast_atan2(p.y(), p.x())), true};
    }
    return d_[i];
  }

 private:
  const std::vector<Eigen::Vector3f>& points_;
  std::vector<Direction> d_;
  std::vector<std::uint8_t> done_;
};

/// Whether `misses` among at most `total` sampled pairs already leave the share alike below
/// `need` (with a pair to spare for rounding).
bool out_of_reach(std::size_t misses, std::size_t total, double need) {
  return need > 0.0 && static_cast<double>(misses) > (1.0 - need) * static_cast<double>(total) + 1.0;
}

/// The share of sampled pairs (i, i + gap), both real returns, in about the same direction;
/// 0 as soon as it cannot reach `need` (where given).
double share_alike(Directions& d, std::size_t gap, bool same_azimuth_too, double need = 0.0) {
  if (gap >= d.size()) return 0.0;
  const std::size_t pairs = d.size() - gap;
  const std::size_t stride = std::max<std::size_t>(1, pairs / kMaxPairs);
  const std::size_t total = (pairs + stride - 1) / stride;
  std::size_t alike = 0, seen = 0;
  for (std::size_t i = 0; i < pairs; i += stride) {
    const Direction a = d[i];
    const Direction b = d[i + gap];
    if (!a.valid || !b.valid) continue;
    ++seen;
    double daz = std::abs(static_cast<double>(a.azimuth) - b.azimuth);
    daz = std::min(daz, 2.0 * kPi - daz);
    if (std::abs(static_cast<double>(a.elevation) - b.elevation) < kSameElevation &&
        (!same_azimuth_too || daz < kSameAzimuth))
      ++alike;
    else if (out_of_reach(seen - alike, total, need))
      return 0.0;
  }
  return seen >= 64 ? static_cast<double>(alike) / static_cast<double>(seen) : 0.0;
}

/// Numbers `layout`'s lasers from the top beam down by the median elevation of their
/// points and tells whether the points keep to their lasers: at least kKeptToLaser of the
/// points within kSameElevation of their laser's median elevation. A count that
/// happens to be lasers times columns in a cloud that dropped its no-returns passes the
/// pair test (points a firing apart agree until the next drop-out) but not this one.
bool number_lasers(Directions& d, OrderLayout& layout) {
  const std::size_t n = d.size();
  const auto laser_at = [&layout](std::size_t i) {
    return layout.firing_major ? i % layout.lasers : i / layout.columns;
  };
  std::vector<std::vector<float>> el(layout.lasers);
  for (std::size_t i = 0; i < n; ++i)
    if (const Direction& a = d[i]; a.valid) el[laser_at(i)].push_back(a.elevation);
  std::vector<float> median(layout.lasers, 0.0F);
  for (std::uint32_t l = 0; l < layout.lasers; ++l) {
    std::vector<float>& v = el[l];  // (reordered: the count below does not mind)
    if (v.empty()) continue;
    std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
    median[l] = v[v.size() / 2];
  }
  std::size_t kept = 0, seen = 0;
  for (std::uint32_t l = 0; l < layout.lasers; ++l)
    for (const float e : el[l]) {
      ++seen;
      if (std::abs(static_cast<double>(e) - median[l]) < kSameElevation) ++kept;
    }
  if (seen < 64 || static_cast<double>(kept) < kKeptToLaser * static_cast<double>(seen)) return false;
  std::vector<std::uint16_t> order(layout.lasers);
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](std::uint16_t a, std::uint16_t b) { return median[a] > median[b]; });
  layout.laser_of.assign(layout.lasers, 0);
  for (std::uint32_t k = 0; k < layout.lasers; ++k) layout.laser_of[order[k]] = static_cast<std::uint16_t>(k);
  return true;
}

}  // namespace

std::optional<OrderLayout> detect_order_layout(const std::vector<Eigen::Vector3f>& points) {
  const std::size_t n = points.size();
  if (n < 256) return std::nullopt;
  Directions d(points);
  const double neighbours_alike = share_alike(d, 1, false);
  OrderLayout layout;
  bool found = false;
  // Firing by firing: neighbours differ in elevation, points a firing apart do not.
  if (neighbours_alike < 0.5)
    for (std::uint32_t l = 2; l <= 1024 && !found; ++l) {
      if (n % l != 0 || n / l < 16) continue;
      if (share_alike(d, l, true, 0.9) >= 0.9) {
        layout.lasers = l;
        layout.columns = static_cast<std::uint32_t>(n / l);
        layout.firing_major = true;
        found = number_lasers(d, layout);
      }
    }
  // Row by row: neighbours alike, and so are points a row apart in azimuth, not in elevation.
  if (!found && neighbours_alike >= 0.8)
    for (std::uint32_t rows = 1024; rows >= 2 && !found; --rows) {  // the shortest row that fits
      if (n % rows != 0) continue;
      const std::size_t w = n / rows;
      if (w < 16 || w > (1U << 20)) continue;
      // a row apart: same azimuth, another elevation
      const std::size_t pairs = n - w;
      const std::size_t stride = std::max<std::size_t>(1, pairs / kMaxPairs);
      const std::size_t total = (pairs + stride - 1) / stride;
      std::size_t same_az = 0, seen = 0;
      for (std::size_t i = 0; i < pairs; i += stride) {
        const Direction a = d[i];
        const Direction b = d[i + w];
        if (!a.valid || !b.valid) continue;
        ++seen;
        double daz = std::abs(static_cast<double>(a.azimuth) - b.azimuth);
        daz = std::min(daz, 2.0 * kPi - daz);
        if (daz < kSameAzimuth) ++same_az;
        else if (out_of_reach(seen - same_az, total, 0.9)) break;
      }
      if (seen >= 64 && static_cast<double>(same_az) >= 0.9 * static_cast<double>(seen)) {
        layout.lasers = rows;
        layout.columns = static_cast<std::uint32_t>(w);
        layout.firing_major = false;
        found = number_lasers(d, layout);
      }
    }
  if (!found) return std::nullopt;
  return layout;
}

}  // namespace lex3d
