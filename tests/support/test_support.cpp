#include "support/test_support.hpp"

#include <cstdlib>
#include <fstream>
#include <vector>
#include <unistd.h>

#include "lex3d/io/io.hpp"

namespace lex3d::test {

std::string shared_data(const std::string& relative) {
  return std::string(LEX3D_SHARED_DATA_DIR) + "/" + relative;
}

std::string sample(const std::string& relative) {
  return std::string(LEX3D_SAMPLES_DIR) + "/" + relative;
}

bool has_shared_data(const std::string& relative) {
  std::error_code ec;
  return std::filesystem::exists(shared_data(relative), ec);
}

namespace {
// Removes the directories handed out by temp_dir when the test binary exits.
struct TempDirs {
  std::vector<std::filesystem::path> dirs;
  ~TempDirs() {
    std::error_code ec;
    for (const auto& d : dirs) std::filesystem::remove_all(d, ec);
  }
};
TempDirs& temp_dirs() {
  static TempDirs t;
  return t;
}
}  // namespace

std::filesystem::path temp_dir(const std::string& name) {
  namespace fs = std::filesystem;
  const fs::path dir = fs::temp_directory_path() /
                       ("lex3d_test_" + std::to_string(::getpid()) + "_" + name);
  fs::remove_all(dir);
  fs::create_directories(dir);
  temp_dirs().dirs.push_back(dir);
  return dir;
}

Cloud load_or_fail(const std::string& path) {
  auto r = io::read_cloud(path);
  if (!r.ok()) {
    ADD_FAILURE() << "cannot read " << path << ": " << r.status().to_string();
    return {};
  }
  return std::move(r).value().cloud;
}

namespace {
void write_raw(const std::string& path, const char* data, std::size_t size) {
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  f.write(data, static_cast<std::streamsize>(size));
  f.close();
  if (!f) ADD_FAILURE() << "could not write " << path;
}
}  // namespace

void write_bytes(const std::string& path, const std::string& bytes) { write_raw(path, bytes.data(), bytes.size()); }

void write_bytes(const std::string& path, const std::vector<std::uint8_t>& bytes) {
  write_raw(path, reinterpret_cast<const char*>(bytes.data()), bytes.size());
}

}  // namespace lex3d::test
