#include "lex3d/lex3d.hpp"

#include "lex3d/core/timer.hpp"

#include <cmath>
#include <stdexcept>
#include <utility>

namespace lex3d {

const char* version() noexcept { return LEX3D_VERSION_STRING; }

void check_cloud(const Cloud& cloud, const std::string& what) {
  const std::size_t n = cloud.size();
  auto check_length = [&](std::size_t size, const char* name) {
    if (size != 0 && size != n)
      throw std::invalid_argument(what + ": " + name + " has " + std::to_string(size) + " values for " +
                                  std::to_string(n) + " points");
  };
  check_length(cloud.intensity.size(), "intensity");
  check_length(cloud.ring.size(), "ring");
  check_length(cloud.column.size(), "column");
  for (std::size_t i = 0; i < n; ++i)
    if (!cloud.points[i].allFinite())
      throw std::invalid_argument(what + ": point " + std::to_string(i) + " is not finite (" +
                                  std::to_string(cloud.points[i].x()) + ", " + std::to_string(cloud.points[i].y()) +
                                  ", " + std::to_string(cloud.points[i].z()) + ")");
  for (std::size_t i = 0; i < cloud.intensity.size(); ++i)
    if (!std::isfinite(cloud.intensity[i]))
      throw std::invalid_argument(what + ": intensity " + std::to_string(i) + " is not finite");
}

void CompressOptions::validate() const {
  CodingOptions::validate();
  LearnParams p;
  p.model = model;
  p.model.threads = threads;
  p.max_iterations = max_iterations;
  p.validate();
  if (!alphabet.empty() && !uses_words())
    throw std::invalid_argument("words off uses no alphabet: drop the alphabet, or set words on or auto");
}

StatusOr<CompressResult> compress(const Cloud& cloud, const CompressOptions& options) {
  options.validate();
  check_cloud(cloud);
  LearnParams p;
  p.model = options.model;
  p.model.threads = options.threads;
  p.max_iterations = options.max_iterations;
  p.seed = options.seed;
  CompressResult r;
  r.input_points = cloud.size();
  const bool words = options.uses_words();
  std::optional<ScanCoder> coder;
  Model model;
  if (words && options.alphabet.empty()) {
    // Learned on the scan itself and embedded, as `lex3d compress SCAN -o OUT`.
    LearnResult learnt = lex3d::learn_alphabet(std::vector<Cloud>{cloud}, p);
    r.features = learnt.scans.front().features.size();
    model = std::move(learnt.models.front());
    coder.emplace(std::move(learnt.alphabet), options);
  } else if (words) {
    auto a = codec::decode_alphabet(options.alphabet);
    if (!a.ok()) return Status(a.status().code(), "alphabet: " + a.status().message(), a.status().offset());
    coder.emplace(std::move(a).value(), options, false, options.alphabet);
    ScanModelStats stats;
    model = coder->model_scan(cloud, p, options.threads, &stats);
    r.features = stats.features;
  } else {
    coder.emplace(Alphabet{}, options);
  }
  r.alphabet_words = words ? coder->alphabet().size() : 0;
  auto coded = coder->code(cloud, model, options.threads);
  if (!coded.ok()) return coded.status();
  CodedScan& c = coded.value();
  r.bytes = std::move(c.bytes);
  r.words = c.words;
  r.max_error = c.max_error;
  r.layer = c.layer;
  r.instances = c.instances;
  r.attributes = std::move(c.attributes);
  r.dropped_attributes = std::move(c.dropped);
  return r;
}

StatusOr<DecompressResult> decompress(const std::vector<std::uint8_t>& model_file,
                                      const std::vector<std::uint8_t>* alphabet_file) {
  if (codec::is_sequence_file(model_file))
    return Status(ErrorCode::kInvalidArgument,
                  "a sequence file holds several scans: decode it with codec::decode_sequence, then each model");
  Stopwatch sw;
  auto decoded = codec::decode_model(model_file, alphabet_file);
  if (!decoded.ok()) return decoded.status();
  const codec::ModelData& d = decoded.value();
  DecompressResult r;
  r.decode_ms = sw.lap_ms();
  auto cloud = residual::decode_cloud(d);
  if (!cloud.ok()) return cloud.status();
  r.reconstruct_ms = sw.lap_ms();
  r.cloud = std::move(cloud).value();
  r.cloud.georef = d.georef;  // true coordinates where the caller needs them
  r.input_points = d.input_points;
  r.instances = d.model.instances.size();
  r.alphabet_words = d.alphabet ? d.alphabet->size() : 0;
  r.residual_layer = d.residual.has_value();
  r.references_alphabet = d.alphabet_hash.has_value();
  return r;
}

AlphabetResult learn_alphabet(const std::vector<Cloud>& clouds, const AlphabetOptions& options) {
  if (clouds.empty()) throw std::invalid_argument("learn_alphabet needs at least one cloud");
  for (std::size_t i = 0; i < clouds.size(); ++i) check_cloud(clouds[i], "clouds[" + std::to_string(i) + "]");
  AlphabetResult r;
  r.learning = lex3d::learn_alphabet(clouds, static_cast<const LearnParams&>(options), options.progress);
  r.learning.scans.clear();
  r.bytes = codec::encode_alphabet(r.learning.alphabet);
  return r;
}

}  // namespace lex3d
