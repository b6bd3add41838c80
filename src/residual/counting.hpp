#pragma once
// A counting sort's order, and when it pays against a comparison sort: shared by the
// sensor-geometry coding (pixels, laser assignments) and the spherical codings' row order.

#include <cstddef>
#include <cstdint>
#include <vector>

namespace lex3d::residual::detail {

/// The positions 0 .. n-1 ordered by key(k) in [0, keys), ties in position order: a counting
/// sort (the order a stable sort by key gives).
template <typename Key>
std::vector<std::uint32_t> counting_order(std::size_t n, std::size_t keys, const Key& key) {
  std::vector<std::uint32_t> start(keys + 1, 0), order(n);
  for (std::size_t k = 0; k < n; ++k) ++start[key(k) + 1];
  for (std::size_t b = 1; b < start.size(); ++b) start[b] += start[b - 1];
  for (std::size_t k = 0; k < n; ++k) order[start[key(k)]++] = static_cast<std::uint32_t>(k);
  return order;
}

/// Whether a counting sort over `keys` keys pays for `n` positions (its table of starts
/// costs no more than a few positions each), as against a comparison sort.
inline bool counting_pays(std::uint64_t keys, std::size_t n) {
  return keys > 0 && keys <= 4 * static_cast<std::uint64_t>(n) + 65536;
}

}  // namespace lex3d::residual::detail
