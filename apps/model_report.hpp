#pragma once
// Shared by `learn` and `reconstruct`: options that shape a model, and the metrics
// of a reconstructed scan (ruhnke2010 §IV plus D1 PSNR / Chamfer / Hausdorff).

#include <CLI/CLI.hpp>

#include <string>
#include <vector>

#include "cli_common.hpp"
#include "json.hpp"
#include "lex3d/eval/metrics.hpp"
#include "lex3d/model/model.hpp"

namespace lex3d::cli {

struct ModelOptions {
  double word_radius = 0.0;
  double coverage_factor = ModelParams{}.coverage_factor;
  double word_spacing_factor = ModelParams{}.word_spacing_factor;
  double sigma_lambda = ModelParams{}.sigma_lambda;
  int refine_iterations = ModelParams{}.refine_iterations;
  int fit_candidates = ModelParams{}.fit_candidates;
  bool prune_keep_cover = false;
  int threads = 2;
  void add_to(CLI::App& app);
  [[nodiscard]] ModelParams params() const;
};

/// Options of the commands that read a set of scans and may learn an alphabet for them:
/// --format, --poses, --input-frame, --iterations, --seed.
struct ScanSetOptions {
  std::string format = "auto";
  std::string metadata;      ///< --metadata: an Ouster capture's metadata JSON
  std::string sensor_model;  ///< --sensor-model: a Velodyne capture's model
  std::string topic;         ///< --topic: a ROS bag's topic
  bool single_return = false;  ///< --single-return: a dual-return capture's first returns only
  std::string poses;
  std::string input_frame = "sensor";  ///< "world": the points are in the frame of the poses
  int iterations = LearnParams{}.max_iterations;
  std::uint64_t seed = LearnParams{}.seed;
  void add_to(CLI::App& app);
  /// Reads `inputs` with these options (formats, poses).
  [[nodiscard]] std::vector<Cloud> load(const std::vector<std::string>& inputs) const;
  /// The same scans one at a time.
  [[nodiscard]] ScanLoader loader(const std::vector<std::string>& inputs) const;
  /// Records the files these options read (the scans, --poses, --metadata) in `files`.
  void record_inputs(OutputSet& files, const std::vector<std::string>& inputs) const;
  /// Learner parameters: these options plus `model`.
  [[nodiscard]] LearnParams learn_params(const ModelParams& model) const;
};

struct ScanReport {
  std::string file;
  std::size_t points = 0;
  std::size_t features = 0;
  std::size_t instances = 0;
  std::size_t reconstructed_points = 0;
  eval::RateResult rates;
  eval::InlierResult inliers;
  eval::DistanceResult distances;
};

/// An alphabet file's bytes and the alphabet they hold; throws CliError(2) when unreadable.
struct AlphabetFile {
  std::vector<std::uint8_t> bytes;
  Alphabet alphabet;
};
AlphabetFile read_alphabet_file(const std::string& path);

/// learn_alphabet with a progress bar (iteration, BIC, alphabet size) on a terminal.
LearnResult learn_with_progress(const std::vector<Cloud>& clouds, const LearnParams& params);

/// Models of `clouds`: learned with `learn` when `reuse` is null, else encoded with the
/// reused alphabet (pruned when learn.prune), with a progress bar either way.
struct ModelSet {
  Alphabet alphabet;
  std::vector<PreparedScan> scans;
  std::vector<Model> models;
  std::vector<EncodeTimings> timings;  ///< per scan, when an alphabet was reused
};
ModelSet build_models(const std::vector<Cloud>& clouds, const LearnParams& learn, const Alphabet* reuse,
                      const std::vector<std::string>& names);

/// Reconstructs `model` (thinned to the alphabet's point spacing) and measures it
/// against the scan.
ScanReport measure(const std::string& file, const PreparedScan& scan, const Model& model, const Alphabet& alphabet,
                   double sigma_lambda, int threads, Reconstruction* reconstruction = nullptr);

/// Totals over several scans (rates over the summed sizes, the alphabet counted once).
ScanReport total(const std::vector<ScanReport>& reports, const std::vector<const Cloud*>& clouds,
                 const std::vector<const Model*>& models, const Alphabet& alphabet);

void print_report_header();
void print_report_row(const ScanReport& r);
void report_json(Json& j, const ScanReport& r);

}  // namespace lex3d::cli
