// lex3d compress IN... -o OUT: model files (formats/model.md), learning an alphabet or
// reusing one.

#include <CLI/CLI.hpp>

#include <algorithm>
#include <cstdio>
#include <exception>
#include <iostream>
#include <optional>
#include <set>

#include "allocator.hpp"
#include "cli_common.hpp"
#include "json.hpp"
#include "lex3d/api/coding.hpp"
#include "lex3d/codec/codec.hpp"
#include "lex3d/core/parallel.hpp"
#include "lex3d/core/timer.hpp"
#include "lex3d/residual/attributes.hpp"
#include "lex3d/residual/residual.hpp"
#include "model_report.hpp"
#include "progress.hpp"

namespace lex3d::cli {

namespace {

struct CompressOptions {
  std::vector<std::string> inputs;
  std::string output;
  std::string alphabet;
  std::string save_alphabet;
  std::string max_error = "auto";
  double target_bpp = 0.0;
  std::string words;  ///< on, off or auto; empty: off with a residual layer, on without
  bool keep_all_points = false;
  std::string layer_coding = "auto";  ///< auto, spherical or voxel
  bool fast = false;                  ///< --fast
  std::string objective = "bound";    ///< --objective: bound or mse
  bool one_file = false;
  int learn_scans = 0;  ///< learn the alphabet on this many evenly spaced scans; 0: on all
  /// Instance steps; 0 (the default) scales them to the alphabet's word radius
  /// (codec::quantization_for_word_radius).
  codec::Quantization quantization{0.0, 0.0, 0.0005};
  bool json = false;
  double intensity_error = 0.0;  ///< 0: intensities kept losslessly
  std::vector<std::string> drop_fields;  ///< fields not kept, by name
  bool drop_attributes = false;
  std::string sensor;  ///< --sensor: a sensor profile (formats/sensor_profile.md)
  ScanSetOptions scan_set;
  ModelOptions model;
};

/// The bound `--max-error auto` gives: 1 cm, below the range noise of spinning lidars
/// (1-3 cm in their data sheets), so that the decoded cloud is as good as the sensor's.
constexpr double kAutoMaxError = 0.01;

/// Parses --max-error: "none", "auto" (kAutoMaxError, or the bound --target-bpp finds) or
/// metres within the residual layer's range.
std::optional<double> parse_max_error(const std::string& text, double target_bpp) {
  if (text == "none") return std::nullopt;
  if (text == "auto") return target_bpp > 0.0 ? std::nullopt : std::optional<double>(kAutoMaxError);
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  if (end == text.c_str() || *end != '\0' || !(v >= residual::kMinMaxError && v <= residual::kMaxMaxError))
    throw CliError(1, "--max-error must be \"auto\", \"none\" or metres in [" + std::to_string(residual::kMinMaxError) + ", " +
                          std::to_string(residual::kMaxMaxError) + "], got \"" + text + "\"");
  return v;
}

void run_compress(const CompressOptions& o) {
  if (!o.alphabet.empty() && !o.save_alphabet.empty())
    throw CliError(1, "--alphabet reuses an alphabet and --save-alphabet writes a learned one: give one of them");
  const std::optional<double> max_error = parse_max_error(o.max_error, o.target_bpp);
  if (max_error && o.target_bpp > 0.0) throw CliError(1, "give --max-error or --target-bpp, not both");
  const bool layered = max_error || o.target_bpp > 0.0;
  if (!layered && o.words == "off")
    throw CliError(1, "--words off needs a residual layer: give --max-error E or --target-bpp B");
  if (o.layer_coding == "voxel" && o.keep_all_points)
    throw CliError(1, "--layer-coding voxel codes one point a cell, --keep-all-points one a point: give one of them");
  // With a layer, words cost more than they save at every bound measured (bench/README.md), so the
  // layer alone is the default; --words on/auto brings them back. An alphabet given or asked
  // for (--alphabet, --save-alphabet) makes it auto: the words are tried, and kept in a scan's
  // file only where they make it smaller.
  const bool alphabet_asked = !o.alphabet.empty() || !o.save_alphabet.empty();
  const std::string words_mode = !o.words.empty() ? o.words : !layered ? "on" : alphabet_asked ? "auto" : "off";
  const bool use_words = words_mode != "off";
  if (!use_words && (!o.alphabet.empty() || !o.save_alphabet.empty()))
    throw CliError(1, "--words off uses no alphabet: drop --alphabet / --save-alphabet");
  // A raw log (pcap) gives one scan a complete turn.
  const ScanLoader loader = o.scan_set.loader(o.inputs);
  std::vector<std::string> outputs;
  if (o.one_file) outputs.push_back(o.output);
  else
    for (std::size_t i = 0; i < loader.size(); ++i) outputs.push_back(numbered_output(o.output, i, loader.size()));
  // Every output is checked before any work; all are written at the end or none is.
  OutputSet files;
  o.scan_set.record_inputs(files, o.inputs);
  files.input(o.alphabet, "--alphabet");
  files.input(o.sensor, "--sensor");
  if (!o.sensor.empty() && !layered) throw CliError(1, "--sensor is used by the residual layer: drop --max-error none");
  for (const auto& out : outputs) {
    files.output(out, "-o");
    check_output_kind(out, "-o", o.one_file ? "sequence" : "model");
  }
  files.output(o.save_alphabet, "--save-alphabet");
  check_output_kind(o.save_alphabet, "--save-alphabet", "alphabet");

  Stopwatch sw;
  // Learning needs the scans it learns from at once (every scan, or --learn-scans K evenly
  // spaced ones); the others, and every scan with an alphabet given or without words, are
  // read, modelled, coded and written as they come (one a thread, see below), so a long
  // sequence needs the memory of a scan a thread (89 balm scans: 826 MB resident when all
  // were held).
  const bool learning = use_words && o.alphabet.empty();
  const std::size_t n_scans = loader.size();
  const ModelParams mp = o.model.params();
  // Scans side by side: as many as threads (one each), or one scan on all the threads.
  const auto side_by_side = static_cast<std::size_t>(std::max(1, std::min<int>(mp.threads, static_cast<int>(n_scans))));
  if (n_scans == 1) keep_heap_on_huge_pages();
  else restore_mmap_threshold();
  std::vector<std::int64_t> learnt_as(n_scans, -1);  // scan -> its place among the learnt scans
  std::vector<Cloud> clouds;                         // the learnt scans
  std::vector<std::string> learnt_names;
  if (learning) {
    const std::size_t k = o.learn_scans > 0 ? std::min<std::size_t>(n_scans, static_cast<std::size_t>(o.learn_scans))
                                            : n_scans;
    for (std::size_t j = 0; j < k; ++j) {
      const std::size_t i = j * n_scans / k;
      learnt_as[i] = static_cast<std::int64_t>(j);
      clouds.push_back(loader.load(i));
      learnt_names.push_back(loader.name(i));
    }
  }
  double read_ms = sw.elapsed_ms();
  LearnParams p = o.scan_set.learn_params(mp);
  std::optional<AlphabetFile> reuse;
  if (!o.alphabet.empty()) reuse = read_alphabet_file(o.alphabet);
  ModelSet set;
  if (learning) set = build_models(clouds, p, nullptr, learnt_names);
  else if (reuse) set.alphabet = reuse->alphabet;
  // The coding choices, the instance steps, the alphabet as a decoder sees it and whether
  // it is embedded or referenced: the library's ScanCoder, shared with lex3d::compress.
  CodingOptions coding;
  coding.max_error = max_error;
  coding.target_bpp = o.target_bpp;
  coding.words = words_mode == "on" ? WordsMode::kOn : words_mode == "off" ? WordsMode::kOff : WordsMode::kAuto;
  coding.keep_all_points = o.keep_all_points;
  coding.layer_coding = o.layer_coding == "spherical" ? LayerCoding::kSpherical
                        : o.layer_coding == "voxel"   ? LayerCoding::kVoxel
                        : o.layer_coding == "laser"   ? LayerCoding::kLaser
                        : o.layer_coding == "acquisition" ? LayerCoding::kAcquisition
                        : o.layer_coding == "lattice" ? LayerCoding::kLattice
                                                      : LayerCoding::kAuto;
  coding.fast = o.fast;
  coding.mse = o.objective == "mse";
  coding.quantization = o.quantization;
  coding.threads = mp.threads;
  coding.keep_attributes = !o.drop_attributes;
  coding.layer_only_references_alphabet = o.one_file;  // a sequence's models all reference its alphabet
  coding.attributes.intensity_error = o.intensity_error;
  coding.attributes.drop = o.drop_fields;
  if (!o.sensor.empty()) coding.sensor_profile = read_sensor_profile(o.sensor);
  const ScanCoder coder(std::move(set.alphabet), coding, !o.save_alphabet.empty() || o.one_file,
                        reuse ? std::move(reuse->bytes) : std::vector<std::uint8_t>{});
  const Alphabet& alphabet = coder.alphabet();
  const std::vector<std::uint8_t>& alphabet_file = coder.alphabet_file();
  const bool embed = coder.embeds_alphabet();

  std::uint64_t total_bytes = 0, total_points = 0;
  Json j;
  j.begin_object();
  j.begin_array("files");
  // The table's header goes out with its first row: a first scan that fails leaves the error alone.
  bool header_printed = false;
  bool any_words = false;
  codec::SequenceData sequence;
  // One scan from its file (or the learnt scans) to its coded bytes: run for several scans
  // at once when there are threads to spare, each scan then on one thread (its stages are
  // partly serial: two scans side by side keep both cores busy). The files do not depend on
  // the thread count; they are written, and reported, in scan order.
  struct Outcome {
    codec::ModelData d;  // the scan's point count and instances, for the report
    CodedScan coded;
    std::size_t features = 0;
    bool modelled = false;  // an alphabet reused: stage times below
    FeatureTimings feature_ms;
    double neighbourhoods_ms = 0.0;
    EncodeTimings encode_ms;
    double read_ms = 0.0, code_ms = 0.0;
    std::exception_ptr error;
  };
  auto produce = [&](std::size_t i, int threads) {
    Outcome out;
    try {
      Cloud streamed;
      codec::ModelData& d = out.d;
      const bool learnt = learnt_as[i] >= 0;
      if (learnt) {
        const auto slot = static_cast<std::size_t>(learnt_as[i]);
        out.features = set.scans[slot].features.size();
        d.model = set.models[slot];
      } else {
        Stopwatch read_sw;
        streamed = loader.load(i);
        out.read_ms = read_sw.elapsed_ms();
        if (use_words) {
          ScanModelStats stats;
          d.model = coder.model_scan(streamed, p, threads, &stats);
          out.features = stats.features;
          out.modelled = true;
          out.feature_ms = stats.feature_ms;
          out.neighbourhoods_ms = stats.neighbourhoods_ms;
          out.encode_ms = stats.encode_ms;
        }
      }
      const Cloud& cloud = learnt ? clouds[static_cast<std::size_t>(learnt_as[i])] : streamed;
      Stopwatch code_sw;
      d.input_points = cloud.size();
      auto coded = coder.code(cloud, d.model, threads);
      // The failures: no layer fits the bit budget; an attribute that cannot be coded.
      if (!coded.ok()) {
        const std::string m = coded.status().to_string();
        if (o.target_bpp > 0.0 && m.find("bits per point") != std::string::npos)
          throw CliError(2, m + "; try a larger --target-bpp or --words on");
        throw CliError(2, loader.name(i) + ": " + m);
      }
      out.coded = std::move(coded).value();
      if (!out.coded.words) d.model.instances.clear();
      out.code_ms = code_sw.elapsed_ms();
    } catch (const std::invalid_argument& e) {
      // Raised by the library on what this scan holds: bad data, named.
      out.error = std::make_exception_ptr(CliError(2, loader.name(i) + ": " + e.what()));
    } catch (...) {
      out.error = std::current_exception();
    }
    return out;
  };
  ProgressBar bar("encoding");
  const auto emit = [&](std::size_t i, Outcome& r) {
    if (r.error) std::rethrow_exception(r.error);
    read_ms += r.read_ms;
    const codec::ModelData& d = r.d;
    const CodedScan& coded = r.coded;
    any_words = any_words || coded.words;
    const std::vector<std::uint8_t>& bytes = coded.bytes;
    Stopwatch write_sw;
    if (o.one_file) sequence.model_files.push_back(bytes);
    else throw_if_error(io::write_file_atomic(files.staged(outputs[i]), bytes));
    const double code_ms = r.code_ms + write_sw.elapsed_ms();
    const std::string& shown = o.one_file ? loader.name(i) : outputs[i];
    const double bpp = d.input_points ? 8.0 * static_cast<double>(bytes.size()) / static_cast<double>(d.input_points) : 0.0;
    total_bytes += bytes.size();
    total_points += d.input_points;
    if (o.json) {
      j.begin_object()
          .value("input", loader.name(i))
          .value("output", o.one_file ? o.output : outputs[i])
          .value("points", d.input_points)
          .value("features", r.features)
          .value("instances", d.model.instances.size())
          .value("bytes", static_cast<std::uint64_t>(bytes.size()))
          .value("bits_per_point", bpp);
      if (r.modelled) {  // an alphabet reused: where each scan's time went
        j.begin_object("timings_ms")
            .value("range_image", r.feature_ms.range_image_ms)
            .value("interest_points", r.feature_ms.interest_ms)
            .value("coverage_points", r.feature_ms.coverage_ms)
            .value("descriptors", r.feature_ms.descriptor_ms)
            .value("neighbourhoods", r.neighbourhoods_ms)
            .value("frames", r.encode_ms.frames_ms)
            .value("words", r.encode_ms.words_ms)
            .value("refine", r.encode_ms.refine_ms)
            .value("prune", r.encode_ms.prune_ms)
            .value("code_and_write", code_ms)
            .end_object();
      }
      if (coded.max_error) {
        j.begin_object("residual")
            .value("max_error_m", *coded.max_error)
            .value("words_used", coded.words)
            .value("word_points", coded.layer.word_points)
            .value("kept_word_points", coded.layer.kept_word_points)
            .value("explained_points", coded.layer.explained_points)
            .value("coded_points", coded.layer.residual_points)
            .value("escaped_points", coded.layer.escaped_points)
            .value("coding", coded.layer.lattice ? "lattice"
                             : coded.layer.acquisition ? "acquisition-order"
                             : coded.layer.laser   ? "sensor-geometry"
                             : coded.layer.voxel ? "voxel"
                             : coded.layer.sweep ? "sweep"
                                                 : "previous-point")
            .value("bytes", coded.layer.bytes);
        if (!coded.layer.laser_table_source.empty())
          j.begin_object("laser_table")
              .value("source", coded.layer.laser_table_source)
              .value("lasers", static_cast<std::uint64_t>(coded.layer.lasers))
              .value("columns", static_cast<std::uint64_t>(coded.layer.columns))
              .value("fit_rms_m", coded.layer.laser_table_rms)
              .end_object();
        if (coded.profile_fit)
          j.begin_object("sensor_profile")
              .value("file", o.sensor)
              .value("lasers_hit", static_cast<std::uint64_t>(coded.profile_fit->lasers_hit))
              .value("median_off_beam_m", coded.profile_fit->median_off_beam_m)
              .value("direction", static_cast<std::int64_t>(coded.profile_fit->direction))
              .value("firing_times", coded.profile_fit->firing_times)
              .end_object();
        j.end_object();
      }
      j.begin_array("attributes");
      for (const auto& a : coded.attributes)
        j.begin_object()
            .value("name", a.name)
            .value("representation", a.representation)
            .value("lossless", a.max_error == 0.0)
            .value("max_error", a.max_error)
            .value("bytes", static_cast<std::uint64_t>(a.bytes))
            .value("bits_per_point", d.input_points ? 8.0 * static_cast<double>(a.bytes) / static_cast<double>(d.input_points) : 0.0)
            .end_object();
      j.end_array();
      j.begin_array("attributes_dropped");
      for (const auto& f : coded.dropped) j.value({}, f);
      j.end_array();
      j.end_object();
    } else {
      bar.clear();  // the table row starts on a clean line
      if (!header_printed)
        std::printf("%-32s %9s %9s %10s %10s%s\n", "output", "points", "instances", "bytes", "bits/pt",
                    layered ? "  max error   coded pts" : "");
      header_printed = true;
      std::printf("%-32s %9llu %9zu %10zu %10.3f", shown.c_str(), static_cast<unsigned long long>(d.input_points),
                  d.model.instances.size(), bytes.size(), bpp);
      if (coded.max_error) std::printf("  %7.4f m %11zu", *coded.max_error, coded.layer.residual_points);
      std::printf("\n");
      if (coded.profile_fit)
        std::printf("  sensor profile %s: %zu of %zu lasers hit, points a median %.2f mm from the beams; layer coded %s\n",
                    o.sensor.c_str(), coded.profile_fit->lasers_hit, coded.profile_fit->lasers,
                    coded.profile_fit->median_off_beam_m * 1e3, coded.layer.laser ? "by sensor geometry" : "otherwise (smaller)");
      int name_width = 10;  // the names in one column (a LAS file's are up to 20 characters)
      for (const auto& a : coded.attributes) name_width = std::max(name_width, static_cast<int>(std::min<std::size_t>(a.name.size(), 64)));
      for (const auto& a : coded.attributes)
        std::printf("  kept %-*s %8zu bytes %7.3f bits/pt  %s\n", name_width, a.name.c_str(), a.bytes,
                    d.input_points ? 8.0 * static_cast<double>(a.bytes) / static_cast<double>(d.input_points) : 0.0,
                    a.representation.c_str());
      for (const auto& f : coded.dropped)
        std::printf("  dropped %s (%s)\n", f.c_str(),
                    o.drop_attributes ? "--drop-attributes"
                    : std::find(o.drop_fields.begin(), o.drop_fields.end(), f) != o.drop_fields.end() ? "--drop-field"
                    : coded.max_error ? "not coded"
                                      : "words alone: give --max-error to keep attributes");
      // (a name given to --drop-field that the scan does not have: likely a typo)
      for (const std::string& f : o.drop_fields)
        if (std::find(coded.dropped.begin(), coded.dropped.end(), f) == coded.dropped.end())
          std::printf("  --drop-field %s: the scan has no field of that name\n", f.c_str());
    }
    std::fflush(stdout);
    bar.update(static_cast<long>(i + 1), static_cast<long>(n_scans), loader.name(i));
  };
  std::vector<Outcome> batch;
  for (std::size_t first = 0; first < n_scans; first += side_by_side) {
    const std::size_t count = std::min(side_by_side, n_scans - first);
    batch.assign(count, Outcome{});
    if (count == 1) batch[0] = produce(first, mp.threads);
    else parallel_for(count, static_cast<int>(count), [&](std::size_t k) { batch[k] = produce(first + k, 1); }, 1);
    for (std::size_t k = 0; k < count; ++k) emit(first + k, batch[k]);
  }
  bar.finish();
  j.end_array();
  // A saved alphabet is written once the models are; it is counted only when a model uses it.
  if (!o.save_alphabet.empty()) throw_if_error(io::write_file_atomic(files.staged(o.save_alphabet), alphabet_file));
  std::uint64_t alphabet_bytes = embed || !any_words ? 0 : alphabet_file.size();
  if (o.one_file) {  // one file: its size is the total (models, alphabet and framing)
    sequence.alphabet_file = alphabet_file;
    // Each scan's name, for decompress to write it back under: kept when the stems are
    // unique (inputs of one name from several folders are numbered on decompress instead).
    std::set<std::string> unique;
    for (std::size_t i = 0; i < loader.size(); ++i) {
      sequence.names.push_back(loader.stem(i));
      if (!codec::is_valid_scan_name(sequence.names.back()) || !unique.insert(sequence.names.back()).second) {
        sequence.names.clear();
        break;
      }
    }
    const std::vector<std::uint8_t> file = codec::encode_sequence(sequence);
    throw_if_error(io::write_file_atomic(files.staged(o.output), file));
    alphabet_bytes = 0;
    total_bytes = file.size();
  }
  files.commit();
  const double total_ms = sw.elapsed_ms();
  const double bpp_all = total_points ? 8.0 * static_cast<double>(total_bytes + alphabet_bytes) / static_cast<double>(total_points) : 0.0;
  if (o.json) {
    j.value("alphabet_words", alphabet.size()).value("alphabet_embedded", embed).value("one_file", o.one_file);
    j.value("alphabet_bytes", alphabet_bytes).value("total_bytes", total_bytes + alphabet_bytes);
    j.value("bits_per_point", bpp_all).value("time_ms", total_ms).value("read_ms", read_ms);
    j.end_object();
    std::cout << j.str() << "\n";
    return;
  }
  const std::string alphabet_path = o.alphabet.empty() ? o.save_alphabet : o.alphabet;
  const std::string where = o.one_file ? "in the sequence file " + o.output
                            : embed   ? std::string("embedded in each model file")
                            : any_words ? std::to_string(alphabet_bytes) + " bytes in " + alphabet_path
                                        : std::to_string(alphabet_file.size()) + " bytes in " + alphabet_path +
                                              "; no scan's file uses it (the layer alone was smaller; they decode "
                                              "without it), so not counted";
  if (embed && alphabet.size() == 0)
    std::printf("alphabet: none (no words: each model file holds its layer alone)\n");
  else
    std::printf("alphabet: %zu words, %s\n", alphabet.size(), where.c_str());
  std::printf("total: %llu bytes for %llu points = %.3f bits per point (alphabet included), %.0f ms\n",
              static_cast<unsigned long long>(total_bytes + alphabet_bytes), static_cast<unsigned long long>(total_points),
              bpp_all, total_ms);
}

}  // namespace

void register_compress(CLI::App& app) {
  auto o = std::make_shared<CompressOptions>();
  CLI::App* sub = app.add_subcommand("compress", "Compress scans into lex3d model files");
  sub->footer("Examples:\n  lex3d compress scan.bin -o scan.lex3dm                  (every point within 1 cm)\n  lex3d compress drive/*.pcd -o drive.lex3dq --one-file --max-error 0.02\n  lex3d compress new/*.bin -o new.lex3dm --alphabet fleet.lex3da --max-error none");
  sub->add_option("scans", o->inputs, "Point clouds")->required();
  sub->add_option("-o,--output", o->output,
                  "Model file (numbered _000, _001... for several scans), or the sequence file with --one-file")
      ->required();
  sub->add_option("--learn-scans", o->learn_scans,
                  "Learn the alphabet on this many evenly spaced scans and code the others with it, one at a "
                  "time (0, the default: learn on every scan)")
      ->check(CLI::Range(0, 1000000));
  sub->add_flag("--one-file", o->one_file,
                "Write one sequence file holding every scan's model and the shared alphabet (formats/sequence.md)");
  sub->add_option("--alphabet", o->alphabet, "Reuse this alphabet file (nothing is learned)");
  sub->add_option("--save-alphabet", o->save_alphabet, "Write the learned alphabet here; the models reference it");
  sub->add_option("--max-error", o->max_error,
                  "The bound of the residual layer, m: every input point has a decoded point within it and vice "
                  "versa; \"auto\": 1 cm (or the bound --target-bpp finds); \"none\": words alone, no bound")
      ->capture_default_str();
  sub->add_option("--target-bpp", o->target_bpp,
                  "Add the residual layer with the smallest error that fits this many bits per input point")
      ->check(CLI::Range(1e-3, 1e3));
  sub->add_option("--words", o->words,
                  "With a residual layer: code every point in the layer (off, the default), use the alphabet's "
                  "words and code only what they do not explain (on), or keep the smaller file per scan (auto)")
      ->check(CLI::IsMember({"on", "off", "auto"}));
  // A step is 0 (derived) or in [1e-6, 0.1].
  const CLI::Validator step_check(
      [](std::string& in) -> std::string {
        char* end = nullptr;
        const double v = std::strtod(in.c_str(), &end);
        if (end == in.c_str() || *end != '\0') return "not a number: " + in;
        return v == 0.0 || (v >= 1e-6 && v <= 0.1) ? "" : "must be 0 or in [1e-6, 0.1], got " + in;
      },
      "0 OR [1e-6, 0.1]");
  sub->add_option("--translation-step", o->quantization.translation_m,
                  "Quantisation step of instance translations, m, in [1e-6, 0.1] (formats/model.md §3); "
                  "0: the word radius / 32")
      ->check(step_check)
      ->capture_default_str();
  sub->add_option("--rotation-step", o->quantization.rotation_rad,
                  "Quantisation step of instance rotations, rad, in [1e-6, 0.1]; 0: 1/32 rad")
      ->check(step_check)
      ->capture_default_str();
  sub->add_flag("--keep-all-points", o->keep_all_points,
                "Residual layer: give every input point its own decoded point (by default a point within the "
                "error of one decoded before it is not coded again; the sensor-geometry coding leaves out only "
                "those that would cost more than their neighbours)");
  sub->add_option("--layer-coding", o->layer_coding,
                  "Residual layer: try the sensor-centred spherical codings, the voxel (octree) coding and, where "
                  "the scan's lasers and columns are known, the sensor-geometry coding, where the points' "
                  "times rise in their order (a LAS file's GPS times), the acquisition-order coding, and where "
                  "they lie on a square lattice in x and y (a gridded product), the lattice coding, and keep "
                  "the smallest (auto), or use only one kind; voxel needs no sensor pose and suits maps merged "
                  "from many viewpoints; laser, acquisition and lattice fall back to spherical where the "
                  "lasers, the times or a lattice are not found (formats/model.md §2.5-2.8, §2.11, §2.12)")
      ->check(CLI::IsMember({"auto", "spherical", "voxel", "laser", "acquisition", "lattice"}))
      ->capture_default_str();
  sub->add_flag("--fast", o->fast,
                "Residual layer: sensor-rate encoding. Lasers estimated from the points take a quarter of the "
                "work, and beside the sensor-geometry coding the other codings are coded in full only where a "
                "trial says they win (an attribute's methods too): a KITTI scan encodes in 0.8 of the time, most files come out the same "
                "and a few up to 6 % larger (bench/README.md, \"Fast encoding\")");
  sub->add_option("--objective", o->objective,
                  "Residual layer: the fewest bits within --max-error (bound), or the fewest bits for the mean "
                  "squared error, still within it (mse): the sensor-geometry coding takes a range step of E, not "
                  "about 1.8 E, and each point the step within E that rate and distortion favour; the other "
                  "codings code to 5/9 E. At the same bound files are larger with a lower mean squared error; "
                  "at the same PSNR smaller (bench/README.md, \"Beam lengths chosen a laser at a time, and the "
                  "mean-squared-error objective\")")
      ->check(CLI::IsMember({"bound", "mse"}))
      ->capture_default_str();
  sub->add_option("--intensity-error", o->intensity_error,
                  "Largest intensity error kept in the model file, in the intensity's own units; 0 keeps the "
                  "intensities losslessly (formats/model.md §2.10)")
      ->check(CLI::Range(0.0, 1e9))
      ->capture_default_str();
  sub->add_flag("--drop-attributes", o->drop_attributes,
                "Keep positions only: no intensity, ring, time or colour (they are listed as dropped)");
  sub->add_option("--drop-field", o->drop_fields,
                  "A field not to keep, by the name compress lists it under (ring, intensity, time, rgb, or a named "
                  "field such as an Ouster capture's signal or near_ir); may be given several times")
      ->type_name("NAME");
  sub->add_option("--sensor", o->sensor,
                  "Sensor profile of the scans' lidar (its laser table: JSON as bench/sensors/*.json, or a Velodyne "
                  "db.xml; formats/sensor_profile.md): the sensor-geometry coding takes each point's laser and column "
                  "from it; scans that do not fit it are refused");
  sub->add_flag("--json", o->json, "Print one JSON object");
  o->scan_set.add_to(*sub);
  o->model.add_to(*sub);
  sub->callback([o] { run_compress(*o); });
}

}  // namespace lex3d::cli
