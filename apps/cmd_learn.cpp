// lex3d learn SCAN... -o ALPHABET: one alphabet for one scan or a whole set.

#include <CLI/CLI.hpp>

#include <cstdio>
#include <iostream>

#include "cli_common.hpp"
#include "json.hpp"
#include "lex3d/codec/codec.hpp"
#include "lex3d/core/timer.hpp"
#include "lex3d/lex3d.hpp"
#include "model_report.hpp"
#include "progress.hpp"

namespace lex3d::cli {

namespace {

struct LearnOptions {
  std::vector<std::string> inputs;
  std::string output;
  int patience = LearnParams{}.patience;
  bool no_prune = false;
  bool json = false;
  ScanSetOptions scan_set;
  ModelOptions model;
};

void run_learn(const LearnOptions& o) {
  OutputSet files;
  o.scan_set.record_inputs(files, o.inputs);
  files.output(o.output, "-o");
  check_output_kind(o.output, "-o", "alphabet");
  Stopwatch sw;
  const std::vector<Cloud> clouds = o.scan_set.load(o.inputs);
  LearnParams p = o.scan_set.learn_params(o.model.params());
  p.patience = o.patience;
  p.prune = !o.no_prune;
  // The same learning and file as lex3d::learn_alphabet (lex3d/lex3d.hpp), with a progress bar.
  AlphabetOptions ao;
  static_cast<LearnParams&>(ao) = p;
  ProgressBar bar("learning");
  ao.progress = [&](const LearnProgress& pr) {
    char detail[96];
    std::snprintf(detail, sizeof detail, "BIC %.6g, %zu words", pr.bic, pr.alphabet_size);
    bar.update(pr.iteration, pr.max_iterations, detail);
  };
  const AlphabetResult learnt = lex3d::learn_alphabet(clouds, ao);
  bar.finish();
  const LearnResult& r = learnt.learning;
  throw_if_error(io::write_file_atomic(files.staged(o.output), learnt.bytes));
  files.commit();
  std::size_t instances = 0, points = 0;
  for (const auto& m : r.models) instances += m.instances.size();
  for (const auto& c : clouds) points += c.size();
  const double total_ms = sw.elapsed_ms();
  if (o.json) {
    Json j;
    j.begin_object();
    j.value("alphabet", o.output).value("scans", clouds.size()).value("points", points);
    j.value("words", r.alphabet.size()).value("word_points", r.alphabet.total_points());
    j.value("word_radius_m", r.alphabet.word_radius).value("instances", instances);
    j.value("iterations", r.accepted + r.rejected).value("accepted", r.accepted).value("rejected", r.rejected);
    j.value("bic_initial", r.bic_history.front()).value("bic_final", r.final_bic);
    j.numbers("bic_history", r.bic_history);
    j.begin_object("timings_ms")
        .value("prepare", r.prepare_ms)
        .value("learn", r.learn_ms)
        .value("prune", r.prune_ms)
        .value("total", total_ms)
        .end_object();
    j.end_object();
    std::cout << j.str() << "\n";
    return;
  }
  std::printf("learned %zu words (%zu points, radius %.3f m) from %zu scan(s), %zu points\n", r.alphabet.size(),
              r.alphabet.total_points(), r.alphabet.word_radius, clouds.size(), points);
  std::printf("candidates %zu accepted, %zu rejected; BIC %.6g -> %.6g; %zu instances after pruning\n", r.accepted,
              r.rejected, r.bic_history.front(), r.final_bic, instances);
  std::printf("time            prepare %.0f ms | learn %.0f ms | prune %.0f ms | total %.0f ms\n", r.prepare_ms,
              r.learn_ms, r.prune_ms, total_ms);
  std::printf("wrote           %s\n", o.output.c_str());
}

}  // namespace

void register_learn(CLI::App& app) {
  auto o = std::make_shared<LearnOptions>();
  CLI::App* sub = app.add_subcommand("learn", "Learn an alphabet of local 3D structures from one or more scans");
  sub->footer("Examples:\n  lex3d learn drive/*.bin -o fleet.lex3da --poses poses.txt");
  sub->add_option("scans", o->inputs, "Point clouds (one alphabet for all)")->required();
  sub->add_option("-o,--output", o->output, "Alphabet file to write")->required();
  sub->add_option("--patience", o->patience, "Stop after this many rejections in a row")->check(CLI::Range(1, 1000000));
  sub->add_flag("--no-prune", o->no_prune, "Keep every instance (skip ruhnke2010 §III-D)");
  sub->add_flag("--json", o->json, "Print one JSON object");
  o->scan_set.add_to(*sub);
  o->model.add_to(*sub);
  sub->callback([o] { run_learn(*o); });
}

}  // namespace lex3d::cli
