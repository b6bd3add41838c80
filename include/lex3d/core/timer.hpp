#pragma once
/// \file
/// Wall-clock stopwatch and peak-memory reading for diagnostics and benchmarks.

#include <chrono>
#include <cstdint>

// The public API: exported by liblex3d.so, which hides everything else.
#pragma GCC visibility push(default)

namespace lex3d {

/// A steady-clock stopwatch started at construction.
class Stopwatch {
 public:
  Stopwatch() : start_(std::chrono::steady_clock::now()) {}
  void reset() { start_ = std::chrono::steady_clock::now(); }
  /// Milliseconds since construction or the last reset().
  [[nodiscard]] double elapsed_ms() const {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start_)
        .count();
  }
  /// Milliseconds since the last lap (or start); starts a new lap.
  double lap_ms() {
    const auto now = std::chrono::steady_clock::now();
    const double ms = std::chrono::duration<double, std::milli>(now - start_).count();
    start_ = now;
    return ms;
  }

 private:
  std::chrono::steady_clock::time_point start_;
};

/// Peak resident set size of this process in bytes (0 where unknown).
[[nodiscard]] std::uint64_t peak_rss_bytes();

}  // namespace lex3d

#pragma GCC visibility pop
