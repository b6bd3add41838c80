// Helpers shared by the residual layer's test files.

#include "residual/residual_test_util.hpp"

#include <cstring>
#include <fstream>

#include <gtest/gtest.h>
#include <zlib.h>

#include "lex3d/codec/codec.hpp"
#include "test_config.hpp"

namespace lex3d::residual_test {

Bytes retype_chunk(Bytes file, const char* from, const char* to, std::uint8_t minor) {
  for (std::size_t at = 20; at + 12 <= file.size();) {
    std::uint64_t len = 0;
    for (int i = 0; i < 8; ++i) len |= static_cast<std::uint64_t>(file[at + 4 + i]) << (8 * i);
    if (std::memcmp(file.data() + at, from, 4) == 0) {
      std::memcpy(file.data() + at, to, 4);
      const auto crc = static_cast<std::uint32_t>(crc32(0L, file.data() + at, static_cast<uInt>(12 + len)));
      for (int i = 0; i < 4; ++i) file[at + 12 + len + i] = static_cast<std::uint8_t>(crc >> (8 * i));
    }
    at += 12 + len + 4;
  }
  file[10] = minor;
  const auto crc = static_cast<std::uint32_t>(crc32(0L, file.data(), 16));
  for (int i = 0; i < 4; ++i) file[16 + i] = static_cast<std::uint8_t>(crc >> (8 * i));
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

}  // namespace lex3d::residual_test
