#pragma once
/// \file
/// A minimal deterministic parallel loop over an index range.

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <thread>
#include <vector>

// The public API: exported by liblex3d.so, which hides everything else.
#pragma GCC visibility push(default)

namespace lex3d {

/// Calls fn(i) for every i in [0, n) on up to `threads` threads, handing out chunks of
/// `grain` indices dynamically (work per index may vary). Each index is visited exactly
/// once, so results written per index do not depend on the thread count. fn must not throw.
template <typename Fn>
void parallel_for(std::size_t n, int threads, Fn&& fn, std::size_t grain = 16) {
  grain = std::max<std::size_t>(grain, 1);
  const std::size_t chunks = (n + grain - 1) / grain;
  const std::size_t t = std::min<std::size_t>(static_cast<std::size_t>(std::max(threads, 1)), chunks);
  if (t <= 1) {
    for (std::size_t i = 0; i < n; ++i) fn(i);
    return;
  }
  std::atomic<std::size_t> next{0};
  auto worker = [&] {
    for (;;) {
      const std::size_t c = next.fetch_add(1, std::memory_order_relaxed);
      if (c >= chunks) return;
      const std::size_t e = std::min(n, (c + 1) * grain);
      for (std::size_t i = c * grain; i < e; ++i) fn(i);
    }
  };
  std::vector<std::thread> pool;
  pool.reserve(t - 1);
  for (std::size_t k = 1; k < t; ++k) pool.emplace_back(worker);
  worker();
  for (auto& th : pool) th.join();
}

}  // namespace lex3d

#pragma GCC visibility pop
