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

void expect_same_georef(const Georeference& g, const Georeference& w) {
  EXPECT_EQ(g.origin, w.origin);
  EXPECT_EQ(g.unit_m, w.unit_m);
  EXPECT_EQ(g.vertical_unit_m, w.vertical_unit_m);
  EXPECT_EQ(g.unit_name, w.unit_name);
  EXPECT_EQ(g.crs_name, w.crs_name);
  EXPECT_EQ(g.epsg, w.epsg);
  EXPECT_EQ(g.las_scale, w.las_scale);
  EXPECT_EQ(g.las_offset, w.las_offset);
  EXPECT_EQ(g.las_version_minor, w.las_version_minor);
  EXPECT_EQ(g.las_point_format, w.las_point_format);
  EXPECT_EQ(g.las_system_id, w.las_system_id);
  EXPECT_EQ(g.las_software, w.las_software);
  ASSERT_EQ(g.crs_records.size(), w.crs_records.size());
  for (std::size_t i = 0; i < w.crs_records.size(); ++i) {
    EXPECT_EQ(g.crs_records[i].user_id, w.crs_records[i].user_id);
    EXPECT_EQ(g.crs_records[i].record_id, w.crs_records[i].record_id);
    EXPECT_EQ(g.crs_records[i].description, w.crs_records[i].description);
    EXPECT_EQ(g.crs_records[i].data, w.crs_records[i].data);
    EXPECT_EQ(g.crs_records[i].extended, w.crs_records[i].extended);
  }
}

}  // namespace lex3d::test
