#pragma once
// Helpers shared by the residual layer's test files (residual_test_util.cpp).

#include <cstdint>
#include <string>
#include <vector>

#include "lex3d/core/cloud.hpp"

namespace lex3d::residual_test {

using Bytes = std::vector<std::uint8_t>;

/// Rewrites chunk `from` of a model file as `to` (its CRC recomputed) and sets the minor version.
Bytes retype_chunk(Bytes file, const char* from, const char* to, std::uint8_t minor);
/// Decoding model file `file` fails, and the message names `needle`.
void expect_rejected(const Bytes& file, const std::string& needle);
/// tests/residual/golden/`name`.
std::string golden_path(const std::string& name);
/// A cloud as text, `%.9g` a coordinate (exact for float32), and back.
void write_xyz(const std::string& path, const Cloud& c);
Cloud read_xyz(const std::string& path);
/// A whole file's bytes (empty when it cannot be read).
Bytes read_bytes(const std::string& path);

}  // namespace lex3d::residual_test
