#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "lex3d/core/timer.hpp"
#include "lex3d/model/model.hpp"
#include "model/point_grid.hpp"

namespace lex3d {

void ModelParams::validate() const {
  if (!(word_radius == 0.0 || (word_radius > 0.0 && word_radius <= 10.0)))
    throw std::invalid_argument("ModelParams::word_radius must be 0 (derive) or in (0, 10] m");
  if (!(coverage_factor > 0.0 && coverage_factor <= 10.0))
    throw std::invalid_argument("ModelParams::coverage_factor must be in (0, 10]");
  if (!(word_spacing_factor >= 0.0 && word_spacing_factor <= 1.0))
    throw std::invalid_argument("ModelParams::word_spacing_factor must be in [0, 1]");
  if (!(sigma_lambda > 0.0 && sigma_lambda <= 100.0))
    throw std::invalid_argument("ModelParams::sigma_lambda must be in (0, 100]");
  if (threads < 1 || threads > 64) throw std::invalid_argument("ModelParams::threads must be in [1, 64]");
  if (fit_candidates < 1 || fit_candidates > 64)
    throw std::invalid_argument("ModelParams::fit_candidates must be in [1, 64]");
  if (refine_iterations < 0 || refine_iterations > 50)
    throw std::invalid_argument("ModelParams::refine_iterations must be in [0, 50]");
  if (!(refine_reach_factor > 0.0 && refine_reach_factor <= 1.0))
    throw std::invalid_argument("ModelParams::refine_reach_factor must be in (0, 1]");
  features.validate();
}

namespace {

double median_range(const Cloud& cloud) {
  if (cloud.empty()) return 0.0;
  const Eigen::Isometry3f T_sensor_cloud = cloud.T_cloud_sensor.inverse().cast<float>();
  std::vector<float> r;
  r.reserve(cloud.size());
  for (const auto& p : cloud.points) r.push_back((T_sensor_cloud * p).norm());
  const auto mid = r.begin() + static_cast<std::ptrdiff_t>(r.size() / 2);
  std::nth_element(r.begin(), mid, r.end());
  return static_cast<double>(*mid);
}

}  // namespace

double derive_word_radius(const Cloud& cloud) {
  const auto res = estimate_angular_resolution(cloud);
  if (!res) return 0.25;  // too few points to measure: ruhnke2010's outdoor value
  const double spacing = median_range(cloud) * std::sqrt(res->azimuth_rad * res->elevation_rad);
  return std::clamp(8.0 * spacing, 0.1, 1.0);
}

namespace {

double resolve_word_radius(const Cloud& cloud, const ModelParams& params, double word_radius) {
  return word_radius > 0.0 ? word_radius : params.word_radius > 0.0 ? params.word_radius : derive_word_radius(cloud);
}

FeatureParams feature_params_for(const Cloud& cloud, const ModelParams& params, double word_radius) {
  FeatureParams fp = params.features;
  fp.threads = params.threads;
  fp.coverage.distance = params.coverage_factor * word_radius;
  if (cloud.has_world_pose) fp.descriptor.up = cloud.T_world_cloud.linear().transpose() * Eigen::Vector3d::UnitZ();
  return fp;
}

}  // namespace

FeatureParams prepare_feature_params(const Cloud& cloud, const ModelParams& params, double word_radius) {
  params.validate();
  return feature_params_for(cloud, params, resolve_word_radius(cloud, params, word_radius));
}

PreparedScan prepare_scan(const Cloud& cloud, const ModelParams& params, double word_radius) {
  params.validate();
  Stopwatch sw;
  PreparedScan s;
  s.cloud = cloud;
  s.word_radius = resolve_word_radius(cloud, params, word_radius);
  const FeatureParams fp = feature_params_for(cloud, params, s.word_radius);
  FeatureResult fr = extract_features(cloud, fp);
  s.features = std::move(fr.features);
  s.timings = fr.timings;
  // The range image measured the beam spacing already (unless its pixel sizes were given).
  const auto res = fr.image.beam_spacing ? fr.image.beam_spacing : estimate_angular_resolution(cloud);
  // The image is not needed any more: its memory, freed now, serves the neighbourhoods
  // below instead of fresh pages (each first touch of which costs a page fault).
  fr.image = RangeImage{};
  s.beam_spacing = res ? std::max(res->azimuth_rad, res->elevation_rad) : 0.2 * M_PI / 180.0;

  // σ of eq. 13 for every point.
  const double factor = params.sigma_lambda * std::tan(s.beam_spacing / 2.0);
  const Eigen::Vector3f origin = cloud.T_cloud_sensor.translation().cast<float>();
  s.sigma.resize(cloud.size());
  for (std::size_t i = 0; i < cloud.size(); ++i)
    s.sigma[i] = static_cast<float>(std::max(1e-3, factor * static_cast<double>((cloud.points[i] - origin).norm())));

  // Points within δ + 3σ of each feature point (the most a word placed there can reach).
  const std::size_t nf = s.features.size();
  s.nearby_offset.assign(nf + 1, 0);
  if (!cloud.empty() && nf > 0) {
    std::vector<Eigen::Vector3f> centre(nf);
    std::vector<float> reach(nf);
    for (std::size_t f = 0; f < nf; ++f) {
      const Eigen::Vector3d t = s.features.features[f].T_cloud_feature.translation();
      const double range = (t - cloud.T_cloud_sensor.translation()).norm();
      centre[f] = t.cast<float>();
      reach[f] = static_cast<float>(s.word_radius + 3.0 * factor * (range + s.word_radius) + 1e-3);
    }
    // Cells about as large as the typical ball: smaller ones cost more registrations
    // than they save in point tests (reaches grow with range, to several δ).
    std::vector<float> sorted = reach;
    const auto mid = sorted.begin() + static_cast<std::ptrdiff_t>(sorted.size() / 2);
    std::nth_element(sorted.begin(), mid, sorted.end());
    detail::BallGrid grid(std::max(static_cast<float>(s.word_radius), *mid));
    grid.points_in_balls(cloud.points, centre, reach, params.threads, s.nearby_offset, s.nearby_index);
  }
  s.prepare_ms = sw.elapsed_ms();
  return s;
}

}  // namespace lex3d
