// Feature extraction speed and counts per dataset, one core by default:
//   lex3d_bench_features [--threads N] [--reps R] DIR_OR_FILE...
// For each argument (a directory of scans, or one scan) prints the median
// per-scan time of each stage, the feature counts and the peak memory.

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "lex3d/core/timer.hpp"
#include "lex3d/features/features.hpp"
#include "lex3d/io/io.hpp"

namespace fs = std::filesystem;
using namespace lex3d;

namespace {

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

std::vector<std::string> scans_of(const std::string& arg) {
  std::vector<std::string> out;
  if (fs::is_directory(arg)) {
    for (const auto& e : fs::directory_iterator(arg)) {
      const std::string ext = e.path().extension().string();
      if (ext == ".bin" || ext == ".pcd" || ext == ".ply" || ext == ".3d") out.push_back(e.path().string());
    }
    std::sort(out.begin(), out.end());
  } else {
    out.push_back(arg);
  }
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  int threads = 1;
  int reps = 3;
  std::vector<std::string> inputs;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--threads") && i + 1 < argc) threads = std::atoi(argv[++i]);
    else if (!std::strcmp(argv[i], "--reps") && i + 1 < argc) reps = std::atoi(argv[++i]);
    else inputs.emplace_back(argv[i]);
  }
  if (inputs.empty() || threads < 1 || reps < 1) {
    std::fprintf(stderr, "usage: lex3d_bench_features [--threads N] [--reps R] DIR_OR_FILE...\n");
    return 1;
  }
  std::printf("# lex3d feature extraction, %d thread(s), median of %d runs per scan, then median over scans\n",
              threads, reps);
  std::printf("%-28s %5s %8s | %7s %7s %7s %7s %8s | %8s %7s | %5s %5s %5s %6s\n", "dataset", "scans", "points",
              "range", "interst", "cover", "descr", "total", "ri+ip+d", "ip-desc", "ip", "ipmin", "ipmax", "cover");
  std::printf("%-28s %5s %8s | %7s %7s %7s %7s %8s | %8s %7s | %5s %5s %5s %6s\n", "", "", "", "ms", "ms", "ms", "ms",
              "ms", "ms", "ms", "", "", "", "");
  for (const auto& arg : inputs) {
    const auto files = scans_of(arg);
    std::vector<double> pts, t_range, t_int, t_cov, t_desc, t_total, t_ip_only, t_ip_desc, n_ip, n_cov;
    for (const auto& f : files) {
      auto r = io::read_cloud(f);
      if (!r.ok()) {
        std::fprintf(stderr, "skipping %s: %s\n", f.c_str(), r.status().to_string().c_str());
        continue;
      }
      const Cloud& cloud = r.value().cloud;
      FeatureParams p;
      p.threads = threads;
      std::vector<double> a, b, c, d, e, g;
      FeatureResult res;
      for (int k = 0; k < reps; ++k) {
        res = extract_features(cloud, p);
        a.push_back(res.timings.range_image_ms);
        b.push_back(res.timings.interest_ms);
        c.push_back(res.timings.coverage_ms);
        d.push_back(res.timings.descriptor_ms);
        e.push_back(res.timings.total_ms());
        // Descriptors of the interest points alone (what place recognition needs).
        std::vector<Keypoint> ip;
        for (std::size_t i = 0; i < res.features.interest_count; ++i) ip.push_back(res.features.features[i].keypoint);
        Stopwatch sw;
        const Features only = describe(res.image, ip, p.descriptor, threads);
        g.push_back(sw.elapsed_ms());
      }
      pts.push_back(static_cast<double>(cloud.size()));
      t_range.push_back(median(a));
      t_int.push_back(median(b));
      t_cov.push_back(median(c));
      t_desc.push_back(median(d));
      t_total.push_back(median(e));
      t_ip_desc.push_back(median(g));
      t_ip_only.push_back(median(a) + median(b) + median(g));
      n_ip.push_back(static_cast<double>(res.features.interest_count));
      n_cov.push_back(static_cast<double>(res.features.coverage_count));
    }
    if (pts.empty()) continue;
    std::string name = fs::path(arg).filename().string();
    if (name.empty()) name = fs::path(arg).parent_path().filename().string();
    std::printf("%-28s %5zu %8.0f | %7.1f %7.1f %7.1f %7.1f %8.1f | %8.1f %7.2f | %5.0f %5.0f %5.0f %6.0f\n",
                name.c_str(), pts.size(), median(pts), median(t_range), median(t_int), median(t_cov), median(t_desc),
                median(t_total), median(t_ip_only), median(t_ip_desc), median(n_ip),
                *std::min_element(n_ip.begin(), n_ip.end()), *std::max_element(n_ip.begin(), n_ip.end()),
                median(n_cov));
  }
  std::printf("# columns: range image, interest operator, coverage points, descriptors of all features, total;\n"
              "# ri+ip+d = range image + interest points + descriptors of the interest points only;\n"
              "# ip = interest points per scan (median, min, max); cover = coverage points per scan (median)\n");
  std::printf("peak memory %.1f MiB\n", static_cast<double>(peak_rss_bytes()) / (1024.0 * 1024.0));
  return 0;
}
