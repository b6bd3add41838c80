// OctoMap occupancy trees as a baseline codec for bench/rd.sh, in two steps so that each
// has its own process (and peak memory):
//   lex3d_bench_octomap encode INPUT TREE.bt --resolution R
//   lex3d_bench_octomap decode TREE.bt OUTPUT
// encode reads INPUT with lex3d::io::read_cloud and marks the leaf voxel (edge R metres)
// of every point occupied (one hit each, OcTree::updateNode; no ray casting, so no free
// space is stored), then writes the tree as OctoMap's binary .bt (maximum-likelihood
// occupancy, pruned: occupied voxels only). decode reads the .bt file and writes the
// centre of every occupied voxel at the finest resolution (pruned nodes are expanded into
// their 8^k leaf voxels) as a point cloud (format from OUTPUT's extension, e.g. .ply).
// Each prints one JSON line: encode {"points", "dropped", "bytes", "encode_ms", "voxels"},
// decode {"points", "decode_ms"}. dropped counts points outside the tree's key range
// (±R·2^15 m). The times cover building + serialising to memory / parsing + extracting
// the centres (no file I/O). OctoMap itself may print to stderr.
// Exit codes: 0 ok, 1 usage, 2 bad data, 3 I/O.

#include <cstdio>
#include <cstdlib>
#include <exception>
#include <fstream>
#include <sstream>
#include <string>
#include <utility>

#include <octomap/OcTree.h>

#include "lex3d/core/timer.hpp"
#include "bench_driver.hpp"
#include "lex3d/io/io.hpp"

using namespace lex3d;

namespace {

constexpr char kTool[] = "lex3d_bench_octomap";

int usage() {
  std::fprintf(stderr,
               "usage: lex3d_bench_octomap encode INPUT TREE.bt --resolution R\n"
               "       lex3d_bench_octomap decode TREE.bt OUTPUT\n");
  return 1;
}

int encode(const std::string& input, const std::string& tree_path, double resolution) {
  int rc = 0;
  const auto input_cloud = bench::read_input(kTool, input, rc);
  if (!input_cloud) return rc;
  const Cloud& cloud = *input_cloud;
  const Stopwatch sw;
  octomap::OcTree tree(resolution);
  std::size_t dropped = 0;
  for (const auto& p : cloud.points) {
    octomap::OcTreeKey key;
    if (!tree.coordToKeyChecked(octomap::point3d(p.x(), p.y(), p.z()), key)) {
      ++dropped;
      continue;
    }
    tree.updateNode(key, true, true);
  }
  tree.updateInnerOccupancy();
  std::stringstream out;
  if (!tree.writeBinary(out)) {
    std::fprintf(stderr, "lex3d_bench_octomap: cannot serialise the tree\n");
    return 2;
  }
  const double ms = sw.elapsed_ms();
  const std::string bytes = out.str();
  if (const int w = bench::write_stream(kTool, tree_path, bytes); w != 0) return w;
  std::printf("{\"points\": %zu, \"dropped\": %zu, \"bytes\": %zu, \"encode_ms\": %.3f, \"leaf_nodes\": %zu}\n",
              cloud.size(), dropped, bytes.size(), ms, tree.getNumLeafNodes());
  return 0;
}

int decode(const std::string& tree_path, const std::string& output) {
  std::ifstream file(tree_path, std::ios::binary);
  if (!file) {
    std::fprintf(stderr, "lex3d_bench_octomap: %s: cannot open\n", tree_path.c_str());
    return 3;
  }
  std::stringstream in;
  in << file.rdbuf();
  const Stopwatch sw;
  octomap::OcTree tree(0.1);
  if (!tree.readBinary(in)) {
    std::fprintf(stderr, "lex3d_bench_octomap: %s: not an OctoMap binary tree\n", tree_path.c_str());
    return 2;
  }
  const unsigned max_depth = tree.getTreeDepth();
  Cloud cloud;
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it) {
    if (!tree.isNodeOccupied(*it)) continue;
    const unsigned depth = it.getDepth();
    if (depth == max_depth) {
      const octomap::point3d c = it.getCoordinate();
      cloud.points.emplace_back(c.x(), c.y(), c.z());
      continue;
    }
    // A pruned node: all of its finest voxels are occupied.
    const octomap::OcTreeKey base = it.getIndexKey();
    const unsigned side = 1U << (max_depth - depth);
    for (unsigned i = 0; i < side; ++i) {
      for (unsigned j = 0; j < side; ++j) {
        for (unsigned k = 0; k < side; ++k) {
          const octomap::OcTreeKey key(static_cast<octomap::key_type>(base[0] + i),
                                       static_cast<octomap::key_type>(base[1] + j),
                                       static_cast<octomap::key_type>(base[2] + k));
          const octomap::point3d c = tree.keyToCoord(key);
          cloud.points.emplace_back(c.x(), c.y(), c.z());
        }
      }
    }
  }
  return bench::write_decoded(kTool, output, cloud, sw.elapsed_ms());
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 4) return usage();
  const std::string mode = argv[1];
  try {
    if (mode == "encode") {
      if (argc != 6 || std::string(argv[4]) != "--resolution") return usage();
      char* end = nullptr;
      const double resolution = std::strtod(argv[5], &end);
      if (*end != '\0' || !(resolution > 0.0)) return usage();
      return encode(argv[2], argv[3], resolution);
    }
    if (mode == "decode") {
      if (argc != 4) return usage();
      return decode(argv[2], argv[3]);
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "lex3d_bench_octomap: %s\n", e.what());
    return 2;
  }
  return usage();
}
