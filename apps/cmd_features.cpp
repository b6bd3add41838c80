// lex3d features FILE: range image, interest points, coverage points, descriptors.

#include <CLI/CLI.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iostream>

#include "cli_common.hpp"
#include "json.hpp"
#include "lex3d/core/timer.hpp"
#include "lex3d/features/features.hpp"

namespace lex3d::cli {

namespace {

struct FeaturesOptions {
  std::string path;
  std::string format = "auto";
  std::string png;
  std::string up = "0,0,1";
  bool json = false;
  int threads = 2;
  double threshold = InterestParams{}.threshold;
  double min_distance = InterestParams{}.min_distance;
  double coverage = CoverageParams{}.distance;
  double support_radius = DescriptorParams{}.support_radius;
  double az_res_deg = 0.0;
  double el_res_deg = 0.0;
};

// A perceptual-ish colour ramp (dark blue -> cyan -> yellow -> red) for ranges.
std::array<std::uint8_t, 3> ramp(double t) {
  t = std::clamp(t, 0.0, 1.0);
  const double r = std::clamp(1.5 - std::abs(4.0 * t - 3.0), 0.0, 1.0);
  const double g = std::clamp(1.5 - std::abs(4.0 * t - 2.0), 0.0, 1.0);
  const double b = std::clamp(1.5 - std::abs(4.0 * t - 1.0), 0.0, 1.0);
  return {static_cast<std::uint8_t>(255 * r), static_cast<std::uint8_t>(255 * g), static_cast<std::uint8_t>(255 * b)};
}

void write_png(const FeatureResult& res, const std::string& path) {
  const RangeImage& img = res.image;
  if (img.empty()) throw CliError(2, "the scan has no points to draw");
  const int sy = std::clamp(static_cast<int>(std::lround(img.elevation_resolution_rad / img.azimuth_resolution_rad)), 1, 8);
  const int W = img.width;
  const int H = img.height * sy;
  std::vector<std::uint8_t> rgb(static_cast<std::size_t>(W) * static_cast<std::size_t>(H) * 3, 0);
  float rmax = 1.0F;
  for (std::size_t k = 0; k < img.range.size(); ++k)
    if (img.state[k] == PixelState::kValid) rmax = std::max(rmax, img.range[k]);
  const double log_max = std::log1p(static_cast<double>(rmax));
  auto put = [&](int x, int y, std::array<std::uint8_t, 3> c) {
    if (x < 0 || y < 0 || x >= W || y >= H) return;
    std::uint8_t* p = &rgb[(static_cast<std::size_t>(y) * static_cast<std::size_t>(W) + static_cast<std::size_t>(x)) * 3];
    p[0] = c[0];
    p[1] = c[1];
    p[2] = c[2];
  };
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) {
      const std::size_t k = img.index(x, y);
      std::array<std::uint8_t, 3> c{0, 0, 0};
      if (img.state[k] == PixelState::kValid) {
        const auto col = ramp(std::log1p(static_cast<double>(img.range[k])) / log_max);
        // Dim the ramp so the feature marks stand out.
        c = {static_cast<std::uint8_t>(col[0] * 3 / 4), static_cast<std::uint8_t>(col[1] * 3 / 4),
             static_cast<std::uint8_t>(col[2] * 3 / 4)};
      } else if (img.state[k] == PixelState::kMaxRange) {
        c = {25, 25, 70};
      }
      for (int r = 0; r < sy; ++r) put(x, y * sy + r, c);
    }
  for (const auto& f : res.features.features) {
    const int x = static_cast<int>(std::floor(f.keypoint.x));
    const int y = static_cast<int>(std::floor(f.keypoint.y)) * sy + sy / 2;
    if (f.keypoint.kind == FeatureKind::kCoverage) {
      put(x, y, {255, 255, 255});
    } else {
      for (int d = -3; d <= 3; ++d) {
        put(x + d, y, {255, 0, 0});
        put(x, y + d, {255, 0, 0});
      }
    }
  }
  throw_if_error(io::write_png_rgb(path, W, H, rgb));
}

void run_features(const FeaturesOptions& o) {
  if (!o.png.empty()) check_output_path(o.png, {o.path});
  Stopwatch sw;
  const io::ReadResult r = load_cloud(o.path, parse_format_option(o.format));
  const double read_ms = sw.lap_ms();
  FeatureParams p;
  p.threads = o.threads;
  p.interest.threshold = o.threshold;
  p.interest.min_distance = o.min_distance;
  p.coverage.distance = o.coverage;
  p.descriptor.support_radius = o.support_radius;
  p.descriptor.up = parse_vector3(o.up, "--up");
  p.range.azimuth_resolution_rad = o.az_res_deg * M_PI / 180.0;
  p.range.elevation_resolution_rad = o.el_res_deg * M_PI / 180.0;
  const FeatureResult res = extract_features(r.cloud, p);
  if (!o.png.empty()) write_png(res, o.png);
  const auto& t = res.timings;
  const auto& img = res.image;
  const double rad2deg = 180.0 / M_PI;
  if (o.json) {
    Json j;
    j.begin_object();
    j.value("file", o.path).value("points", r.cloud.size());
    j.begin_object("range_image")
        .value("width", img.width)
        .value("height", img.height)
        .value("azimuth_resolution_deg", img.azimuth_resolution_rad * rad2deg)
        .value("elevation_resolution_deg", img.elevation_resolution_rad * rad2deg)
        .value("valid_pixels", img.valid_count)
        .value("hidden_points", img.points_hidden)
        .end_object();
    j.value("interest_points", res.features.interest_count).value("coverage_points", res.features.coverage_count);
    j.value("local_maxima", res.interest.maxima)
        .value("occlusion_rejected", res.interest.occlusion_rejected)
        .value("line_rejected", res.interest.line_rejected);
    j.value("descriptor_dim", res.features.descriptor_dim);
    j.begin_object("timings_ms")
        .value("read", read_ms)
        .value("range_image", t.range_image_ms)
        .value("interest", t.interest_ms)
        .value("coverage", t.coverage_ms)
        .value("descriptors", t.descriptor_ms)
        .value("total", t.total_ms())
        .end_object();
    if (!o.png.empty()) j.value("png", o.png);
    j.end_object();
    std::cout << j.str() << "\n";
    return;
  }
  std::printf("%s: %zu points\n", o.path.c_str(), r.cloud.size());
  std::printf("range image     %d x %d, %.4f x %.4f deg/px, %zu valid pixels, %zu points hidden\n", img.width,
              img.height, img.azimuth_resolution_rad * rad2deg, img.elevation_resolution_rad * rad2deg,
              img.valid_count, img.points_hidden);
  std::printf("interest points %zu  (local maxima %zu, line filter rejected %zu, occlusion pixels %zu)\n",
              res.features.interest_count, res.interest.maxima, res.interest.line_rejected,
              res.interest.occlusion_rejected);
  std::printf("coverage points %zu  (every point within %.3g m of a feature)\n", res.features.coverage_count,
              o.coverage);
  std::printf("descriptors     %zu x %d\n", res.features.size(), res.features.descriptor_dim);
  std::printf("time            read %.1f ms | range image %.1f | interest %.1f | coverage %.1f | descriptors %.1f | total %.1f ms\n",
              read_ms, t.range_image_ms, t.interest_ms, t.coverage_ms, t.descriptor_ms, t.total_ms());
  if (!o.png.empty()) std::printf("wrote           %s\n", o.png.c_str());
}

}  // namespace

void register_features(CLI::App& app) {
  auto o = std::make_shared<FeaturesOptions>();
  CLI::App* sub = app.add_subcommand("features", "Range image, interest points, coverage points and descriptors");
  sub->footer("Examples:\n  lex3d features scan.bin --png features.png --json");
  sub->add_option("file", o->path, "Point cloud (.bin, .pcd, .ply, .xyz/.txt, .3d)")->required();
  sub->add_option("--format", o->format, "Input format: auto, kitti, binxyz, pcd, ply, xyz, uos");
  sub->add_option("--png", o->png, "Draw the range image with interest (red) and coverage (white) points");
  sub->add_flag("--json", o->json, "Print one JSON object");
  add_threads_option(*sub, o->threads, "Worker threads for descriptors");
  sub->add_option("--threshold", o->threshold, "Interest value threshold, (0, 1]");
  sub->add_option("--min-distance", o->min_distance, "Minimum 3D distance between interest points, m");
  sub->add_option("--coverage", o->coverage, "Coverage distance, m (0 disables coverage points)");
  sub->add_option("--support-radius", o->support_radius, "Descriptor support radius, m");
  sub->add_option("--up", o->up, "World up direction in the scan frame, x,y,z");
  sub->add_option("--azimuth-res-deg", o->az_res_deg, "Horizontal pixel size, degrees (0 = from the data)");
  sub->add_option("--elevation-res-deg", o->el_res_deg, "Vertical pixel size, degrees (0 = from the data)");
  sub->callback([o] { run_features(*o); });
}

}  // namespace lex3d::cli
