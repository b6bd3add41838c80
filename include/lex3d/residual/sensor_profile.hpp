#pragma once
/// \file
/// Sensor profiles (formats/sensor_profile.md): a spinning lidar's laser table as its user
/// knows it (a vendor calibration), given to the sensor-geometry coding of the residual
/// layer in place of a table estimated from the points. `apply_sensor_profile` assigns each
/// point of a scan to a laser of the table and a column of its azimuth grid and sets the
/// scan's SensorGeometry, as the readers of raw sensor logs do.

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "lex3d/core/cloud.hpp"
#include "lex3d/core/status.hpp"

// The public API: exported by liblex3d.so, which hides everything else.
#pragma GCC visibility push(default)

namespace lex3d::residual {

/// One laser of a profile, as the vendor tables give it.
struct ProfileLaser {
  double elevation_deg = 0.0;  ///< beam elevation, degrees, [-90, 90]
  double azimuth_deg = 0.0;    ///< azimuth offset from the column's azimuth, degrees, in the spin direction, [-180, 180]
  double fire_us = 0.0;        ///< firing time within a firing sequence, microseconds, [-1e6, 1e6] (relative)
  double z_offset = 0.0;       ///< height of the beam origin, metres, [-10, 10]
  double horiz_offset = 0.0;   ///< beam origin's offset across the beam (to its left seen from above), metres, [-10, 10]
};

/// A sensor profile (formats/sensor_profile.md).
struct SensorProfile {
  std::string sensor;              ///< the sensor's name ("" when the file gives none)
  std::string origin;              ///< the file it was read from (messages name it)
  std::uint32_t columns = 0;       ///< firings a turn, [16, 2^20]
  double range_step = 0.0;         ///< the sensor's distance resolution, metres, (0, 1]
  double rate_hz = 10.0;           ///< turns a second the columns and firing times are for, (0, 100]
  std::vector<ProfileLaser> lasers;  ///< 1..1024 lasers, in the table's order (the stored laser numbers)
};

/// Parses a profile from `text` (the JSON of formats/sensor_profile.md, or a Velodyne
/// `db.xml` / VeloView calibration XML, told apart by the first character). `origin` names
/// the file in every message and is kept in the result. kBadData for a syntax error, a
/// missing field, a value of the wrong type, a non-finite value or one out of its range.
[[nodiscard]] StatusOr<SensorProfile> parse_sensor_profile(std::string_view text, const std::string& origin);

/// How a scan's points fit a profile.
struct ProfileFit {
  std::size_t points = 0;             ///< points assigned (every point of the scan)
  std::size_t lasers = 0;             ///< lasers of the table
  std::size_t lasers_hit = 0;         ///< lasers of the table with at least one point
  double median_off_beam_m = 0.0;     ///< median distance of the points from their beams, metres
  double limit_m = 0.0;               ///< the largest median accepted (kOffBeamSteps range steps)
  int direction = 1;                  ///< the azimuth grid's direction found (+1: azimuth grows with the column)
  bool firing_times = false;          ///< the firing times shift the lasers' azimuths (measured to fit better)
};

/// Largest median distance of a scan's points from their beams, in range steps of the
/// profile, for the profile to be taken as the scan's sensor.
inline constexpr double kOffBeamSteps = 2.0;

/// Assigns every point of `cloud` (sensor at cloud.T_cloud_sensor) to the laser of
/// `profile` whose beam passes nearest it and to the column of the azimuth grid it falls
/// in, and sets cloud.ring, cloud.column and cloud.geometry (source "profile <file>").
/// The grid's phase and direction and whether the points' azimuths include the firing
/// times are taken from the points (the most coherent grid). `what` names the scan in (empty: none)
/// messages. kBadData (nothing changed) when the scan's own laser count (a ring field, an
/// organised cloud's rows) differs from the profile's, when fewer than half the profile's
/// lasers get a hundredth of a laser's share of the points (a scan of fewer lasers), or when
/// the median distance of the points from their beams exceeds kOffBeamSteps range steps. An empty cloud is left as it
/// is. Deterministic.
[[nodiscard]] StatusOr<ProfileFit> apply_sensor_profile(Cloud& cloud, const SensorProfile& profile,
                                                        const std::string& what);

}  // namespace lex3d::residual

#pragma GCC visibility pop
