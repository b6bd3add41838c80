// Geometry metrics between an original cloud and a decoded one, printed as the
// independent checker /work/shared/tools/pcmetrics.py prints them:
//   lex3d_eval_clouds ORIGINAL DECODED [--peak P] [--tau T] [--threads N] [--time]
// One JSON line with the keys of pcmetrics.py (n_original, n_decoded, d1_mse,
// d1_psnr_db, chamfer_m, hausdorff_m, coverage, outliers, tau_m, peak_m), so the two
// outputs can be compared field by field. Clouds are read with lex3d::io::read_cloud
// (format detected from extension and content). After those keys it also prints
// rmse_m (sqrt of d1_mse), mse_ab / mse_ba (each direction), and coverage_2cm /
// coverage_5cm / outliers_2cm / outliers_5cm (fixed tolerances, for bench/rd.sh), all
// from the same pass. --time prints the compare_clouds wall time on stderr.
// Exit codes: 0 ok, 1 usage, 2 bad data, 3 I/O.

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <string>
#include <utility>

#include "lex3d/core/timer.hpp"
#include "lex3d/eval/metrics.hpp"
#include "lex3d/io/io.hpp"

using namespace lex3d;

namespace {

int usage() {
  std::fprintf(stderr,
               "usage: lex3d_eval_clouds ORIGINAL DECODED [--peak P] [--tau T] [--threads N] [--time]\n");
  return 1;
}

/// A number as Python's json.dumps writes it: shortest round-trip form, Infinity/NaN.
std::string json_number(double v) {
  if (std::isnan(v)) return "NaN";
  if (std::isinf(v)) return v > 0 ? "Infinity" : "-Infinity";
  char buf[40];
  for (int precision = 1; precision <= 17; ++precision) {
    std::snprintf(buf, sizeof buf, "%.*g", precision, v);
    if (std::strtod(buf, nullptr) == v) break;
  }
  std::string s(buf);
  // Python prints floats with a '.' or an exponent ("1.0", "1e-05").
  if (s.find_first_of(".eEn") == std::string::npos) s += ".0";
  return s;
}

bool parse_double(const char* text, double& out) {
  char* end = nullptr;
  out = std::strtod(text, &end);
  return end != text && *end == '\0';
}

}  // namespace

int main(int argc, char** argv) {
  std::string paths[2];
  int n_paths = 0;
  double peak = 59.70, tau = 0.05, threads = 2;
  bool show_time = false;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--peak" || arg == "--tau" || arg == "--threads") {
      if (i + 1 >= argc) return usage();
      double& dst = arg == "--peak" ? peak : arg == "--tau" ? tau : threads;
      if (!parse_double(argv[++i], dst)) return usage();
    } else if (arg == "--time") {
      show_time = true;
    } else if (!arg.empty() && arg[0] == '-') {
      return usage();
    } else {
      if (n_paths == 2) return usage();
      paths[n_paths++] = arg;
    }
  }
  if (n_paths != 2 || threads != std::floor(threads) || threads < 1 || threads > 64) return usage();

  Cloud clouds[2];
  for (int k = 0; k < 2; ++k) {
    auto r = io::read_cloud(paths[k]);
    if (!r.ok()) {
      std::fprintf(stderr, "lex3d_eval_clouds: %s\n", r.status().to_string().c_str());
      return exit_code_for(r.status().code());
    }
    clouds[k] = std::move(r).value().cloud;
  }

  eval::DistanceParams params;
  params.peak = peak;
  params.taus = {tau, 0.02, 0.05};
  params.threads = static_cast<int>(threads);
  eval::DistanceResult d;
  try {
    const Stopwatch sw;
    d = eval::compare_clouds(clouds[0], clouds[1], params);
    if (show_time) std::fprintf(stderr, "compare_clouds: %.1f ms\n", sw.elapsed_ms());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "lex3d_eval_clouds: %s\n", e.what());
    return 1;
  }

  std::printf(
      "{\"n_original\": %zu, \"n_decoded\": %zu, \"d1_mse\": %s, \"d1_psnr_db\": %s, \"chamfer_m\": %s, "
      "\"hausdorff_m\": %s, \"coverage\": %s, \"outliers\": %s, \"tau_m\": %s, \"peak_m\": %s, \"rmse_m\": %s, "
      "\"mse_ab\": %s, \"mse_ba\": %s, \"coverage_2cm\": %s, \"coverage_5cm\": %s, \"outliers_2cm\": %s, "
      "\"outliers_5cm\": %s}\n",
      d.points_a, d.points_b, json_number(std::max(d.mse_ab, d.mse_ba)).c_str(), json_number(d.d1_psnr_db).c_str(),
      json_number(d.chamfer).c_str(), json_number(d.hausdorff).c_str(), json_number(d.coverage[0]).c_str(),
      json_number(d.outliers[0]).c_str(), json_number(tau).c_str(), json_number(peak).c_str(),
      json_number(d.rmse).c_str(), json_number(d.mse_ab).c_str(), json_number(d.mse_ba).c_str(),
      json_number(d.coverage[1]).c_str(), json_number(d.coverage[2]).c_str(), json_number(d.outliers[1]).c_str(),
      json_number(d.outliers[2]).c_str());
  return 0;
}
