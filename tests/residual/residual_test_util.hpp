#pragma once
// Helpers shared by the residual layer's test files (residual_test_util.cpp).

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "lex3d/core/cloud.hpp"
#include "lex3d/residual/residual.hpp"

namespace lex3d::residual_test {

using Bytes = std::vector<std::uint8_t>;

/// `file` with the header's minor version set to `minor` and its header CRC recomputed.
Bytes with_minor(Bytes file, std::uint8_t minor);
/// Rewrites chunk `from` of a model file as `to` (its CRC recomputed) and sets the minor version.
Bytes retype_chunk(Bytes file, const char* from, const char* to, std::uint8_t minor);
/// `file` with `edit` applied to the payload (start, length) of each chunk of type `type`,
/// its CRC recomputed; the header as it was.
Bytes edit_chunk(Bytes file, const char* type, const std::function<void(std::uint8_t*, std::uint64_t)>& edit);
/// Decoding model file `file` fails, and the message names `needle`.
void expect_rejected(const Bytes& file, const std::string& needle);
/// tests/residual/golden/`name`.
std::string golden_path(const std::string& name);
/// A cloud as text, `%.9g` a coordinate (exact for float32), and back.
void write_xyz(const std::string& path, const Cloud& c);
Cloud read_xyz(const std::string& path);
/// A whole file's bytes (empty when it cannot be read).
Bytes read_bytes(const std::string& path);
/// `b` with the little-endian f64 or u32 at `at` replaced by `v`.
Bytes poke_f64(Bytes b, std::size_t at, double v);
Bytes poke_u32(Bytes b, std::size_t at, std::uint32_t v);
/// Writes model file `file` as golden file `stem`.lex3dm, with `input` and the cloud it
/// decodes to as `stem`.input.xyz / .decoded.xyz.
void write_golden_files(const std::string& stem, const Bytes& file, const Cloud& input);
/// A model file without words holding `input`'s layer at bound `e` (every coding tried);
/// `stats`, where given, the layer's.
Bytes wordless_layer_file(const Cloud& input, double e, residual::LayerStats* stats = nullptr);
/// Golden file `stem`.lex3dm decodes to its recorded cloud bit for bit, within `max_error`
/// of `input` both ways, and is a file of format 1.`minor` whose chunks are `chunk_types`
/// ("MHDR RESL IEND ").
void expect_golden(const std::string& stem, const Cloud& input, double max_error, int minor,
                   const std::string& chunk_types);
/// Model file `file` (with instances and a layer in chunk `chunk`, a coding of format 1.12)
/// decodes and is format 1.`minor` (12, or 13 for what that version adds); claiming 1.11 is
/// refused, and so is its layer in chunk `other` (the message naming `coding`).
void expect_format_1_12(const Bytes& file, const char* chunk, const char* other, const std::string& coding,
                        int minor = 12);
/// The layer of `cloud` at bound `e` (every coding tried) is `chosen` (its LayerStats flag),
/// smaller than `ratio` times the voxel coding's, and meets the bound both ways.
void expect_beats_voxel(const Cloud& cloud, double e, bool residual::LayerStats::*chosen, double ratio);
/// A payload of a coding on a grid (formats/model.md §2.11, §2.12) is refused (`decodes`
/// false) with a step out of range, an origin not finite or beyond 10^9 m, a reserved field
/// (at `reserved_at`) of `bad`, or more coded points than its bytes can hold.
void expect_grid_fields_checked(const Bytes& good, std::size_t reserved_at, const std::function<bool(const Bytes&)>& decodes,
                                std::uint32_t bad = 1);
/// A layer payload cut anywhere is refused within its first `header` bytes and else decodes
/// to `points` points or is refused; so is one with a byte flipped from `header` on.
void expect_cuts_and_flips_bounded(const Bytes& good, std::size_t header, std::uint64_t points,
                                   const std::function<bool(const Bytes&, std::uint64_t&)>& decode);

}  // namespace lex3d::residual_test
