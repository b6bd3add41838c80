// Repeatability of the place descriptors (range-image patch, VD-LSD) under re-sampling, and
// their cost, on the same spots:
//   lex3d_bench_descriptors --turn SCAN [FRACTION...]     the scan against itself turned about
//                                                         the sensor's axis by FRACTION of an
//                                                         azimuth pixel (default 0.25 0.5)
//   lex3d_bench_descriptors --pair SCAN_A SCAN_B POSES IA IB   two scans of a sequence with
//                                                         world <- sensor poses (lines IA, IB)
// The spots are scan A's strongest interest points (as many as a place database keeps, 160).
// Each spot is described in A with its own frame and in B at the same 3D point (moved by the
// known transform) with the frame B's points give it. A spot *matches* when its nearest
// descriptor among all of B's spots is its own (and *passes the ratio test* when that is also
// nearer than 0.8 times the second nearest, place matching's test). Prints, per descriptor, the
// spots described in both, the matching rate, the ratio-test rate, the median distance to the
// same spot and to the nearest other spot (both as a share of the descriptor's largest
// distance), and the CPU time to describe the spots of one scan (median over A and B; one thread).

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <string>
#include <vector>

#include "lex3d/features/features.hpp"
#include "lex3d/features/vdlsd.hpp"
#include "lex3d/io/io.hpp"

using namespace lex3d;

namespace {

constexpr std::size_t kSpots = 160;  // PlaceStorageParams::max_features
VdlsdParams g_vdlsd;                 // --max-support, --local-points override its defaults

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

Cloud load(const std::string& path) {
  auto r = io::read_cloud(path);
  if (!r.ok()) {
    std::fprintf(stderr, "%s\n", r.status().to_string().c_str());
    std::exit(2);
  }
  return std::move(r.value().cloud);
}

struct Described {
  std::vector<float> patch, vdlsd;
  int patch_dim = 0, vdlsd_dim = 0;
  double patch_ms = 0.0, vdlsd_ms = 0.0;
};

FeatureParams params_for(const Cloud& c) {
  FeatureParams p;
  p.threads = 1;
  p.coverage.distance = 0.0;
  if (c.has_world_pose) p.descriptor.up = c.T_world_cloud.linear().transpose() * Eigen::Vector3d::UnitZ();
  return p;
}

VdlsdParams vdlsd_params(const RangeImage& img) {
  VdlsdParams v = g_vdlsd;
  v.beam_spacing_rad = std::min(0.2, std::max(img.azimuth_resolution_rad, img.elevation_resolution_rad));
  return v;
}

// Describes `kps` of `img` (of cloud `c`) both ways; `ok` marks those with a frame fitted on points.
double cpu_ms() { return 1000.0 * static_cast<double>(std::clock()) / CLOCKS_PER_SEC; }

Described describe_both(const Cloud& c, const RangeImage& img, const std::vector<Keypoint>& kps, const FeatureParams& p) {
  Described d;
  double t0 = cpu_ms();
  const Features f = describe(img, kps, p.descriptor, 1);
  d.patch_ms = cpu_ms() - t0;
  d.patch = f.descriptors;
  d.patch_dim = f.descriptor_dim;
  std::vector<Pose> frames;
  for (const auto& x : f.features) frames.push_back(x.T_cloud_feature);
  t0 = cpu_ms();
  const VdlsdResult v = describe_vdlsd(c, frames, vdlsd_params(img), 1);
  d.vdlsd_ms = cpu_ms() - t0;
  d.vdlsd = v.descriptors;
  d.vdlsd_dim = v.descriptor_dim;
  return d;
}

void report(const char* name, const std::vector<float>& a, const std::vector<float>& b, int dim, std::size_t n,
            double max_distance, double ms) {
  std::size_t match = 0, ratio = 0;
  std::vector<double> same, other;
  for (std::size_t i = 0; i < n; ++i) {
    double best = HUGE_VAL, second = HUGE_VAL, own = 0.0, nearest_other = HUGE_VAL;
    std::size_t arg = n;
    for (std::size_t j = 0; j < n; ++j) {
      const double d = std::sqrt(static_cast<double>(
          descriptor_distance_sq(a.data() + i * static_cast<std::size_t>(dim), b.data() + j * static_cast<std::size_t>(dim), dim)));
      if (j == i) own = d;
      else nearest_other = std::min(nearest_other, d);
      if (d < best) {
        second = best;
        best = d;
        arg = j;
      } else if (d < second) {
        second = d;
      }
    }
    match += arg == i ? 1 : 0;
    ratio += (arg == i && best < 0.8 * second) ? 1 : 0;
    same.push_back(own / max_distance);
    other.push_back(nearest_other / max_distance);
  }
  std::printf("  %-6s %4zu spots  matching %.3f  ratio test %.3f  same spot %.3f  nearest other %.3f  %6.1f ms CPU a scan\n",
              name, n, n ? static_cast<double>(match) / static_cast<double>(n) : 0.0,
              n ? static_cast<double>(ratio) / static_cast<double>(n) : 0.0, median(same), median(other), ms);
}

// A's strongest spots, described in A and, at the same 3D points moved by T_B_A (cloud frames), in B.
void compare(const Cloud& a, const Cloud& b, const Pose& T_B_A) {
  const FeatureParams pa = params_for(a), pb = params_for(b);
  const FeatureResult fa = extract_features(a, pa);
  const RangeImage ib = make_range_image(b, pb.range);
  std::vector<Keypoint> ka, kb;
  const std::size_t n = std::min<std::size_t>(kSpots, fa.features.interest_count);
  const Eigen::Isometry3f T_sensor_cloud_b = ib.T_cloud_sensor.inverse().cast<float>();
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector3f p_cloud_a = fa.features.features[i].T_cloud_feature.translation().cast<float>();
    const Eigen::Vector3f p_sensor_b = T_sensor_cloud_b * (T_B_A.cast<float>() * p_cloud_a);
    const auto k = keypoint_at(ib, p_sensor_b);
    if (!k) continue;
    ka.push_back(fa.features.features[i].keypoint);
    kb.push_back(*k);
  }
  const Described da = describe_both(a, fa.image, ka, pa);
  const Described db = describe_both(b, ib, kb, pb);
  std::printf("  %zu of A's %zu strongest interest points fall into B's image\n", ka.size(), n);
  // Largest distances: patch values in [-1, 1] (2 sqrt(dim)); VD-LSD: 2 sqrt(2) (disjoint histograms).
  report("patch", da.patch, db.patch, da.patch_dim, ka.size(), 2.0 * std::sqrt(static_cast<double>(da.patch_dim)),
         median({da.patch_ms, db.patch_ms}));
  report("vdlsd", da.vdlsd, db.vdlsd, da.vdlsd_dim, ka.size(), 2.0 * std::sqrt(2.0), median({da.vdlsd_ms, db.vdlsd_ms}));
}

int usage() {
  std::fprintf(stderr,
               "usage: lex3d_bench_descriptors --turn SCAN [FRACTION...]\n"
               "       lex3d_bench_descriptors --pair SCAN_A SCAN_B POSES IA IB\n");
  return 1;
}

}  // namespace

int main(int argc, char** argv) {
  // Leading options: --max-support N, --local-points N.
  while (argc > 2 && (!std::strcmp(argv[1], "--max-support") || !std::strcmp(argv[1], "--local-points"))) {
    (!std::strcmp(argv[1], "--max-support") ? g_vdlsd.max_support : g_vdlsd.local_points) = std::atoi(argv[2]);
    argv += 2;
    argc -= 2;
  }
  g_vdlsd.validate();
  if (argc < 3) return usage();
  if (!std::strcmp(argv[1], "--turn")) {
    const Cloud a = load(argv[2]);
    std::vector<double> fractions;
    for (int i = 3; i < argc; ++i) fractions.push_back(std::atof(argv[i]));
    if (fractions.empty()) fractions = {0.25, 0.5};
    const RangeImage img = make_range_image(a, params_for(a).range);
    for (const double f : fractions) {
      const double angle = f * img.azimuth_resolution_rad;
      Pose T = Pose::Identity();
      T.linear() = Eigen::AngleAxisd(angle, Eigen::Vector3d::UnitZ()).toRotationMatrix();
      Cloud b = a;
      for (auto& p : b.points) p = (T.cast<float>() * p).eval();
      std::printf("%s turned by %.2f of an azimuth pixel (%.4f deg):\n", argv[2], f, angle * 180.0 / M_PI);
      compare(a, b, T);
    }
    return 0;
  }
  if (!std::strcmp(argv[1], "--pair") && argc == 7) {
    Cloud a = load(argv[2]), b = load(argv[3]);
    auto poses = io::read_pose_list(argv[4]);
    if (!poses.ok()) {
      std::fprintf(stderr, "%s\n", poses.status().to_string().c_str());
      return 2;
    }
    const long ia = std::atol(argv[5]), ib = std::atol(argv[6]);
    const auto& P = poses.value();
    if (ia < 0 || ib < 0 || static_cast<std::size_t>(std::max(ia, ib)) >= P.size()) {
      std::fprintf(stderr, "%s: no pose line %ld or %ld\n", argv[4], ia, ib);
      return 2;
    }
    a.T_world_cloud = P[static_cast<std::size_t>(ia)];
    b.T_world_cloud = P[static_cast<std::size_t>(ib)];
    a.has_world_pose = b.has_world_pose = true;
    const Pose T_B_A = b.T_world_cloud.inverse() * a.T_world_cloud;
    std::printf("%s -> %s (poses %ld, %ld; %.2f m, %.1f deg apart):\n", argv[2], argv[3], ia, ib,
                T_B_A.translation().norm(), Eigen::AngleAxisd(T_B_A.linear()).angle() * 180.0 / M_PI);
    compare(a, b, T_B_A);
    return 0;
  }
  return usage();
}
