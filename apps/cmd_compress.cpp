// lex3d compress IN... -o OUT: model files (formats/model.md), learning an alphabet or
// reusing one.

#include <CLI/CLI.hpp>

#include <cstdio>
#include <optional>
#include <iostream>

#include "cli_common.hpp"
#include "json.hpp"
#include "lex3d/codec/codec.hpp"
#include "lex3d/core/timer.hpp"
#include "model_report.hpp"

namespace lex3d::cli {

namespace {

struct CompressOptions {
  std::vector<std::string> inputs;
  std::string output;
  std::string alphabet;
  std::string save_alphabet;
  bool json = false;
  ScanSetOptions scan_set;
  ModelOptions model;
};

void run_compress(const CompressOptions& o) {
  if (!o.alphabet.empty() && !o.save_alphabet.empty())
    throw CliError(1, "--alphabet reuses an alphabet and --save-alphabet writes a learned one: give one of them");
  std::vector<std::string> outputs;
  for (std::size_t i = 0; i < o.inputs.size(); ++i) outputs.push_back(numbered_output(o.output, i, o.inputs.size()));
  std::vector<std::string> protected_paths = o.inputs;
  if (!o.alphabet.empty()) protected_paths.push_back(o.alphabet);
  for (const auto& out : outputs) check_output_path(out, protected_paths);
  if (!o.save_alphabet.empty()) check_output_path(o.save_alphabet, protected_paths);

  Stopwatch sw;
  const std::vector<Cloud> clouds = o.scan_set.load(o.inputs);
  const ModelParams mp = o.model.params();
  LearnParams p = o.scan_set.learn_params(mp);
  std::optional<AlphabetFile> reuse;
  if (!o.alphabet.empty()) reuse = read_alphabet_file(o.alphabet);
  const ModelSet set = build_models(clouds, p, reuse ? &reuse->alphabet : nullptr, o.inputs);
  const Alphabet& alphabet = set.alphabet;
  const std::vector<Model>& models = set.models;
  std::vector<std::uint8_t> alphabet_file;
  if (reuse) {
    alphabet_file = std::move(reuse->bytes);
  } else if (!o.save_alphabet.empty()) {
    alphabet_file = codec::encode_alphabet(alphabet);
    throw_if_error(io::write_file_atomic(o.save_alphabet, alphabet_file));
  }
  const bool embed = alphabet_file.empty();
  const std::uint64_t hash = embed ? 0 : codec::alphabet_hash(alphabet_file);

  std::uint64_t total_bytes = 0, total_points = 0;
  Json j;
  j.begin_object();
  j.begin_array("files");
  if (!o.json) std::printf("%-32s %9s %9s %10s %10s\n", "output", "points", "instances", "bytes", "bits/pt");
  for (std::size_t i = 0; i < clouds.size(); ++i) {
    codec::ModelData d;
    d.input_points = clouds[i].size();
    d.T_cloud_sensor = clouds[i].T_cloud_sensor;
    d.model = models[i];
    if (embed) d.alphabet = alphabet;
    else d.alphabet_hash = hash;
    const std::vector<std::uint8_t> bytes = codec::encode_model(d);
    throw_if_error(io::write_file_atomic(outputs[i], bytes));
    const double bpp = d.input_points ? 8.0 * static_cast<double>(bytes.size()) / static_cast<double>(d.input_points) : 0.0;
    total_bytes += bytes.size();
    total_points += d.input_points;
    if (o.json) {
      j.begin_object()
          .value("input", o.inputs[i])
          .value("output", outputs[i])
          .value("points", d.input_points)
          .value("features", set.scans[i].features.size())
          .value("instances", d.model.instances.size())
          .value("bytes", static_cast<std::uint64_t>(bytes.size()))
          .value("bits_per_point", bpp)
          .end_object();
    } else {
      std::printf("%-32s %9llu %9zu %10zu %10.3f\n", outputs[i].c_str(), static_cast<unsigned long long>(d.input_points),
                  d.model.instances.size(), bytes.size(), bpp);
    }
  }
  j.end_array();
  const double total_ms = sw.elapsed_ms();
  const std::uint64_t alphabet_bytes = embed ? 0 : alphabet_file.size();
  const double bpp_all = total_points ? 8.0 * static_cast<double>(total_bytes + alphabet_bytes) / static_cast<double>(total_points) : 0.0;
  if (o.json) {
    j.value("alphabet_words", alphabet.size()).value("alphabet_embedded", embed);
    j.value("alphabet_bytes", alphabet_bytes).value("total_bytes", total_bytes + alphabet_bytes);
    j.value("bits_per_point", bpp_all).value("time_ms", total_ms);
    j.end_object();
    std::cout << j.str() << "\n";
    return;
  }
  std::printf("alphabet: %zu words, %s\n", alphabet.size(),
              embed ? "embedded in each model file"
                    : (std::to_string(alphabet_bytes) + " bytes in " + (o.alphabet.empty() ? o.save_alphabet : o.alphabet)).c_str());
  std::printf("total: %llu bytes for %llu points = %.3f bits per point (alphabet included), %.0f ms\n",
              static_cast<unsigned long long>(total_bytes + alphabet_bytes), static_cast<unsigned long long>(total_points),
              bpp_all, total_ms);
}

}  // namespace

void register_compress(CLI::App& app) {
  auto o = std::make_shared<CompressOptions>();
  CLI::App* sub = app.add_subcommand("compress", "Compress scans into lex3d model files");
  sub->add_option("scans", o->inputs, "Point clouds")->required();
  sub->add_option("-o,--output", o->output, "Model file (numbered _000, _001... for several scans)")->required();
  sub->add_option("--alphabet", o->alphabet, "Reuse this alphabet file (nothing is learned)");
  sub->add_option("--save-alphabet", o->save_alphabet, "Write the learned alphabet here; the models reference it");
  sub->add_flag("--json", o->json, "Print one JSON object");
  o->scan_set.add_to(*sub);
  o->model.add_to(*sub);
  sub->callback([o] { run_compress(*o); });
}

}  // namespace lex3d::cli
