// Compresses a pcl::PointCloud<pcl::PointXYZI> with a 1 cm bound and gets a
// pcl::PointCloud<pcl::PointXYZ> back; prints what the conversion dropped and the sizes.

#include <lex3d/core/pcl_conversions.hpp>
#include <lex3d/lex3d.hpp>

#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include <cmath>
#include <cstdio>
#include <limits>

int main() {
  pcl::PointCloud<pcl::PointXYZI> scan;  // a spiral staircase of points, one no-return
  for (int i = 0; i < 20000; ++i) {
    const float a = 0.01f * static_cast<float>(i);
    pcl::PointXYZI p;
    p.x = 5.f * std::cos(a);
    p.y = 5.f * std::sin(a);
    p.z = 0.002f * static_cast<float>(i);
    p.intensity = static_cast<float>(i % 256);
    scan.push_back(p);
  }
  scan[7].x = std::numeric_limits<float>::quiet_NaN();

  lex3d::PclConversionStats stats;
  const lex3d::Cloud cloud = lex3d::from_pcl(scan, &stats);
  lex3d::CompressOptions options;
  options.max_error = 0.01;
  auto file = lex3d::compress(cloud, options);
  if (!file.ok()) return std::fprintf(stderr, "compress: %s\n", file.status().to_string().c_str()), 2;
  auto back = lex3d::decompress(file.value().bytes);
  if (!back.ok()) return std::fprintf(stderr, "decompress: %s\n", back.status().to_string().c_str()), 2;
  const pcl::PointCloud<pcl::PointXYZ> decoded = lex3d::to_pcl<pcl::PointXYZ>(back.value().cloud);
  std::printf("%zu PCL points (%zu non-finite dropped) -> %zu bytes -> %zu PCL points", scan.size(), stats.non_finite,
              file.value().bytes.size(), decoded.size());
  for (const auto& a : file.value().dropped_attributes) std::printf("; %s not stored", a.c_str());
  std::printf("\n");
  return decoded.empty() ? 1 : 0;
}
