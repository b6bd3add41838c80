// Parameters, quantisers and the PlaceScan of a prepared scan (stored features and the
// coarse range image).

#include <algorithm>
#include <array>
#include <cstring>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "lex3d/features/vdlsd.hpp"
#include "lex3d/place/place.hpp"
#include "lex3d/range/pixel_locator.hpp"
#include "place/internal.hpp"

namespace lex3d {

namespace {

void check(bool ok, const char* what) {
  if (!ok) throw std::invalid_argument(what);
}

}  // namespace

void PlaceStorageParams::validate() const {
  check(max_features >= 1 && max_features <= 4096, "PlaceStorageParams::max_features must be in [1, 4096]");
  check(descriptor_bits == 4 || descriptor_bits == 8, "PlaceStorageParams::descriptor_bits must be 4 or 8");
  check(coarse_azimuth_deg >= 0.05 && coarse_azimuth_deg <= 10.0,
        "PlaceStorageParams::coarse_azimuth_deg must be in [0.05, 10]");
  check(coarse_row_factor >= 1 && coarse_row_factor <= 16, "PlaceStorageParams::coarse_row_factor must be in [1, 16]");
  check(range_step >= 0.001 && range_step <= 1.0, "PlaceStorageParams::range_step must be in [0.001, 1] m");
}

void PlaceParams::validate() const {
  check(top_k >= 1 && top_k <= 1000000, "PlaceParams::top_k must be in [1, 1e6]");
  check(ratio > 0.0 && ratio <= 1.0, "PlaceParams::ratio must be in (0, 1]");
  check(min_inliers >= 3 && min_inliers <= 1000, "PlaceParams::min_inliers must be in [3, 1000]");
  check(inlier_distance > 0.0 && inlier_distance <= 10.0, "PlaceParams::inlier_distance must be in (0, 10] m");
  check(consistency_tolerance > 0.0 && consistency_tolerance <= 10.0,
        "PlaceParams::consistency_tolerance must be in (0, 10] m");
  check(hypotheses_per_size >= 1 && hypotheses_per_size <= 100000,
        "PlaceParams::hypotheses_per_size must be in [1, 1e5]");
  check(gravity_pairs >= 0 && gravity_pairs <= 100000, "PlaceParams::gravity_pairs must be in [0, 1e5]");
  check(surface_yaws >= 0 && surface_yaws <= 36, "PlaceParams::surface_yaws must be in [0, 36]");
  check(scored_hypotheses >= 1 && scored_hypotheses <= 100, "PlaceParams::scored_hypotheses must be in [1, 100]");
  check(refine_iterations >= 0 && refine_iterations <= 50, "PlaceParams::refine_iterations must be in [0, 50]");
  check(validation_points >= 1 && validation_points <= 4096, "PlaceParams::validation_points must be in [1, 4096]");
  check(error_radius_px >= 0 && error_radius_px <= 20, "PlaceParams::error_radius_px must be in [0, 20]");
  check(max_range_difference > 0.0 && max_range_difference <= 10.0,
        "PlaceParams::max_range_difference must be in (0, 10] m");
  check(penalty >= 0.0 && penalty <= 1.0, "PlaceParams::penalty must be in [0, 1]");
  check(accept_score >= 0.0 && accept_score <= 1.0, "PlaceParams::accept_score must be in [0, 1]");
  check(max_tilt_deg >= 0.0 && max_tilt_deg <= 180.0, "PlaceParams::max_tilt_deg must be in [0, 180]");
  check(max_distance >= 0.0 && max_distance <= 1e4, "PlaceParams::max_distance must be in [0, 1e4] m");
  check(max_conflict > 0.0 && max_conflict <= 1.0, "PlaceParams::max_conflict must be in (0, 1]");
  check(max_vertical_offset >= 0.0 && max_vertical_offset <= 100.0,
        "PlaceParams::max_vertical_offset must be in [0, 100] m");
  check(dense_iterations >= 0 && dense_iterations <= 100, "PlaceParams::dense_iterations must be in [0, 100]");
  check(dense_points >= 16 && dense_points <= 1000000, "PlaceParams::dense_points must be in [16, 1e6]");
  check(dense_gate_start > 0.0 && dense_gate_start <= 10.0, "PlaceParams::dense_gate_start must be in (0, 10] m");
  check(dense_gate_end > 0.0 && dense_gate_end <= dense_gate_start,
        "PlaceParams::dense_gate_end must be in (0, dense_gate_start] m");
  check(dense_candidates >= 1 && dense_candidates <= 1000000, "PlaceParams::dense_candidates must be in [1, 1e6]");
  check(threads >= 1 && threads <= 64, "PlaceParams::threads must be in [1, 64]");
  check(fabmap_p_detect > 0.0 && fabmap_p_detect < 1.0, "PlaceParams::fabmap_p_detect must be in (0, 1)");
  check(fabmap_p_false > 0.0 && fabmap_p_false < fabmap_p_detect,
        "PlaceParams::fabmap_p_false must be in (0, fabmap_p_detect)");
  check(fabmap_new_place_prior > 0.0 && fabmap_new_place_prior < 1.0,
        "PlaceParams::fabmap_new_place_prior must be in (0, 1)");
}

const char* to_string(PlaceDescriptor d) noexcept {
  return d == PlaceDescriptor::kVdlsd ? "vdlsd" : "patch";
}

namespace detail {

int stored_descriptor_dim(const PlaceStorageParams& storage, const Alphabet* alphabet) noexcept {
  if (storage.descriptor == PlaceDescriptor::kVdlsd) return vdlsd_dimension(VdlsdParams{}.bins);
  return alphabet != nullptr ? alphabet->descriptor_dim : 0;
}

std::uint8_t quantise_descriptor_value(float v, int bits) noexcept {
  const float levels = static_cast<float>((1 << bits) - 1);
  const float c = std::clamp((v + 1.0F) * 0.5F, 0.0F, 1.0F) * levels;
  return static_cast<std::uint8_t>(std::lround(std::isfinite(c) ? c : 0.0F));
}

float dequantise_descriptor_value(std::uint8_t code, int bits) noexcept {
  const float levels = static_cast<float>((1 << bits) - 1);
  return static_cast<float>(code) / levels * 2.0F - 1.0F;
}

void finish_place_scan(PlaceScan& scan) {
  const std::size_t n = scan.features.size();
  scan.descriptors.resize(scan.descriptor_codes.size());
  for (std::size_t i = 0; i < scan.descriptor_codes.size(); ++i)
    scan.descriptors[i] = dequantise_descriptor_value(scan.descriptor_codes[i], scan.descriptor_bits);
  detail::make_dense_points(scan);
  // Upright pair table.
  scan.pairs.clear();
  {
    const Eigen::Matrix3f R = scan.has_world_pose ? Eigen::Matrix3f(scan.T_world_cloud.linear().cast<float>())
                                                  : Eigen::Matrix3f::Identity();
    std::vector<Eigen::Vector3f> g;
    g.reserve(n);
    for (const auto& f : scan.features) g.push_back(R * f.position);
    const std::size_t np = std::min<std::size_t>(n, 65535);
    for (std::size_t a = 0; a < np; ++a)
      for (std::size_t b = a + 1; b < np; ++b) {
        const Eigen::Vector3f v = g[b] - g[a];
        const float h = std::hypot(v.x(), v.y());
        if (h >= 1.0F)
          scan.pairs.push_back({h, v.z(), std::atan2(v.y(), v.x()), static_cast<std::uint16_t>(a), static_cast<std::uint16_t>(b)});
      }
    // By horizontal distance, ties by (a, b): the pairs are made in (a, b) order, so a stable
    // sort on the distance alone gives that order. The distances are finite and at least 1, so
    // their bit patterns sort as the values do: three stable 11-bit counting passes.
    std::vector<PlaceScan::FeaturePair> tmp(scan.pairs.size());
    auto key = [](const PlaceScan::FeaturePair& e) {
      std::uint32_t k = 0;
      std::memcpy(&k, &e.horizontal, sizeof k);
      return k;
    };
    for (int shift = 0; shift < 32; shift += 11) {
      std::array<std::size_t, 2049> start{};
      for (const auto& e : scan.pairs) ++start[((key(e) >> shift) & 0x7FFU) + 1];
      for (std::size_t b = 1; b < start.size(); ++b) start[b] += start[b - 1];
      for (const auto& e : scan.pairs) tmp[start[(key(e) >> shift) & 0x7FFU]++] = e;
      scan.pairs.swap(tmp);
    }
  }
  // Farthest-point order: the strongest feature first, then always the feature
  // farthest from those chosen (ties: lower index).
  scan.validation.clear();
  if (n == 0) return;
  scan.validation.reserve(n);
  std::vector<float> d2(n, std::numeric_limits<float>::infinity());
  std::vector<bool> used(n, false);
  std::size_t next = 0;
  for (std::size_t k = 0; k < n; ++k) {
    scan.validation.push_back(static_cast<std::uint32_t>(next));
    used[next] = true;
    const Eigen::Vector3f p = scan.features[next].position;
    std::size_t best = n;
    float best_d = -1.0F;
    for (std::size_t i = 0; i < n; ++i) {
      if (used[i]) continue;
      d2[i] = std::min(d2[i], (scan.features[i].position - p).squaredNorm());
      if (d2[i] > best_d) {
        best_d = d2[i];
        best = i;
      }
    }
    if (best == n) break;
    next = best;
  }
}

void make_dense_points(PlaceScan& scan) {
  const RangeImage& c = scan.coarse;
  scan.dense_points.clear();
  scan.dense_normals.clear();
  scan.dense_index.clear();
  if (c.empty() || c.state.size() != static_cast<std::size_t>(c.width) * static_cast<std::size_t>(c.height) ||
      c.range.size() != c.state.size() || c.row_edges.size() != static_cast<std::size_t>(c.height) + 1)
    return;
  // Sensor-frame points along the pixel-centre rays.
  // The rays are RangeImage::ray(x + 0.5, y + 0.5), its sines and cosines taken once a row
  // and once a column.
  std::vector<double> cos_az(static_cast<std::size_t>(c.width)), sin_az(cos_az.size());
  std::vector<double> cos_el(static_cast<std::size_t>(c.height)), sin_el(cos_el.size());
  for (int x = 0; x < c.width; ++x) {
    const double az = c.azimuth_max_rad - (x + 0.5) * c.azimuth_resolution_rad;
    cos_az[static_cast<std::size_t>(x)] = std::cos(az);
    sin_az[static_cast<std::size_t>(x)] = std::sin(az);
  }
  for (int y = 0; y < c.height; ++y) {
    const double el = c.elevation_at(y + 0.5);
    cos_el[static_cast<std::size_t>(y)] = std::cos(el);
    sin_el[static_cast<std::size_t>(y)] = std::sin(el);
  }
  // Only the valid pixels' points are set and read.
  std::vector<Eigen::Vector3f> pts(c.state.size());
  std::size_t valid = 0;
  for (int y = 0; y < c.height; ++y)
    for (int x = 0; x < c.width; ++x) {
      const std::size_t i = c.index(x, y);
      if (c.state[i] != PixelState::kValid) continue;
      ++valid;
      const auto ux = static_cast<std::size_t>(x), uy = static_cast<std::size_t>(y);
      const Eigen::Vector3f ray(static_cast<float>(cos_el[uy] * cos_az[ux]), static_cast<float>(cos_el[uy] * sin_az[ux]),
                                static_cast<float>(sin_el[uy]));
      pts[i] = ray * c.range[i];
    }
  // Normals from the neighbours left/right and up/down on the same surface: a neighbour
  // counts when its range differs by at most what a surface inclined by 75 degrees to the
  // ray gives across one pixel (tan 75° ≈ 3.7 pixel footprints), plus a quantisation step.
  const auto px = static_cast<float>(std::max(c.azimuth_resolution_rad, c.elevation_resolution_rad));
  scan.dense_index.assign(c.state.size(), -1);
  scan.dense_points.reserve(valid);
  scan.dense_normals.reserve(valid);
  const Eigen::Matrix3f R = c.T_cloud_sensor.linear().cast<float>();
  const Eigen::Vector3f t = c.T_cloud_sensor.translation().cast<float>();
  auto neighbour = [&](int x, int y, float r, float tolerance, Eigen::Vector3f& out) {
    const int xx = c.wrap_x(x);
    if (xx < 0 || y < 0 || y >= c.height) return false;
    const std::size_t j = c.index(xx, y);
    if (c.state[j] != PixelState::kValid) return false;
    if (std::abs(c.range[j] - r) > tolerance) return false;
    out = pts[j];
    return true;
  };
  for (int y = 0; y < c.height; ++y)
    for (int x = 0; x < c.width; ++x) {
      const std::size_t i = c.index(x, y);
      if (c.state[i] != PixelState::kValid) continue;
      const float r = c.range[i];
      const float tol = 3.7F * px * r + 0.05F;
      Eigen::Vector3f l, rr, u, d;
      const bool hl = neighbour(x - 1, y, r, tol, l), hr = neighbour(x + 1, y, r, tol, rr);
      const bool hu = neighbour(x, y - 1, r, tol, u), hd = neighbour(x, y + 1, r, tol, d);
      if (!(hl || hr) || !(hu || hd)) continue;
      const Eigen::Vector3f a = (hr ? rr : pts[i]) - (hl ? l : pts[i]);
      const Eigen::Vector3f b = (hd ? d : pts[i]) - (hu ? u : pts[i]);
      Eigen::Vector3f n = a.cross(b);
      const float nn = n.norm();
      if (!(nn > 0.0F)) continue;
      n /= nn;
      if (n.dot(pts[i]) > 0.0F) n = -n;  // towards the sensor
      scan.dense_index[i] = static_cast<std::int32_t>(scan.dense_points.size());
      scan.dense_points.push_back(R * pts[i] + t);
      scan.dense_normals.push_back(R * n);
    }
}

RangeImage make_coarse_image(const RangeImage& fine, const PlaceStorageParams& storage) {
  RangeImage c;
  c.T_cloud_sensor = fine.T_cloud_sensor;
  c.min_range = fine.min_range;
  c.full_circle = fine.full_circle;
  if (fine.empty() || fine.row_edges.size() != static_cast<std::size_t>(fine.height) + 1) return c;
  double res = storage.coarse_azimuth_deg * M_PI / 180.0;
  int width = 0;
  if (fine.full_circle) {
    width = std::max(1, static_cast<int>(std::lround(2.0 * M_PI / res)));
    res = 2.0 * M_PI / width;
  } else {
    width = std::max(1, static_cast<int>(std::ceil(fine.width * fine.azimuth_resolution_rad / res - 1e-9)));
  }
  const int f = storage.coarse_row_factor;
  const int height = (fine.height + f - 1) / f;
  c.width = width;
  c.height = height;
  c.azimuth_resolution_rad = res;
  c.azimuth_max_rad = fine.azimuth_max_rad;
  c.elevation_resolution_rad = fine.elevation_resolution_rad * f;
  c.row_edges.resize(static_cast<std::size_t>(height) + 1);
  for (int y = 0; y <= height; ++y)
    c.row_edges[static_cast<std::size_t>(y)] = fine.row_edges[static_cast<std::size_t>(std::min(y * f, fine.height))];
  const std::size_t pixels = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
  c.state.assign(pixels, PixelState::kUnobserved);
  c.range.assign(pixels, std::numeric_limits<float>::quiet_NaN());
  // The pixel of floor() of c.project(dir), found from border tables.
  const PixelLocator locator(c);
  auto cell = [&](const Eigen::Vector3f& dir, std::size_t& idx) {
    int x = 0, yi = 0;
    float r = 0;
    if (!locator.locate(dir, x, yi, r)) return false;
    const int xi = c.wrap_x(x);
    if (xi < 0 || !c.in_image(xi, yi)) return false;
    idx = c.index(xi, yi);
    return true;
  };
  for (int y = 0; y < fine.height; ++y) {
    for (int x = 0; x < fine.width; ++x) {
      const std::size_t i = fine.index(x, y);
      std::size_t j = 0;
      if (fine.state[i] == PixelState::kValid) {
        if (!cell(fine.point[i], j)) continue;
        const float r = fine.range[i];
        if (c.state[j] != PixelState::kValid || r < c.range[j]) c.range[j] = r;
        c.state[j] = PixelState::kValid;
      } else if (fine.state[i] == PixelState::kMaxRange) {
        if (!cell(fine.ray(x + 0.5, y + 0.5), j)) continue;
        if (c.state[j] == PixelState::kUnobserved) c.state[j] = PixelState::kMaxRange;
      }
    }
  }
  // Quantise the ranges exactly as the database stores them.
  for (std::size_t j = 0; j < pixels; ++j) {
    if (c.state[j] != PixelState::kValid) continue;
    const std::uint16_t code = quantise_range(c.range[j], storage.range_step);
    c.range[j] = dequantise_range(code, storage.range_step);
    ++c.valid_count;
  }
  return c;
}

std::uint16_t quantise_range(float r, double step) noexcept {
  const double q = std::round(static_cast<double>(r) / step);
  return static_cast<std::uint16_t>(std::clamp(q, 1.0, 65534.0));
}

float dequantise_range(std::uint16_t code, double step) noexcept {
  return static_cast<float>(static_cast<double>(code) * step);
}

}  // namespace detail

namespace {

// Word ids of every feature (interest and coverage): the word with the nearest descriptor.
Model assign_words(const Features& features, const Alphabet& alphabet) {
  Model model;
  if (alphabet.size() > 0 && features.size() > 0) {
    if (alphabet.descriptor_dim != features.descriptor_dim)
      throw std::invalid_argument("make_place_scan: the alphabet's descriptors have " +
                                  std::to_string(alphabet.descriptor_dim) + " values, the scan's " +
                                  std::to_string(features.descriptor_dim));
    const WordIndex index(alphabet);
    const auto matches = index.nearest(features.descriptors.data(), features.size(), 1);
    model.instances.resize(matches.size());
    for (std::size_t i = 0; i < matches.size(); ++i) {
      model.instances[i].word = matches[i].word;
      model.instances[i].feature = static_cast<std::uint32_t>(i);
      model.instances[i].T_cloud_word = features.features[i].T_cloud_feature;
    }
  }
  return model;
}

// The PlaceScan of a cloud, its features, its word instances and its (fine) range image.
PlaceScan build_place_scan(const Cloud& cloud, const Features& f, const Model& model, const PlaceStorageParams& storage,
                           const RangeImage& fine, std::string name, int threads = 1) {
  PlaceScan p;
  p.name = std::move(name);
  p.T_world_cloud = cloud.T_world_cloud;
  p.has_world_pose = cloud.has_world_pose;
  // Bag of words.
  std::vector<std::uint32_t> ids;
  ids.reserve(model.instances.size());
  for (const auto& in : model.instances) ids.push_back(in.word);
  std::sort(ids.begin(), ids.end());
  for (std::size_t i = 0; i < ids.size();) {
    std::size_t j = i;
    while (j < ids.size() && ids[j] == ids[i]) ++j;
    p.words.emplace_back(ids[i], static_cast<std::uint32_t>(j - i));
    i = j;
  }
  // The strongest interest-point features (they come first, by decreasing interest).
  const std::size_t n = std::min<std::size_t>(f.interest_count, static_cast<std::size_t>(storage.max_features));
  p.descriptor = storage.descriptor;
  p.descriptor_dim = f.descriptor_dim;
  // VD-LSD in the same frames, its local neighbourhoods grown with the image's beam spacing.
  VdlsdResult vd;
  if (storage.descriptor == PlaceDescriptor::kVdlsd) {
    std::vector<Pose> frames(n);
    for (std::size_t i = 0; i < n; ++i) frames[i] = f.features[i].T_cloud_feature;
    VdlsdParams vp;
    vp.beam_spacing_rad = std::min(0.2, std::max(fine.azimuth_resolution_rad, fine.elevation_resolution_rad));
    vd = describe_vdlsd(cloud, frames, vp, std::clamp(threads, 1, 64));
    p.descriptor_dim = vd.descriptor_dim;
    p.empty_descriptors = vd.empty;
  }
  p.descriptor_bits = storage.descriptor_bits;
  p.features.reserve(n);
  p.descriptor_codes.reserve(n * static_cast<std::size_t>(std::max(0, f.descriptor_dim)));
  for (std::size_t i = 0; i < n; ++i) {
    const Pose& T = f.features[i].T_cloud_feature;
    PlaceFeature pf;
    pf.position = T.translation().cast<float>();
    pf.rotation = detail::dequantise_rotation(detail::quantise_rotation(Eigen::Quaterniond(T.linear()).cast<float>()));
    p.features.push_back(pf);
    const float* d = vd.descriptor_dim > 0 ? vd.descriptors.data() + i * static_cast<std::size_t>(vd.descriptor_dim)
                                           : f.descriptor(i);
    for (int k = 0; k < p.descriptor_dim; ++k)
      p.descriptor_codes.push_back(detail::quantise_descriptor_value(d[k], storage.descriptor_bits));
  }
  p.coarse = detail::make_coarse_image(fine, storage);
  detail::finish_place_scan(p);
  return p;
}

}  // namespace

PlaceScan make_place_scan(const PreparedScan& scan, const Model& model, const PlaceStorageParams& storage,
                          const RangeImageParams& range, std::string name) {
  storage.validate();
  const RangeImage fine = make_range_image(scan.cloud, range);
  return build_place_scan(scan.cloud, scan.features, model, storage, fine, std::move(name));
}

PlaceScan make_place_scan(const PreparedScan& scan, const Alphabet& alphabet, const PlaceStorageParams& storage,
                          const RangeImageParams& range, std::string name) {
  const Model model = assign_words(scan.features, alphabet);
  return make_place_scan(scan, model, storage, range, std::move(name));
}

PlaceScan make_place_scan(const Cloud& cloud, const Alphabet& alphabet, const PlaceStorageParams& storage,
                          const ModelParams& params, std::string name) {
  storage.validate();
  // prepare_scan's feature extraction, its range image kept for the coarse image (the same
  // image make_range_image(cloud, params.features.range) gives); the neighbourhoods and σ
  // prepare_scan adds for coding are not needed here.
  const FeatureResult fr = extract_features(cloud, prepare_feature_params(cloud, params, alphabet.word_radius));
  const Model model = assign_words(fr.features, alphabet);
  return build_place_scan(cloud, fr.features, model, storage, fr.image, std::move(name), params.threads);
}

namespace detail {

std::array<std::int16_t, 4> quantise_rotation(const Eigen::Quaternionf& q_in) noexcept {
  Eigen::Quaternionf q = q_in.normalized();
  if (q.w() < 0) q.coeffs() = -q.coeffs();
  auto c = [](float v) { return static_cast<std::int16_t>(std::lround(std::clamp(v, -1.0F, 1.0F) * 32767.0F)); };
  return {c(q.w()), c(q.x()), c(q.y()), c(q.z())};
}

Eigen::Quaternionf dequantise_rotation(const std::array<std::int16_t, 4>& c) noexcept {
  Eigen::Quaternionf q(static_cast<float>(c[0]), static_cast<float>(c[1]), static_cast<float>(c[2]),
                       static_cast<float>(c[3]));
  if (q.norm() <= 0.0F) return Eigen::Quaternionf::Identity();
  return q.normalized();
}

}  // namespace detail

}  // namespace lex3d
