#pragma once
// Private pieces of the place module shared between its sources.

#include <array>
#include <cstdint>
#include <mutex>
#include <vector>

#include "lex3d/place/place.hpp"

namespace lex3d {

// Squared tf-idf norms of every scan once scans were added in memory (idf depends on N);
// computed at the first retrieval after an add.
struct PlaceDatabase::NormCache {
  std::mutex mutex;
  bool valid = false;
  std::vector<double> norm2;
};

}  // namespace lex3d

namespace lex3d::detail {

/// Fills scan.dense_points / dense_normals / dense_index from scan.coarse.
void make_dense_points(PlaceScan& scan);
/// The coarse range image a database stores (ranges already quantised).
RangeImage make_coarse_image(const RangeImage& fine, const PlaceStorageParams& storage);
/// Range code: round(r / step) clamped to [1, 65534]; 0 and 65535 mark unobserved / max range.
std::uint16_t quantise_range(float r, double step) noexcept;
float dequantise_range(std::uint16_t code, double step) noexcept;
/// Unit quaternion as four int16 (w x y z, w >= 0, scale 32767).
std::array<std::int16_t, 4> quantise_rotation(const Eigen::Quaternionf& q) noexcept;
Eigen::Quaternionf dequantise_rotation(const std::array<std::int16_t, 4>& c) noexcept;

/// The payload of a SCAN chunk (formats/place_db.md §3.3).
std::vector<std::uint8_t> encode_scan_payload(const PlaceScan& scan, double range_step);

/// The vocabulary words of a scan (from its descriptors, or its codes when they are not
/// dequantised); empty when the descriptor sizes differ.
std::vector<std::pair<std::uint32_t, std::uint32_t>> vocabulary_words(const PlaceVocabulary& v, const PlaceScan& scan);

}  // namespace lex3d::detail
