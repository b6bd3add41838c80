#pragma once
// The process's heap policy (glibc). A compress call allocates and frees tens of
// megabytes stage after stage; by default glibc serves blocks above 128 KiB (a threshold
// that then grows) with fresh mappings and returns freed memory to the system, so each
// stage pays its page faults again: ~4,500 faults, ~10 % of compressing a KITTI scan.
// Here the heap keeps what it frees, blocks up to 32 MiB come from it, and its first
// 30 MiB are on transparent huge pages where the system allows them (one fault per 2 MiB).
// On kitti00/000005, one thread: 4,486 -> 1,161 page faults, whole process 0.93x;
// decompressing it, 0.82x; a place query with it, 0.90x. Called where it pays, before the
// first large allocation: when compress, decompress or place query handles one scan. Over
// many scans in one process glibc's own threshold, which rises to the size of the blocks
// freed, gives nearly the same (nine KITTI scans on one thread: 1.016x the time without
// this), while a heap that never shrinks grows with fragmentation (88 balm scans: 130 MB
// resident against 56 MB one at a time, and 125-250 MB against 93 MB two at a time, each
// thread's heap keeping its largest size).

#include <cstddef>
#include <cstdlib>

#if defined(__GLIBC__)
#include <malloc.h>
#endif

#include "core/huge_pages.hpp"

namespace lex3d::cli {

inline void keep_heap_on_huge_pages() noexcept {
#if defined(__GLIBC__)
  constexpr std::size_t kMiB = std::size_t{1} << 20;
  // Below glibc's largest mmap threshold (32 MiB on 64-bit), so the block is heap.
  constexpr std::size_t kStart = 30 * kMiB;
  if (mallopt(M_MMAP_THRESHOLD, static_cast<int>(32 * kMiB)) == 0) return;
  mallopt(M_TRIM_THRESHOLD, static_cast<int>(512 * kMiB));
  mallopt(M_TOP_PAD, static_cast<int>(16 * kMiB));
  // Grow the heap by kStart at once and mark it; freed, it stays as the heap's top and
  // serves the allocations that follow. Nothing is touched here, so nothing is faulted.
  void* block = std::malloc(kStart);
  if (block == nullptr) return;
  detail::advise_huge_pages(block, kStart);
  std::free(block);
#endif
}

/// Over many scans in one process, where glibc's own mmap threshold (which rises to the
/// size of the blocks freed) serves best: an environment that fixes it, as
/// MALLOC_TRIM_THRESHOLD_ (which Dask's LocalCluster sets for its workers and children),
/// MALLOC_TOP_PAD_ or MALLOC_MMAP_THRESHOLD_ do, leaves every block above 128 KiB to a fresh
/// mapping, so each stage of each scan faults its pages again (89 balm scans: 7.5 s against
/// 4.0 s). There the threshold is raised to glibc's largest (32 MiB) and the trim threshold
/// left as the environment set it.
inline void restore_mmap_threshold() noexcept {
#if defined(__GLIBC__)
  constexpr std::size_t kMiB = std::size_t{1} << 20;
  const bool fixed = std::getenv("MALLOC_MMAP_THRESHOLD_") == nullptr &&
                     (std::getenv("MALLOC_TRIM_THRESHOLD_") != nullptr || std::getenv("MALLOC_TOP_PAD_") != nullptr);
  if (fixed) mallopt(M_MMAP_THRESHOLD, static_cast<int>(32 * kMiB));
#endif
}

}  // namespace lex3d::cli
