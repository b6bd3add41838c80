#pragma once
// Transparent huge pages for large arrays of fresh memory: each first write to a 4 KiB
// page of fresh memory costs a page fault (about 1.5 us with the zeroing), a 2 MiB page
// one fault for all of it.

#include <cstddef>
#include <cstdint>

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

}  // namespace lex3d::detail
