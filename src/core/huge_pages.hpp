#pragma once
// Transparent huge pages for large arrays of fresh memory: each first write to a 4 KiB
// page of fresh memory costs a page fault (about 1.5 us with the zeroing), a 2 MiB page
// one fault for all of it.

#include <cstddef>
#include <cstdint>
#include <vector>

#if defined(__linux__)
#include <sys/mman.h>
#endif

namespace lex3d::detail {

inline constexpr std::size_t kHugePage = std::size_t{2} << 20;

/// Asks for transparent huge pages on the whole 2 MiB pages of [p, p + bytes), memory
/// not written yet (advice only: without huge pages nothing changes).
inline void advise_huge_pages(const void* p, std::size_t bytes) noexcept {
#if defined(__linux__) && defined(MADV_HUGEPAGE)
  const auto a = reinterpret_cast<std::uintptr_t>(p);
  const std::uintptr_t lo = (a + kHugePage - 1) / kHugePage * kHugePage;
  const std::uintptr_t hi = (a + bytes) / kHugePage * kHugePage;
  if (hi > lo) madvise(reinterpret_cast<void*>(lo), hi - lo, MADV_HUGEPAGE);
#else
  (void)p;
  (void)bytes;
#endif
}

/// Reserves room for n elements in the empty `v`. An array of a megabyte or more (fresh
/// memory) gets room for a 2 MiB page more, all of it on huge pages where it can: only
/// the part before the first 2 MiB boundary is left to small pages.
template <class T>
void reserve_on_huge_pages(std::vector<T>& v, std::size_t n) {
  if (n * sizeof(T) < kHugePage / 2) {
    v.reserve(n);
    return;
  }
  v.reserve(n + (kHugePage + sizeof(T) - 1) / sizeof(T));
  advise_huge_pages(v.data(), v.capacity() * sizeof(T));
}

}  // namespace lex3d::detail
