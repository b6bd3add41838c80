#include "model_report.hpp"

#include <cmath>
#include <cstdio>

#include "lex3d/codec/codec.hpp"
#include "progress.hpp"

namespace lex3d::cli {

void ModelOptions::add_to(CLI::App& app) {
  app.add_option("--word-radius", word_radius, "Word radius, m (0 = 8 beam spacings at the median range)");
  app.add_option("--coverage-factor", coverage_factor, "Coverage points at most this many word radii apart");
  app.add_option("--word-spacing", word_spacing_factor, "Word points thinned to this many word radii");
  app.add_option("--sigma-lambda", sigma_lambda, "λ of σ = λ tan(α/2) range (likelihood, inliers)");
  app.add_option("--refine-iterations", refine_iterations, "ICP rounds fitting each instance to the scan (0 = off)")
      ->check(CLI::Range(0, 50));
  app.add_option("--fit-candidates", fit_candidates, "Words (nearest by descriptor) an instance chooses from by fit")
      ->check(CLI::Range(1, 64));
  app.add_flag("--prune-keep-cover", prune_keep_cover,
               "Pruning keeps an instance that is the last to explain some scan point within sigma (more "
               "inliers, larger models; by default ruhnke2010's likelihood rule alone)");
  add_threads_option(app, threads, "Worker threads");
}

ModelParams ModelOptions::params() const {
  ModelParams p;
  p.word_radius = word_radius;
  p.coverage_factor = coverage_factor;
  p.word_spacing_factor = word_spacing_factor;
  p.sigma_lambda = sigma_lambda;
  p.refine_iterations = refine_iterations;
  p.fit_candidates = fit_candidates;
  p.prune_keeps_sole_cover = prune_keep_cover;
  p.threads = threads;
  return p;
}

void ScanSetOptions::add_to(CLI::App& app) {
  app.add_option("--format", format, "Input format: auto, kitti, binxyz, pcd, ply, xyz, uos, pcap");
  app.add_option("--metadata", metadata, "Metadata of a pcap: an Ouster metadata JSON, or a Velodyne calibration (db.xml, VeloView XML or the ROS driver's YAML; needed for an HDL-64E) (default: the .json, .xml, .yaml or .yml beside it, same stem)");
  app.add_option("--sensor-model", sensor_model, "Read a Velodyne pcap as this model: vlp16, puck-hires, hdl32e, vlp32c or hdl64e (default: detected from the packets)");
  app.add_option("--topic", topic, "The topic of a ROS bag to read (default: its only PointCloud2 or Ouster packet topic)");
  app.add_flag("--single-return", single_return, "A dual-return capture: keep one return a pixel (Ouster's strongest, Velodyne's last), as a single-return capture gives it, organised; the second returns are counted, not kept (default: each a point of its own with a return field)");
  app.add_option("--poses", poses, "World <- sensor pose of each scan (KITTI poses.txt layout)");
  app.add_option("--input-frame", input_frame,
                 "Frame of the scans' points: sensor (each scan in its own sensor frame), or world (already in "
                 "the world frame of --poses, as the scans of a registered map; the poses then place each "
                 "scan's sensor, which the range image and the residual layer are centred on)")
      ->check(CLI::IsMember({"sensor", "world"}));
  app.add_option("--iterations", iterations, "Candidate words drawn at most when learning")
      ->check(CLI::Range(1, 1000000));
  app.add_option("--seed", seed, "Seed of the candidate order when learning");
}

std::vector<Cloud> ScanSetOptions::load(const std::vector<std::string>& inputs) const {
  const ScanLoader l = loader(inputs);
  std::vector<Cloud> clouds;
  clouds.reserve(l.size());
  for (std::size_t i = 0; i < l.size(); ++i) clouds.push_back(l.load(i));
  return clouds;
}

ScanLoader ScanSetOptions::loader(const std::vector<std::string>& inputs) const {
  io::ReadOptions options = read_options(parse_format_option(format), metadata, sensor_model);
  options.bag_topic = topic;
  options.single_return = single_return;
  return ScanLoader(inputs, options, poses, input_frame == "world");
}

void ScanSetOptions::record_inputs(OutputSet& files, const std::vector<std::string>& inputs) const {
  files.inputs(inputs, "input");
  files.input(poses, "--poses");
  files.input(metadata, "--metadata");
}

LearnParams ScanSetOptions::learn_params(const ModelParams& model) const {
  LearnParams p;
  p.model = model;
  p.max_iterations = iterations;
  p.seed = seed;
  return p;
}

AlphabetFile read_alphabet_file(const std::string& path) {
  auto bytes = io::read_file(path);
  if (!bytes.ok()) throw CliError(2, bytes.status().to_string());
  auto a = codec::decode_alphabet(bytes.value());
  if (!a.ok()) throw CliError(2, path + ": " + a.status().to_string());
  return {std::move(bytes).value(), std::move(a).value()};
}

LearnResult learn_with_progress(const std::vector<Cloud>& clouds, const LearnParams& params) {
  ProgressBar bar("learning");
  return learn_alphabet(clouds, params, [&](const LearnProgress& pr) {
    char detail[96];
    std::snprintf(detail, sizeof detail, "BIC %.6g, %zu words", pr.bic, pr.alphabet_size);
    bar.update(pr.iteration, pr.max_iterations, detail);
  });
}

ModelSet build_models(const std::vector<Cloud>& clouds, const LearnParams& learn, const Alphabet* reuse,
                      const std::vector<std::string>& names) {
  ModelSet set;
  if (reuse == nullptr) {
    LearnResult r = learn_with_progress(clouds, learn);
    set.alphabet = std::move(r.alphabet);
    set.scans = std::move(r.scans);
    set.models = std::move(r.models);
    return set;
  }
  set.alphabet = *reuse;
  ProgressBar bar("encoding");
  for (std::size_t i = 0; i < clouds.size(); ++i) {
    set.scans.push_back(prepare_scan(clouds[i], learn.model, set.alphabet.word_radius));
    set.timings.emplace_back();
    set.models.push_back(encode_scan(set.scans.back(), set.alphabet, learn.prune, learn.model, &set.timings.back()));
    bar.update(static_cast<long>(i + 1), static_cast<long>(clouds.size()), i < names.size() ? names[i] : "");
  }
  return set;
}

namespace {
std::vector<std::vector<Eigen::Vector3f>> word_points(const Alphabet& a) {
  std::vector<std::vector<Eigen::Vector3f>> w;
  w.reserve(a.size());
  for (const auto& word : a.words) w.push_back(word.points);
  return w;
}
void split(const Model& m, std::vector<std::uint32_t>& ids, std::vector<Pose>& poses) {
  for (const auto& inst : m.instances) {
    ids.push_back(inst.word);
    poses.push_back(inst.T_cloud_word);
  }
}
}  // namespace

ScanReport measure(const std::string& file, const PreparedScan& scan, const Model& model, const Alphabet& alphabet,
                   double sigma_lambda, int threads, Reconstruction* reconstruction) {
  ScanReport r;
  r.file = file;
  r.points = scan.cloud.size();
  r.features = scan.features.size();
  r.instances = model.instances.size();
  Reconstruction rec = reconstruct(model, alphabet, alphabet.point_spacing);
  r.reconstructed_points = rec.cloud.size();
  std::vector<std::uint32_t> ids;
  std::vector<Pose> poses;
  split(model, ids, poses);
  r.rates = eval::compression_rates(scan.cloud, word_points(alphabet), ids, poses);
  eval::RangeSigma sigma;
  sigma.factor = sigma_lambda * std::tan(scan.beam_spacing / 2.0);
  sigma.min_sigma = 1e-3;
  sigma.origin = scan.cloud.T_cloud_sensor.translation();
  r.inliers = eval::inliers_outliers(scan.cloud, rec.cloud, sigma, threads);
  eval::DistanceParams dp;
  dp.threads = threads;
  r.distances = eval::compare_clouds(scan.cloud, rec.cloud, dp);
  if (reconstruction) *reconstruction = std::move(rec);
  return r;
}

ScanReport total(const std::vector<ScanReport>& reports, const std::vector<const Cloud*>& clouds,
                 const std::vector<const Model*>& models, const Alphabet& alphabet) {
  ScanReport t;
  t.file = "total";
  Cloud all;
  std::vector<std::uint32_t> ids;
  std::vector<Pose> poses;
  double inl = 0, outl = 0, mse_ab = 0, mse_ba = 0;
  std::size_t rec_points = 0;
  for (std::size_t i = 0; i < reports.size(); ++i) {
    const auto& r = reports[i];
    t.points += r.points;
    t.features += r.features;
    t.instances += r.instances;
    t.reconstructed_points += r.reconstructed_points;
    inl += r.inliers.inliers * static_cast<double>(r.points);
    outl += r.inliers.outliers * static_cast<double>(r.reconstructed_points);
    mse_ab += r.distances.mse_ab * static_cast<double>(r.points);
    mse_ba += r.distances.mse_ba * static_cast<double>(r.reconstructed_points);
    rec_points += r.reconstructed_points;
    all.points.insert(all.points.end(), clouds[i]->points.begin(), clouds[i]->points.end());
    split(*models[i], ids, poses);
  }
  t.rates = eval::compression_rates(all, word_points(alphabet), ids, poses);
  t.inliers.inliers = t.points ? inl / static_cast<double>(t.points) : 0.0;
  t.inliers.outliers = rec_points ? outl / static_cast<double>(rec_points) : 0.0;
  t.distances.mse_ab = t.points ? mse_ab / static_cast<double>(t.points) : 0.0;
  t.distances.mse_ba = rec_points ? mse_ba / static_cast<double>(rec_points) : 0.0;
  const double mse = std::max(t.distances.mse_ab, t.distances.mse_ba);
  t.distances.rmse = std::sqrt(mse);
  t.distances.d1_psnr_db = mse > 0 ? 10.0 * std::log10(3.0 * 59.70 * 59.70 / mse) : INFINITY;
  t.distances.chamfer = NAN;
  t.distances.hausdorff = NAN;
  for (const auto& r : reports) t.distances.hausdorff = std::isnan(t.distances.hausdorff) ? r.distances.hausdorff : std::max(t.distances.hausdorff, r.distances.hausdorff);
  return t;
}

void print_report_header() {
  std::printf("%-28s %8s %8s %9s %7s %7s %8s %8s %9s %9s %9s\n", "scan", "points", "features", "instances",
              "rate", "gzip", "inliers", "outliers", "D1 PSNR", "chamfer", "hausdorff");
}

void print_report_row(const ScanReport& r) {
  std::string name = r.file;
  if (name.size() > 28) name = "..." + name.substr(name.size() - 25);
  std::printf("%-28s %8zu %8zu %9zu %6.1f%% %6.1f%% %7.1f%% %7.1f%% %6.2f dB %7.4f m %7.3f m\n", name.c_str(), r.points,
              r.features, r.instances, 100.0 * r.rates.rate, 100.0 * r.rates.gzip_rate, 100.0 * r.inliers.inliers,
              100.0 * r.inliers.outliers, r.distances.d1_psnr_db, r.distances.chamfer, r.distances.hausdorff);
}

void report_json(Json& j, const ScanReport& r) {
  j.value("file", r.file).value("points", r.points).value("features", r.features).value("instances", r.instances);
  j.value("reconstructed_points", r.reconstructed_points);
  j.value("model_bytes", r.rates.model_bytes).value("raw_bytes", r.rates.raw_bytes);
  j.value("compression_rate", r.rates.rate).value("gzip_rate", r.rates.gzip_rate);
  j.value("inliers", r.inliers.inliers).value("outliers", r.inliers.outliers);
  j.value("d1_psnr_db", r.distances.d1_psnr_db).value("rmse_m", r.distances.rmse);
  j.value("chamfer_m", r.distances.chamfer).value("hausdorff_m", r.distances.hausdorff);
}

}  // namespace lex3d::cli
