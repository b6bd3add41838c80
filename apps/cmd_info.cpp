// lex3d info FILE: what a point cloud file holds.

#include <CLI/CLI.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iostream>

#include "cli_common.hpp"
#include "json.hpp"
#include "lex3d/range/range_image.hpp"

namespace lex3d::cli {

namespace {

struct InfoOptions {
  std::string path;
  std::string format = "auto";
  bool json = false;
};

double quantile(std::vector<float> v, double q) {
  if (v.empty()) return std::nan("");
  const auto k = static_cast<std::size_t>(q * static_cast<double>(v.size() - 1));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return static_cast<double>(v[k]);
}

void run_info(const InfoOptions& o) {
  const io::ReadResult r = load_cloud(o.path, parse_format_option(o.format));
  const Cloud& c = r.cloud;
  const Bounds b = compute_bounds(c);
  std::vector<float> ranges;
  ranges.reserve(c.size());
  const Eigen::Isometry3f T_sensor_cloud = c.T_cloud_sensor.inverse().cast<float>();
  for (const auto& p : c.points) ranges.push_back((T_sensor_cloud * p).norm());
  float imin = 0.0F, imax = 0.0F;
  if (c.has_intensity()) {
    const auto [lo, hi] = std::minmax_element(c.intensity.begin(), c.intensity.end());
    imin = *lo;
    imax = *hi;
  }
  const auto res = estimate_angular_resolution(c);
  const double rad2deg = 180.0 / M_PI;
  const double r_min = quantile(ranges, 0.0), r_med = quantile(ranges, 0.5), r_max = quantile(ranges, 1.0);

  if (o.json) {
    Json j;
    j.begin_object();
    j.value("file", o.path).value("format", io::format_name(r.format)).value("encoding", r.encoding);
    j.value("file_bytes", r.file_bytes).value("points", c.size());
    j.value("non_finite_dropped", r.non_finite_dropped).value("no_return_dropped", r.no_return_dropped);
    j.value("has_intensity", c.has_intensity());
    if (b.valid) {
      j.numbers("bounds_min", {b.min.x(), b.min.y(), b.min.z()});
      j.numbers("bounds_max", {b.max.x(), b.max.y(), b.max.z()});
    }
    j.begin_object("range_m").value("min", r_min).value("median", r_med).value("max", r_max).end_object();
    if (c.has_intensity()) j.begin_object("intensity").value("min", imin).value("max", imax).end_object();
    if (res)
      j.begin_object("angular_resolution_deg")
          .value("azimuth", res->azimuth_rad * rad2deg)
          .value("elevation", res->elevation_rad * rad2deg)
          .end_object();
    j.value("has_world_pose", c.has_world_pose);
    j.end_object();
    std::cout << j.str() << "\n";
    return;
  }
  std::printf("file           %s\n", o.path.c_str());
  std::printf("format         %s%s%s\n", std::string(io::format_name(r.format)).c_str(),
              r.encoding.empty() ? "" : " / ", r.encoding.c_str());
  std::printf("file size      %llu bytes\n", static_cast<unsigned long long>(r.file_bytes));
  std::printf("points         %zu\n", c.size());
  std::printf("NaN/Inf dropped %zu\n", r.non_finite_dropped);
  if (r.no_return_dropped) std::printf("no-return      %zu (kept as max-range directions)\n", r.no_return_dropped);
  if (b.valid)
    std::printf("bounds         [%.3f %.3f %.3f] .. [%.3f %.3f %.3f] m\n", static_cast<double>(b.min.x()),
                static_cast<double>(b.min.y()), static_cast<double>(b.min.z()), static_cast<double>(b.max.x()),
                static_cast<double>(b.max.y()), static_cast<double>(b.max.z()));
  if (!ranges.empty()) std::printf("range          min %.3f  median %.3f  max %.3f m\n", r_min, r_med, r_max);
  if (c.has_intensity())
    std::printf("intensity      %.4g .. %.4g\n", static_cast<double>(imin), static_cast<double>(imax));
  if (res)
    std::printf("beam spacing   %.4f deg horizontal, %.4f deg vertical (estimated)\n", res->azimuth_rad * rad2deg,
                res->elevation_rad * rad2deg);
  if (c.has_world_pose) std::printf("world pose     yes\n");
}

}  // namespace

void register_info(CLI::App& app) {
  auto o = std::make_shared<InfoOptions>();
  CLI::App* sub = app.add_subcommand("info", "Describe a point cloud file: format, points, bounds, ranges");
  sub->add_option("file", o->path, "Point cloud (.bin, .pcd, .ply, .xyz/.txt, .3d)")->required();
  sub->add_option("--format", o->format, "Input format: auto, kitti, binxyz, pcd, ply, xyz, uos");
  sub->add_flag("--json", o->json, "Print one JSON object");
  sub->callback([o] { run_info(*o); });
}

}  // namespace lex3d::cli
