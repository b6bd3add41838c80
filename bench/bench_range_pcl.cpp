// lex3d's range image against pcl::RangeImage at the same angular resolution:
//   lex3d_bench_range_pcl SCAN...
// Prints build time (median of 7), pixels with a return, and how faithful the
// pixels' 3D points are to the points that produced them.

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#include <pcl/kdtree/kdtree_flann.h>
#include <pcl/range_image/range_image_spherical.h>

#include "lex3d/core/timer.hpp"
#include "lex3d/io/io.hpp"
#include "lex3d/range/range_image.hpp"

using namespace lex3d;

namespace {
double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}
}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: lex3d_bench_range_pcl SCAN...\n");
    return 1;
  }
  std::printf("%-44s %8s | %9s %9s %10s | %9s %9s %10s\n", "scan", "points", "lex3d ms", "valid px", "error mm",
              "pcl ms", "valid px", "error mm");
  for (int a = 1; a < argc; ++a) {
    auto r = io::read_cloud(argv[a]);
    if (!r.ok()) {
      std::fprintf(stderr, "%s\n", r.status().to_string().c_str());
      continue;
    }
    const Cloud& c = r.value().cloud;
    const auto res = estimate_angular_resolution(c);
    if (!res) continue;
    RangeImageParams p;
    p.azimuth_resolution_rad = res->azimuth_rad;
    p.elevation_resolution_rad = res->elevation_rad;
    std::vector<double> t_own, t_pcl;
    RangeImage own;
    for (int k = 0; k < 7; ++k) {
      Stopwatch sw;
      own = make_range_image(c, p);
      t_own.push_back(sw.elapsed_ms());
    }
    // lex3d keeps the exact point of each pixel: its error is the distance to the source point.
    double own_err = 0.0;
    for (std::size_t k = 0; k < own.point.size(); ++k)
      if (own.state[k] == PixelState::kValid)
        own_err += static_cast<double>((own.point[k] - c.points[static_cast<std::size_t>(own.source[k])]).norm());
    own_err /= static_cast<double>(std::max<std::size_t>(1, own.valid_count));

    pcl::PointCloud<pcl::PointXYZ> pc;
    pc.reserve(c.size());
    for (const auto& q : c.points) pc.push_back(pcl::PointXYZ(q.x(), q.y(), q.z()));
    pcl::RangeImageSpherical ri;
    std::vector<double> pcl_err_v;
    for (int k = 0; k < 7; ++k) {
      Stopwatch sw;
      ri.createFromPointCloud(pc, static_cast<float>(res->azimuth_rad), static_cast<float>(res->elevation_rad),
                              pcl::deg2rad(360.0F), pcl::deg2rad(180.0F), Eigen::Affine3f::Identity(),
                              pcl::RangeImage::LASER_FRAME, 0.0F, 0.0F, 0);
      t_pcl.push_back(sw.elapsed_ms());
    }
    // pcl::RangeImage recomputes each pixel's point from the pixel centre and the
    // range; measure how far that lands from the nearest input point.
    pcl::KdTreeFLANN<pcl::PointXYZ> tree;
    tree.setInputCloud(pc.makeShared());
    std::size_t pcl_valid = 0;
    double pcl_err = 0.0;
    std::vector<int> idx(1);
    std::vector<float> d2(1);
    for (std::size_t k = 0; k < ri.size(); ++k) {
      const auto& q = ri.points[k];
      if (!std::isfinite(q.range)) continue;
      ++pcl_valid;
      if (tree.nearestKSearch(pcl::PointXYZ(q.x, q.y, q.z), 1, idx, d2) == 1) pcl_err += std::sqrt(static_cast<double>(d2[0]));
    }
    const std::size_t compared = pcl_valid;
    pcl_err /= static_cast<double>(std::max<std::size_t>(1, compared));
    std::printf("%-44s %8zu | %9.2f %9zu %10.2f | %9.2f %9zu %10.2f\n", argv[a], c.size(), median(t_own),
                own.valid_count, own_err * 1000.0, median(t_pcl), pcl_valid, pcl_err * 1000.0);
  }
  return 0;
}
