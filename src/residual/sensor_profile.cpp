// Sensor profiles (formats/sensor_profile.md): parsing, and the laser and column of every
// point of a scan from a given laser table.

#include "lex3d/residual/sensor_profile.hpp"

#include <algorithm>
#include <cmath>
#include <complex>
#include <limits>
#include <map>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/xml_elements.hpp"

namespace lex3d::residual {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kTwoPi = 2.0 * kPi;
constexpr double kDeg = kPi / 180.0;
constexpr std::size_t kMaxProfileLasers = 1024;
constexpr std::uint32_t kMinColumns = 16;
constexpr std::uint32_t kMaxColumns = 1U << 20;

Status bad(const std::string& origin, const std::string& message) {
  return bad_data(origin.empty() ? message : origin + ": " + message);
}

std::string number_text(double v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

/// A value checked against [lo, hi]; the message names the field.
std::optional<std::string> out_of_range(const std::string& field, double v, double lo, double hi, bool open_lo = false) {
  if (!std::isfinite(v)) return field + " is not a finite number";
  if (v < lo || v > hi || (open_lo && v == lo))
    return field + " is " + number_text(v) + ", outside " + (open_lo ? "(" : "[") + number_text(lo) + ", " +
           number_text(hi) + "]";
  return std::nullopt;
}

// ---------------------------------------------------------------------------------------
// JSON
// ---------------------------------------------------------------------------------------

using nlohmann::json;

/// A number field of `j`: nullopt when absent (and not `required`); an error message for a
/// missing required field or a value that is not a number.
struct NumberField {
  std::optional<double> value;
  std::string error;
};
NumberField number_field(const json& j, const char* key, const std::string& where, bool required) {
  const auto it = j.find(key);
  if (it == j.end()) {
    if (required) return {std::nullopt, where + key + " is missing"};
    return {};
  }
  if (!it->is_number()) return {std::nullopt, where + key + " is " + std::string(it->type_name()) + ", expected a number"};
  return {it->get<double>(), ""};
}

StatusOr<SensorProfile> parse_json(std::string_view text, const std::string& origin) {
  json j;
  try {
    j = json::parse(text.begin(), text.end());
  } catch (const json::parse_error& e) {
    return bad(origin, "not a valid sensor profile JSON at byte " + std::to_string(e.byte) + " (NaN and Infinity are not JSON)");
  } catch (const json::exception& e) {
    return bad(origin, std::string("not a valid sensor profile JSON: ") + e.what());
  }
  if (!j.is_object()) return bad(origin, std::string("the profile is a JSON ") + j.type_name() + ", expected an object");
  SensorProfile p;
  p.origin = origin;
  if (const auto it = j.find("sensor"); it != j.end()) {
    if (!it->is_string()) return bad(origin, std::string("sensor is ") + it->type_name() + ", expected a string");
    p.sensor = it->get<std::string>();
  }
  if (const auto it = j.find("columns"); it != j.end()) {
    if (!it->is_number()) return bad(origin, std::string("columns is ") + it->type_name() + ", expected a whole number");
    const double c = it->get<double>();
    if (auto e = out_of_range("columns", c, kMinColumns, kMaxColumns)) return bad(origin, *e);
    if (c != std::floor(c)) return bad(origin, "columns is " + number_text(c) + ", expected a whole number");
    p.columns = static_cast<std::uint32_t>(c);
  }
  const NumberField step = number_field(j, "range_step", "", true);
  if (!step.error.empty()) return bad(origin, step.error);
  if (auto e = out_of_range("range_step", *step.value, 0.0, 1.0, true)) return bad(origin, *e);
  p.range_step = *step.value;
  const NumberField rate = number_field(j, "rate_hz", "", false);
  if (!rate.error.empty()) return bad(origin, rate.error);
  if (rate.value) {
    if (auto e = out_of_range("rate_hz", *rate.value, 0.0, 100.0, true)) return bad(origin, *e);
    p.rate_hz = *rate.value;
  }
  const auto lasers = j.find("lasers");
  if (lasers == j.end()) return bad(origin, "lasers is missing");
  if (!lasers->is_array()) return bad(origin, std::string("lasers is ") + lasers->type_name() + ", expected an array");
  if (lasers->empty() || lasers->size() > kMaxProfileLasers)
    return bad(origin, "lasers has " + std::to_string(lasers->size()) + " entries, expected 1 to " +
                           std::to_string(kMaxProfileLasers));
  for (std::size_t l = 0; l < lasers->size(); ++l) {
    const json& e = (*lasers)[l];
    const std::string where = "lasers[" + std::to_string(l) + "].";
    if (!e.is_object()) return bad(origin, "lasers[" + std::to_string(l) + "] is " + e.type_name() + ", expected an object");
    struct Spec {
      const char* key;
      double ProfileLaser::*field;
      double lo, hi;
      bool required;
    };
    static constexpr Spec kSpecs[] = {{"elevation_deg", &ProfileLaser::elevation_deg, -90.0, 90.0, true},
                                      {"azimuth_deg", &ProfileLaser::azimuth_deg, -180.0, 180.0, false},
                                      {"fire_us", &ProfileLaser::fire_us, -1e6, 1e6, false},
                                      {"z_offset", &ProfileLaser::z_offset, -10.0, 10.0, false},
                                      {"horiz_offset", &ProfileLaser::horiz_offset, -10.0, 10.0, false}};
    ProfileLaser laser;
    for (const Spec& s : kSpecs) {
      const NumberField f = number_field(e, s.key, where, s.required);
      if (!f.error.empty()) return bad(origin, f.error);
      if (!f.value) continue;
      if (auto m = out_of_range(where + s.key, *f.value, s.lo, s.hi)) return bad(origin, *m);
      laser.*s.field = *f.value;
    }
    p.lasers.push_back(laser);
  }
  return p;
}

// ---------------------------------------------------------------------------------------
// Velodyne db.xml / VeloView calibration XML (boost serialization)
// ---------------------------------------------------------------------------------------

StatusOr<SensorProfile> parse_xml(std::string_view text, const std::string& origin) {
  SensorProfile p;
  p.origin = origin;
  p.sensor = "Velodyne (calibration XML)";
  const auto lsb = ::lex3d::detail::xml_element(text, "distLSB_");
  if (!lsb) return bad(origin, "distLSB_ is missing (the distance resolution, centimetres)");
  const auto step_cm = ::lex3d::detail::text_number(lsb->first);
  if (!step_cm) return bad(origin, "distLSB_ is not a number");
  if (auto e = out_of_range("distLSB_", *step_cm, 0.0, 100.0, true)) return bad(origin, *e);
  p.range_step = *step_cm / 100.0;
  std::map<long, ProfileLaser> by_id;
  std::size_t at = 0;
  while (auto px = ::lex3d::detail::xml_element(text, "px", at)) {
    at = px->second;
    const std::string where = "laser " + std::to_string(by_id.size()) + ": ";
    const auto field = [&](const char* name, bool required, double lo, double hi,
                           std::optional<double>& out) -> std::optional<std::string> {
      const auto e = ::lex3d::detail::xml_element(px->first, name);
      if (!e) return required ? std::optional<std::string>(where + name + " is missing") : std::nullopt;
      out = ::lex3d::detail::text_number(e->first);
      if (!out) return where + name + " is not a number";
      return out_of_range(where + name, *out, lo, hi);
    };
    std::optional<double> id, rot, vert, vert_off, horiz_off;
    for (auto e : {field("id_", true, 0, kMaxProfileLasers - 1, id), field("vertCorrection_", true, -90, 90, vert),
                   field("rotCorrection_", false, -180, 180, rot),
                   field("vertOffsetCorrection_", false, -1000, 1000, vert_off),
                   field("horizOffsetCorrection_", false, -1000, 1000, horiz_off)})
      if (e) return bad(origin, *e);
    if (*id != std::floor(*id)) return bad(origin, where + "id_ is not a whole number");
    ProfileLaser l;
    l.elevation_deg = *vert;
    // db.xml's rotation correction is subtracted from the firing's azimuth, which grows in
    // the spin direction: the beam lies -rotCorrection_ from its column in that direction.
    l.azimuth_deg = rot ? -*rot : 0.0;
    l.z_offset = vert_off ? *vert_off / 100.0 : 0.0;
    l.horiz_offset = horiz_off ? *horiz_off / 100.0 : 0.0;
    if (!by_id.emplace(static_cast<long>(*id), l).second)
      return bad(origin, "laser id_ " + std::to_string(static_cast<long>(*id)) + " appears twice");
  }
  if (by_id.empty()) return bad(origin, "no laser (<px> element) found");
  long expect = 0;
  for (const auto& [id, l] : by_id) {
    if (id != expect) return bad(origin, "laser ids are not 0.." + std::to_string(by_id.size() - 1) + " (" +
                                             std::to_string(expect) + " is missing)");
    p.lasers.push_back(l);
    ++expect;
  }
  return p;
}

// ---------------------------------------------------------------------------------------
// Assignment
// ---------------------------------------------------------------------------------------

struct Laser {
  double tan_el, cos_el, z0, side, az;  // az: the laser's azimuth offset + firing advance (radians, spin direction)
  double fire;                          // firing advance, radians of spin
};

/// Vertical distance of a point (horizontal range rho, height z) from laser l's cone.
inline double vertical(const Laser& l, double rho, double z, double& rho_b) {
  rho_b = l.side == 0.0 ? rho : std::sqrt(std::max(0.0, rho * rho - l.side * l.side));
  return (z - l.z0 - l.tan_el * rho_b) * l.cos_el;
}

}  // namespace

StatusOr<SensorProfile> parse_sensor_profile(std::string_view text, const std::string& origin) {
  std::size_t first = 0;
  // a UTF-8 byte order mark, then blanks
  if (text.substr(0, 3) == "\xEF\xBB\xBF") first = 3;
  while (first < text.size() && std::isspace(static_cast<unsigned char>(text[first]))) ++first;
  if (first == text.size()) return bad(origin, "the sensor profile is empty");
  if (text[first] == '<') return parse_xml(text, origin);
  return parse_json(text, origin);
}

StatusOr<ProfileFit> apply_sensor_profile(Cloud& cloud, const SensorProfile& profile, const std::string& what) {
  const std::size_t n = cloud.size();
  const std::size_t L = profile.lasers.size();
  const std::string& name = profile.origin.empty() ? std::string("the sensor profile") : profile.origin;
  if (L == 0 || L > kMaxProfileLasers) throw std::invalid_argument("sensor profile " + name + " has no lasers");
  if (!(profile.range_step > 0.0)) throw std::invalid_argument("sensor profile " + name + ": range_step is not positive");
  ProfileFit fit;
  fit.limit_m = kOffBeamSteps * profile.range_step;
  fit.lasers = L;
  if (n == 0) return fit;
  // The scan's own laser count, where it has one, must be the profile's.
  if (cloud.rows > 0 && cloud.rows != L)
    return bad(what, "its " + std::to_string(cloud.rows) + " rows (lasers) do not match the " + std::to_string(L) +
                         " lasers of sensor profile " + name);
  if (cloud.rows == 0 && cloud.has_rings()) {
    const std::size_t rings = *std::max_element(cloud.ring.begin(), cloud.ring.end()) + 1U;
    if (rings > L || 2 * rings <= L)
      return bad(what, "its ring field numbers " + std::to_string(rings) + " lasers, sensor profile " + name + " has " +
                           std::to_string(L));
  }

  // The points in the sensor frame: horizontal range, azimuth, height.
  const Pose T_sensor_cloud = cloud.T_cloud_sensor.inverse();
  std::vector<double> rho(n), theta(n), z(n);
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d q = T_sensor_cloud * cloud.points[i].cast<double>();
    rho[i] = std::hypot(q.x(), q.y());
    theta[i] = std::atan2(q.y(), q.x());
    z[i] = q.z();
  }
  double fire_min = std::numeric_limits<double>::infinity();
  for (const auto& l : profile.lasers) fire_min = std::min(fire_min, l.fire_us);
  std::vector<Laser> lasers(L);
  bool any_fire = false, any_side = false;
  for (std::size_t l = 0; l < L; ++l) {
    const ProfileLaser& p = profile.lasers[l];
    Laser& b = lasers[l];
    b.tan_el = std::tan(p.elevation_deg * kDeg);
    b.cos_el = std::cos(p.elevation_deg * kDeg);
    b.z0 = p.z_offset;
    b.side = p.horiz_offset;
    b.az = p.azimuth_deg * kDeg;
    b.fire = kTwoPi * profile.rate_hz * (p.fire_us - fire_min) * 1e-6;
    any_fire = any_fire || b.fire != 0.0;
    any_side = any_side || b.side != 0.0;
  }

  // First, each point's laser by height alone (the nearest cone).
  std::vector<std::uint16_t> ring(n);
  for (std::size_t i = 0; i < n; ++i) {
    double best = std::numeric_limits<double>::infinity(), rb = 0.0;
    for (std::size_t l = 0; l < L; ++l) {
      const double v = std::abs(vertical(lasers[l], rho[i], z[i], rb));
      if (v < best) {
        best = v;
        ring[i] = static_cast<std::uint16_t>(l);
      }
    }
  }

  // The columns a turn: the profile's, or 2π over the median azimuth step between a laser's
  // neighbouring points (missing returns make some steps multiples of it).
  std::uint32_t columns = profile.columns;
  if (columns == 0) {
    std::vector<std::vector<double>> az(L);
    for (std::size_t i = 0; i < n; ++i)
      if (rho[i] > 1.0) az[ring[i]].push_back(theta[i]);
    std::vector<double> gaps;
    for (auto& a : az) {
      std::sort(a.begin(), a.end());
      for (std::size_t k = 1; k < a.size(); ++k)
        if (a[k] - a[k - 1] > 1e-6) gaps.push_back(a[k] - a[k - 1]);
    }
    if (gaps.size() < 16)
      return bad(what, "too few points to find the azimuth step for sensor profile " + name + " (it gives no columns)");
    std::nth_element(gaps.begin(), gaps.begin() + static_cast<std::ptrdiff_t>(gaps.size() / 2), gaps.end());
    const double w = std::round(kTwoPi / gaps[gaps.size() / 2]);
    if (!(w >= kMinColumns && w <= kMaxColumns))
      return bad(what, "its azimuth step gives " + number_text(w) + " columns a turn, outside [16, 2^20] (sensor profile " +
                           name + ")");
    columns = static_cast<std::uint32_t>(w);
  }
  const double W = columns;

  // The grid: its direction, the firing times' share and the sideways offsets' sign, each
  // the way that makes the points' beam azimuths the most coherent on the grid; its phase,
  // their circular mean.
  struct Variant {
    int direction;
    bool fire;
    int side_sign;
    double coherence = -1.0;
    double phase = 0.0;
  };
  std::vector<Variant> variants;
  for (int dir : {-1, 1})
    for (bool f : {false, true})
      for (int s : {1, -1}) {
        if ((f && !any_fire) || (s < 0 && !any_side)) continue;
        variants.push_back({dir, f, s});
      }
  const std::size_t stride = std::max<std::size_t>(1, n / 40000);
  const auto beam_azimuth = [&](std::size_t i, const Laser& b, int side_sign) {
    if (b.side == 0.0 || !(rho[i] > 0.0)) return theta[i];
    return theta[i] - std::asin(std::clamp(side_sign * b.side / rho[i], -1.0, 1.0));
  };
  // The lasers' azimuths on the grid, in the cloud's counter-clockwise sense:
  // column_azimuth = direction · (azimuth offset + firing advance).
  const auto column_azimuth = [&](const Laser& b, const Variant& v) {
    return v.direction * (b.az + (v.fire ? b.fire : 0.0));
  };
  for (Variant& v : variants) {
    std::complex<double> sum = 0.0;
    std::size_t count = 0;
    for (std::size_t i = 0; i < n; i += stride) {
      if (!(rho[i] > 0.5)) continue;
      const Laser& b = lasers[ring[i]];
      sum += std::polar(1.0, W * (beam_azimuth(i, b, v.side_sign) - column_azimuth(b, v)));
      ++count;
    }
    v.coherence = count ? std::abs(sum) / static_cast<double>(count) : 0.0;
    v.phase = std::arg(sum);
  }
  std::size_t pick = 0;
  for (std::size_t k = 1; k < variants.size(); ++k)
    if (variants[k].coherence > variants[pick].coherence + 1e-9) pick = k;
  const Variant& v = variants[pick];
  const double azimuth0 = v.phase / W;
  // Each laser's columns renumbered by the whole steps of its azimuth offset, so that a
  // column holds the points of one azimuth whatever their laser (destaggered, as the range
  // image's neighbours across lasers are then neighbours in space).
  std::vector<double> col_az(L);
  for (std::size_t l = 0; l < L; ++l) {
    const double a = column_azimuth(lasers[l], v);
    col_az[l] = a - std::round(a * W / kTwoPi) * (kTwoPi / W);
  }

  // A real sensor's firings drift from a regular grid as its spin rate varies over a turn:
  // the grid's local phase in each of `sectors` sectors of the turn (the circular mean over
  // the points there, lasers by height), in columns, is taken off before a point's column is
  // rounded and its distance across the beam measured.
  const std::uint32_t sectors = std::max<std::uint32_t>(1, std::min<std::uint32_t>(64, columns / 8));
  const auto grid_position = [&](std::size_t i, std::size_t l) {
    return v.direction * (beam_azimuth(i, lasers[l], v.side_sign) - col_az[l] - azimuth0) * W / kTwoPi;
  };
  const auto sector_of = [&](double g) {
    double f = std::fmod(g / W, 1.0);
    if (f < 0) f += 1.0;
    return std::min<std::uint32_t>(sectors - 1, static_cast<std::uint32_t>(f * sectors));
  };
  std::vector<std::complex<double>> drift_sum(sectors, 0.0);
  for (std::size_t i = 0; i < n; ++i) {
    if (!(rho[i] > 0.5)) continue;
    const double g = grid_position(i, ring[i]);
    drift_sum[sector_of(g)] += std::polar(1.0, kTwoPi * g);
  }
  std::vector<double> drift(sectors, 0.0);
  for (std::uint32_t k = 0; k < sectors; ++k)
    if (std::abs(drift_sum[k]) > 0.0) drift[k] = std::arg(drift_sum[k]) / kTwoPi;

  // Then each point's laser and column by its distance from the beam: the lasers whose
  // cones lie within half a column's width of the nearest are tried across the beam too.
  std::vector<std::uint32_t> column(n);
  std::vector<double> off(n);
  std::vector<double> vert(L), rbs(L);
  const double half_step = kPi / W;
  for (std::size_t i = 0; i < n; ++i) {
    double vmin = std::numeric_limits<double>::infinity();
    for (std::size_t l = 0; l < L; ++l) {
      vert[l] = std::abs(vertical(lasers[l], rho[i], z[i], rbs[l]));
      vmin = std::min(vmin, vert[l]);
    }
    const double reach = vmin + rho[i] * half_step;
    double best = std::numeric_limits<double>::infinity();
    for (std::size_t l = 0; l < L; ++l) {
      if (vert[l] > reach) continue;
      double g = grid_position(i, l);
      g -= drift[sector_of(g)];
      const double c = std::round(g);
      const double t = (g - c) * (kTwoPi / W) * rbs[l];
      const double d2 = vert[l] * vert[l] + t * t;
      if (d2 < best) {
        best = d2;
        ring[i] = static_cast<std::uint16_t>(l);
        const double m = std::fmod(c, W);
        column[i] = static_cast<std::uint32_t>(m < 0 ? m + W : m) % columns;
      }
    }
    off[i] = std::sqrt(best);
  }
  std::vector<double> sorted = off;
  std::nth_element(sorted.begin(), sorted.begin() + static_cast<std::ptrdiff_t>(n / 2), sorted.end());
  fit.points = n;
  fit.median_off_beam_m = sorted[n / 2];
  fit.direction = v.direction;
  fit.firing_times = v.fire;
  // A laser counts as hit with a hundredth of a laser's share of the points (a few stray
  // points do not make a laser of a sparser sensor).
  std::vector<std::size_t> per_laser(L, 0);
  for (std::size_t i = 0; i < n; ++i) ++per_laser[ring[i]];
  const std::size_t least = std::max<std::size_t>(1, n / (100 * L));
  fit.lasers_hit = static_cast<std::size_t>(
      std::count_if(per_laser.begin(), per_laser.end(), [&](std::size_t c) { return c >= least; }));
  if (n >= 100 * L && 2 * fit.lasers_hit < L)
    return bad(what, "only " + std::to_string(fit.lasers_hit) + " of the " + std::to_string(L) +
                         " lasers of sensor profile " + name + " have points: the scan has fewer lasers than the profile");
  if (!(fit.median_off_beam_m <= fit.limit_m)) {
    std::ostringstream m;
    m.setf(std::ios::fixed);
    m.precision(1);
    m << "its points lie a median " << fit.median_off_beam_m * 1e3 << " mm from the beams of sensor profile " << name
      << ", more than " << kOffBeamSteps << " range steps (" << fit.limit_m * 1e3 << " mm): not this sensor's scan";
    return bad(what, m.str());
  }

  SensorGeometry g;
  g.columns = columns;
  g.direction = v.direction;
  g.azimuth0 = azimuth0;
  g.source = "profile " + name;
  g.sensor = profile.sensor;
  for (std::size_t l = 0; l < L; ++l) {
    const Laser& b = lasers[l];
    g.elevation.push_back(std::atan(b.tan_el));
    g.z_offset.push_back(b.z0);
    if (b.side != 0.0) {
      // the beam origin across the beam: at the column's azimuth + π/2, the beam turned back
      g.column_azimuth.push_back(col_az[l] + kPi / 2.0);
      g.radial_offset.push_back(v.side_sign * b.side);
      g.beam_azimuth.push_back(-kPi / 2.0);
    } else {
      g.column_azimuth.push_back(col_az[l]);
      g.radial_offset.push_back(0.0);
      g.beam_azimuth.push_back(0.0);
    }
  }
  cloud.ring = std::move(ring);
  cloud.column = std::move(column);
  cloud.geometry = std::move(g);
  return fit;
}

}  // namespace lex3d::residual
