// lex3d decompress MODEL -o OUT: the reconstruction as a point cloud and/or an OctoMap.

#include <CLI/CLI.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <cstdio>
#include <iostream>
#include <thread>

#include "allocator.hpp"
#include "cli_common.hpp"
#include "json.hpp"
#include "lex3d/codec/codec.hpp"
#include "lex3d/core/timer.hpp"
#include "lex3d/eval/metrics.hpp"
#include "lex3d/io/rosbag.hpp"
#include "lex3d/lex3d.hpp"
#include "lex3d/residual/residual.hpp"

namespace lex3d::cli {

namespace {

struct DecompressOptions {
  std::string input;
  std::string output;
  std::string alphabet;
  std::string octomap;
  double resolution = 0.1;
  std::string free_space = "cast";  ///< cast (rays from the sensor) or none (occupied voxels only)
  std::string reference;
  std::string reference_format = "auto";
  double sigma_lambda = ModelParams{}.sigma_lambda;
  bool json = false;
  int threads = 1;  // set by --threads
};

/// A sequence file: every scan's decoded cloud, written to OUT_000, OUT_001, ...
void run_decompress_sequence(const DecompressOptions& o, const std::vector<std::uint8_t>& bytes) {
  if (o.output.empty() || !o.octomap.empty() || !o.reference.empty() || !o.alphabet.empty())
    throw CliError(1, "a sequence file decompresses to point clouds: give -o OUT only (no --octomap, --reference, --alphabet)");
  Stopwatch sw;
  auto seq = codec::decode_sequence(bytes);
  if (!seq.ok()) throw CliError(2, o.input + ": " + seq.status().to_string());
  const codec::SequenceData& s = seq.value();
  // Every scan is decoded and staged before any is renamed into place: all or nothing.
  OutputSet files;
  files.input(o.input, "model");
  std::vector<std::string> outputs;
  const bool bag = is_bag_output(o.output);  // one bag, a message a scan (stamped from its name)
  std::unique_ptr<io::BagWriter> bag_out;
  if (bag) files.output(o.output, "-o");
  for (std::size_t i = 0; i < s.model_files.size() && !bag; ++i) {
    // A file that keeps its scans' names (sequence 1.1) writes OUT_<name>; else OUT_000...
    outputs.push_back(s.names.empty() ? numbered_output(o.output, i, s.model_files.size())
                                      : named_output(o.output, s.names[i], s.model_files.size()));
    files.output(outputs.back(), "-o");
  }
  Json j;
  j.begin_object().value("sequence", o.input).value("scans", s.model_files.size()).begin_array("files");
  std::uint64_t input_points = 0, points = 0;
  // Scans are decoded `threads` at a time (each on one thread); what is printed follows the
  // scan order. Point-cloud files are written by their thread into their own staged file, a
  // bag's messages in scan order as each batch is done; memory holds one batch of clouds.
  struct Decoded {
    std::uint64_t input_points = 0;
    std::size_t points = 0;
    bool residual_layer = false;
    std::string error;  // non-empty: the scan failed
    int exit_code = 2;  // decoding: bad data; writing: as the write's status says
  };
  const std::size_t n = s.model_files.size();
  const std::size_t batch = static_cast<std::size_t>(std::max(1, o.threads));
  if (bag) {
    outputs.assign(n, o.output);
    auto w = io::BagWriter::open(files.staged(o.output));
    if (!w.ok()) throw CliError(exit_code_for(w.status().code()), w.status().to_string());
    bag_out = std::move(w).value();
  }
  std::vector<std::string> staged(n);
  if (!bag)
    for (std::size_t i = 0; i < n; ++i) staged[i] = files.staged(outputs[i]);
  for (std::size_t first = 0; first < n; first += batch) {
    const std::size_t count = std::min(batch, n - first);
    std::vector<Decoded> done(count);
    std::vector<Cloud> clouds(count);
    auto work = [&](std::size_t k) {
      const std::size_t i = first + k;
      auto d = codec::decode_model(s.model_files[i], &s.alphabet_file);
      if (!d.ok()) return void(done[k].error = d.status().to_string());
      auto cloud = residual::decode_cloud(d.value());
      if (!cloud.ok()) return void(done[k].error = cloud.status().to_string());
      cloud.value().georef = d.value().georef;  // written in true coordinates
      if (!bag) {
        const Status w = io::write_cloud(staged[i], cloud.value());
        if (!w.ok()) {
          done[k].exit_code = exit_code_for(w.code());
          done[k].error = outputs[i] + ": " + w.to_string();
          return;
        }
      }
      done[k].input_points = d.value().input_points;
      done[k].points = cloud.value().size();
      done[k].residual_layer = d.value().residual.has_value();
      clouds[k] = std::move(cloud).value();
    };
    std::vector<std::thread> pool;
    for (std::size_t k = 1; k < count; ++k) pool.emplace_back(work, k);
    work(0);
    for (auto& t : pool) t.join();
    for (std::size_t k = 0; k < count; ++k) {
      const std::size_t i = first + k;
      if (!done[k].error.empty())
        throw CliError(done[k].exit_code, o.input + ": scan " + std::to_string(i) + ": " + done[k].error);
      input_points += done[k].input_points;
      points += done[k].points;
      if (o.json)
        j.begin_object().value("output", outputs[i]).value("input_points", done[k].input_points)
            .value("points", done[k].points).value("residual_layer", done[k].residual_layer).end_object();
      else
        std::printf("%s: %zu points (scan %zu of %zu)\n", outputs[i].c_str(), done[k].points, i + 1, n);
      if (bag) {
        io::BagScan scan;
        if (!s.names.empty()) stamp_from_name(s.names[i], scan.stamp_sec, scan.stamp_nsec);
        scan.cloud = std::move(clouds[k]);
        throw_if_error(bag_out->write(scan));
      } else {
        note_fields_not_written(outputs[i], clouds[k]);
      }
    }
  }
  if (bag) throw_if_error(bag_out->close());
  files.commit();
  const double bpp = input_points ? 8.0 * static_cast<double>(bytes.size()) / static_cast<double>(input_points) : 0.0;
  if (o.json) {
    j.end_array().value("input_points", input_points).value("points", points).value("bits_per_point", bpp);
    j.value("time_ms", sw.elapsed_ms()).end_object();
    std::cout << j.str() << "\n";
  } else {
    std::printf("%s: %zu bytes, %zu scans, %llu input points = %.3f bits per point\n", o.input.c_str(), bytes.size(),
                s.model_files.size(), static_cast<unsigned long long>(input_points), bpp);
  }
}

void run_decompress(const DecompressOptions& o) {
  if (o.output.empty() && o.octomap.empty()) throw CliError(1, "give -o OUT and/or --octomap OUT.bt");
  OutputSet files;
  files.input(o.input, "model");
  files.input(o.alphabet, "--alphabet");
  files.input(o.reference, "--reference");
  files.output(o.output, "-o");
  check_output_kind(o.output, "-o", "cloud");
  files.output(o.octomap, "--octomap");
  Stopwatch sw;
  set_current_file(o.input);
  auto bytes = io::read_file(o.input);
  if (!bytes.ok()) throw CliError(exit_code_for(bytes.status().code()) == 4 ? 4 : 2, bytes.status().to_string());
  const std::string kind = lex3d_file_kind(bytes.value());
  if (kind != "model" && kind != "sequence")
    throw CliError(2, o.input + ": not a lex3d model or sequence file" +
                          (kind.empty() ? std::string(" (bad magic)") : " (it is a lex3d " + kind + " file)"));
  if (codec::is_sequence_file(bytes.value())) {
    run_decompress_sequence(o, bytes.value());
    return;
  }
  keep_heap_on_huge_pages();  // one scan to rebuild
  std::vector<std::uint8_t> alphabet_file;
  if (!o.alphabet.empty()) {
    auto a = io::read_file(o.alphabet);
    if (!a.ok()) throw CliError(2, "--alphabet " + a.status().to_string());
    alphabet_file = std::move(a).value();
    const std::string akind = lex3d_file_kind(alphabet_file);
    if (akind != "alphabet")
      throw CliError(2, "--alphabet " + o.alphabet + ": not a lex3d alphabet file" +
                            (akind.empty() ? std::string(" (bad magic)") : " (it is a lex3d " + akind + " file)"));
  }
  // The same decoding as lex3d::decompress (lex3d/lex3d.hpp).
  auto decoded = lex3d::decompress(bytes.value(), o.alphabet.empty() ? nullptr : &alphabet_file);
  if (!decoded.ok()) {
    // A model that references an alphabet decoded without one: the alphabet is missing input (2).
    const auto& st = decoded.status();
    if (st.code() == ErrorCode::kInvalidArgument && o.alphabet.empty())
      throw CliError(2, o.input + ": " + st.to_string() + "; give that alphabet file with --alphabet FILE");
    throw CliError(2, o.input + ": " + st.to_string());
  }
  const DecompressResult& d = decoded.value();
  if (!o.alphabet.empty() && !d.references_alphabet)
    std::fprintf(stderr, "note: %s embeds its alphabet; --alphabet %s is not used\n", o.input.c_str(),
                 o.alphabet.c_str());
  const double decode_ms = d.decode_ms;
  const double reconstruct_ms = d.reconstruct_ms;
  Cloud cloud = std::move(decoded.value().cloud);  // georeferenced: written in true coordinates where the format can
  sw.lap_ms();
  if (!o.output.empty()) {
    throw_if_error(io::write_cloud(files.staged(o.output), cloud));
    note_fields_not_written(o.output, cloud);
    const std::string ext = std::filesystem::path(o.output).extension().string();
    if (cloud.georef && (ext == ".bin" || ext == ".BIN"))
      std::fprintf(stderr, "note: %s holds float32 coordinates relative to the georeference origin (%.3f, %.3f, %.3f) m; "
                           "write .las, .pcd, .ply or .xyz for the true coordinates\n",
                   o.output.c_str(), cloud.georef->origin.x(), cloud.georef->origin.y(), cloud.georef->origin.z());
  }
  io::OctomapStats oct;
  if (!o.octomap.empty()) {
    auto r = io::write_octomap(files.staged(o.octomap), cloud,
                               o.free_space == "cast" ? std::optional<Eigen::Vector3d>(cloud.T_cloud_sensor.translation())
                                                      : std::nullopt,
                               o.resolution);
    throw_if_error(r.status());
    oct = r.value();
  }
  files.commit();
  const double write_ms = sw.lap_ms();

  const double bpp = d.input_points ? 8.0 * static_cast<double>(bytes.value().size()) / static_cast<double>(d.input_points) : 0.0;
  eval::DistanceResult dist;
  eval::InlierResult inl;
  const bool compare = !o.reference.empty();
  if (compare) {
    Cloud ref = load_cloud(o.reference, parse_format_option(o.reference_format)).cloud;
    // compare in the model's local frame: a reference read about another origin (or none) is moved to it
    if (cloud.georef || ref.georef) {
      const Eigen::Vector3d to_model = (ref.georef ? ref.georef->origin : Eigen::Vector3d::Zero()) -
                                       (cloud.georef ? cloud.georef->origin : Eigen::Vector3d::Zero());
      if (!to_model.isZero()) {
        for (auto& p : ref.points) p = (p.cast<double>() + to_model).cast<float>();
        ref.T_cloud_sensor.translation() += to_model;
      }
    }
    // A reference without a viewpoint of its own (a PLY or .bin in the model's frame, say a
    // world-frame scan compressed with --input-frame world) is seen from the model's sensor.
    if (ref.T_cloud_sensor.matrix() == Pose::Identity().matrix()) ref.T_cloud_sensor = cloud.T_cloud_sensor;
    eval::DistanceParams dp;
    dp.threads = o.threads;
    dist = eval::compare_clouds(ref, cloud, dp);
    const auto res = estimate_angular_resolution(ref);
    eval::RangeSigma sigma;
    const double alpha = res ? std::max(res->azimuth_rad, res->elevation_rad) : 0.2 * M_PI / 180.0;
    sigma.factor = o.sigma_lambda * std::tan(alpha / 2.0);
    sigma.min_sigma = 1e-3;
    sigma.origin = ref.T_cloud_sensor.translation();
    inl = eval::inliers_outliers(ref, cloud, sigma, o.threads);
  }
  if (o.json) {
    Json j;
    j.begin_object();
    j.value("model", o.input).value("model_bytes", static_cast<std::uint64_t>(bytes.value().size()));
    j.value("input_points", d.input_points).value("bits_per_point", bpp);
    j.value("instances", d.instances).value("words", d.alphabet_words);
    j.value("points", cloud.size());
    j.value("residual_layer", d.residual_layer);
    if (!o.output.empty()) j.value("output", o.output);
    if (!o.octomap.empty())
      j.begin_object("octomap")
          .value("file", o.octomap)
          .value("resolution_m", o.resolution)
          .value("occupied_leaves", oct.occupied_leaves)
          .value("free_leaves", oct.free_leaves)
          .value("bytes", oct.file_bytes)
          .end_object();
    if (compare) {
      j.begin_object("against_reference")
          .value("d1_psnr_db", dist.d1_psnr_db)
          .value("rmse_m", dist.rmse)
          .value("chamfer_m", dist.chamfer)
          .value("hausdorff_m", dist.hausdorff)
          .value("inliers", inl.inliers)
          .value("outliers", inl.outliers)
          .end_object();
    }
    j.begin_object("timings_ms").value("decode", decode_ms).value("reconstruct", reconstruct_ms).value("write", write_ms).end_object();
    j.end_object();
    std::cout << j.str() << "\n";
    return;
  }
  std::printf("%s: %zu bytes, %llu input points = %.3f bits per point; %zu instances of %zu words\n", o.input.c_str(),
              bytes.value().size(), static_cast<unsigned long long>(d.input_points), bpp, d.instances,
              d.alphabet_words);
  std::printf("reconstruction: %zu points (decode %.1f ms, reconstruct %.1f ms)\n", cloud.size(), decode_ms, reconstruct_ms);
  if (!o.output.empty()) std::printf("wrote %s\n", o.output.c_str());
  if (!o.octomap.empty())
    std::printf("wrote %s: OctoMap at %.3g m, %zu occupied and %zu free leaves, %llu bytes\n", o.octomap.c_str(),
                o.resolution, oct.occupied_leaves, oct.free_leaves, static_cast<unsigned long long>(oct.file_bytes));
  if (compare)
    std::printf("against %s: D1 PSNR %.2f dB, RMSE %.4f m, inliers %.1f%%, outliers %.1f%%, Chamfer %.4f m, Hausdorff %.3f m\n",
                o.reference.c_str(), dist.d1_psnr_db, dist.rmse, 100.0 * inl.inliers, 100.0 * inl.outliers, dist.chamfer,
                dist.hausdorff);
}

}  // namespace

void register_decompress(CLI::App& app) {
  auto o = std::make_shared<DecompressOptions>();
  CLI::App* sub = app.add_subcommand("decompress", "Reconstruct a point cloud (or an OctoMap) from a model file, "
                                                   "or every scan of a sequence file");
  sub->footer("Examples:\n  lex3d decompress scan.lex3dm -o scan.pcd --reference scan.bin\n  lex3d decompress drive.lex3dq -o drive.ply                (one file a scan)\n  lex3d decompress scan.lex3dm --octomap scan.bt --resolution 0.1");
  sub->add_option("model", o->input, "lex3d model file or sequence file")->required();
  sub->add_option("-o,--output", o->output, "Point cloud to write (.pcd, .ply, .bin, .xyz; .bag: ROS PointCloud2 messages, every scan of a sequence in one bag)");
  sub->add_option("--alphabet", o->alphabet, "The alphabet file a model references");
  sub->add_option("--octomap", o->octomap, "Also write an OctoMap occupancy tree (.bt)");
  sub->add_option("--resolution", o->resolution, "OctoMap resolution, m")->check(CLI::Range(1e-3, 100.0));
  sub->add_option("--free-space", o->free_space,
                  "OctoMap free space: cast along the rays from the stored sensor origin (cast), or none, only "
                  "the occupied voxels (for a map merged from many viewpoints, which has no one origin)")
      ->check(CLI::IsMember({"cast", "none"}))
      ->capture_default_str();
  sub->add_option("--reference", o->reference, "Compare the reconstruction with this scan (D1 PSNR, inliers)");
  sub->add_option("--reference-format", o->reference_format, "Format of --reference");
  sub->add_option("--sigma-lambda", o->sigma_lambda, "λ of σ = λ tan(α/2) range for inliers/outliers");
  add_threads_option(*sub, o->threads, "Worker threads (scans of a sequence decoded side by side, the comparison)");
  sub->add_flag("--json", o->json, "Print one JSON object");
  sub->callback([o] { run_decompress(*o); });
}

}  // namespace lex3d::cli
