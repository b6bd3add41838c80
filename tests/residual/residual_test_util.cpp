// Helpers shared by the residual layer's test files.

#include "residual/residual_test_util.hpp"

#include <cmath>
#include <cstring>
#include <limits>
#include <utility>
#include <fstream>

#include <gtest/gtest.h>
#include <zlib.h>

#include "lex3d/codec/codec.hpp"
#include "lex3d/eval/metrics.hpp"
#include "lex3d/residual/residual.hpp"
#include "test_config.hpp"

namespace lex3d::residual_test {

Bytes with_minor(Bytes file, std::uint8_t minor) {
  file[10] = minor;
  const auto crc = static_cast<std::uint32_t>(crc32(0L, file.data(), 16));
  for (int i = 0; i < 4; ++i) file[16 + i] = static_cast<std::uint8_t>(crc >> (8 * i));
  return file;
}

namespace {
/// Calls `change(at, len)` on each chunk of type `type` (its type at `at`, its payload of
/// `len` bytes at `at` + 12), then recomputes that chunk's CRC.
void change_chunks(Bytes& file, const char* type, const std::function<void(std::size_t, std::uint64_t)>& change) {
  for (std::size_t at = 20; at + 12 <= file.size();) {
    std::uint64_t len = 0;
    for (int i = 0; i < 8; ++i) len |= static_cast<std::uint64_t>(file[at + 4 + i]) << (8 * i);
    if (std::memcmp(file.data() + at, type, 4) == 0) {
      change(at, len);
      const auto crc = static_cast<std::uint32_t>(crc32(0L, file.data() + at, static_cast<uInt>(12 + len)));
      for (int i = 0; i < 4; ++i) file[at + 12 + len + i] = static_cast<std::uint8_t>(crc >> (8 * i));
    }
    at += 12 + len + 4;
  }
}
}  // namespace

Bytes retype_chunk(Bytes file, const char* from, const char* to, std::uint8_t minor) {
  change_chunks(file, from, [&](std::size_t at, std::uint64_t) { std::memcpy(file.data() + at, to, 4); });
  return with_minor(std::move(file), minor);
}

Bytes edit_chunk(Bytes file, const char* type, const std::function<void(std::uint8_t*, std::uint64_t)>& edit) {
  change_chunks(file, type, [&](std::size_t at, std::uint64_t len) { edit(file.data() + at + 12, len); });
  return file;
}

void expect_rejected(const Bytes& file, const std::string& needle) {
  const auto d = codec::decode_model(file);
  ASSERT_FALSE(d.ok()) << "expected a failure naming " << needle;
  EXPECT_NE(d.status().message().find(needle), std::string::npos) << d.status().to_string();
}

std::string golden_path(const std::string& name) {
  return std::string(LEX3D_TEST_DATA_DIR) + "/../residual/golden/" + name;
}

void write_xyz(const std::string& path, const Cloud& c) {
  std::ofstream out(path);
  char line[128];
  for (const auto& p : c.points) {
    std::snprintf(line, sizeof line, "%.9g %.9g %.9g\n", static_cast<double>(p.x()), static_cast<double>(p.y()),
                  static_cast<double>(p.z()));
    out << line;
  }
}

Cloud read_xyz(const std::string& path) {
  std::ifstream in(path);
  Cloud c;
  float x = 0, y = 0, z = 0;
  while (in >> x >> y >> z) c.points.emplace_back(x, y, z);
  return c;
}

Bytes read_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return Bytes(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

Bytes poke_f64(Bytes b, std::size_t at, double v) {
  std::uint64_t w = 0;
  std::memcpy(&w, &v, 8);
  for (int i = 0; i < 8; ++i) b[at + static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(w >> (8 * i));
  return b;
}

Bytes poke_u32(Bytes b, std::size_t at, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) b[at + static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(v >> (8 * i));
  return b;
}

void write_golden_files(const std::string& stem, const Bytes& file, const Cloud& input) {
  const auto decoded = codec::decode_model(file);
  ASSERT_TRUE(decoded.ok()) << decoded.status().to_string();
  const auto cloud = residual::decode_cloud(decoded.value());
  ASSERT_TRUE(cloud.ok()) << cloud.status().to_string();
  std::ofstream out(golden_path(stem + ".lex3dm"), std::ios::binary);
  out.write(reinterpret_cast<const char*>(file.data()), static_cast<std::streamsize>(file.size()));
  ASSERT_TRUE(out.good());
  write_xyz(golden_path(stem + ".input.xyz"), input);
  write_xyz(golden_path(stem + ".decoded.xyz"), cloud.value());
}

Bytes wordless_layer_file(const Cloud& input, double e, residual::LayerStats* stats) {
  codec::ModelData d;
  d.input_points = input.size();
  d.alphabet = Alphabet{};
  const residual::LayerStats st = residual::add_layer(d, Alphabet{}, input, e);
  if (stats) *stats = st;
  return codec::encode_model(d);
}

void expect_format_1_12(const Bytes& file, const char* chunk, const char* other, const std::string& coding,
                        int minor) {
  EXPECT_EQ(file[10], minor) << "a layer in " << chunk << " makes the file format 1." << minor;
  ASSERT_TRUE(codec::decode_model(file).ok());
  expect_rejected(retype_chunk(file, chunk, chunk, 11), "1.1");
  expect_rejected(retype_chunk(file, chunk, other, static_cast<std::uint8_t>(minor)), coding);
  const auto info = codec::inspect(file);
  ASSERT_TRUE(info.ok());
  std::string types;
  for (const auto& c : info.value().chunks) types += c.type + " ";
  EXPECT_EQ(types, std::string("MHDR ALPH INST ") + chunk + " IEND ");
}

void expect_beats_voxel(const Cloud& cloud, double e, bool residual::LayerStats::*chosen, double ratio) {
  residual::LayerStats st, voxel_st;
  const Bytes layer = residual::encode_layer(cloud, Cloud{}, cloud.T_cloud_sensor, e, &st);
  EXPECT_TRUE(st.*chosen);
  residual::LayerOptions voxel_only;
  voxel_only.spherical = false;
  voxel_only.laser = false;
  voxel_only.acquisition = false;
  voxel_only.lattice = false;
  const Bytes voxel = residual::encode_layer(cloud, Cloud{}, cloud.T_cloud_sensor, e, &voxel_st, voxel_only);
  ASSERT_TRUE(voxel_st.voxel);
  EXPECT_LT(static_cast<double>(layer.size()), ratio * static_cast<double>(voxel.size()));
  const auto d = residual::decode_layer(layer, Cloud{}, cloud.T_cloud_sensor, cloud.size());
  ASSERT_TRUE(d.ok()) << d.status().to_string();
  EXPECT_LE(eval::compare_clouds(cloud, d.value()).hausdorff, e);
  EXPECT_LE(eval::compare_clouds(d.value(), cloud).hausdorff, e);
}

void expect_grid_fields_checked(const Bytes& good, std::size_t reserved_at, const std::function<bool(const Bytes&)>& decodes,
                                std::uint32_t bad) {
  ASSERT_TRUE(decodes(good));
  for (const double step : {0.0, -0.01, 0.1, std::nan("")}) EXPECT_FALSE(decodes(poke_f64(good, 16, step))) << step;
  for (const double o : {std::nan(""), 1e10, -std::numeric_limits<double>::infinity()})
    for (const std::size_t at : {40U, 48U, 56U}) EXPECT_FALSE(decodes(poke_f64(good, at, o))) << o << " at " << at;
  EXPECT_FALSE(decodes(poke_u32(good, reserved_at, bad))) << "reserved field";
  Bytes many = good;
  for (int i = 0; i < 8; ++i) many[32 + static_cast<std::size_t>(i)] = 0xFF;
  EXPECT_FALSE(decodes(many)) << "coded points";
}

void expect_cuts_and_flips_bounded(const Bytes& good, std::size_t header, std::uint64_t points,
                                   const std::function<bool(const Bytes&, std::uint64_t&)>& decode) {
  std::uint64_t n = 0;
  for (std::size_t k = 0; k < good.size(); k += (k < header + 16 ? 1 : 53)) {
    const bool ok = decode(Bytes(good.begin(), good.begin() + static_cast<std::ptrdiff_t>(k)), n);
    if (k < header) EXPECT_FALSE(ok) << k;
    if (ok) EXPECT_EQ(n, points) << k;
  }
  for (std::size_t at = header; at < good.size(); at += 29) {
    Bytes b = good;
    b[at] ^= 0x5A;
    if (decode(b, n)) EXPECT_EQ(n, points) << at;
  }
}

void expect_golden(const std::string& stem, const Cloud& input, double max_error, int minor,
                   const std::string& chunk_types) {
  const Bytes file = read_bytes(golden_path(stem + ".lex3dm"));
  const Cloud recorded = read_xyz(golden_path(stem + ".decoded.xyz"));
  ASSERT_FALSE(file.empty());
  ASSERT_FALSE(input.empty());
  ASSERT_FALSE(recorded.empty());
  const auto d = codec::decode_model(file);
  ASSERT_TRUE(d.ok()) << d.status().to_string();
  EXPECT_EQ(d.value().input_points, input.size());
  const auto cloud = residual::decode_cloud(d.value());
  ASSERT_TRUE(cloud.ok()) << cloud.status().to_string();
  ASSERT_EQ(cloud.value().size(), recorded.size());
  for (std::size_t i = 0; i < recorded.size(); ++i) EXPECT_TRUE(cloud.value().points[i] == recorded.points[i]) << i;
  EXPECT_LE(eval::compare_clouds(input, cloud.value()).hausdorff, max_error);
  EXPECT_LE(eval::compare_clouds(cloud.value(), input).hausdorff, max_error);
  const auto info = codec::inspect(file);
  ASSERT_TRUE(info.ok());
  EXPECT_EQ(info.value().minor, minor);
  std::string types;
  for (const auto& c : info.value().chunks) types += c.type + " ";
  EXPECT_EQ(types, chunk_types);
}

}  // namespace lex3d::residual_test
