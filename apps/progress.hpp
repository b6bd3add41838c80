#pragma once
// Progress of long work on stderr (learning, encoding sets of scans, place build/add/eval):
// a one-line bar with the elapsed time and an estimate of the time left when stderr is a
// terminal; nothing otherwise, unless `--progress` asks for plain lines (one a second at
// most, and the last), which logs and CI keep; `--quiet` draws nothing at all. Errors and
// notes are not progress: they are printed whatever the mode.

#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <string>
#include <utility>

namespace lex3d::cli {

/// How progress is shown: kAuto (a bar on a terminal, else nothing), kQuiet (never),
/// kLines (a bar on a terminal, else plain lines). Set once by main from --quiet/--progress.
enum class ProgressMode { kAuto, kQuiet, kLines };

inline ProgressMode& progress_mode() {
  static ProgressMode mode = ProgressMode::kAuto;
  return mode;
}

class ProgressBar {
 public:
  explicit ProgressBar(std::string label)
      : label_(std::move(label)),
        terminal_(::isatty(STDERR_FILENO) != 0),
        bar_(terminal_ && progress_mode() != ProgressMode::kQuiet),
        lines_(!terminal_ && progress_mode() == ProgressMode::kLines),
        start_(std::chrono::steady_clock::now()) {}
  ~ProgressBar() { finish(); }
  ProgressBar(const ProgressBar&) = delete;
  ProgressBar& operator=(const ProgressBar&) = delete;

  /// Redraws at most ten times a second (plain lines: once a second), and always at the end.
  void update(long done, long total, const std::string& detail) {
    if (!bar_ && !lines_) return;
    const auto now = std::chrono::steady_clock::now();
    if (done < total && now - last_ < std::chrono::milliseconds(bar_ ? 100 : 1000)) return;
    last_ = now;
    const double elapsed = std::chrono::duration<double>(now - start_).count();
    const std::string times = time_text(elapsed, done, total);
    if (lines_) {
      std::fprintf(stderr, "%s %ld/%ld %s (%s)\n", label_.c_str(), done, total, detail.c_str(), times.c_str());
      std::fflush(stderr);
      return;
    }
    const int width = 24;
    const double frac = total > 0 ? static_cast<double>(done) / static_cast<double>(total) : 1.0;
    const int filled = static_cast<int>(frac * width + 0.5);
    std::string bar(static_cast<std::size_t>(filled), '#');
    bar.resize(width, '.');
    std::fprintf(stderr, "\r%s [%s] %ld/%ld %s  %s\033[K", label_.c_str(), bar.c_str(), done, total, detail.c_str(),
                 times.c_str());
    std::fflush(stderr);
    drawn_ = true;
  }
  /// Takes the bar off its line, so that what is printed next (a table row on stdout, a
  /// note) starts on a clean line; the next update draws it again.
  void clear() {
    if (!drawn_) return;
    std::fprintf(stderr, "\r\033[K");
    std::fflush(stderr);
    drawn_ = false;
    last_ = {};
  }
  void finish() {
    if (drawn_) std::fprintf(stderr, "\n");
    drawn_ = false;
  }

 private:
  /// "12 s, about 28 s left" (the estimate from the rate so far, once a step is done).
  static std::string time_text(double elapsed, long done, long total) {
    char buf[96];
    if (done > 0 && done < total) {
      const double left = elapsed / static_cast<double>(done) * static_cast<double>(total - done);
      std::snprintf(buf, sizeof buf, "%.0f s, about %.0f s left", elapsed, left);
    } else {
      std::snprintf(buf, sizeof buf, "%.0f s", elapsed);
    }
    return buf;
  }

  std::string label_;
  bool terminal_;
  bool bar_;
  bool lines_;
  bool drawn_ = false;
  std::chrono::steady_clock::time_point start_;
  std::chrono::steady_clock::time_point last_{};
};

}  // namespace lex3d::cli
