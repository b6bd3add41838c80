#include "lex3d/api/coding.hpp"

#include <algorithm>
#include <stdexcept>
#include <string>
#include <utility>

namespace lex3d {

namespace {

bool step_ok(double v) { return v == 0.0 || (v >= 1e-6 && v <= 0.1); }

}  // namespace

void CodingOptions::validate() const {
  if (max_error && !(*max_error >= residual::kMinMaxError && *max_error <= residual::kMaxMaxError))
    throw std::invalid_argument("max_error must be metres in [" + std::to_string(residual::kMinMaxError) + ", " +
                                std::to_string(residual::kMaxMaxError) + "], got " + std::to_string(*max_error));
  if (!(target_bpp == 0.0 || (target_bpp >= 1e-3 && target_bpp <= 1e3)))
    throw std::invalid_argument("target_bpp must be 0 (off) or in [0.001, 1000], got " + std::to_string(target_bpp));
  if (max_error && target_bpp > 0.0) throw std::invalid_argument("give max_error or target_bpp, not both");
  if (!layered() && words == WordsMode::kOff)
    throw std::invalid_argument("words off needs a residual layer: give max_error or target_bpp");
  if (layer_coding == LayerCoding::kVoxel && keep_all_points)
    throw std::invalid_argument("layer coding voxel codes one point a cell, keep_all_points one a point: give one of them");
  if (!step_ok(quantization.translation_m) || !step_ok(quantization.rotation_rad))
    throw std::invalid_argument("quantization steps must be 0 (derived) or in [1e-6, 0.1]");
  if (threads < 1 || threads > 64) throw std::invalid_argument("threads must be in [1, 64], got " + std::to_string(threads));
  if (sensor_profile && !layered())
    throw std::invalid_argument("a sensor profile is used by the residual layer: give max_error or target_bpp");
  attributes.validate();
}

std::vector<std::string> attribute_fields(const Cloud& cloud) {
  std::vector<std::string> f;
  if (cloud.has_rings()) f.emplace_back("ring");
  if (cloud.has_intensity()) f.emplace_back("intensity");
  if (cloud.has_time()) f.emplace_back("time");
  if (cloud.has_rgb()) f.emplace_back("rgb");
  for (const IntegerField& x : cloud.fields)
    if (x.values.size() == cloud.size()) f.push_back(x.name);
  return f;
}

WordsMode CodingOptions::words_mode() const noexcept {
  // With a layer, words cost more than they save at every bound measured (bench/README.md), so the
  // layer alone is the default.
  if (words != WordsMode::kDefault) return words;
  return layered() ? WordsMode::kOff : WordsMode::kOn;
}

residual::LayerOptions CodingOptions::layer_options() const {
  residual::LayerOptions l;
  l.thin = !keep_all_points;
  l.spherical = layer_coding == LayerCoding::kAuto || layer_coding == LayerCoding::kSpherical;
  l.voxel = layer_coding == LayerCoding::kAuto || layer_coding == LayerCoding::kVoxel;
  l.laser = layer_coding == LayerCoding::kAuto || layer_coding == LayerCoding::kLaser;
  l.acquisition = layer_coding == LayerCoding::kAuto || layer_coding == LayerCoding::kAcquisition;
  l.lattice = layer_coding == LayerCoding::kAuto || layer_coding == LayerCoding::kLattice;
  l.fast = fast;
  l.mse = mse;
  l.threads = threads;
  return l;
}

ScanCoder::ScanCoder(Alphabet alphabet, const CodingOptions& options, bool reference_alphabet,
                     std::vector<std::uint8_t> reused_file)
    : alphabet_(std::move(alphabet)), options_(options), quantization_(options.quantization) {
  options_.validate();
  const codec::Quantization derived = codec::quantization_for_word_radius(alphabet_.word_radius);
  if (quantization_.translation_m == 0.0) quantization_.translation_m = derived.translation_m;
  if (quantization_.rotation_rad == 0.0) quantization_.rotation_rad = derived.rotation_rad;
  const bool reused = !reused_file.empty();
  if (reused) alphabet_file_ = std::move(reused_file);
  else if (reference_alphabet) alphabet_file_ = codec::encode_alphabet(alphabet_, quantization_);
  if (!alphabet_file_.empty()) hash_ = codec::alphabet_hash(alphabet_file_);
  // The residual layer is coded against the words exactly as a decoder will place them:
  // with the alphabet decoded from its file.
  if (options_.layered() && options_.uses_words()) {
    if (reused) {
      decoder_alphabet_ = alphabet_;
    } else {
      auto a = codec::decode_alphabet(alphabet_file_.empty() ? codec::encode_alphabet(alphabet_, quantization_)
                                                             : alphabet_file_);
      if (!a.ok()) throw std::logic_error("an encoded alphabet does not decode: " + a.status().to_string());
      decoder_alphabet_ = std::move(a).value();
    }
  }
}

Model ScanCoder::model_scan(const Cloud& cloud, const LearnParams& params, int threads, ScanModelStats* stats) const {
  if (!options_.uses_words()) return {};
  ModelParams mp = params.model;
  mp.threads = threads;
  const PreparedScan ps = prepare_scan(cloud, mp, alphabet_.word_radius);
  ScanModelStats local;
  ScanModelStats& s = stats ? *stats : local;
  Model m = encode_scan(ps, alphabet_, params.prune, mp, &s.encode_ms);
  s.features = ps.features.size();
  s.feature_ms = ps.timings;
  s.neighbourhoods_ms = ps.prepare_ms - ps.timings.total_ms();
  return m;
}

StatusOr<CodedScan> ScanCoder::code(const Cloud& cloud, const Model& model, int threads) const {
  codec::ModelData words_data;
  words_data.model = model;
  words_data.input_points = cloud.size();
  words_data.T_cloud_sensor = cloud.T_cloud_sensor;
  words_data.georef = cloud.georef;  // true coordinates: origin + point (formats/model.md §2.8)
  words_data.stamp = cloud.stamp;  // when and in which frame (formats/model.md §2.13)
  if (embeds_alphabet()) words_data.alphabet = alphabet_;
  else words_data.alphabet_hash = hash_;
  const codec::Quantization& q = quantization_;
  if (!options_.layered()) {
    CodedScan c;
    c.bytes = codec::encode_model(words_data, q);
    c.instances = model.instances.size();
    c.dropped = attribute_fields(cloud);  // words alone: the decoded points stand for no input point
    return c;
  }
  // A sensor profile gives the layer every point's laser and column (and the scan's beam
  // layout); the attributes stay those of the input.
  std::optional<residual::ProfileFit> profile_fit;
  Cloud profiled;
  if (options_.sensor_profile) {
    profiled.points = cloud.points;
    profiled.T_cloud_sensor = cloud.T_cloud_sensor;
    profiled.rows = cloud.rows;
    profiled.ring = cloud.ring;
    auto fit = residual::apply_sensor_profile(profiled, *options_.sensor_profile, "");
    if (!fit.ok()) return fit.status();
    profile_fit = fit.value();
  }
  const Cloud& layer_input = options_.sensor_profile ? profiled : cloud;
  residual::AttributeOptions attribute_options = options_.attributes;
  attribute_options.fast = attribute_options.fast || options_.fast;
  const residual::AttributeOptions* attributes = options_.keep_attributes ? &attribute_options : nullptr;
  residual::LayerOptions layer_options = options_.layer_options();
  layer_options.threads = threads;
  const WordsMode mode = options_.words_mode();
  std::vector<bool> forms;  // with words?
  if (mode != WordsMode::kOff) forms.push_back(true);
  if (mode != WordsMode::kOn) forms.push_back(false);
  const std::optional<double> max_error = options_.max_error;
  std::optional<CodedScan> best;
  for (const bool with_words : forms) {
    codec::ModelData d = words_data;
    Alphabet empty;
    if (!with_words) {
      d.model.instances.clear();
      // A layer-only file embeds an empty alphabet (a few dozen bytes), so it decodes alone, or
      // keeps referencing the shared alphabet file (as a sequence file's models must).
      if (!d.alphabet_hash || !options_.layer_only_references_alphabet) {
        d.alphabet = empty;
        d.alphabet_hash.reset();
      }
    }
    const Alphabet& alphabet = with_words ? *decoder_alphabet_ : empty;
    const Cloud placed = residual::decoder_word_cloud(d, alphabet, q);
    auto encode = [&](double e, residual::LayerStats* st) {
      d.residual = residual::encode_layer(layer_input, placed, d.T_cloud_sensor, e, st, layer_options);
      return codec::encode_model(d, q);
    };
    // The final bound's layer also says which input point each decoded point stands for:
    // their attributes go into the file (formats/model.md §2.10).
    auto encode_with_attributes = [&](double e, residual::LayerStats& st, std::vector<residual::AttributeField>& kept) {
      residual::LayerOptions lo = layer_options;
      lo.track_sources = true;
      d.residual = residual::encode_layer(layer_input, placed, d.T_cloud_sensor, e, &st, lo);
      std::vector<std::uint8_t> payload = residual::encode_attributes(cloud, st.sources, *attributes, &kept, st.layer,
                                                                        threads);
      if (!payload.empty()) d.attributes = std::move(payload);
      st.sources.clear();
      st.sources.shrink_to_fit();
      st.layer.clear();
      return codec::encode_model(d, q);
    };
    CodedScan c;
    c.profile_fit = profile_fit;
    c.words = with_words;
    c.max_error = max_error;
    c.instances = d.model.instances.size();
    if (!max_error) {
      const auto budget = static_cast<std::size_t>(options_.target_bpp * static_cast<double>(cloud.size()) / 8.0);
      c.max_error = residual::fit_max_error([&](double e) { return encode(e, nullptr).size(); }, budget);
      if (!c.max_error) continue;
    }
    try {
      c.bytes = attributes ? encode_with_attributes(*c.max_error, c.layer, c.attributes) : encode(*c.max_error, &c.layer);
    } catch (const std::invalid_argument& e) {  // the scan's attributes are bad data
      return bad_data(e.what());
    }
    for (const std::string& f : attribute_fields(cloud))
      if (std::none_of(c.attributes.begin(), c.attributes.end(), [&](const auto& a) { return a.name == f; }))
        c.dropped.push_back(f);
    const bool better = !best || (max_error ? c.bytes.size() < best->bytes.size()
                                            : (*c.max_error < *best->max_error ||
                                               (*c.max_error == *best->max_error && c.bytes.size() < best->bytes.size())));
    if (better) best = std::move(c);
  }
  if (!best)
    return bad_data("no residual layer fits " + std::to_string(options_.target_bpp) + " bits per point (even at a " +
                    std::to_string(residual::kMaxMaxError) + " m error)");
  return std::move(*best);
}

}  // namespace lex3d
