#include "lex3d/core/layout.hpp"

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

struct Direction {
  float elevation = 0, azimuth = 0;
  bool valid = false;
};

/// The share of sampled pairs (i, i + gap), both real returns, in about the same direction.
double share_alike(const std::vector<Direction>& d, std::size_t gap, bool same_azimuth_too) {
  if (gap >= d.size()) return 0.0;
  const std::size_t pairs = d.size() - gap;
  const std::size_t stride = std::max<std::size_t>(1, pairs / kMaxPairs);
  std::size_t alike = 0, seen = 0;
  for (std::size_t i = 0; i < pairs; i += stride) {
    const Direction& a = d[i];
    const Direction& b = d[i + gap];
    if (!a.valid || !b.valid) continue;
    ++seen;
    double daz = std::abs(static_cast<double>(a.azimuth) - b.azimuth);
    daz = std::min(daz, 2.0 * kPi - daz);
    if (std::abs(static_cast<double>(a.elevation) - b.elevation) < kSameElevation &&
        (!same_azimuth_too || daz < kSameAzimuth))
      ++alike;
  }
  return seen >= 64 ? static_cast<double>(alike) / static_cast<double>(seen) : 0.0;
}

}  // namespace

std::optional<OrderLayout> detect_order_layout(const std::vector<Eigen::Vector3f>& points) {
  const std::size_t n = points.size();
  if (n < 256) return std::nullopt;
  std::vector<Direction> d(n);
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d p = points[i].cast<double>();
    const double rho = std::hypot(p.x(), p.y());
    if (!(rho > 0.3) || !p.allFinite()) continue;
    d[i] = {static_cast<float>(std::atan2(p.z(), rho)), static_cast<float>(std::atan2(p.y(), p.x())), true};
  }
  const double neighbours_alike = share_alike(d, 1, false);
  OrderLayout layout;
  bool found = false;
  // Firing by firing: neighbours differ in elevation, points a firing apart do not.
  if (neighbours_alike < 0.5)
    for (std::uint32_t l = 2; l <= 1024 && !found; ++l) {
      if (n % l != 0 || n / l < 16) continue;
      if (share_alike(d, l, true) >= 0.9) {
        layout.lasers = l;
        layout.columns = static_cast<std::uint32_t>(n / l);
        layout.firing_major = true;
        found = true;
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
      std::size_t same_az = 0, seen = 0;
      for (std::size_t i = 0; i < pairs; i += stride) {
        if (!d[i].valid || !d[i + w].valid) continue;
        ++seen;
        double daz = std::abs(static_cast<double>(d[i].azimuth) - d[i + w].azimuth);
        daz = std::min(daz, 2.0 * kPi - daz);
        if (daz < kSameAzimuth) ++same_az;
      }
      if (seen >= 64 && static_cast<double>(same_az) >= 0.9 * static_cast<double>(seen)) {
        layout.lasers = rows;
        layout.columns = static_cast<std::uint32_t>(w);
        layout.firing_major = false;
        found = true;
      }
    }
  if (!found) return std::nullopt;
  // Lasers numbered from the top beam down by the median elevation of their points.
  std::vector<std::vector<float>> el(layout.lasers);
  for (std::size_t i = 0; i < n; ++i)
    if (d[i].valid) el[layout.firing_major ? i % layout.lasers : i / layout.columns].push_back(d[i].elevation);
  std::vector<float> median(layout.lasers, 0.0F);
  for (std::uint32_t l = 0; l < layout.lasers; ++l) {
    auto& v = el[l];
    if (v.empty()) continue;
    std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
    median[l] = v[v.size() / 2];
  }
  std::vector<std::uint16_t> order(layout.lasers);
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](std::uint16_t a, std::uint16_t b) { return median[a] > median[b]; });
  layout.laser_of.assign(layout.lasers, 0);
  for (std::uint32_t k = 0; k < layout.lasers; ++k) layout.laser_of[order[k]] = static_cast<std::uint16_t>(k);
  return layout;
}

}  // namespace lex3d
