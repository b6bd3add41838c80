#pragma once
// Helpers shared by the test binaries: data paths, skip-when-absent, temp dirs.

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "lex3d/core/cloud.hpp"
#include "test_config.hpp"

namespace lex3d::test {

/// Path of a file under ../shared/data (may not exist on a user's machine).
std::string shared_data(const std::string& relative);
/// Path of a file under samples/ (always present).
std::string sample(const std::string& relative);
/// True when ../shared/data holds `relative`.
bool has_shared_data(const std::string& relative);
/// A fresh empty directory for one test, removed at exit of the process.
std::filesystem::path temp_dir(const std::string& name);
/// Reads a cloud or fails the current test.
Cloud load_or_fail(const std::string& path);
/// Writes `bytes` to `path` (replacing it), or fails the current test.
void write_bytes(const std::string& path, const std::string& bytes);
void write_bytes(const std::string& path, const std::vector<std::uint8_t>& bytes);
/// Expects `got` to hold what a model file keeps of georeference `want` (origin, units, CRS
/// name and records, the LAS container's fields; not the measured representation error).
void expect_same_georef(const Georeference& got, const Georeference& want);

}  // namespace lex3d::test

/// Skips the current test when ../shared/data lacks `relative`.
#define LEX3D_REQUIRE_SHARED(relative)                                              \
  do {                                                                              \
    if (!::lex3d::test::has_shared_data(relative))                                  \
      GTEST_SKIP() << "shared data not available: " << (relative);                  \
  } while (0)
