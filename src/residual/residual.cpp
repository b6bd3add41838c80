// The residual layer (formats/model.md §2.5, include/lex3d/residual/residual.hpp).
//
// Encoder: mark the word points that have an input point within E (kept), mark the
// input points a kept word point explains, and code the others. Coded points are
// ordered along rows of elevation (half the data's vertical beam spacing high) by
// azimuth, or in input order when that codes smaller, and predicted from the point
// coded before: same range, same elevation, azimuth advanced by the last step. The
// residuals are quantised with steps that make every error component at most q/2 in
// metres (range step q, angle steps q / range), and every decoded point is checked
// against its input point; a point that fails (near the sensor or a pole) is coded
// as a Cartesian offset instead ("escaped").

#include "lex3d/residual/residual.hpp"
#include "lex3d/residual/attributes.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <unordered_map>
#include <functional>
#include <future>
#include <optional>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>

#include "lex3d/core/parallel.hpp"
#include "lex3d/model/model.hpp"
#include "lex3d/range/range_image.hpp"
#include "codec/bytes.hpp"
#include "residual/acquisition.hpp"
#include "residual/angles.hpp"
#include "residual/counting.hpp"
#include "residual/laser.hpp"
#include "residual/lattice.hpp"
#include "residual/layer_lasers.hpp"
#include "residual/point_ball_grid.hpp"
#include "residual/range_coder.hpp"
#include "residual/voxel.hpp"

namespace lex3d::residual {
namespace {

using detail::BitModel;
using detail::IntModel;
using detail::RangeDecoder;
using detail::RangeEncoder;
using detail::kMaxVoxelDepth;
using detail::PointBallGrid;

constexpr double kPi = 3.14159265358979323846;
constexpr std::uint64_t kHeadBytes = 32;  // max_error f64, step f64, word_points u64, coded_points u64
/// An RESW payload (formats/model.md §2.6) starts with coding u32 and this marker, which
/// no RESD payload can start with (its first field, max_error, would read as a NaN).
constexpr std::uint32_t kSweepMarker = 0xFFFFFFFFU;
/// A sensor-geometry payload whose fields leave out T_sensor_head, the identity, has this
/// marker instead (formats/model.md §2.8, format 1.11).
constexpr std::uint32_t kLaserShortMarker = 0xFFFFFFFEU;
constexpr std::uint32_t kCodingSweep = 1;
constexpr std::uint64_t kSweepPrefixBytes = 8;  // coding u32, marker u32
constexpr std::uint64_t kSweepExtraBytes = 8;   // cell f64, after the RESD header fields
constexpr std::uint32_t kCodingVoxel = 2;
constexpr std::uint64_t kVoxelExtraBytes = 28;  // origin 3 f64, depth u32, after the RESD header fields
constexpr std::uint32_t kCodingLaser = 3;
constexpr std::uint32_t kCodingAcquisition = 4;
constexpr std::uint64_t kAcquisitionExtraBytes = 28;  // origin 3 f64, fit_pulses u32, after the RESD header fields
/// The line fits of x and y the encoder tries (formats/model.md §2.11.1), 0 for format
/// 1.12's step. On Autzen (GPS-time order) the fit coded 1.3 % fewer bytes than the step
/// at E = 14 mm, 2.8 % at 0.1 m, 4.9 % at 0.15 m and 7.1 % at 0.2 m: it averages out the
/// grid's rounding of the pulses before, which a step from the last pulse carries whole.
const std::vector<std::uint32_t> kAcquisitionFits = {0, 8, 12, 16};
/// Bit 0 of an RESG payload's order field (formats/model.md §2.12): the cells' points
/// stacked, lowest first (format 1.13).
constexpr std::uint32_t kLatticeStackedBit = 1U;
/// The cell shapes the encoder tries (§2.11.2): cubes and cells 1.5 and 2 times taller
/// than wide, each with its z planes from the lowest point and half a cell lower.
const std::vector<detail::CellShape> kAcquisitionShapes = {{1.0, 0.0}, {1.0, 0.5}, {1.5, 0.0},
                                                           {1.5, 0.5}, {2.0, 0.0}, {2.0, 0.5}};
constexpr std::uint32_t kCodingLattice = 5;
constexpr std::uint64_t kLatticeExtraBytes = 44;  // origin 3 f64, pitch f64, columns u32, rows u32, reserved u32
/// A lattice layer has at most this many cells a coded point, and 64 more (formats/model.md §2.12).
constexpr std::uint64_t kMaxLatticeCellsPerPoint = 4;
/// Shares of 2E' the sensor-geometry coding tries for its range step (encoder only): the
/// largest for a table that reproduces the points (read from a sensor's metadata), the
/// smaller two for an estimated table, which leave room for corrections across the beams.
constexpr double kLaserShares[] = {0.985, 0.9, 0.75};
/// LayerOptions::mse (encoder only): the sensor-geometry coding's one share of 2E' (a range
/// step of E') and the scale of λ in its choice of beam lengths; the other codings code to
/// kMseOthersShare E, the bound at which the default's range step for an estimated table
/// (share kLaserShares[1]) is this one. Measured at equal D1 PSNR (bench/rd.sh, lex3d
/// alone, 70-86 dB) against shares 0.35-0.6 and scales 1-3 (bench/README.md, "Beam
/// lengths chosen a laser at a time, and the mean-squared-error objective").
constexpr double kMseShare = 0.5;
constexpr double kMseLambdaScale = 2.0;
constexpr double kMseOthersShare = kMseShare / kLaserShares[1];
/// The voxel coding is not coded in full when its trial window costs this many times the
/// sensor-geometry coding's bits a point (encoder only).
constexpr double kLaserSkipRatio = 1.6;
/// With a laser table read from the sensor, neither the voxel nor the spherical codings are
/// tried further when the spherical trial window costs this many times the sensor-geometry
/// coding's bits a point (encoder only). On the Ouster scans at 5-50 mm the window cost
/// 2.1-2.5 times the sensor-geometry bits and the full spherical coding 1.4-2.1 times.
constexpr double kExactLaserSkipRatio = 2.0;
/// What a payload of a coding adds to its stream besides the fields every coding has.
constexpr std::uint64_t extra_bytes(std::uint32_t coding) {
  return coding == kCodingSweep   ? kSweepPrefixBytes + kSweepExtraBytes
         : coding == kCodingVoxel ? kSweepPrefixBytes + kVoxelExtraBytes
         : coding == kCodingLaser ? kSweepPrefixBytes + detail::kLaserFieldBytes
         : coding == kCodingAcquisition ? kSweepPrefixBytes + kAcquisitionExtraBytes
         : coding == kCodingLattice ? kSweepPrefixBytes + kLatticeExtraBytes
                                  : 0;
}
/// A voxel layer's origin lies within this many metres of the model frame's origin.
constexpr double kMaxVoxelOrigin = 1e9;
/// A decoder accepts at most this many voxels per payload byte: a node's occupancy costs
/// at least seven binary decisions of >= 0.011 bits (so about 100 nodes a byte), and a
/// node holds at most eight voxels.
constexpr std::uint64_t kMaxVoxelsPerByte = 1000;
/// The voxel coding's trial window, in spherical trial windows (encoder only); one beside a
/// sensor-geometry coding, whose bits rule out the voxel coding long before the window's size
/// matters (bench/fast.sh's 300 codings: 299 the same bytes, one 5.8 % smaller).
constexpr std::size_t kVoxelTrialSpan = 4;
/// The voxel coding is not coded in full when its trial costs this many times the
/// spherical winner's (encoder only). Measured, voxel / spherical on the trial windows
/// and in full: single spinning-lidar scans (kitti00, balm) 1.32-1.84 and 1.36-1.95;
/// where voxels win (a balm map, scan001, room_scan1 at 4 cm) at most 0.88 and 0.81.
constexpr double kVoxelSkipRatio = 1.25;
/// The spherical winner is not coded in full when the voxel trial costs less than this
/// share of its bits (encoder only). Measured where voxels win: trial 0.60-0.88, in full
/// 0.56-0.81 (the balm map, scan001, room_scan1 at 4 cm); where they lose, the trial never
/// went below 1.04. With the octree contexts of format 1.8 single scans at 6-20 cm come
/// close: a balm scan at 10 cm had a trial of 0.84 and lost in full (1.07), while trials
/// of 0.46-0.77 (kitti00, HDL-32E, balm at 15-20 cm) won in full (0.69-0.84).
constexpr double kSphericalSkipRatio = 0.8;
/// Beside a sensor-geometry coding, the spherical winner is coded first on a sample spread
/// over its order (kSampleRuns runs of it, every kSampleEvery-th kept: a quarter of the
/// points with only 8 breaks) and is not coded in full where the sample costs this many
/// times the sensor-geometry coding's bits a point or more (encoder only). Measured on 593
/// codings (every kitti00 and balm scan, the newer_college, Velodyne, indoor, Ouster, LAS
/// and re-sampled inputs at 5, 14, 35 and 100 mm): where the spherical coding won in full
/// its sample cost at most 1.12 times the sensor-geometry bits; kitti00 at 14 mm 1.30-1.32.
/// The middle window does not tell so well: 1.42 where the spherical coding won (balm).
constexpr double kSampleSkipRatio = 1.2;
constexpr std::size_t kSampleRuns = 32;
constexpr std::size_t kSampleEvery = 4;
/// Sweep coding: the elevation follows the slope over this many decoded points back.
constexpr unsigned kSlopeSpan = 7;
/// Largest |elevation / azimuth| slope the sweep coding extrapolates.
constexpr double kMaxSlope = 8.0;
/// The step is this share of the largest step whose error bound is E (2E/sqrt(3)),
/// leaving room for the second-order terms of spherical quantisation.
constexpr double kStepShare = 0.95;
/// Azimuth steps larger than this are not extrapolated (a row change or a gap), radians.
constexpr double kMaxAzimuthStep = 0.05;
/// Smallest |cos(elevation)| the azimuth step divides by (about 89.1 degrees).
constexpr double kMinCosElevation = 1.0 / 64.0;
/// Points of the window on which the two coding orders are compared (encoder only).
constexpr std::size_t kOrderTrialPoints = 8192;
using detail::kMaxSteps;
/// A decoder accepts at most this many coded points per payload byte (each point costs
/// at least four binary decisions of >= 0.011 bits).
constexpr std::uint64_t kMaxPointsPerByte = 200;
/// The same for a sensor-geometry layer of range predictor 4 or 5, whose mixed occupancy and
/// zero decisions cost at least log2(4096 / 4095) bits each: at most 11,355 points a byte.
constexpr std::uint64_t kMaxMixedPointsPerByte = 12000;

// ---------------------------------------------------------------------------------------
// The point predictor and quantiser shared by encoder and decoder
// ---------------------------------------------------------------------------------------

using detail::wrap_angle;

struct Spherical {
  double r, azimuth, elevation;
};

Spherical to_spherical(const Eigen::Vector3d& p) {
  const double r = p.norm();
  if (r == 0.0) return {0.0, 0.0, 0.0};
  return {r, std::atan2(p.y(), p.x()), std::asin(std::clamp(p.z() / r, -1.0, 1.0))};
}

/// The decoder's state: the last decoded point, azimuth step and (for the sweep coding)
/// the elevation-over-azimuth slope across the last kSlopeSpan points.
struct Predictor {
  double r = 0.0, azimuth = 0.0, elevation = 0.0, azimuth_step = 0.0, slope = 0.0;
  Eigen::Vector3d last = Eigen::Vector3d::Zero();
  std::int64_t last_kr = 0, last_kl = 0, last_ka = 0;
  bool last_escaped = false;
  std::array<double, 8> past_elevation{}, past_azimuth{};  // ring of the last 8 points
  std::uint64_t decoded_points = 0;

  void update(const Eigen::Vector3d& decoded, const Spherical& s) {
    const double step = wrap_angle(s.azimuth - azimuth);
    azimuth_step = std::abs(step) <= kMaxAzimuthStep ? step : 0.0;
    r = s.r;
    azimuth = s.azimuth;
    elevation = s.elevation;
    last = decoded;
    past_elevation[decoded_points % 8] = s.elevation;
    past_azimuth[decoded_points % 8] = s.azimuth;
    ++decoded_points;
    slope = 0.0;
    if (decoded_points > kSlopeSpan && azimuth_step != 0.0) {
      const std::size_t back = (decoded_points - 1 - kSlopeSpan) % 8;
      const double da = wrap_angle(s.azimuth - past_azimuth[back]);
      if (std::abs(da) > 1e-7 && std::abs(da) <= kSlopeSpan * kMaxAzimuthStep)
        slope = std::clamp((s.elevation - past_elevation[back]) / da, -kMaxSlope, kMaxSlope);
    }
  }
};

/// The ranges decoded so far by direction (sweep coding): cells `cell` radians wide in
/// elevation and azimuth, each holding the range and index of the last point decoded in
/// it, in an open-addressing table (kept at most half full).
class AngularMemory {
 public:
  explicit AngularMemory(double cell) : inv_(cell > 0.0 ? 1.0 / cell : 0.0) {
    if (inv_ != 0.0) slots_.assign(1024, Slot{});
  }
  void insert(const Spherical& s, std::uint64_t index) {
    if (inv_ == 0.0) return;
    if (2 * (used_ + 1) > slots_.size()) grow();
    Slot& slot = find(key(s.elevation, s.azimuth, 0, 0));
    if (slot.index == 0) ++used_;
    slot.range = s.r;
    slot.index = index;
  }
  /// The range of a point decoded before `index` - 3 in the cell of (elevation, azimuth)
  /// or, failing that, the first of its four neighbours (up, down, right, left) with one.
  [[nodiscard]] std::optional<double> near(double elevation, double azimuth, std::uint64_t index) const {
    if (inv_ == 0.0) return std::nullopt;
    static constexpr int kOffsets[5][2] = {{0, 0}, {1, 0}, {-1, 0}, {0, 1}, {0, -1}};
    for (const auto& o : kOffsets) {
      const Slot& slot = slots_[position(key(elevation, azimuth, o[0], o[1]))];
      if (slot.index != 0 && slot.index + 3 < index) return slot.range;
    }
    return std::nullopt;
  }

 private:
  struct Slot {
    std::uint64_t key = 0;
    std::uint64_t index = 0;  // 1-based; 0: empty
    double range = 0.0;
  };
  [[nodiscard]] std::uint64_t key(double elevation, double azimuth, int drow, int dcol) const {
    const auto cell = [&](double a) { return static_cast<std::int64_t>(std::floor(std::clamp(a * inv_, -1e9, 1e9))); };
    const auto row = static_cast<std::uint64_t>(cell(elevation) + drow);
    const auto col = static_cast<std::uint64_t>(cell(azimuth) + dcol);
    return (row << 32) ^ (col & 0xFFFFFFFFULL);
  }
  static std::size_t hash(std::uint64_t k) {
    k ^= k >> 33;
    k *= 0xff51afd7ed558ccdULL;
    k ^= k >> 33;
    return static_cast<std::size_t>(k);
  }
  /// Where `k` is, or the empty slot where it would go.
  [[nodiscard]] std::size_t position(std::uint64_t k) const {
    const std::size_t mask = slots_.size() - 1;
    std::size_t i = hash(k) & mask;
    while (slots_[i].index != 0 && slots_[i].key != k) i = (i + 1) & mask;
    return i;
  }
  Slot& find(std::uint64_t k) {
    Slot& slot = slots_[position(k)];
    slot.key = k;
    return slot;
  }
  void grow() {
    std::vector<Slot> old = std::move(slots_);
    slots_.assign(2 * old.size(), Slot{});
    for (const Slot& o : old)
      if (o.index != 0) slots_[position(o.key)] = o;
  }
  double inv_;
  std::vector<Slot> slots_;
  std::size_t used_ = 0;
};

/// The point that residuals (kr, ke, ka) decode to, sensor frame; its spherical form in `s`.
Eigen::Vector3d spherical_point(const Predictor& pr, double q, std::int64_t kr, std::int64_t ke, std::int64_t ka,
                                Spherical& s) {
  s.r = pr.r + static_cast<double>(kr) * q;
  const double rho = std::max(s.r, q);
  s.elevation = pr.elevation + static_cast<double>(ke) * (q / rho);
  const double c = std::max(std::abs(std::cos(s.elevation)), kMinCosElevation);
  s.azimuth = wrap_angle(pr.azimuth + pr.azimuth_step + static_cast<double>(ka) * (q / (rho * c)));
  const double ce = std::cos(s.elevation);
  return {s.r * ce * std::cos(s.azimuth), s.r * ce * std::sin(s.azimuth), s.r * std::sin(s.elevation)};
}

/// Sweep coding: the azimuth step is taken at the last elevation, and the elevation is
/// predicted along the slope for the decoded azimuth change.
double sweep_azimuth_step(const Predictor& pr, double q, double rho) {
  return q / (rho * std::max(std::abs(std::cos(pr.elevation)), kMinCosElevation));
}
Eigen::Vector3d sweep_point(const Predictor& pr, double q, std::int64_t kr, std::int64_t ke, std::int64_t ka,
                            Spherical& s) {
  s.r = pr.r + static_cast<double>(kr) * q;
  const double rho = std::max(s.r, q);
  const double da = pr.azimuth_step + static_cast<double>(ka) * sweep_azimuth_step(pr, q, rho);
  s.azimuth = wrap_angle(pr.azimuth + da);
  s.elevation = pr.elevation + pr.slope * da + static_cast<double>(ke) * (q / rho);
  const double ce = std::cos(s.elevation);
  return {s.r * ce * std::cos(s.azimuth), s.r * ce * std::sin(s.azimuth), s.r * std::sin(s.elevation)};
}

Eigen::Vector3f to_cloud_frame(const Pose& T_cloud_sensor, const Eigen::Vector3d& p_sensor) {
  return (T_cloud_sensor * p_sensor).cast<float>();
}

using detail::quantise;

/// The models of one coded-point stream: each spherical residual is conditioned on the
/// classes of two residuals the decoder already has (formats/model.md §2.5.3). (Three,
/// 512 contexts, coded kitti00/000000 1.8 % larger: too many contexts to learn.)
struct PointModels {
  static constexpr int kContexts = IntModel::kClasses * IntModel::kClasses;
  BitModel escape[2];
  IntModel range{kContexts}, elevation{kContexts}, azimuth{kContexts};
  IntModel cartesian[3];
  std::int64_t kr2 = 0, ka2 = 0;  // the range and azimuth residuals before the last ones

  int range_ctx(const Predictor& p) const { return IntModel::context_of(p.last_kr, kr2); }
  /// Sweep coding: the second class is that of the range step to the point decoded
  /// earlier in the predicted direction (0 when there is none).
  static int sweep_range_ctx(const Predictor& p, std::optional<double> near, double q) {
    const double d = near ? std::clamp((*near - p.r) / q, -1e9, 1e9) : 0.0;
    return IntModel::context_of(p.last_kr, static_cast<std::int64_t>(std::llround(d)));
  }
  int elevation_ctx(const Predictor& p, std::int64_t kr) const { return IntModel::context_of(p.last_kl, kr); }
  int azimuth_ctx(const Predictor& p) const { return IntModel::context_of(p.last_ka, ka2); }
  void shift(Predictor& p, std::int64_t kr, std::int64_t kl, std::int64_t ka) {
    kr2 = p.last_kr;
    ka2 = p.last_ka;
    p.last_kr = kr;
    p.last_kl = kl;
    p.last_ka = ka;
  }
};

/// Codes `points` (indices into `input`) in the given order; returns the stream and the
/// number of escaped points. `spherical[i]`: input point i in sensor-centred spherical
/// coordinates (to_spherical), for every point in `order`.
std::vector<std::uint8_t> code_points(RangeEncoder enc, const std::vector<Eigen::Vector3f>& input,
                                      const std::vector<Spherical>& spherical, const std::vector<std::uint32_t>& order,
                                      const Pose& T_cloud_sensor, const Pose& T_sensor_cloud, double q, double bound,
                                      std::size_t& escaped, std::size_t& coded_count, bool thin, double sweep_cell,
                                      std::vector<std::uint32_t>* sources = nullptr,
                                      std::size_t give_up_bytes = std::numeric_limits<std::size_t>::max(),
                                      bool* gave_up = nullptr) {
  const bool sweep = sweep_cell > 0.0;
  AngularMemory memory(sweep_cell);
  PointModels m;
  Predictor pr;
  escaped = 0;
  coded_count = 0;
  const double e2 = bound * bound;  // E' of formats/model.md §2.5.4
  // Thinning: the points decoded so far, to skip an input point one of them already explains.
  PointBallGrid seen(bound, thin ? order.size() : 0);
  auto remember = [&](const Eigen::Vector3f& d) {
    if (thin) seen.insert(d);
  };
  if (gave_up) *gave_up = false;
  for (std::uint32_t idx : order) {
    const Eigen::Vector3d truth_cloud = input[idx].cast<double>();
    if (thin && seen.any_within(truth_cloud)) continue;
    // (a trial that only needs to know whether it stays within give_up_bytes stops once the
    // bytes written exceed them: the finished stream could only be longer)
    if ((coded_count & 255U) == 0 && enc.bytes_out() > give_up_bytes && gave_up) {
      *gave_up = true;
      return {};
    }
    ++coded_count;
    if (sources) sources->push_back(idx);
    const Eigen::Vector3d p = T_sensor_cloud * truth_cloud;
    const Spherical& t = spherical[idx];
    // Spherical attempt: range first (the angle steps depend on it), then elevation, azimuth.
    bool ok = true;
    std::int64_t kr = 0, ke = 0, ka = 0;
    ok = quantise(t.r - pr.r, q, kr);
    Spherical s{};
    Eigen::Vector3d decoded;
    if (ok) {
      const double r_hat = pr.r + static_cast<double>(kr) * q;
      const double rho = std::max(r_hat, q);
      if (sweep) {  // azimuth first: the elevation follows the slope for its change
        ok = quantise(wrap_angle(t.azimuth - pr.azimuth - pr.azimuth_step), sweep_azimuth_step(pr, q, rho), ka);
        const double da = pr.azimuth_step + static_cast<double>(ka) * sweep_azimuth_step(pr, q, rho);
        ok = ok && quantise(t.elevation - (pr.elevation + pr.slope * da), q / rho, ke);
      } else {
        ok = quantise(t.elevation - pr.elevation, q / rho, ke);
        const double e_hat = pr.elevation + static_cast<double>(ke) * (q / rho);
        const double c = std::max(std::abs(std::cos(e_hat)), kMinCosElevation);
        ok = ok && quantise(wrap_angle(t.azimuth - pr.azimuth - pr.azimuth_step), q / (rho * c), ka);
      }
      if (ok) {
        decoded = sweep ? sweep_point(pr, q, kr, ke, ka, s) : spherical_point(pr, q, kr, ke, ka, s);
        const Eigen::Vector3f back_f = to_cloud_frame(T_cloud_sensor, decoded);
        ok = r_hat > 0.0 && (back_f.cast<double>() - truth_cloud).squaredNorm() <= e2;
        if (ok) remember(back_f);
      }
    }
    enc.put(m.escape[pr.last_escaped ? 1 : 0], !ok);
    if (ok) {
      const int range_ctx = sweep ? PointModels::sweep_range_ctx(
                                        pr, memory.near(pr.elevation, wrap_angle(pr.azimuth + pr.azimuth_step), coded_count), q)
                                  : m.range_ctx(pr);
      m.range.put(enc, range_ctx, kr);
      m.elevation.put(enc, m.elevation_ctx(pr, kr), ke);
      m.azimuth.put(enc, m.azimuth_ctx(pr), ka);
      m.shift(pr, kr, ke, ka);
      pr.last_escaped = false;
      pr.update(decoded, s);
      memory.insert(s, coded_count);
      continue;
    }
    // Escape: a Cartesian offset from the last decoded point with a quarter step.
    ++escaped;
    const double qc = q / 4.0;
    std::int64_t kc[3];
    for (int a = 0; a < 3; ++a)
      if (!quantise(p[a] - pr.last[a], qc, kc[a]))
        throw std::invalid_argument("residual layer: a point lies beyond 2^30 steps of " + std::to_string(qc) +
                                    " m from the one coded before it");
    for (int a = 0; a < 3; ++a) m.cartesian[a].put(enc, 0, kc[a]);
    Eigen::Vector3d d;
    for (int a = 0; a < 3; ++a) d[a] = pr.last[a] + static_cast<double>(kc[a]) * qc;
    const Eigen::Vector3f back_f = to_cloud_frame(T_cloud_sensor, d);
    remember(back_f);
    if ((back_f.cast<double>() - truth_cloud).squaredNorm() > e2)
      throw std::invalid_argument("residual layer: an error bound of " + std::to_string(bound) +
                                  " m is below the float32 precision of a point's coordinates");
    pr.last_escaped = true;
    const Spherical sd = to_spherical(d);
    pr.update(d, sd);
    memory.insert(sd, coded_count);
  }
  return enc.finish();
}

// ---------------------------------------------------------------------------------------
// Voxel coding (formats/model.md §2.7)
// ---------------------------------------------------------------------------------------

/// A voxel layer: the grid and the coded stream.
struct VoxelLayer {
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();
  double cell = 0.0;
  int depth = 0;
  std::size_t voxels = 0;
  std::vector<std::uint8_t> stream;
};

/// The decoded point of voxel (x, y, z): its centre, as every decoder computes it.
Eigen::Vector3f voxel_centre(const Eigen::Vector3d& origin, double cell, std::uint32_t x, std::uint32_t y,
                             std::uint32_t z) {
  return {static_cast<float>(origin.x() + (static_cast<double>(x) + 0.5) * cell),
          static_cast<float>(origin.y() + (static_cast<double>(y) + 0.5) * cell),
          static_cast<float>(origin.z() + (static_cast<double>(z) + 0.5) * cell)};
}

/// The cells of the input points `coded` in a grid of `cell` from `origin` (the corner of
/// their bounding box) as Morton codes, one a point, with the octree depth they need; every
/// point is checked to lie within `bound` of its cell's centre as a decoder computes it
/// (float32 coordinates).
enum class VoxelFit { kOk, kMiss /* a point is not within bound */, kTooDeep /* > kMaxVoxelDepth levels */ };
VoxelFit voxel_codes(const std::vector<Eigen::Vector3f>& input, const std::vector<std::uint32_t>& coded,
                 const Eigen::Vector3d& origin, double cell, double bound, std::vector<std::uint64_t>& codes,
                 int& depth) {
  const double inv = 1.0 / cell;
  double top = 0.0;
  for (const std::uint32_t i : coded) top = std::max(top, ((input[i].cast<double>() - origin) * inv).maxCoeff());
  if (!(top < static_cast<double>(1U << kMaxVoxelDepth) - 1.0)) return VoxelFit::kTooDeep;
  depth = 1;
  while (depth < kMaxVoxelDepth && std::ldexp(1.0, depth) <= top) ++depth;
  codes.resize(coded.size());
  const double b2 = bound * bound;
  for (std::size_t k = 0; k < coded.size(); ++k) {
    const Eigen::Vector3d p = input[coded[k]].cast<double>();
    std::uint32_t c[3];
    for (int a = 0; a < 3; ++a) c[a] = static_cast<std::uint32_t>(std::floor((p[a] - origin[a]) * inv));
    codes[k] = detail::morton(c[0], c[1], c[2]);
    if (!((voxel_centre(origin, cell, c[0], c[1], c[2]).cast<double>() - p).squaredNorm() <= b2)) return VoxelFit::kMiss;
  }
  return VoxelFit::kOk;
}

Eigen::Vector3d corner_of(const std::vector<Eigen::Vector3f>& input, const std::vector<std::uint32_t>& coded) {
  Eigen::Vector3d lo = input[coded[0]].cast<double>();
  for (const std::uint32_t i : coded) lo = lo.cwiseMin(input[i].cast<double>());
  return lo;
}

/// The widest cell whose centre is within `bound` of every point of the cell.
double voxel_cell(double bound) { return 2.0 * bound / std::sqrt(3.0) * (1.0 - 1e-6); }

/// Codes the input points `coded` as the voxels that hold them, after the keep mask that
/// `enc` holds already. The cells are voxel_cell(bound) wide, and narrowed when a point is
/// not within `bound` of its cell's centre as a decoder computes it. nullopt when there is
/// nothing to code or the octree would need more than kMaxVoxelDepth levels.
std::optional<VoxelLayer> voxel_layer(RangeEncoder enc, const std::vector<Eigen::Vector3f>& input,
                                      const std::vector<std::uint32_t>& coded, double bound,
                                      std::size_t give_up_bytes = std::numeric_limits<std::size_t>::max(),
                                      bool* gave_up = nullptr) {
  if (gave_up) *gave_up = false;
  if (coded.empty()) return std::nullopt;
  VoxelLayer v;
  v.origin = corner_of(input, coded);
  v.cell = voxel_cell(bound);
  std::vector<std::uint64_t> leaves;
  for (int attempt = 0;; ++attempt) {
    if (attempt == 8) return std::nullopt;  // float32 cannot hold centres this close (not seen)
    const VoxelFit fit = voxel_codes(input, coded, v.origin, v.cell, bound, leaves, v.depth);
    if (fit == VoxelFit::kOk) break;
    if (fit == VoxelFit::kTooDeep) return std::nullopt;
    v.cell *= 1.0 - 1e-3;
  }
  std::sort(leaves.begin(), leaves.end());
  leaves.erase(std::unique(leaves.begin(), leaves.end()), leaves.end());
  v.voxels = leaves.size();
  if (!detail::encode_occupancy(enc, leaves, v.depth, detail::OccupancyContexts::kMixed, give_up_bytes)) {
    if (gave_up) *gave_up = true;
    return std::nullopt;
  }
  v.stream = enc.finish();
  return v;
}

using codec::bytes::ld_f64;
using codec::bytes::ld_u64;
using codec::bytes::put_f64;
using codec::bytes::put_u64;

/// The `span` consecutive entries of `coded` about its middle (a trial's window; span <= size).
std::vector<std::uint32_t> middle_window(const std::vector<std::uint32_t>& coded, std::size_t span) {
  const std::size_t at = coded.size() / 2 - span / 2;
  return {coded.begin() + static_cast<std::ptrdiff_t>(at), coded.begin() + static_cast<std::ptrdiff_t>(at + span)};
}

/// The row of elevation a point lies in (row_order's rows, row_height apart).
std::int64_t row_of(const Spherical& s, double row_height) { return static_cast<std::int64_t>(std::floor(s.elevation / row_height)); }

/// Orders the coded points along rows of elevation by azimuth.
std::vector<std::uint32_t> row_order(const std::vector<Spherical>& spherical, const std::vector<std::uint32_t>& coded,
                                     double row_height) {
  struct Key {
    std::int64_t row;
    double azimuth;
    std::uint32_t index;
  };
  std::vector<Key> keys;
  keys.reserve(coded.size());
  std::int64_t row_lo = std::numeric_limits<std::int64_t>::max(), row_hi = std::numeric_limits<std::int64_t>::min();
  for (std::uint32_t i : coded) {
    const Spherical& s = spherical[i];
    keys.push_back({row_of(s, row_height), s.azimuth, i});
    row_lo = std::min(row_lo, keys.back().row);
    row_hi = std::max(row_hi, keys.back().row);
  }
  const auto by_azimuth = [](const Key& a, const Key& b) {
    if (a.azimuth != b.azimuth) return a.azimuth < b.azimuth;
    return a.index < b.index;
  };
  // (the keys are all distinct, so any sort gives this one order: where the rows are few
  // enough, the keys are bucketed by row first and each row sorted on its own)
  std::vector<Key> sorted;
  if (!keys.empty() && detail::counting_pays(static_cast<std::uint64_t>(row_hi - row_lo) + 1, keys.size())) {
    const std::vector<std::uint32_t> by_row =
        detail::counting_order(keys.size(), static_cast<std::size_t>(row_hi - row_lo) + 1,
                               [&](std::size_t k) { return static_cast<std::size_t>(keys[k].row - row_lo); });
    sorted.reserve(keys.size());
    for (const std::uint32_t k : by_row) sorted.push_back(keys[k]);
    for (std::size_t a = 0, b = 0; a < sorted.size(); a = b) {
      while (b < sorted.size() && sorted[b].row == sorted[a].row) ++b;
      std::sort(sorted.begin() + static_cast<std::ptrdiff_t>(a), sorted.begin() + static_cast<std::ptrdiff_t>(b), by_azimuth);
    }
  } else {
    sorted = std::move(keys);
    std::sort(sorted.begin(), sorted.end(), [&](const Key& a, const Key& b) {
      return a.row != b.row ? a.row < b.row : by_azimuth(a, b);
    });
  }
  std::vector<std::uint32_t> order;
  order.reserve(sorted.size());
  for (const Key& k : sorted) order.push_back(k.index);
  return order;
}

}  // namespace

bool has_coding_field(const std::uint8_t* payload, std::size_t size) {
  // codec::layer_coding: coding u32 and the marker
  if (size < kSweepPrefixBytes) return false;
  const std::uint32_t marker = codec::bytes::ld_u32(payload + 4);
  return marker == kSweepMarker || (marker == kLaserShortMarker && codec::bytes::ld_u32(payload) == kCodingLaser);
}

StatusOr<LayerHeader> read_layer_header(const std::uint8_t* payload, std::size_t size) {
  LayerHeader h;
  std::size_t at = 0;
  if (has_coding_field(payload, size)) {
    h.coding = codec::bytes::ld_u32(payload);
    if (h.coding < kCodingSweep || h.coding > kCodingLattice)
      return bad_data("residual layer coding " + std::to_string(h.coding) + " is unknown (1-5 expected)", 0);
    at = kSweepPrefixBytes;
    h.head_pose = codec::bytes::ld_u32(payload + 4) == kSweepMarker;
    const std::uint64_t need = kHeadBytes + extra_bytes(h.coding) - (h.head_pose ? 0 : 96);
    if (size < need)
      return bad_data("residual layer is " + std::to_string(size) + " bytes, at least " + std::to_string(need) +
                          " expected",
                      0);
  } else if (size < kHeadBytes) {
    return bad_data("residual layer is " + std::to_string(size) + " bytes, at least 32 expected", 0);
  }
  h.fields_offset = at;
  h.max_error = ld_f64(payload + at);
  h.step = ld_f64(payload + at + 8);
  h.word_points = ld_u64(payload + at + 16);
  h.coded_points = ld_u64(payload + at + 24);
  h.stream_offset = at + kHeadBytes;
  if (h.coding == kCodingSweep) {
    h.cell = ld_f64(payload + at + kHeadBytes);
    h.stream_offset += kSweepExtraBytes;
  } else if (h.coding == kCodingVoxel) {
    for (int a = 0; a < 3; ++a) h.origin[static_cast<std::size_t>(a)] = ld_f64(payload + at + kHeadBytes + 8 * a);
    const std::uint32_t depth_field = codec::bytes::ld_u32(payload + at + kHeadBytes + 24);
    h.depth = depth_field & 0xFFU;
    h.octree_contexts = (depth_field >> 8) & 0xFFU;
    h.voxel_reserved = depth_field >> 16;
    h.stream_offset += kVoxelExtraBytes;
  } else if (h.coding == kCodingAcquisition) {
    for (int a = 0; a < 3; ++a) h.origin[static_cast<std::size_t>(a)] = ld_f64(payload + at + kHeadBytes + 8 * a);
    const std::uint32_t prediction = codec::bytes::ld_u32(payload + at + kHeadBytes + 24);
    h.fit_pulses = prediction & ~detail::kTallCellsBit;
    h.stream_offset += kAcquisitionExtraBytes;
    if ((prediction & detail::kTallCellsBit) != 0) {
      if (size < h.stream_offset + 8)
        return bad_data("residual layer is " + std::to_string(size) + " bytes, at least " +
                            std::to_string(h.stream_offset + 8) + " expected (the cells' height)",
                        0);
      h.step_z = ld_f64(payload + h.stream_offset);
      if (!(h.step_z > 0.0)) h.step_z = std::numeric_limits<double>::quiet_NaN();  // (refused as a height)
      h.stream_offset += 8;
    }
  } else if (h.coding == kCodingLattice) {
    for (int a = 0; a < 3; ++a) h.origin[static_cast<std::size_t>(a)] = ld_f64(payload + at + kHeadBytes + 8 * a);
    h.pitch = ld_f64(payload + at + kHeadBytes + 24);
    h.columns = codec::bytes::ld_u32(payload + at + kHeadBytes + 32);
    h.rows = codec::bytes::ld_u32(payload + at + kHeadBytes + 36);
    h.voxel_reserved = codec::bytes::ld_u32(payload + at + kHeadBytes + 40);
    h.stream_offset += kLatticeExtraBytes;
  } else if (h.coding == kCodingLaser) {
    h.tangential_step = ld_f64(payload + at + kHeadBytes);
    // after the step across the beams and the shift unit (f64 each), as laser_layer writes them
    h.lasers = codec::bytes::ld_u32(payload + at + kHeadBytes + 16);
    h.columns = codec::bytes::ld_u32(payload + at + kHeadBytes + 20);
    const std::uint32_t predictor_field = codec::bytes::ld_u32(payload + at + kHeadBytes + 28);
    h.predictor = predictor_field & 0xFFU;
    h.table_predictors = (predictor_field & detail::kTablePredictorsBit) != 0;
    h.motion = (predictor_field & detail::kMotionBit) != 0;
    h.quick_models = (predictor_field & detail::kQuickModelsBit) != 0;
    h.stream_offset += h.head_pose ? detail::kLaserFieldBytes : detail::kLaserShortFieldBytes;
  }
  return h;
}

Cloud word_cloud(const codec::ModelData& data) {
  if (!data.alphabet) throw std::invalid_argument("word_cloud: the model data has no alphabet");
  Cloud c = reconstruct(data.model, *data.alphabet, data.alphabet->point_spacing).cloud;
  c.T_cloud_sensor = data.T_cloud_sensor;
  return c;
}

std::vector<std::uint8_t> encode_layer(const Cloud& input, const Cloud& words, const Pose& T_cloud_sensor,
                                       double bound_asked, LayerStats* stats, const LayerOptions& options) {
  if (!(bound_asked >= kMinMaxError && bound_asked <= kMaxMaxError))
    throw std::invalid_argument("residual layer: max error " + std::to_string(bound_asked) + " m is outside [" +
                                std::to_string(kMinMaxError) + ", " + std::to_string(kMaxMaxError) + "]");
  const std::size_t n_in = input.size(), n_w = words.size();
  if (n_in > 0xFFFFFFF0U || n_w > 0xFFFFFFF0U) throw std::invalid_argument("residual layer: too many points");
  const int threads = std::max(1, options.threads);

  // Every decision below uses E less a margin (check_error), so that a decoder whose
  // floating-point results differ from this machine's in the last bits (another libm, fused
  // multiply-adds) still meets E: 1e-5 of E plus two float32 ulps of the largest coordinate.
  float extent = 0.0F;
  for (const auto& p : input.points) extent = std::max(extent, p.cwiseAbs().maxCoeff());
  for (const auto& p : words.points) extent = std::max(extent, p.cwiseAbs().maxCoeff());
  extent = std::max(extent, static_cast<float>(T_cloud_sensor.translation().cwiseAbs().maxCoeff()));
  // With `mse` the sensor-geometry coding codes to the bound asked and the others (and the
  // words' keep mask) to kMseOthersShare of it: max_error and check_error are theirs.
  const double max_error = options.mse ? std::max(kMinMaxError, kMseOthersShare * bound_asked) : bound_asked;
  const auto check_of = [extent](double e) { return e * (1.0 - 1e-5) - 2.5e-7 * static_cast<double>(extent); };
  const double check_error = check_of(max_error);
  const double laser_check_error = check_of(bound_asked);
  if (!(check_error > 0.5 * max_error))
    throw std::invalid_argument("residual layer: a max error of " + std::to_string(bound_asked) +
                                " m is below the float32 resolution of coordinates as large as " +
                                std::to_string(extent) + " m");

  // Kept word points: an input point within E. Explained input points: a kept word point within E.
  std::vector<std::uint8_t> keep(n_w, 0), explained(n_in, 0);
  if (n_w > 0 && n_in > 0) {
    PointBallGrid input_grid(check_error, n_in);
    for (const auto& p : input.points) input_grid.insert(p);
    parallel_for(n_w, threads, [&](std::size_t i) { keep[i] = input_grid.any_within(words.points[i].cast<double>()) ? 1 : 0; }, 4096);
    std::vector<std::uint32_t> kept;
    for (std::size_t i = 0; i < n_w; ++i)
      if (keep[i]) kept.push_back(static_cast<std::uint32_t>(i));
    if (!kept.empty()) {
      PointBallGrid word_grid(check_error, kept.size());
      for (std::uint32_t i : kept) word_grid.insert(words.points[i]);
      parallel_for(n_in, threads, [&](std::size_t i) { explained[i] = word_grid.any_within(input.points[i].cast<double>()) ? 1 : 0; }, 4096);
    }
  }
  std::vector<std::uint32_t> coded;
  for (std::size_t i = 0; i < n_in; ++i)
    if (!explained[i]) coded.push_back(static_cast<std::uint32_t>(i));

  const double q = kStepShare * 2.0 * max_error / std::sqrt(3.0);
  const Pose T_sensor_cloud = T_cloud_sensor.inverse();
  // The coded points in sensor-centred spherical coordinates, once for the row order and
  // every way of coding them (indexed by input point; the others are not read): those of a
  // trial window first, all of them only where a spherical coding is coded in full (not
  // beside a laser table read from the sensor that rules it out).
  std::vector<Spherical> spherical(n_in);
  const auto to_spherical_at = [&](const std::vector<std::uint32_t>& which) {
    parallel_for(which.size(), threads, [&](std::size_t k) {
      spherical[which[k]] = to_spherical(T_sensor_cloud * input.points[which[k]].cast<double>());
    }, 4096);
  };

  // The keep mask, then the points: in row order and in input order, the smaller wins.
  RangeEncoder head;
  {
    BitModel keep_model[4];
    int ctx = 0;
    for (std::size_t i = 0; i < n_w; ++i) {
      head.put(keep_model[ctx], keep[i] != 0);
      ctx = ((ctx << 1) | keep[i]) & 3;
    }
  }
  // (what the keep mask takes of every stream, left out of the codings' bits a point)
  const std::size_t head_bytes = RangeEncoder(head).finish().size();
  Cloud sensor_frame;
  sensor_frame.points.reserve(std::min<std::size_t>(coded.size(), 4096));
  for (std::size_t k = 0; k < coded.size() && sensor_frame.points.size() < 4096; k += std::max<std::size_t>(1, coded.size() / 4096))
    sensor_frame.points.push_back((T_sensor_cloud * input.points[coded[k]].cast<double>()).cast<float>());
  const auto res = estimate_angular_resolution(sensor_frame);
  const double row_height = res && res->elevation_rad > 0.0 ? 0.5 * res->elevation_rad : 0.5 * kPi / 180.0;

  // Row order or input order, each with the previous-point coding (RESD) and the sweep
  // coding (RESW): on a large layer, a window of consecutive input points is coded the
  // four ways and only the winner is coded in full; a small layer is coded all four ways.
  const bool thin = options.thin;
  // Sweep coding's direction cells: half the angular spacing of the coded points.
  const double sweep_cell = res ? 0.5 * std::max(res->azimuth_rad, res->elevation_rad) : 0.0;
  // (every coded point in row order: made only when a spherical coding is coded in full)
  std::vector<std::uint32_t> rows;
  // (a spherical or voxel coding stopped once it could no longer be the smallest)
  bool spherical_out = false, voxel_out = false;
  const auto need_rows = [&] {
    if (!rows.empty()) return;
    to_spherical_at(coded);
    rows = row_order(spherical, coded, row_height);
  };
  // The sample of an order (kSampleRuns runs, every kSampleEvery-th kept), and of the row
  // order: the rows whose first point falls in a kept run, in row order (every coded point's
  // row sorted, a row at a time rather than by a table over the rows, which an estimated
  // row height far below the points' spacing would make huge; only the sample put in row
  // order).
  const auto runs_sample = [&](const std::vector<std::uint32_t>& order) {
    std::vector<std::uint32_t> out;
    out.reserve(order.size() / kSampleEvery + 1);
    for (std::size_t k = 0; k < order.size(); ++k)
      if ((k * kSampleRuns / order.size()) % kSampleEvery == 0) out.push_back(order[k]);
    to_spherical_at(out);
    return out;
  };
  const auto row_sample = [&] {
    to_spherical_at(coded);
    std::vector<std::int64_t> sorted(coded.size());
    for (std::size_t k = 0; k < coded.size(); ++k) sorted[k] = row_of(spherical[coded[k]], row_height);
    std::sort(sorted.begin(), sorted.end());
    // (the rows kept, ascending: each row's first point is its run's start in `sorted`)
    std::vector<std::int64_t> kept_rows;
    for (std::size_t a = 0; a < sorted.size(); ++a)
      if ((a == 0 || sorted[a] != sorted[a - 1]) && (a * kSampleRuns / sorted.size()) % kSampleEvery == 0)
        kept_rows.push_back(sorted[a]);
    std::vector<std::uint32_t> picked;
    for (const std::uint32_t i : coded)
      if (std::binary_search(kept_rows.begin(), kept_rows.end(), row_of(spherical[i], row_height))) picked.push_back(i);
    return row_order(spherical, picked, row_height);
  };
  struct Way {
    bool by_rows;
    bool sweep;
  };
  std::vector<Way> ways = {{true, false}, {false, false}};
  if (options.sweep && sweep_cell > 0.0) {
    ways.push_back({true, true});
    ways.push_back({false, true});
  }
  std::vector<std::vector<std::uint32_t>> way_sources(ways.size());
  auto code = [&](const std::vector<std::uint32_t>& order, bool sweep, std::size_t& escaped, std::size_t& count,
                  std::vector<std::uint32_t>* sources = nullptr,
                  std::size_t give_up_bytes = std::numeric_limits<std::size_t>::max(), bool* gave_up = nullptr) {
    if (sources) sources->clear();
    return code_points(head, input.points, spherical, order, T_cloud_sensor, T_sensor_cloud, q, check_error, escaped, count, thin,
                       sweep ? sweep_cell : 0.0, sources, give_up_bytes, gave_up);
  };
  std::vector<std::vector<std::uint8_t>> streams(ways.size());
  std::vector<std::size_t> escaped(ways.size(), 0), counts(ways.size(), 0);
  std::size_t best = 0;
  // The voxel coding (§2.7) competes too: alone with `spherical` off; else coded in full
  // alongside the spherical winner unless its trial below rules it out.
  std::optional<VoxelLayer> voxel;
  // (a voxel stands for every point in it: not with `thin` off, which gives each its own)
  const bool voxel_allowed = options.voxel && options.thin;
  // The sensor-geometry coding (§2.8) where the scan's lasers and columns are known: the
  // smallest of its range-step shares and laser estimates kept (laser_layer).
  std::optional<detail::LaserLayer> laser;
  std::optional<detail::LaserAssignment> lasers_of;
  if (options.laser && !coded.empty()) lasers_of = detail::assign_lasers(input, T_cloud_sensor, true, threads, options.fast);
  // A table read from the sensor reproduces the beams: the whole budget along them.
  const bool exact_table = lasers_of && lasers_of->fit_rms < 1e-3 * bound_asked;
  // The acquisition-order coding (§2.11) where the points come in the order they were
  // fired (their times rise): an airborne or mobile-mapping scanner's file. Not beside a
  // laser table read from the sensor, whose coding follows the firing order already (on
  // the Ouster and Velodyne captures it won every turn).
  std::optional<detail::AcquisitionLayer> acquisition;
  if (options.acquisition && !exact_table && input.has_time() && detail::acquisition_ordered(input.time, coded))
    acquisition = detail::acquisition_layer(head, input.points, input.time, coded, check_error, options.thin,
                                            kAcquisitionFits, threads, kAcquisitionShapes);
  // The lattice coding (§2.12) where the points gather at the points of a square lattice
  // in x and y, one or a few a cell (a gridded product).
  std::optional<detail::LatticeLayer> lattice;
  if (options.lattice && !exact_table)
    if (const auto found = detail::find_lattice(input.points, coded))
      lattice = detail::lattice_layer(head, input.points, coded, *found, check_error);
  // Where one of those two codes the layer, a table estimated from the points that misses
  // them by more than 4 E (an airborne file's: Autzen 0.60 m, hexbin 0.17 m) is not tried:
  // its coding would correct across the beam at nearly every point.
  const double grid_bits = [&] {
    double bits = std::numeric_limits<double>::infinity();
    for (const std::vector<std::uint8_t>* st : {acquisition ? &acquisition->stream : nullptr, lattice ? &lattice->stream : nullptr})
      if (st != nullptr && !coded.empty())
        bits = std::min(bits, 8.0 * static_cast<double>(st->size() - std::min(st->size(), head_bytes)) /
                                  static_cast<double>(coded.size()));
    return bits;
  }();
  const bool tall = acquisition && acquisition->step_z != acquisition->step;
  const std::size_t acquisition_bytes = acquisition ? extra_bytes(kCodingAcquisition) + (tall ? 8 : 0) +
                                                          acquisition->stream.size()
                                                    : std::numeric_limits<std::size_t>::max();
  const std::size_t lattice_bytes =
      lattice ? extra_bytes(kCodingLattice) + lattice->stream.size() : std::numeric_limits<std::size_t>::max();
  if (lasers_of && std::isfinite(grid_bits) && !exact_table && lasers_of->fit_rms > 4.0 * max_error) lasers_of.reset();
  // On two threads or more, the voxel trial of a large layer (below) starts now, beside the
  // sensor-geometry coding, whose coding in full keeps one thread alone: it is the same trial
  // on the same window, so the file is the same. Not beside a table read from the sensor,
  // where the trial waits for that coding's bits. The window is the one the trial takes beside
  // a sensor-geometry coding (one spherical window); should that coding fail, the trial is
  // made again on its own window.
  // (the voxel trial's window: one spherical window beside a sensor-geometry coding, else
  // kVoxelTrialSpan of them)
  const auto voxel_trial_span = [&coded](bool beside_laser) {
    return std::min(coded.size(), (beside_laser ? 1 : kVoxelTrialSpan) * kOrderTrialPoints);
  };
  std::future<std::optional<VoxelLayer>> early_voxel;
  std::size_t early_span = 0;
  if (threads >= 2 && lasers_of && !exact_table && options.spherical && voxel_allowed &&
      coded.size() > 4 * kOrderTrialPoints) {
    early_span = voxel_trial_span(true);
    early_voxel = std::async(std::launch::async, [&input, &coded, check_error, span = early_span] {
      return voxel_layer(RangeEncoder{}, input.points, middle_window(coded, span), check_error);
    });
  }
  if (lasers_of) {
    // With `mse`, one share and λ (kMseShare, kMseLambdaScale) whatever the table.
    const std::vector<double> shares = options.mse   ? std::vector<double>{kMseShare}
                                       : exact_table ? std::vector<double>{kLaserShares[0]}
                                                     : std::vector<double>{kLaserShares[1], kLaserShares[2]};
    const double lambda_scale = options.mse ? kMseLambdaScale : 1.0;
    // Lasers estimated two ways from the points: both are candidates, the smaller kept.
    std::vector<const detail::LaserAssignment*> candidates = {&*lasers_of};
    if (lasers_of->alternative) candidates.push_back(lasers_of->alternative.get());
    std::size_t chosen = 0;
    laser = detail::laser_layer(head, input.points, coded, candidates, T_cloud_sensor, bound_asked, laser_check_error,
                                options.thin, shares, lambda_scale, threads, &chosen, options.fast);
    if (laser && chosen == 1) lasers_of = detail::LaserAssignment(*candidates[1]);
  }
  const std::size_t laser_bytes =
      laser ? extra_bytes(kCodingLaser) + laser->stream.size() : std::numeric_limits<std::size_t>::max();
  const bool others = (!laser && !acquisition && !lattice) || options.spherical || options.voxel;
  // Beside a sensor-geometry coding, on a large layer: the voxel trial takes a window a
  // quarter as large, and the voxel coding is coded in full only where its trial comes within
  // kVoxelSkipRatio of the sensor-geometry bits (its smaller window overstates it: 0.93-1.5
  // times the larger window's bits on the shared scans) or the points are dense. On
  // kitti00/000000 at 14 mm that is 0.17 G of 1.75 G instructions; on bench/fast.sh's 300
  // codings 299 files are the same bytes and one (a balm scan at 10 cm) 5.8 % smaller.
  // With `fast` the spherical winner too is coded in full only where its trial window beats
  // the sensor-geometry bits. (Not so by default: on balm's non-repeating scans the middle
  // window misjudges the whole; the spherical coding won in full at window ratios up to 1.40
  // and lost at 0.75.)
  const bool beside_laser = laser.has_value();
  const bool fast_laser = options.fast && beside_laser;
  bool spherical_may_win = true;
  // (and with `fast` no sweep coding: on the 300 files of bench/fast.sh it never won; it
  // does on a tilting 2D scanner's scan, indoor/scan001.3d, beside an estimated table)
  while (fast_laser && ways.size() > 2) ways.pop_back();
  if (others && !options.spherical && voxel_allowed) voxel = voxel_layer(head, input.points, coded, check_error);
  if (others && !voxel) {
    const bool try_voxel = voxel_allowed && options.spherical;
    if (coded.size() > 4 * kOrderTrialPoints) {
      // On a large layer, a window of consecutive input points is coded the spherical ways
      // and only the winner is coded in full. The voxel coding, on a window four times as
      // large (its contexts need more points to learn; as large beside a sensor-geometry
      // coding, whose bits rule it out sooner), is coded in full too unless it
      // costs kVoxelSkipRatio times the spherical winner's bits there: a single scan of a
      // spinning lidar, whose full costs differ about as much, skips it.
      const std::vector<std::uint32_t> window = middle_window(coded, kOrderTrialPoints);
      to_spherical_at(window);
      const std::vector<std::uint32_t> window_rows = row_order(spherical, window, row_height);
      std::vector<std::size_t> trial(ways.size(), 0);
      double voxel_window_bits = 0.0;
      const std::size_t voxel_span = voxel_trial_span(beside_laser);
      const auto voxel_trial_bits = [&](const std::optional<VoxelLayer>& v) {
        voxel_window_bits = v ? 8.0 * static_cast<double>(v->stream.size()) / static_cast<double>(voxel_span)
                              : std::numeric_limits<double>::infinity();
      };
      const auto voxel_trial = [&] {
        voxel_trial_bits(voxel_layer(RangeEncoder{}, input.points, middle_window(coded, voxel_span), check_error));
      };
      // (the trial started beside the sensor-geometry coding, where it is this one)
      const bool early = early_voxel.valid() && early_span == voxel_span;
      // Where half the points or more lie closer to their laser's next than a voxel cell is
      // wide, the voxel coding (which merges such points) is tried in full whatever the
      // trials say: on the Ouster turns at E = 20 cm it coded 15 % smaller than the
      // sensor-geometry coding, whose bits the spherical trial still exceeded 2.1 times, and
      // on a re-sampled VLS-128 scan at 15 cm 24 % smaller, its trial window 1.6 times the
      // sensor-geometry bits.
      bool dense = false;
      if (laser && lasers_of && lasers_of->table.columns > 0) {
        const double step = 2.0 * kPi / static_cast<double>(lasers_of->table.columns);
        const double cell = 2.0 * check_error / std::sqrt(3.0);
        std::size_t close = 0;
        for (const std::uint32_t i : coded)
          close += (T_sensor_cloud * input.points[i].cast<double>()).norm() * step < cell ? 1 : 0;
        dense = 2 * close >= coded.size();
      }
      // With a laser table read from the sensor, the spherical trial comes first, alone:
      // where it costs kExactLaserSkipRatio times the sensor-geometry coding's bits or
      // more and the points are not dense, neither the voxel trial nor a full spherical
      // coding runs.
      const bool defer_voxel = laser && exact_table;
      // (the voxel trial, the longest job, first: the other thread meanwhile takes the
      // spherical ones)
      const std::size_t first_way = try_voxel && !defer_voxel && !early ? 1 : 0;
      // The sensor-geometry coding, already coded in full, rules out a voxel coding whose
      // trial costs kLaserSkipRatio times its bits or more.
      const double laser_bits =
          laser ? 8.0 * static_cast<double>(laser->stream.size() - std::min(laser->stream.size(), head_bytes)) /
                      static_cast<double>(coded.size())
                : std::numeric_limits<double>::infinity();
      // Where the trial can only rule the spherical codings out (a table from the sensor, the
      // points not dense), a way whose window has passed the bytes that rule it out stops
      // there and counts as one byte more: the same decisions, in 0.96 of the instructions
      // on the OS-2-128 turn. (2 bytes of margin over the rounding of the bits a point.)
      std::size_t give_up = std::numeric_limits<std::size_t>::max();
      if (defer_voxel && !dense && std::isfinite(laser_bits))
        give_up = head_bytes + static_cast<std::size_t>(std::ceil(kExactLaserSkipRatio * laser_bits *
                                                                  static_cast<double>(kOrderTrialPoints) / 8.0)) + 1;
      parallel_for(ways.size() + first_way, threads, [&](std::size_t job) {
        if (job < first_way) {
          voxel_trial();
          return;
        }
        const std::size_t w = job - first_way;
        std::size_t e = 0, n = 0;
        bool gave_up = false;
        trial[w] = code(ways[w].by_rows ? window_rows : window, ways[w].sweep, e, n, nullptr, give_up, &gave_up).size();
        if (gave_up) trial[w] = give_up + 1;
      }, 1);
      if (try_voxel && !defer_voxel && early) voxel_trial_bits(early_voxel.get());
      for (std::size_t w = 1; w < ways.size(); ++w)
        if (trial[w] < trial[best]) best = w;
      const double spherical_window_bits =
          8.0 * static_cast<double>(trial[best] - std::min(trial[best], head_bytes)) / static_cast<double>(kOrderTrialPoints);
      const bool skip_others = defer_voxel && !dense && spherical_window_bits >= kExactLaserSkipRatio * laser_bits;
      if (try_voxel && defer_voxel && !skip_others) voxel_trial();
      // The acquisition-order or lattice coding, coded in full already, rules out a voxel or
      // spherical coding whose trial costs kVoxelSkipRatio times its bits or more (Autzen at
      // 14 mm: 17.9 and 11.8 bits a point).
      const bool full_voxel = !skip_others && try_voxel &&
                              (dense || (voxel_window_bits <= kVoxelSkipRatio * spherical_window_bits &&
                                         voxel_window_bits < kLaserSkipRatio * laser_bits &&
                                         (!beside_laser || voxel_window_bits < kVoxelSkipRatio * laser_bits))) &&
                              voxel_window_bits < kVoxelSkipRatio * grid_bits;
      spherical_may_win = !fast_laser || spherical_window_bits < laser_bits;
      // By default, beside a sensor-geometry coding, the spherical winner's sample
      // (kSampleSkipRatio) decides instead: coded until it passes the bytes that rule it
      // out, and only where the window costs at least the sensor-geometry bits (where it
      // costs less, the spherical coding won 142 of the 166 such codings above: coded in full
      // at once).
      if (beside_laser && !fast_laser && !skip_others && std::isfinite(laser_bits) &&
          spherical_window_bits >= laser_bits) {
        const std::vector<std::uint32_t> sample = ways[best].by_rows ? row_sample() : runs_sample(coded);
        const std::size_t limit =
            head_bytes + static_cast<std::size_t>(std::ceil(kSampleSkipRatio * laser_bits * static_cast<double>(sample.size()) / 8.0));
        std::size_t e = 0, n = 0;
        bool gave_up = false;
        const std::size_t bytes = code(sample, ways[best].sweep, e, n, nullptr, limit, &gave_up).size();
        // (the stop is checked every 256 points: a sample that ends past the limit is out too)
        spherical_may_win = !gave_up && bytes <= limit;
      }
      // Where the voxel trial wins clearly (a map), the spherical winner is not coded in full.
      // (The spherical trial does not rule it out against the sensor-geometry coding: on a
      // HDL-32E cloud stored firing by firing its window cost 1.6 times the sensor-geometry
      // coding's bits while in full it came out 5 % smaller, and balm's scans above.)
      const bool full_spherical = !skip_others && spherical_may_win &&
                                  !(try_voxel && voxel_window_bits < kSphericalSkipRatio * spherical_window_bits) &&
                                  spherical_window_bits < kVoxelSkipRatio * grid_bits;
      if (full_spherical) need_rows();
      // The codings coded in full already (sensor geometry, acquisition order, lattice) each
      // beat a spherical coding that comes out larger: that coding stops once its bytes pass
      // the smallest of them (as it cannot be kept then, the same file).
      const std::size_t in_hand = std::min({laser_bytes, acquisition_bytes, lattice_bytes});
      // So does a voxel coding past the sensor-geometry coding's bytes (that bound alone where
      // there is one: a voxel coding it beats sends the spherical coding to be coded after all,
      // below).
      const auto give_up_at = [](std::size_t bound, std::size_t extra) {
        return bound == std::numeric_limits<std::size_t>::max() ? bound : bound > extra ? bound - extra : 0;
      };
      const std::size_t sphere_give_up = give_up_at(in_hand, extra_bytes(ways[best].sweep ? kCodingSweep : 0));
      // (the spherical winner, coded in full until it passes sphere_give_up)
      const auto code_winner = [&] {
        streams[best] = code(ways[best].by_rows ? rows : coded, ways[best].sweep, escaped[best], counts[best],
                             &way_sources[best], sphere_give_up, &spherical_out);
        if (spherical_out) way_sources[best].clear();
      };
      const std::size_t voxel_give_up = give_up_at(laser ? laser_bytes : in_hand, extra_bytes(kCodingVoxel));
      parallel_for((full_voxel ? 1 : 0) + (full_spherical ? 1 : 0), threads, [&](std::size_t job) {
        if (job == 0 && full_spherical) {
          code_winner();
        } else {
          voxel = voxel_layer(head, input.points, coded, check_error, voxel_give_up, &voxel_out);
        }
      }, 1);
      // Neither coded in full (the voxel trial ruled the spherical one out, and the voxel
      // coding failed or the sensor-geometry coding beat its trial): the spherical winner is
      // coded now, stopping as the full one above does once it passes the coding in hand
      // (without one it is the only coding left). On a 128-beam scan whose spherical window
      // cost 4.2 times the sensor-geometry bits it coded all 202k points in full here before.
      if (!voxel && !voxel_out && !full_spherical && !skip_others && spherical_may_win && !std::isfinite(grid_bits)) {
        need_rows();
        code_winner();
      }
    } else {
      need_rows();
      parallel_for(ways.size() + (try_voxel ? 1 : 0), threads, [&](std::size_t w) {
        if (w == ways.size()) voxel = voxel_layer(head, input.points, coded, check_error);
        else streams[w] = code(ways[w].by_rows ? rows : coded, ways[w].sweep, escaped[w], counts[w], &way_sources[w]);
      }, 1);
      for (std::size_t w = 1; w < ways.size(); ++w)
        if (streams[w].size() < streams[best].size()) best = w;
    }
  }
  // A spherical winner skipped for a voxel coding that the sensor-geometry coding beats may
  // beat both: it is coded in full after all.
  if (others && options.spherical && laser && spherical_may_win && (voxel || voxel_out) && streams[best].empty() && !spherical_out &&
      (voxel_out || laser_bytes < extra_bytes(kCodingVoxel) + voxel->stream.size())) {
    need_rows();
    streams[best] = code(ways[best].by_rows ? rows : coded, ways[best].sweep, escaped[best], counts[best], &way_sources[best]);
  }
  const bool use_voxel =
      voxel && (streams[best].empty() ||  // (no spherical stream: `spherical` off, or skipped)
                extra_bytes(kCodingVoxel) + voxel->stream.size() <
                    extra_bytes(ways[best].sweep ? kCodingSweep : 0) + streams[best].size());
  const bool sweep = !use_voxel && ways[best].sweep;
  // (the bound of the coding kept: the one asked for with the sensor-geometry coding)
  double kept_error = max_error;
  const auto fill_stats = [&](std::size_t residual, std::size_t escapes, bool is_sweep, bool is_voxel, bool is_laser,
                              std::size_t bytes) {
    if (!stats) return;
    *stats = LayerStats{};
    stats->max_error = kept_error;
    stats->word_points = n_w;
    stats->kept_word_points = static_cast<std::size_t>(std::count(keep.begin(), keep.end(), std::uint8_t{1}));
    stats->explained_points = n_in - coded.size();
    stats->residual_points = residual;
    stats->escaped_points = escapes;
    stats->sweep = is_sweep;
    stats->voxel = is_voxel;
    stats->laser = is_laser;
    stats->bytes = bytes;
    // (a spherical stream, or one stopped once it could not be the smallest: trials write neither)
    stats->spherical_in_full = !streams[best].empty() || spherical_out;
    if (lasers_of) {
      stats->laser_table_source = lasers_of->source;
      stats->laser_table_rms = lasers_of->fit_rms;
      stats->lasers = lasers_of->table.lasers();
      stats->columns = lasers_of->table.columns;
    }
  };
  // The input point each decoded point stands for (LayerStats::sources). The decoder gives
  // the kept word points first, in word order, then the coded points in stream order: where
  // the coding names each coded point's input point (`coded_sources`), the layer need not be
  // decoded (on kitti00/000000 that decoding was 0.20 G of the 1.75 G instructions of an
  // encoding that keeps the intensity); the voxel coding's points are found by decoding.
  // A sensor-geometry layer's points also come with their lasers and columns (`laser_keys`,
  // LayerStats::layer), the kept word points with a laser of their own and no column.
  const auto fill_sources = [&](const std::vector<std::uint8_t>& payload, const std::vector<std::uint32_t>* coded_sources,
                                const detail::LaserLayer* laser_keys = nullptr) {
    if (!stats || !options.track_sources) return;
    const std::size_t kept_n = stats->kept_word_points;
    std::vector<Eigen::Vector3f> to_find;  // (the decoded points found by distance)
    if (coded_sources) {
      for (std::size_t i = 0; i < n_w; ++i)
        if (keep[i]) to_find.push_back(words.points[i]);
      if (to_find.size() != kept_n) throw std::logic_error("residual layer: kept word points miscounted");
      if (laser_keys) {
        if (laser_keys->laser_of.size() != coded_sources->size())
          throw std::logic_error("residual layer: coded points and their lasers differ in number");
        LayerKeys& k = stats->layer;
        k.columns = laser_keys->columns;
        k.laser.assign(kept_n, static_cast<std::uint16_t>(laser_keys->lasers));
        k.laser.insert(k.laser.end(), laser_keys->laser_of.begin(), laser_keys->laser_of.end());
        k.column.assign(kept_n, laser_keys->columns);
        k.column.insert(k.column.end(), laser_keys->column_of.begin(), laser_keys->column_of.end());
      }
    } else {
      auto decoded = detail::decode_layer_lasers(payload, words, T_cloud_sensor, n_in, stats->layer);
      if (!decoded.ok()) throw std::logic_error("residual layer does not decode: " + decoded.status().to_string());
      to_find = std::move(decoded.value().points);
    }
    std::vector<std::uint32_t>& out_sources = stats->sources;
    out_sources.assign(to_find.size() + (coded_sources ? coded_sources->size() : 0), 0);
    if (coded_sources) std::copy(coded_sources->begin(), coded_sources->end(), out_sources.begin() + static_cast<std::ptrdiff_t>(kept_n));
    if (to_find.empty()) return;
    PointBallGrid grid(kept_error, n_in);
    for (const auto& p : input.points) grid.insert(p);
    std::vector<std::uint8_t> missing(to_find.size(), 0);
    parallel_for(to_find.size(), threads, [&](std::size_t j) {
      const std::uint32_t i = grid.nearest_within(to_find[j].cast<double>());
      if (i == PointBallGrid::kNoPoint) missing[j] = 1;
      else out_sources[j] = i;
    }, 4096);
    if (std::any_of(missing.begin(), missing.end(), [](std::uint8_t m) { return m != 0; }))
      throw std::logic_error("residual layer: a decoded point has no input point within the bound");
  };
  const bool coded_others = use_voxel || !streams[best].empty();
  const std::size_t others_bytes = !others || !coded_others ? std::numeric_limits<std::size_t>::max()
                                   : use_voxel ? extra_bytes(kCodingVoxel) + voxel->stream.size()
                                               : extra_bytes(sweep ? kCodingSweep : 0) + streams[best].size();
  // A payload of the codings on a grid from an origin (§2.11, §2.12): the coding and marker,
  // the fields every coding has, the origin, `fields` (the coding's own), the stream; its
  // coded points each stand for their own input point, `sources`.
  const auto grid_payload = [&](std::uint32_t coding, double step, const Eigen::Vector3d& origin,
                                const std::vector<std::uint32_t>& sources, const std::vector<std::uint8_t>& stream,
                                const auto& fields) {
    std::vector<std::uint8_t> out;
    out.reserve(kHeadBytes + extra_bytes(coding) + stream.size());
    codec::bytes::put_u32(out, coding);
    codec::bytes::put_u32(out, kSweepMarker);
    put_f64(out, max_error);
    put_f64(out, step);
    put_u64(out, n_w);
    put_u64(out, sources.size());
    for (int a = 0; a < 3; ++a) put_f64(out, origin[a]);
    fields(out);
    out.insert(out.end(), stream.begin(), stream.end());
    fill_stats(sources.size(), 0, false, false, false, out.size());
    if (stats) {
      stats->lattice = coding == kCodingLattice;
      stats->acquisition = coding == kCodingAcquisition;
    }
    fill_sources(out, &sources);
    return out;
  };
  if (lattice && lattice_bytes < std::min({others_bytes, laser_bytes, acquisition_bytes}))
    return grid_payload(kCodingLattice, lattice->step, lattice->origin, lattice->sources, lattice->stream,
                        [&](std::vector<std::uint8_t>& out) {
                          put_f64(out, lattice->pitch);
                          codec::bytes::put_u32(out, lattice->columns);
                          codec::bytes::put_u32(out, lattice->rows);
                          codec::bytes::put_u32(out, lattice->stacked ? kLatticeStackedBit : 0U);
                        });
  if (acquisition && acquisition_bytes < std::min(others_bytes, laser_bytes))
    return grid_payload(kCodingAcquisition, acquisition->step, acquisition->origin, acquisition->sources,
                        acquisition->stream, [&](std::vector<std::uint8_t>& out) {
                          codec::bytes::put_u32(out, acquisition->fit_pulses | (tall ? detail::kTallCellsBit : 0U));
                          if (tall) put_f64(out, acquisition->step_z);
                        });
  if (laser && laser_bytes < others_bytes) {
    std::vector<std::uint8_t> out;
    out.reserve(kHeadBytes + extra_bytes(kCodingLaser) + laser->stream.size());
    // Fields without T_sensor_head (the identity) take marker 0xFFFFFFFE (format 1.11): 96
    // bytes a file for any table but a sensor's own with an offset head (an Ouster's metadata).
    codec::bytes::put_u32(out, kCodingLaser);
    codec::bytes::put_u32(out, laser->head_pose ? kSweepMarker : kLaserShortMarker);
    kept_error = bound_asked;
    put_f64(out, kept_error);
    put_f64(out, laser->range_step);
    put_u64(out, n_w);
    put_u64(out, laser->coded);
    out.insert(out.end(), laser->fields.begin(), laser->fields.end());
    out.insert(out.end(), laser->stream.begin(), laser->stream.end());
    fill_stats(laser->coded, 0, false, false, true, out.size());
    fill_sources(out, &laser->sources, &*laser);
    return out;
  }
  const std::vector<std::uint8_t>& stream = use_voxel ? voxel->stream : streams[best];

  // The payload: the coding and marker (RESW, RESV), the fields every coding has, the
  // coding's own fields, the stream.
  std::vector<std::uint8_t> out;
  out.reserve(kHeadBytes + extra_bytes(kCodingVoxel) + stream.size());
  if (use_voxel || sweep) {
    codec::bytes::put_u32(out, use_voxel ? kCodingVoxel : kCodingSweep);
    codec::bytes::put_u32(out, kSweepMarker);
  }
  put_f64(out, max_error);
  put_f64(out, use_voxel ? voxel->cell : q);
  put_u64(out, n_w);
  put_u64(out, use_voxel ? voxel->voxels : counts[best]);
  if (sweep) put_f64(out, sweep_cell);
  if (use_voxel) {
    for (int a = 0; a < 3; ++a) put_f64(out, voxel->origin[a]);
    // depth u8, contexts u8 (1: §2.7.4), reserved u16
    codec::bytes::put_u32(out, static_cast<std::uint32_t>(voxel->depth) |
                                   static_cast<std::uint32_t>(detail::OccupancyContexts::kMixed) << 8);
  }
  out.insert(out.end(), stream.begin(), stream.end());
  fill_stats(use_voxel ? voxel->voxels : counts[best], use_voxel ? 0 : escaped[best], sweep, use_voxel, false, out.size());
  fill_sources(out, use_voxel ? nullptr : &way_sources[best]);
  return out;
}

StatusOr<Cloud> decode_layer(const std::vector<std::uint8_t>& payload, const Cloud& words, const Pose& T_cloud_sensor,
                             std::uint64_t max_points) {
  LayerKeys keys;
  return detail::decode_layer_lasers(payload, words, T_cloud_sensor, max_points, keys);
}

StatusOr<Cloud> detail::decode_layer_lasers(const std::vector<std::uint8_t>& payload, const Cloud& words,
                                            const Pose& T_cloud_sensor, std::uint64_t max_points,
                                            LayerKeys& keys) {
  keys.clear();
  const auto header = read_layer_header(payload.data(), payload.size());
  if (!header.ok()) return header.status();
  const LayerHeader& h = header.value();
  const double max_error = h.max_error;
  const double q = h.step;
  const std::uint64_t n_w = h.word_points;
  const std::uint64_t n_c = h.coded_points;
  const std::uint64_t at = h.fields_offset;
  if (!(max_error >= kMinMaxError && max_error <= kMaxMaxError))
    return bad_data("residual layer max_error " + std::to_string(max_error) + " is outside [1e-4, 10] m", at);
  if (h.coding != kCodingLaser && !(q > 0.0 && q <= 2.0 * max_error / std::sqrt(3.0)))
    return bad_data("residual layer step " + std::to_string(q) + " is not in (0, 2*max_error/sqrt(3)]", at + 8);
  if (n_w != words.size())
    return bad_data("residual layer covers " + std::to_string(n_w) + " word points but the reconstruction has " +
                        std::to_string(words.size()),
                    at + 16);
  const std::uint64_t stream_bytes = payload.size() - h.stream_offset;
  const bool voxel = h.coding == kCodingVoxel;
  const bool sweep = h.coding == kCodingSweep;
  const bool laser = h.coding == kCodingLaser;
  const bool acquisition = h.coding == kCodingAcquisition;
  const bool lattice = h.coding == kCodingLattice;
  const auto too_many = [&](std::uint64_t per_byte) {
    return n_c > max_points || n_c > per_byte * stream_bytes + 64;
  };
  const auto too_many_error = [&] {
    return bad_data("residual layer coded_points " + std::to_string(n_c) + " exceeds what the model (" +
                        std::to_string(max_points) + " input points) or the stored bytes can hold",
                    at + 24);
  };
  // (a sensor-geometry layer's bound depends on its predictor, checked once it is read)
  if (too_many(voxel ? kMaxVoxelsPerByte : laser ? kMaxMixedPointsPerByte : kMaxPointsPerByte)) return too_many_error();
  detail::LaserTable table;
  double tangential_step = 0.0;
  if (laser) {
    if (!(q > 0.0 && q <= 2.0 * max_error))
      return bad_data("residual layer range step " + std::to_string(q) + " is not in (0, 2*max_error]", at + 8);
    if (auto e = detail::read_laser_fields(payload.data() + at + kHeadBytes, payload.size() - at - kHeadBytes, max_error,
                                           table, tangential_step, h.head_pose))
      return bad_data("residual layer " + e->message, at + kHeadBytes + e->offset);
    if (too_many(table.predictor >= 4 ? kMaxMixedPointsPerByte : kMaxPointsPerByte)) return too_many_error();
  }
  if (sweep && !(h.cell >= 1e-6 && h.cell <= kPi))
    return bad_data("residual layer direction cell " + std::to_string(h.cell) + " rad is not in [1e-6, pi]", at + 32);

  RangeDecoder dec(payload.data() + h.stream_offset, static_cast<std::size_t>(stream_bytes));
  Cloud out;
  out.T_cloud_sensor = T_cloud_sensor;
  {
    BitModel keep_model[4];
    int ctx = 0;
    for (std::size_t i = 0; i < words.size(); ++i) {
      const bool k = dec.get(keep_model[ctx]);
      if (k) out.points.push_back(words.points[i]);
      ctx = ((ctx << 1) | (k ? 1 : 0)) & 3;
    }
  }
  out.points.reserve(out.points.size() + static_cast<std::size_t>(n_c));
  if (voxel) {
    const Eigen::Vector3d origin(h.origin[0], h.origin[1], h.origin[2]);
    if (!(q >= 1e-7))
      return bad_data("residual layer voxel cell " + std::to_string(q) + " m is below 1e-7 m", at + 8);
    if (!origin.allFinite() || !(origin.cwiseAbs().maxCoeff() <= kMaxVoxelOrigin))
      return bad_data("residual layer voxel origin is not finite or lies beyond 1e9 m", at + kHeadBytes);
    if (h.depth < 1 || h.depth > static_cast<std::uint32_t>(kMaxVoxelDepth))
      return bad_data("residual layer octree depth " + std::to_string(h.depth) + " is not in [1, 21]",
                      at + kHeadBytes + 24);
    if (h.octree_contexts > 1)
      return bad_data("residual layer octree contexts " + std::to_string(h.octree_contexts) + " is unknown (0 or 1 expected)",
                      at + kHeadBytes + 25);
    if (h.voxel_reserved != 0)
      return bad_data("residual layer voxel reserved field is " + std::to_string(h.voxel_reserved) + ", not 0",
                      at + kHeadBytes + 26);
    if (n_c == 0) return bad_data("residual layer voxel coding holds no voxel", at + 24);
    std::vector<std::uint64_t> leaves;
    if (!detail::decode_occupancy(dec, static_cast<int>(h.depth), n_c, leaves,
                                  static_cast<detail::OccupancyContexts>(h.octree_contexts)) ||
        leaves.size() != n_c)
      return bad_data("residual layer octree does not hold the " + std::to_string(n_c) + " voxels its header states",
                      h.stream_offset);
    if (dec.overrun() > 8)
      return bad_data("residual layer stream ends " + std::to_string(dec.overrun()) + " bytes early", payload.size());
    for (const std::uint64_t code : leaves) {
      std::uint32_t x = 0, y = 0, z = 0;
      detail::unmorton(code, x, y, z);
      const Eigen::Vector3f c = voxel_centre(origin, q, x, y, z);
      if (!c.allFinite()) return bad_data("residual layer voxel decodes to a non-finite position", h.stream_offset);
      out.points.push_back(c);
    }
    return out;
  }
  if (lattice || acquisition) {
    // The codings on a grid from an origin (§2.11, §2.12): the step, the origin, the
    // lattice's reserved field, the acquisition coding's line fit.
    const Eigen::Vector3d origin(h.origin[0], h.origin[1], h.origin[2]);
    if (!(q >= 1e-7))
      return bad_data("residual layer grid step " + std::to_string(q) + " m is below 1e-7 m", at + 8);
    if (!origin.allFinite() || !(origin.cwiseAbs().maxCoeff() <= kMaxVoxelOrigin))
      return bad_data("residual layer grid origin is not finite or lies beyond 1e9 m", at + kHeadBytes);
    if ((h.voxel_reserved & ~kLatticeStackedBit) != 0)
      return bad_data("residual layer lattice order field is " + std::to_string(h.voxel_reserved) + ", not 0 or 1",
                      at + kHeadBytes + 40);
    if (!detail::valid_fit_pulses(h.fit_pulses))
      return bad_data("residual layer line fit over " + std::to_string(h.fit_pulses) + " pulses (0 or 3-" +
                          std::to_string(detail::kMaxFitPulses) + " allowed; bits 9-31 clear)",
                      at + kHeadBytes + 24);
    // (cells taller than wide, at most kMaxCellHeight times; cubes without the field)
    const double step_z = h.step_z == 0.0 ? q : h.step_z;
    if (acquisition && !(step_z >= q && step_z <= detail::kMaxCellHeight * q))
      return bad_data("residual layer cell height " + std::to_string(h.step_z) + " m is not within 1-4 cell widths",
                      at + kHeadBytes + 28);
    std::optional<std::string> e;
    if (lattice) {
      if (!(h.pitch >= q && h.pitch <= 1e4))
        return bad_data("residual layer lattice pitch " + std::to_string(h.pitch) + " m is not in [step, 1e4]",
                        at + kHeadBytes + 24);
      if (h.columns == 0 || h.rows == 0 ||
          static_cast<std::uint64_t>(h.columns) * h.rows > kMaxLatticeCellsPerPoint * n_c + 64)
        return bad_data("residual layer lattice of " + std::to_string(h.columns) + " x " + std::to_string(h.rows) +
                            " cells is empty or has more than 4 a coded point",
                        at + kHeadBytes + 32);
      e = detail::decode_lattice_points(dec, origin, h.pitch, q, h.columns, h.rows,
                                        (h.voxel_reserved & kLatticeStackedBit) != 0, n_c, out.points);
    } else {
      e = detail::decode_acquisition_points(dec, origin, q, step_z, h.fit_pulses, n_c, out.points);
    }
    if (e) return bad_data("residual layer " + *e, h.stream_offset);
    if (dec.overrun() > 8)
      return bad_data("residual layer stream ends " + std::to_string(dec.overrun()) + " bytes early", payload.size());
    return out;
  }
  if (laser) {
    // (the kept word points: a laser of their own, no column)
    keys.columns = table.columns;
    keys.laser.reserve(out.points.size() + static_cast<std::size_t>(n_c));
    keys.laser.assign(out.points.size(), static_cast<std::uint16_t>(table.lasers()));
    keys.column.reserve(keys.laser.capacity());
    keys.column.assign(out.points.size(), table.columns);
    if (auto e = detail::decode_laser_points(dec, table, max_error, q, tangential_step, n_c, T_cloud_sensor, out.points,
                                             &keys))
      return bad_data("residual layer " + e->message, h.stream_offset);
    return out;
  }
  PointModels m;
  Predictor pr;
  AngularMemory memory(sweep ? h.cell : 0.0);
  const double qc = q / 4.0;
  for (std::uint64_t i = 0; i < n_c; ++i) {
    const bool escaped = dec.get(m.escape[pr.last_escaped ? 1 : 0]);
    Eigen::Vector3d d;
    Spherical s{};
    if (!escaped) {
      const int range_ctx =
          sweep ? PointModels::sweep_range_ctx(pr, memory.near(pr.elevation, wrap_angle(pr.azimuth + pr.azimuth_step), i + 1), q)
                : m.range_ctx(pr);
      const std::int64_t kr = m.range.get(dec, range_ctx);
      const std::int64_t ke = m.elevation.get(dec, m.elevation_ctx(pr, kr));
      const std::int64_t ka = m.azimuth.get(dec, m.azimuth_ctx(pr));
      d = sweep ? sweep_point(pr, q, kr, ke, ka, s) : spherical_point(pr, q, kr, ke, ka, s);
      m.shift(pr, kr, ke, ka);
    } else {
      for (int a = 0; a < 3; ++a) d[a] = pr.last[a] + static_cast<double>(m.cartesian[a].get(dec, 0)) * qc;
      s = to_spherical(d);
    }
    const Eigen::Vector3f pc = to_cloud_frame(T_cloud_sensor, d);
    if (!d.allFinite() || !(d.norm() < 1e12) || !pc.allFinite())
      return bad_data("residual layer point " + std::to_string(i) + " decodes to a non-finite position", h.stream_offset);
    pr.last_escaped = escaped;
    pr.update(d, s);
    memory.insert(s, i + 1);
    out.points.push_back(pc);
  }
  if (dec.overrun() > 8)
    return bad_data("residual layer stream ends " + std::to_string(dec.overrun()) + " bytes early", payload.size());
  return out;
}

Cloud decoder_word_cloud(const codec::ModelData& data, const Alphabet& alphabet, const codec::Quantization& q) {
  // The instances as the decoder will see them: quantised by a round trip through the codec.
  codec::ModelData words_only;
  words_only.input_points = data.input_points;
  words_only.T_cloud_sensor = data.T_cloud_sensor;
  words_only.model = data.model;
  words_only.alphabet = alphabet;  // embedded so that the round trip needs no file
  auto decoded = codec::decode_model(codec::encode_model(words_only, q));
  if (!decoded.ok()) throw std::logic_error("residual layer: the model does not round-trip: " + decoded.status().to_string());
  codec::ModelData placed = std::move(decoded).value();
  placed.alphabet = alphabet;
  return word_cloud(placed);
}

LayerStats add_layer(codec::ModelData& data, const Alphabet& alphabet, const Cloud& input, double max_error,
                     const LayerOptions& options, const codec::Quantization& q) {
  const Cloud words = decoder_word_cloud(data, alphabet, q);
  LayerStats stats;
  data.residual = encode_layer(input, words, data.T_cloud_sensor, max_error, &stats, options);
  return stats;
}

std::optional<double> fit_max_error(const std::function<std::size_t(double)>& size_of, std::size_t target_bytes,
                                    double relative_tolerance) {
  if (!(relative_tolerance > 0.0 && relative_tolerance < 1.0))
    throw std::invalid_argument("fit_max_error: relative tolerance must be in (0, 1)");
  if (size_of(kMaxMaxError) > target_bytes) return std::nullopt;
  if (size_of(kMinMaxError) <= target_bytes) return kMinMaxError;
  double lo = std::log(kMinMaxError), hi = std::log(kMaxMaxError);  // size(lo) > target >= size(hi)
  while (hi - lo > std::log1p(relative_tolerance)) {
    const double mid = 0.5 * (lo + hi);
    if (size_of(std::exp(mid)) <= target_bytes) hi = mid;
    else lo = mid;
  }
  return std::exp(hi);
}

StatusOr<Cloud> decode_cloud(const codec::ModelData& data) {
  Cloud words = word_cloud(data);
  LayerKeys keys;  // each decoded point's laser and column in a sensor-geometry layer's table
  StatusOr<Cloud> decoded = data.residual ? detail::decode_layer_lasers(*data.residual, words, data.T_cloud_sensor,
                                                                        data.input_points, keys)
                                          : StatusOr<Cloud>(std::move(words));
  if (decoded.ok()) decoded.value().stamp = data.stamp;
  if (!decoded.ok() || !data.attributes) return decoded;
  Cloud cloud = std::move(decoded).value();
  if (Status s = detail::decode_attributes(*data.attributes, keys, cloud); !s.ok())
    return Status(s.code(), "ATTR chunk: " + s.message(), s.offset());
  return cloud;
}

}  // namespace lex3d::residual
