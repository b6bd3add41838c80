// lex3d features FILE: range image, interest points, coverage points, descriptors.

#include <CLI/CLI.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>

#include "cli_common.hpp"
#include "json.hpp"
#include "plot.hpp"
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

// A colour ramp for ranges (dark blue -> cyan -> yellow -> red), dimmed a quarter so the
// feature marks stand out. Red and blue are never both above half: magenta, white and grey
// are free for the marks and the pixels without a range.
plot::Rgb ramp(double t) {
  t = std::clamp(t, 0.0, 1.0);
  const double r = std::clamp(1.5 - std::abs(4.0 * t - 3.0), 0.0, 1.0);
  const double g = std::clamp(1.5 - std::abs(4.0 * t - 2.0), 0.0, 1.0);
  const double b = std::clamp(1.5 - std::abs(4.0 * t - 1.0), 0.0, 1.0);
  auto dim = [](double v) { return static_cast<std::uint8_t>(std::lround(191.0 * v)); };
  return {dim(r), dim(g), dim(b)};
}

const plot::Rgb kInterest{255, 0, 255};
const plot::Rgb kCoverage{255, 255, 255};
const plot::Rgb kNoReturn{0, 0, 0};
const plot::Rgb kMaxRange{120, 120, 120};

// Round angle steps: 1, 2, 5, 10, 15, 30, 45 or 90 degrees.
plot::Ticks angle_ticks(double lo, double hi, int max_ticks) {
  plot::Ticks t = plot::nice_ticks(lo, hi, max_ticks);
  if (t.step > 10.0 && t.step < 100.0)
    for (const double s : {15.0, 30.0, 45.0, 90.0}) {
      plot::Ticks u;
      u.step = s;
      for (double v = std::ceil(lo / s - 1e-9) * s; v <= hi + 1e-9; v += s) u.values.push_back(v);
      if (static_cast<int>(u.values.size()) <= max_ticks) return u;
    }
  return t;
}

void write_png(const FeatureResult& res, const std::string& path, const std::string& name) {
  const RangeImage& img = res.image;
  if (img.empty()) throw CliError(2, "the scan has no points to draw");
  // Pixels drawn z wide and z * sy tall (sy: the pixel's aspect), so that a narrow image is
  // not a thumbnail; the text is twice the font's size beside an image this wide.
  const int sy = std::clamp(static_cast<int>(std::lround(img.elevation_resolution_rad / img.azimuth_resolution_rad)), 1, 8);
  const int z = img.width < 1000 ? std::clamp((800 + img.width - 1) / img.width, 2, 64) : 1;
  const int s = 2;
  const int iw = img.width * z, ih = img.height * sy * z;
  float rmax = 1.0F;
  std::size_t max_range_pixels = 0;
  for (std::size_t k = 0; k < img.range.size(); ++k) {
    if (img.state[k] == PixelState::kValid) rmax = std::max(rmax, img.range[k]);
    if (img.state[k] == PixelState::kMaxRange) ++max_range_pixels;
  }
  const double log_max = std::log1p(static_cast<double>(rmax));

  std::vector<plot::LegendEntry> entries;
  entries.push_back({plot::LegendEntry::Style::kMarker, "interest point (" + std::to_string(res.features.interest_count) + ")",
                     kInterest, plot::Marker::kSquare});
  entries.push_back({plot::LegendEntry::Style::kMarker, "coverage point (" + std::to_string(res.features.coverage_count) + ")",
                     kCoverage, plot::Marker::kSquare});
  entries.push_back({plot::LegendEntry::Style::kSwatch, "no return", kNoReturn});
  if (max_range_pixels > 0) entries.push_back({plot::LegendEntry::Style::kSwatch, "at or beyond the maximum range", kMaxRange});
  const plot::Rect legend_box = plot::legend_size(entries, s);

  const int left = 96, top = 62;
  const int bar_w = std::min(iw, 720);
  const int below = top + ih + 64;  // under the azimuth ticks and their label
  const int W = std::max(left + iw + 24, left + bar_w + 40 + legend_box.width() + 24);
  const int H = below + std::max(legend_box.height(), 16 + 60) + 16;
  plot::Canvas c(W, H);
  const plot::Rect area{left, top, left + iw, top + ih};
  plot::title(c, area, 8, "Range image: " + name);
  char sub[160];
  std::snprintf(sub, sizeof sub, "%d x %d pixels of %.3f x %.3f deg", img.width, img.height,
                img.azimuth_resolution_rad * 180.0 / M_PI, img.elevation_resolution_rad * 180.0 / M_PI);
  c.text((area.left + area.right) / 2, 30, sub, plot::kBlack, s, plot::Align::kCentre);

  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) {
      const std::size_t k = img.index(x, y);
      plot::Rgb col = kNoReturn;
      if (img.state[k] == PixelState::kValid) col = ramp(std::log1p(static_cast<double>(img.range[k])) / log_max);
      else if (img.state[k] == PixelState::kMaxRange) col = kMaxRange;
      c.fill({left + x * z, top + y * sy * z, left + (x + 1) * z, top + (y + 1) * sy * z}, col);
    }
  auto at = [&](const auto& kp) {
    return std::array<int, 2>{left + static_cast<int>(std::floor(kp.x * static_cast<float>(z))), top + static_cast<int>(std::floor(kp.y)) * sy * z + sy * z / 2};
  };
  for (const auto& f : res.features.features)
    if (f.keypoint.kind == FeatureKind::kCoverage) {
      const auto [x, y] = at(f.keypoint);
      const int d = std::min(z, 3);
      c.fill({x, y, x + d, y + d}, kCoverage);
    }
  for (const auto& f : res.features.features)  // on top of the coverage points
    if (f.keypoint.kind != FeatureKind::kCoverage) {
      const auto [x, y] = at(f.keypoint);
      c.marker(x, y, plot::Marker::kSquare, 6, plot::kBlack);
      c.marker(x, y, plot::Marker::kSquare, 4, kInterest);
    }

  // Azimuth along x (column 0 starts at azimuth_max_rad, decreasing), elevation along y from
  // the row borders (rows need not be evenly spaced).
  const double deg = 180.0 / M_PI;
  const double az0 = img.azimuth_max_rad * deg, az1 = (img.azimuth_max_rad - img.width * img.azimuth_resolution_rad) * deg;
  plot::Chart ch(c, area, az0, az1, 0.0, 1.0);
  ch.axes(angle_ticks(std::min(az0, az1), std::max(az0, az1), std::max(2, iw / 110)), plot::Ticks{},
          "azimuth, deg", "", false, s);
  const std::vector<double>& e = img.row_edges;
  if (e.size() == static_cast<std::size_t>(img.height) + 1) {
    const double el_top = e.front() * deg, el_bottom = e.back() * deg;
    const plot::Ticks yt = angle_ticks(el_bottom, el_top, std::max(2, ih / 28));
    int widest = 0, last = -1000;
    for (const double v : yt.values) {
      // The row holding v, and where in it.
      double row = -1;
      for (int r = 0; r < img.height; ++r)
        if (e[r] * deg >= v && v >= e[r + 1] * deg) {
          const double span = (e[r] - e[r + 1]) * deg;
          row = r + (span > 0 ? (e[r] * deg - v) / span : 0.5);
          break;
        }
      if (row < 0) continue;
      const int y = top + static_cast<int>(std::lround(row * sy * z));
      c.fill({left - 5, y, left, y + 1}, plot::kBlack);
      if (std::abs(y - last) < (plot::kCapHeight + 4) * s) continue;
      const plot::Rect b = c.text(left - 9, y, plot::format_tick(v, 0), plot::kBlack, s, plot::Align::kEnd, plot::Align::kCentre);
      widest = std::max(widest, b.width());
      last = y;
    }
    const std::string label = plot::text_width("elevation, deg", s) <= ih ? "elevation, deg" : "elev., deg";
    if (plot::text_width(label, s) <= ih + 2 * top - 16)  // else it would run into the title
      c.text_up(left - 9 - widest - 8, (area.top + area.bottom) / 2, label, plot::kBlack, s, plot::Align::kCentre,
                plot::Align::kEnd);
  }

  // The range colour bar (log scale: the ramp runs over log(1 + range)) and the legend.
  const plot::Rect bar{left, below, left + bar_w, below + 16};
  std::vector<double> ticks;
  for (const double v : {0.0, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0, 500.0, 1000.0})
    if (v <= rmax) ticks.push_back(v);
  plot::colour_bar(c, bar, ramp, [&](double v) { return std::log1p(v) / log_max; }, ticks, 0,
                   "range, m (log scale, up to " + plot::format_tick(rmax, 1) + ")", s);
  plot::legend(c, bar.right + 40, below, entries, plot::Align::kStart, plot::Align::kStart, s);
  throw_if_error(io::write_png_rgb(path, c.width(), c.height(), c.rgb()));
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
  if (!o.png.empty()) write_png(res, o.png, std::filesystem::path(o.path).filename().string());
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
  sub->add_option("--png", o->png, "Draw the range image (colour: range, with a colour bar in metres) with the interest (magenta) and coverage (white) points to this PNG; default: no picture")
      ->type_name("FILE");
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
