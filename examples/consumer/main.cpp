// Compresses a synthetic scan (a floor inside a circular wall), or the scan file given as
// its argument (any format lex3d reads: a ROS bag's first cloud too), with a 2 cm bound and
// decompresses it; prints the library's version, the size and the bits per point.
// Exit code 0 when the headers match the library and both steps succeed, 2 when the file
// cannot be read.

#include <lex3d/io/io.hpp>
#include <lex3d/lex3d.hpp>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <utility>

int main(int argc, char** argv) {
  if (std::strcmp(lex3d::version(), LEX3D_VERSION_STRING) != 0) {
    std::fprintf(stderr, "headers %s, library %s\n", LEX3D_VERSION_STRING, lex3d::version());
    return 1;
  }
  lex3d::Cloud cloud;
  if (argc > 1) {
    auto read = lex3d::io::read_cloud(argv[1]);
    if (!read.ok()) {
      std::fprintf(stderr, "%s\n", read.status().to_string().c_str());
      return 2;
    }
    cloud = std::move(read.value().cloud);
  }
  // else 64 beams x 1024 columns of a sensor 1.7 m above the floor, inside a 20 m circular wall.
  for (int row = 0; argc <= 1 && row < 64; ++row) {
    const double elevation = (-24.0 + 26.0 * row / 63.0) * M_PI / 180.0;
    for (int col = 0; col < 1024; ++col) {
      const double azimuth = 2.0 * M_PI * col / 1024.0;
      const double to_floor = elevation < 0 ? 1.7 / std::sin(-elevation) : 1e9;
      const double to_wall = 20.0 / std::cos(elevation);
      const double r = std::min(to_floor, to_wall);
      cloud.points.emplace_back(static_cast<float>(r * std::cos(elevation) * std::cos(azimuth)),
                                static_cast<float>(r * std::cos(elevation) * std::sin(azimuth)),
                                static_cast<float>(r * std::sin(elevation)));
    }
  }
  lex3d::CompressOptions options;
  options.max_error = 0.02;
  auto file = lex3d::compress(cloud, options);
  if (!file.ok()) {
    std::fprintf(stderr, "compress: %s\n", file.status().to_string().c_str());
    return 2;
  }
  auto back = lex3d::decompress(file.value().bytes);
  if (!back.ok()) {
    std::fprintf(stderr, "decompress: %s\n", back.status().to_string().c_str());
    return 2;
  }
  std::printf("lex3d %s: %zu points -> %zu bytes (%.2f bits a point) -> %zu points\n", lex3d::version(),
              cloud.size(), file.value().bytes.size(), file.value().bits_per_point(), back.value().cloud.size());
  return back.value().cloud.empty() ? 1 : 0;
}
