// read_cloud: reads the file, picks the format and hands the bytes to its
// reader; read_file; helpers the readers share.
//
// The readers, one a source: read_bin.cpp (KITTI / x y z float binaries),
// read_pcd.cpp (PCD ascii, binary, binary_compressed), read_ply.cpp (PLY ascii,
// binary little/big endian), read_text.cpp (x y z text and 3DTK `.3d`).
// Every reader works on the whole file in memory and checks each length read
// from the file against the bytes left before it allocates or reads; errors
// are one-line messages "<path>: <what is wrong>" with a byte offset where one
// is meaningful.

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <new>
#include <stdexcept>

#include "io/internal.hpp"
#include "lex3d/io/io.hpp"
#include "lex3d/io/rosbag.hpp"
#include "lex3d/io/sensor_log.hpp"

namespace lex3d::io {

using detail::msg;

namespace detail {

std::vector<std::string_view> split_ws(std::string_view line) {
  std::vector<std::string_view> out;
  for_each_token(line, false, [&](const char* b, const char* e) {
    out.emplace_back(b, static_cast<std::size_t>(e - b));
    return true;
  });
  return out;
}

// A cloud whose coordinates lie farther from their frame's origin than the cloud's own
// extent, where float32 would round them by more than a millionth of that extent (at
// least of a metre; a UTM
// or state-plane map: 0.25 m at 5,403,850 m), is stored relative to an origin: its bounding
// box centre rounded to the largest power of ten not above the extent, so that the local
// coordinates stay within the extent and the origin reads well. Anything else is rounded
// to float32 as before.
/// Keeps the points of `r` for which keep(i) holds (called once a point, in order), with
/// every per-point channel (keep_cloud_points) and the result's colours.
template <class Keep>
std::size_t keep_points(ReadResult& r, Keep keep) {
  return keep_cloud_points(r.cloud, keep, &r.colors);
}

std::optional<Eigen::Vector3d> wide_origin(const std::vector<Eigen::Vector3d>& points) {
  const std::size_t n = points.size();
  if (n == 0) return std::nullopt;
  Eigen::Vector3d lo = points[0], hi = points[0];
  for (const Eigen::Vector3d& p : points) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  const double extent = (hi - lo).maxCoeff();
  const Eigen::Vector3d centre = 0.5 * (lo + hi);
  const double max_abs = std::max(lo.cwiseAbs().maxCoeff(), hi.cwiseAbs().maxCoeff());
  const auto f = static_cast<float>(max_abs);
  const double half_ulp = 0.5 * (static_cast<double>(std::nextafter(f, INFINITY)) - static_cast<double>(f));
  if (!(centre.cwiseAbs().maxCoeff() > extent && half_ulp > 1e-6 * std::max(extent, 1.0))) return std::nullopt;
  const double step = std::pow(10.0, std::floor(std::log10(std::max(extent, 1e-3))));
  Eigen::Vector3d origin;
  for (int a = 0; a < 3; ++a) origin[a] = std::round(centre[a] / step) * step;
  return origin;
}

Status check_reach(const std::vector<Eigen::Vector3d>& points, const std::string& path) {
  double max_abs = 0.0;
  for (const Eigen::Vector3d& p : points) max_abs = std::max(max_abs, p.cwiseAbs().maxCoeff());
  if (!(max_abs <= kMaxCoordinateM))
    return bad_data(msg(path, "the points reach " + std::to_string(max_abs) +
                                  " m, beyond any coordinate frame on Earth (the limit is 1e9 m)"));
  return {};
}

void set_relative_points(Cloud& cloud, const std::vector<Eigen::Vector3d>& points, const Eigen::Vector3d& origin,
                         const std::string& unit_name) {
  const std::size_t n = points.size();
  cloud.points.resize(n);
  Georeference g;
  g.origin = origin;
  g.unit_name = unit_name;
  double worst2 = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d local = points[i] - origin;
    cloud.points[i] = local.cast<float>();
    worst2 = std::max(worst2, (cloud.points[i].cast<double>() - local).squaredNorm());
  }
  g.representation_error_m = std::sqrt(worst2);
  // A sensor pose given with the points (a PCD VIEWPOINT) moves with them; none given (the
  // identity) leaves the sensor at the local origin, near the points, as a LAS file's is:
  // at the CRS's origin, thousands of kilometres off, no bound finer than float32's
  // resolution there (0.5 m) could be kept.
  if (!cloud.T_cloud_sensor.matrix().isIdentity(0.0)) cloud.T_cloud_sensor.translation() -= origin;
  cloud.georef = std::move(g);
}

void Builder::drop_unfit_fields() {
  for (std::size_t k = unfit_.size(); k-- > 0;) {
    if (!unfit_[k]) continue;
    const bool wide = r_.cloud.fields[k].type == FieldType::kFloat64;
    r_.dropped_fields.push_back(printable(r_.cloud.fields[k].name, 64) +
                                (wide ? " (double-precision values that float32 does not hold)" : " (values above 2^31 - 1)"));
    r_.cloud.fields.erase(r_.cloud.fields.begin() + static_cast<std::ptrdiff_t>(k));
  }
  unfit_.clear();
}

Status Builder::finish(const std::string& path) {
  drop_unfit_fields();
  if (!wide_) return {};
  const std::size_t n = wide_points_.size();
  const std::optional<Eigen::Vector3d> origin = wide_origin(wide_points_);
  if (!origin) {
    // float32 as before; a value beyond float's range is not finite there: dropped and counted
    r_.cloud.points.resize(n);
    for (std::size_t i = 0; i < n; ++i) r_.cloud.points[i] = wide_points_[i].cast<float>();
    keep_points(r_, [&](std::size_t i) {
      const Eigen::Vector3f& p = r_.cloud.points[i];
      if (!p.allFinite()) {
        ++r_.non_finite_dropped;
        return false;
      }
      if (organised_ && p.isZero(0.0F)) {  // underflowed to (0, 0, 0): a no-return, as in float files
        ++r_.no_return_dropped;
        return false;
      }
      return true;
    });
    return {};
  }
  if (Status st = check_reach(wide_points_, path); !st.ok()) return st;
  set_relative_points(r_.cloud, wide_points_, *origin, "metre (assumed: the file names no unit)");
  wide_points_.clear();
  wide_points_.shrink_to_fit();
  return {};
}

}  // namespace detail

Status set_double_points(Cloud& cloud, const std::vector<Eigen::Vector3d>& points, const std::string& what,
                         const std::string& unit_name) {
  if (Status st = detail::check_reach(points, what); !st.ok()) return st;
  if (const auto origin = detail::wide_origin(points)) {
    detail::set_relative_points(cloud, points, *origin, unit_name);
    return {};
  }
  cloud.points.resize(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) cloud.points[i] = points[i].cast<float>();
  return {};
}

namespace {

/// Drops the points no lidar can have measured (see ReadResult::far_dropped), keeping every
/// per-point channel in step.
void drop_far_points(ReadResult& r) {
  Cloud& c = r.cloud;
  const std::size_t n = c.points.size();
  if (n == 0 || c.georef) return;
  const Eigen::Vector3f o = c.T_cloud_sensor.translation().cast<float>();
  std::vector<float> d(n);
  for (std::size_t i = 0; i < n; ++i) d[i] = (c.points[i] - o).norm();  // inf for 1e30-ish: fine
  std::vector<float> sorted = d;
  const std::size_t k = std::min(n - 1, static_cast<std::size_t>(0.99 * static_cast<double>(n)));
  std::nth_element(sorted.begin(), sorted.begin() + static_cast<std::ptrdiff_t>(k), sorted.end());
  constexpr double kTerrestrialReachM = 1e4;  // no terrestrial lidar measures 10 km
  const double limit = std::max(kTerrestrialReachM, 100.0 * static_cast<double>(sorted[k]));
  sorted.clear();
  sorted.shrink_to_fit();
  r.far_limit_m = limit;
  const std::size_t kept = detail::keep_points(r, [&](std::size_t i) { return static_cast<double>(d[i]) <= limit; });
  if (kept == n) return;
  r.far_dropped = n - kept;
  char buf[160];
  std::snprintf(buf, sizeof buf, "%zu point%s farther than %.0f m from the sensor dropped (beyond any lidar's reach)",
                r.far_dropped, r.far_dropped == 1 ? "" : "s", limit);
  r.notes.emplace_back(buf);
}

/// `<dir>/<stem>.pose` for `<dir>/<stem>.3d`.
std::string pose_path_for(const std::string& path) {
  const std::size_t slash = path.find_last_of('/');
  const std::size_t dot = path.find_last_of('.');
  if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return path + ".pose";
  return path.substr(0, dot) + ".pose";
}

/// A raw log's first complete turn (the others read to count them, one at a time).
StatusOr<ReadResult> read_log_first_turn(const std::string& path, const ReadOptions& options) {
  auto reader = SensorLogReader::open(path, options);
  if (!reader.ok()) return reader.status();
  ReadResult r;
  for (;;) {
    auto turn = reader.value()->next();
    if (!turn.ok()) return turn.status();
    if (!turn.value()) break;
    if (r.scans_in_file++ > 0) continue;
    r.no_return_dropped = turn.value()->no_returns;
    r.cloud = std::move(turn.value()->cloud);
  }
  const SensorLogInfo& info = reader.value()->info();
  r.format = Format::kPcap;
  r.encoding = info.vendor + " " + info.profile;
  r.sensor = info.sensor;
  struct stat st {};
  if (::stat(path.c_str(), &st) == 0) r.file_bytes = static_cast<std::uint64_t>(st.st_size);
  return r;
}

/// A ROS bag's first scan on the topic options.bag_topic (the others read to count them,
/// one at a time: BagReader).
StatusOr<ReadResult> read_bag_first_scan(const std::string& path, const ReadOptions& options) {
  auto reader = BagReader::open(path, options.bag_topic, options);
  if (!reader.ok()) return reader.status();
  ReadResult r;
  for (;;) {
    auto scan = reader.value()->next();
    if (!scan.ok()) return scan.status();
    if (!scan.value()) break;
    if (r.scans_in_file++ == 0) r.cloud = std::move(scan.value()->cloud);
  }
  const BagScans& b = reader.value()->summary();
  r.encoding = "ROS bag " + b.topic + " (" + b.type + ")";
  r.sensor = b.sensor;
  r.no_return_dropped = b.no_return_dropped;
  r.non_finite_dropped = b.non_finite_dropped;
  r.dropped_fields = b.dropped_fields;
  r.notes = b.notes;
  struct stat st {};
  if (::stat(path.c_str(), &st) == 0) r.file_bytes = static_cast<std::uint64_t>(st.st_size);
  return r;
}

StatusOr<ReadResult> read_cloud_impl(const std::string& path, const ReadOptions& options) {
  if (options.format == Format::kPcap || (options.format == Format::kAuto && is_sensor_log(path)))
    return read_log_first_turn(path, options);
  if (options.format == Format::kAuto && is_rosbag(path)) return read_bag_first_scan(path, options);
  auto file = read_file(path);
  if (!file.ok()) return file.status();
  const std::vector<std::uint8_t>& bytes = file.value();
  ReadResult r;
  r.file_bytes = bytes.size();
  if (bytes.empty()) return bad_data(msg(path, "file is empty"), 0);
  Format f = options.format;
  const bool detected = f == Format::kAuto;
  if (detected) {
    auto d = detail::detect_from_bytes(path, bytes.data(), std::min<std::size_t>(bytes.size(), 4096),
                                       bytes.size());
    if (!d.ok()) return d.status();
    f = d.value();
  }
  r.format = f;
  Status s;
  switch (f) {
    case Format::kKitti:
    case Format::kBinXyz:
      s = detail::read_float_binary(path, bytes.data(), bytes.size(), f, detected, r);
      break;
    case Format::kPcd: s = detail::read_pcd(path, bytes.data(), bytes.size(), r); break;
    case Format::kPly: s = detail::read_ply(path, bytes.data(), bytes.size(), r); break;
    case Format::kXyz: s = detail::read_text(path, bytes.data(), bytes.size(), false, options, r); break;
    case Format::kLas: s = detail::read_las(path, bytes.data(), bytes.size(), r); break;
    case Format::kUos3d: s = detail::read_text(path, bytes.data(), bytes.size(), true, options, r); break;
    case Format::kPcap:  // handled above; reached only when detection disagrees with is_sensor_log
    case Format::kAuto: s = bad_data(msg(path, "cannot tell the format")); break;
  }
  if (!s.ok()) return s;
  drop_far_points(r);
  if (f == Format::kUos3d && options.load_pose) {
    const std::string pose_path = pose_path_for(path);
    struct stat st {};
    if (::stat(pose_path.c_str(), &st) == 0) {
      auto pose = detail::read_uos_pose(pose_path);
      if (!pose.ok()) return pose.status();
      r.cloud.T_world_cloud = pose.value();
      r.cloud.has_world_pose = true;
    }
  }
  return r;
}

}  // namespace

StatusOr<std::vector<std::uint8_t>> read_file(const std::string& path, std::uint64_t max_bytes) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return io_error(msg(path, std::string("cannot open: ") + std::strerror(errno)));
  struct Closer {
    int fd;
    ~Closer() { ::close(fd); }
  } closer{fd};
  struct stat st {};
  if (::fstat(fd, &st) != 0) return io_error(msg(path, std::string("cannot stat: ") + std::strerror(errno)));
  if (S_ISDIR(st.st_mode)) return io_error(msg(path, "is a directory"));
  auto too_big = [&]() {
    return bad_data(msg(path, "file is larger than the limit of " + std::to_string(max_bytes) + " bytes"));
  };
  std::vector<std::uint8_t> buf;
  try {
    std::size_t want = 0;
    if (S_ISREG(st.st_mode)) {
      const auto sz = static_cast<std::uint64_t>(st.st_size);
      if (sz > max_bytes) return too_big();
      want = static_cast<std::size_t>(sz);
    }
    buf.resize(want);
    std::size_t got = 0;
    while (got < buf.size()) {
      const ssize_t r = ::read(fd, buf.data() + got, buf.size() - got);
      if (r < 0 && errno == EINTR) continue;
      if (r < 0) return io_error(msg(path, std::string("cannot read: ") + std::strerror(errno)));
      if (r == 0) break;  // the file shrank
      got += static_cast<std::size_t>(r);
    }
    if (got == buf.size()) {
      // the file grew, or it is a pipe: read the rest in chunks
      std::array<std::uint8_t, 1U << 14> chunk{};
      for (;;) {
        const ssize_t r = ::read(fd, chunk.data(), chunk.size());
        if (r < 0 && errno == EINTR) continue;
        if (r < 0) return io_error(msg(path, std::string("cannot read: ") + std::strerror(errno)));
        if (r == 0) break;
        const auto n = static_cast<std::size_t>(r);
        if (got + n > max_bytes) return too_big();
        buf.insert(buf.end(), chunk.begin(), chunk.begin() + r);
        got += n;
      }
    }
    buf.resize(got);
  } catch (const std::bad_alloc&) {
    return out_of_memory(msg(path, "out of memory reading the file"));
  }
  return buf;
}

StatusOr<ReadResult> read_cloud(const std::string& path, const ReadOptions& options) {
  try {
    auto r = read_cloud_impl(path, options);
    // colours travel with the cloud (Cloud::rgb) as well as in ReadResult::colors
    if (r.ok() && r.value().cloud.rgb.empty() && !r.value().colors.empty() &&
        r.value().colors.size() == r.value().cloud.size())
      r.value().cloud.rgb = r.value().colors;
    return r;
  } catch (const std::bad_alloc&) {
    return out_of_memory(msg(path, "out of memory reading the point cloud"));
  } catch (const std::length_error&) {
    return out_of_memory(msg(path, "out of memory reading the point cloud"));
  }
}

}  // namespace lex3d::io
