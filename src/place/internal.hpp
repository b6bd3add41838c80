#pragma once
// Private pieces of the place module shared between its sources.

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
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
  PlaceWordStatistics stats;  // the statistics norm2 was computed under (global norms only)
};

}  // namespace lex3d

namespace lex3d::detail {

/// Little-endian loads from index and chunk bytes.
inline std::uint32_t ld32(const std::uint8_t* p) {
  return static_cast<std::uint32_t>(p[0]) | static_cast<std::uint32_t>(p[1]) << 8 |
         static_cast<std::uint32_t>(p[2]) << 16 | static_cast<std::uint32_t>(p[3]) << 24;
}
inline std::uint64_t ld64(const std::uint8_t* p) { return ld32(p) | static_cast<std::uint64_t>(ld32(p + 4)) << 32; }
inline double ldf64(const std::uint8_t* p) {
  const std::uint64_t v = ld64(p);
  double d = 0;
  std::memcpy(&d, &v, 8);
  return d;
}

/// Squared tf-idf norms of `n` scans over an inverted index (formats/place_db.md §3.4):
/// Σ_w (count / total(scan) · idf(w, postings_w))², summed in word order, the stored postings
/// of a word (views into the index bytes: `word_start`, `postings`, `word_slots`) before those
/// of scans added in memory. One function for the alphabet's index and the vocabulary's, and
/// for a shard's entries under the whole's idf, so all give the same numbers for the same postings.
template <typename StoredIndex, typename Posting, typename Total, typename Idf>
void tfidf_norms_with(std::size_t n, const StoredIndex& stored, const std::vector<std::vector<Posting>>& added,
                      Total total, Idf idf_of, std::vector<double>& norm2) {
  const std::size_t words = std::max<std::size_t>(stored.word_slots, added.size());
  norm2.assign(n, 0.0);
  for (std::size_t w = 0; w < words; ++w) {
    const std::size_t ns = w < stored.word_slots ? static_cast<std::size_t>(ld64(stored.word_start + 8 * (w + 1)) -
                                                                              ld64(stored.word_start + 8 * w))
                                                 : 0;
    const std::size_t na = w < added.size() ? added[w].size() : 0;
    if (ns + na == 0) continue;
    const double idf = idf_of(w, ns + na);
    if (ns > 0) {
      const std::uint64_t a = ld64(stored.word_start + 8 * w);
      for (std::uint64_t k = a; k < a + ns; ++k) {
        const std::uint32_t s = ld32(stored.postings + 8 * k);
        const double v = static_cast<double>(ld32(stored.postings + 8 * k + 4)) / static_cast<double>(total(s)) * idf;
        norm2[s] += v * v;
      }
    }
    for (std::size_t j = 0; j < na; ++j) {
      const auto& p = added[w][j];
      const double v = static_cast<double>(p.count) / static_cast<double>(total(p.scan)) * idf;
      norm2[p.scan] += v * v;
    }
  }
}

/// tfidf_norms_with the database's own idf, ln(1 + n / postings_w).
template <typename StoredIndex, typename Posting, typename Total>
void tfidf_norms(std::size_t n, const StoredIndex& stored, const std::vector<std::vector<Posting>>& added,
                 Total total, std::vector<double>& norm2) {
  tfidf_norms_with(
      n, stored, added, total,
      [n](std::size_t, std::size_t postings) {
        return std::log(1.0 + static_cast<double>(n) / static_cast<double>(postings));
      },
      norm2);
}

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
