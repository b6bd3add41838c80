#pragma once
// What the benchmark drivers of other codecs (bench_octomap.cpp, bench_pcl_octree.cpp)
// share: reading the input cloud, writing the coded stream, writing the decoded cloud and
// its one-line JSON report, each error as one line on stderr with lex3d's exit codes.

#include <cstdio>
#include <fstream>
#include <optional>
#include <string>
#include <utility>

#include "lex3d/io/io.hpp"

namespace lex3d::bench {

/// The cloud at `path`, or nullopt after printing the error (`rc`: the exit code).
inline std::optional<Cloud> read_input(const char* tool, const std::string& path, int& rc) {
  auto r = io::read_cloud(path);
  if (!r.ok()) {
    std::fprintf(stderr, "%s: %s\n", tool, r.status().to_string().c_str());
    rc = exit_code_for(r.status().code());
    return std::nullopt;
  }
  return std::move(r).value().cloud;
}

/// Writes a coded stream; 0, or 3 after printing the error.
inline int write_stream(const char* tool, const std::string& path, const std::string& bytes) {
  std::ofstream file(path, std::ios::binary);
  file.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  file.close();
  if (!file) {
    std::fprintf(stderr, "%s: %s: cannot write\n", tool, path.c_str());
    return 3;
  }
  return 0;
}

/// Writes the decoded cloud and prints {"points", "decode_ms"}; the exit code.
inline int write_decoded(const char* tool, const std::string& output, const Cloud& cloud, double decode_ms) {
  const Status s = io::write_cloud(output, cloud);
  if (!s.ok()) {
    std::fprintf(stderr, "%s: %s\n", tool, s.to_string().c_str());
    return exit_code_for(s.code());
  }
  std::printf("{\"points\": %zu, \"decode_ms\": %.3f}\n", cloud.size(), decode_ms);
  return 0;
}

}  // namespace lex3d::bench
