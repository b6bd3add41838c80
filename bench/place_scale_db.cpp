// Makes a large place database from a small one for bench/place_scale.sh: the base scans
// unmodified, then perturbed copies of them (a random rigid motion of the scan's frame and a
// few percent dropout of its word instances, features and coarse-image pixels) until N
// entries. Writes the database one entry at a time (PlaceFileWriter) and, per entry, its name,
// the world position of its sensor and its T_world_cloud (for judging matches).
// Usage: lex3d_place_scale_db BASE.lex3dp N SEED DROPOUT OUT.lex3dp OUT_sensors.txt

#include <cmath>
#include <cstdio>
#include <random>
#include <string>

#include "lex3d/io/io.hpp"
#include "lex3d/io/mapped_file.hpp"
#include "lex3d/place/place.hpp"

namespace {

using lex3d::Pose;

Pose random_motion(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Eigen::Quaterniond q(u(rng), u(rng), u(rng), u(rng));
  if (q.norm() < 1e-3) q = Eigen::Quaterniond::Identity();
  Pose M = Pose::Identity();
  M.linear() = q.normalized().toRotationMatrix();
  M.translation() = Eigen::Vector3d(20.0 * u(rng), 20.0 * u(rng), 2.0 * u(rng));
  return M;
}

lex3d::PlaceScan perturb(const lex3d::PlaceScan& in, std::mt19937_64& rng, double dropout, const std::string& name) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  lex3d::PlaceScan s;
  s.name = name;
  s.descriptor_dim = in.descriptor_dim;
  s.descriptor_bits = in.descriptor_bits;
  const Pose M = random_motion(rng);  // new cloud frame <- old cloud frame
  s.has_world_pose = in.has_world_pose;
  s.T_world_cloud = in.T_world_cloud * M.inverse();
  for (const auto& [w, c] : in.words) {
    std::uint32_t kept = 0;
    for (std::uint32_t k = 0; k < c; ++k) kept += u(rng) >= dropout ? 1 : 0;
    if (kept > 0) s.words.emplace_back(w, kept);
  }
  const Eigen::Quaternionf qm(M.linear().cast<float>());
  const auto dim = static_cast<std::size_t>(std::max(0, in.descriptor_dim));
  for (std::size_t i = 0; i < in.features.size(); ++i) {
    if (u(rng) < dropout) continue;
    lex3d::PlaceFeature f;
    f.position = (M * in.features[i].position.cast<double>()).cast<float>();
    f.rotation = (qm * in.features[i].rotation).normalized();
    s.features.push_back(f);
    s.descriptor_codes.insert(s.descriptor_codes.end(), in.descriptor_codes.begin() + static_cast<std::ptrdiff_t>(i * dim),
                              in.descriptor_codes.begin() + static_cast<std::ptrdiff_t>((i + 1) * dim));
  }
  s.coarse = in.coarse;
  s.coarse.T_cloud_sensor = M * in.coarse.T_cloud_sensor;
  for (std::size_t i = 0; i < s.coarse.state.size(); ++i)
    if (s.coarse.state[i] == lex3d::PixelState::kValid && u(rng) < dropout) {
      s.coarse.state[i] = lex3d::PixelState::kUnobserved;
      --s.coarse.valid_count;
    }
  return s;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 7) {
    std::fprintf(stderr, "usage: %s BASE.lex3dp N SEED DROPOUT OUT.lex3dp OUT_sensors.txt\n", argv[0]);
    return 1;
  }
  const std::string base_path = argv[1], out_path = argv[5], sensors_path = argv[6];
  const auto n = static_cast<std::size_t>(std::stoull(argv[2]));
  std::mt19937_64 rng(std::stoull(argv[3]));
  const double dropout = std::stod(argv[4]);
  auto bytes = lex3d::io::read_file(base_path);
  if (!bytes.ok()) {
    std::fprintf(stderr, "%s\n", bytes.status().to_string().c_str());
    return 3;
  }
  auto db = lex3d::PlaceDatabase::load(bytes.value());
  if (!db.ok()) {
    std::fprintf(stderr, "%s: %s\n", base_path.c_str(), db.status().to_string().c_str());
    return 2;
  }
  const lex3d::PlaceDatabase& base = db.value();
  std::vector<lex3d::PlaceScan> scans;
  for (std::size_t i = 0; i < base.size(); ++i) scans.push_back(base.scan(i));
  auto file = lex3d::io::PositionalFile::create_new(out_path);
  if (!file.ok()) {
    std::fprintf(stderr, "%s\n", file.status().to_string().c_str());
    return 3;
  }
  lex3d::PlaceFileWriter w(base.storage(), base.has_alphabet() ? &base.alphabet() : nullptr, base.descriptor_dim());
  w.set_vocabulary(base.vocabulary());  // the base's recognition vocabulary, when it has one
  auto put = [&](const lex3d::PlaceFileWriter::Piece& p) {
    const auto st = file.value()->write_at(p.offset, p.bytes.data(), p.bytes.size());
    if (!st.ok()) {
      std::fprintf(stderr, "%s\n", st.to_string().c_str());
      std::exit(3);
    }
  };
  std::string sensors;
  auto note = [&](const lex3d::PlaceScan& s) {
    const Eigen::Vector3d p = (s.T_world_cloud * s.coarse.T_cloud_sensor).translation();
    char buf[256];
    std::snprintf(buf, sizeof buf, "%s %.4f %.4f %.4f", s.name.c_str(), p.x(), p.y(), p.z());
    sensors += buf;
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 4; ++c) {
        std::snprintf(buf, sizeof buf, " %.9g", s.T_world_cloud.matrix()(r, c));
        sensors += buf;
      }
    sensors += "\n";
  };
  put(w.begin());
  for (std::size_t i = 0; i < n; ++i) {
    if (i < scans.size()) {
      put(w.add(scans[i]));
      note(scans[i]);
      continue;
    }
    const auto& src = scans[i % scans.size()];
    const lex3d::PlaceScan s = perturb(src, rng, dropout, src.name + "~" + std::to_string(i / scans.size()));
    put(w.add(s));
    note(s);
  }
  const auto [idx, commit] = w.finish();
  put(idx);
  put(commit);
  if (!file.value()->close().ok()) return 3;
  if (!lex3d::io::write_file_atomic(sensors_path, std::vector<std::uint8_t>(sensors.begin(), sensors.end())).ok()) return 3;
  return 0;
}
