// lex3d reconstruct SCAN... [--alphabet A] -o OUT.ply: model and reconstruction in
// memory, written with each point coloured by its word, and the metrics.

#include <CLI/CLI.hpp>

#include <cstdio>
#include <optional>
#include <iostream>

#include "cli_common.hpp"
#include "json.hpp"
#include "lex3d/core/timer.hpp"
#include "model_report.hpp"

namespace lex3d::cli {

namespace {

struct ReconstructOptions {
  std::vector<std::string> inputs;
  std::string output;
  std::string alphabet;
  bool no_prune = false;
  bool json = false;
  ScanSetOptions scan_set;
  ModelOptions model;
};

void run_reconstruct(const ReconstructOptions& o) {
  std::vector<std::string> outputs;
  for (std::size_t i = 0; i < o.inputs.size(); ++i) outputs.push_back(numbered_output(o.output, i, o.inputs.size()));
  OutputSet files;
  o.scan_set.record_inputs(files, o.inputs);
  files.input(o.alphabet, "--alphabet");
  for (const auto& out : outputs) {
    files.output(out, "-o");
    check_output_kind(out, "-o", "cloud");
  }
  Stopwatch sw;
  const std::vector<Cloud> clouds = o.scan_set.load(o.inputs);
  const ModelParams mp = o.model.params();
  LearnParams p = o.scan_set.learn_params(mp);
  p.prune = !o.no_prune;
  std::optional<AlphabetFile> reuse;
  if (!o.alphabet.empty()) reuse = read_alphabet_file(o.alphabet);
  ModelSet set = build_models(clouds, p, reuse ? &reuse->alphabet : nullptr, o.inputs);
  const Alphabet& alphabet = set.alphabet;
  const std::vector<PreparedScan>& scans = set.scans;
  const std::vector<Model>& models = set.models;
  const double model_ms = sw.lap_ms();

  std::vector<ScanReport> reports;
  for (std::size_t i = 0; i < clouds.size(); ++i) {
    Reconstruction rec;
    reports.push_back(measure(o.inputs[i], scans[i], models[i], alphabet, mp.sigma_lambda, mp.threads, &rec));
    io::WriteOptions wo;
    wo.colors.reserve(rec.word_of_point.size());
    for (const auto w : rec.word_of_point) wo.colors.push_back(word_color(w));
    throw_if_error(io::write_cloud(files.staged(outputs[i]), rec.cloud, wo));
  }
  files.commit();
  const double measure_ms = sw.lap_ms();
  std::vector<const Cloud*> cl;
  std::vector<const Model*> ml;
  for (std::size_t i = 0; i < clouds.size(); ++i) {
    cl.push_back(&clouds[i]);
    ml.push_back(&models[i]);
  }
  const ScanReport all = total(reports, cl, ml, alphabet);

  if (o.json) {
    Json j;
    j.begin_object();
    j.value("alphabet_words", alphabet.size()).value("alphabet_points", alphabet.total_points());
    j.value("word_radius_m", alphabet.word_radius);
    j.begin_array("scans");
    for (const auto& r : reports) {
      j.begin_object();
      report_json(j, r);
      j.end_object();
    }
    j.end_array();
    j.begin_object("total");
    report_json(j, all);
    j.end_object();
    j.begin_object("timings_ms").value("model", model_ms).value("reconstruct_and_measure", measure_ms).end_object();
    j.end_object();
    std::cout << j.str() << "\n";
    return;
  }
  std::printf("alphabet: %zu words, %zu points, radius %.3f m\n", alphabet.size(), alphabet.total_points(),
              alphabet.word_radius);
  print_report_header();
  for (const auto& r : reports) print_report_row(r);
  if (reports.size() > 1) print_report_row(all);
  std::printf("time: model %.0f ms, reconstruction + metrics %.0f ms\n", model_ms, measure_ms);
  for (const auto& out : outputs) std::printf("wrote %s\n", out.c_str());
}

}  // namespace

void register_reconstruct(CLI::App& app) {
  auto o = std::make_shared<ReconstructOptions>();
  CLI::App* sub = app.add_subcommand("reconstruct", "Model scans with an alphabet and write the reconstruction");
  sub->footer("Examples:\n  lex3d reconstruct scan.bin --alphabet fleet.lex3da -o words.ply   (points coloured by word)");
  sub->add_option("scans", o->inputs, "Point clouds")->required();
  sub->add_option("-o,--output", o->output, "Reconstruction (.ply or .pcd; numbered for several scans)")->required();
  sub->add_option("--alphabet", o->alphabet, "Use this alphabet instead of learning one");
  sub->add_flag("--no-prune", o->no_prune, "Keep every instance");
  sub->add_flag("--json", o->json, "Print one JSON object");
  o->scan_set.add_to(*sub);
  o->model.add_to(*sub);
  sub->callback([o] { run_reconstruct(*o); });
}

}  // namespace lex3d::cli
