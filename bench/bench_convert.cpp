// Converts a point cloud to another format, keeping only x y z, so that every codec of
// bench/rd.sh sees the same points:
//   lex3d_convert INPUT OUTPUT [--format F]
// INPUT is read with lex3d::io::read_cloud (format detected, or --format kitti|binxyz|
// pcd|ply|xyz|uos); non-finite points and no-return readings are dropped as the reader
// drops them. OUTPUT's format follows its extension (.ply binary, .pcd, .bin KITTI,
// .xyz). Prints one JSON line: {"points": N, "format": "..."}.
// Exit codes: 0 ok, 1 usage, 2 bad data, 3 I/O.

#include <cstdio>
#include <string>
#include <utility>

#include "lex3d/io/io.hpp"

using namespace lex3d;

namespace {

int usage() {
  std::fprintf(stderr, "usage: lex3d_convert INPUT OUTPUT [--format F]\n");
  return 1;
}

}  // namespace

int main(int argc, char** argv) {
  std::string paths[2];
  int n_paths = 0;
  io::ReadOptions read_options;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--format") {
      if (i + 1 >= argc) return usage();
      const auto f = io::parse_format(argv[++i]);
      if (!f) return usage();
      read_options.format = *f;
    } else if (!arg.empty() && arg[0] == '-') {
      return usage();
    } else {
      if (n_paths == 2) return usage();
      paths[n_paths++] = arg;
    }
  }
  if (n_paths != 2) return usage();

  auto r = io::read_cloud(paths[0], read_options);
  if (!r.ok()) {
    std::fprintf(stderr, "lex3d_convert: %s\n", r.status().to_string().c_str());
    return exit_code_for(r.status().code());
  }
  io::ReadResult result = std::move(r).value();
  Cloud xyz;
  xyz.points = std::move(result.cloud.points);
  io::WriteOptions write_options;
  write_options.write_intensity = false;
  const Status s = io::write_cloud(paths[1], xyz, write_options);
  if (!s.ok()) {
    std::fprintf(stderr, "lex3d_convert: %s\n", s.to_string().c_str());
    return exit_code_for(s.code());
  }
  std::printf("{\"points\": %zu, \"format\": \"%s\"}\n", xyz.size(),
              std::string(io::format_name(result.format)).c_str());
  return 0;
}
