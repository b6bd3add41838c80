// Test helper: writes a scan moved into another frame, as the scans of a registered map
// are stored (a PLY carries no sensor pose).
// Usage: lex3d_test_transform IN OUT.ply POSES  (the first pose of POSES, KITTI layout)
#include <cstdio>

#include "lex3d/io/io.hpp"

int main(int argc, char** argv) {
  if (argc != 4) {
    std::fprintf(stderr, "usage: %s IN OUT.ply POSES\n", argv[0]);
    return 1;
  }
  auto in = lex3d::io::read_cloud(argv[1]);
  auto poses = lex3d::io::read_pose_list(argv[3]);
  if (!in.ok() || !poses.ok() || poses.value().empty()) {
    std::fprintf(stderr, "%s: cannot read the input or the poses\n", argv[0]);
    return 2;
  }
  lex3d::Cloud out;
  const lex3d::Pose T = poses.value().front();
  for (const auto& p : in.value().cloud.points) out.points.push_back((T * p.cast<double>()).cast<float>());
  lex3d::io::WriteOptions options;
  options.write_intensity = false;
  const auto s = lex3d::io::write_cloud(argv[2], out, options);
  if (!s.ok()) {
    std::fprintf(stderr, "%s: %s\n", argv[0], s.to_string().c_str());
    return 3;
  }
  return 0;
}
