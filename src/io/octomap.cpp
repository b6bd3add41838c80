#include <sstream>
#include <string>

#include <octomap/OcTree.h>

#include "lex3d/io/io.hpp"

namespace lex3d::io {

StatusOr<OctomapStats> write_octomap(const std::string& path, const Cloud& cloud,
                                     const std::optional<Eigen::Vector3d>& sensor_origin, double resolution) {
  if (!(resolution > 0.0 && resolution <= 100.0))
    return Status(ErrorCode::kInvalidArgument, "octomap resolution must be in (0, 100] m, got " + std::to_string(resolution));
  octomap::OcTree tree(resolution);
  if (sensor_origin) {
    octomap::Pointcloud pc;
    pc.reserve(cloud.size());
    for (const auto& p : cloud.points) pc.push_back(p.x(), p.y(), p.z());
    const octomap::point3d origin(static_cast<float>(sensor_origin->x()), static_cast<float>(sensor_origin->y()),
                                  static_cast<float>(sensor_origin->z()));
    // Discretised insertion casts one ray a voxel end point instead of one a point: the
    // same map for dense scans, several times faster.
    tree.insertPointCloud(pc, origin, -1.0, false, true);
  } else {
    for (const auto& p : cloud.points) tree.updateNode(octomap::point3d(p.x(), p.y(), p.z()), true, true);
  }
  tree.updateInnerOccupancy();
  tree.prune();
  OctomapStats stats;
  for (auto it = tree.begin_leafs(), end = tree.end_leafs(); it != end; ++it)
    (tree.isNodeOccupied(*it) ? stats.occupied_leaves : stats.free_leaves)++;
  // The .bt layout of OcTree::writeBinary, written here because the packaged library's
  // writeBinary prints progress on stderr: maximum-likelihood occupancy, then the
  // header lines and the tree's binary data.
  tree.toMaxLikelihood();
  tree.prune();
  std::ostringstream out(std::ios::binary);
  out << "# Octomap OcTree binary file\nid " << tree.getTreeType() << "\nsize " << tree.size() << "\nres "
      << tree.getResolution() << "\ndata\n";
  tree.writeBinaryData(out);
  if (!out.good()) return io_error(path + ": octomap serialisation failed");
  const std::string s = out.str();
  const std::vector<std::uint8_t> bytes(s.begin(), s.end());
  Status st = write_file_atomic(path, bytes);
  if (!st.ok()) return st;
  stats.file_bytes = bytes.size();
  return stats;
}

}  // namespace lex3d::io
