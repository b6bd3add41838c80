#pragma once
// Private helpers shared by the io sources: message formatting, number
// parsing on byte buffers, line scanning and format sniffing. Not installed.

#include <charconv>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <string>
#include <string_view>
#include <system_error>
#include <type_traits>
#include <vector>

#include "lex3d/core/cloud.hpp"
#include "lex3d/core/status.hpp"
#include "lex3d/io/io.hpp"

namespace lex3d::io::detail {

/// `s` made safe for a one-line message: control and non-ASCII bytes become
/// '?', and it is cut to `max_len` characters (with "..." when cut).
std::string printable(std::string_view s, std::size_t max_len = 48);

/// The path as it appears in messages (printable, never more than one line).
inline std::string display_path(const std::string& path) { return printable(path, 4096); }

/// "<path>: <what>" — the shape of every error message of the module.
inline std::string msg(const std::string& path, const std::string& what) {
  return display_path(path) + ": " + what;
}

/// Lower-cased extension with the dot (".pcd"), or "" when there is none.
std::string extension_lower(const std::string& path);

/// ASCII lower-case copy.
std::string to_lower(std::string_view s);

/// Decides the format of `path` from its extension and its first bytes
/// (`head`, possibly the whole file) given the whole file size.
StatusOr<Format> detect_from_bytes(const std::string& path, const std::uint8_t* head,
                                   std::size_t head_size, std::uint64_t file_size);

/// Reads a 3DTK `.pose` file (line 1 `tx ty tz` cm, line 2 `rx ry rz` degrees,
/// both in the left-handed 3DTK frame) and returns the pose in lex3d's
/// right-handed metric frame (see read.cpp for the axis mapping).
StatusOr<Pose> read_uos_pose(const std::string& pose_path);

/// Maps a 3DTK left-handed centimetre vector to lex3d's right-handed metre frame:
/// x_out = z_in/100, y_out = -x_in/100, z_out = y_in/100.
inline Eigen::Vector3d uos_to_lex3d(double x, double y, double z) {
  return {z / 100.0, -x / 100.0, y / 100.0};
}

// ---------------------------------------------------------------- text scanning

inline bool is_space(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f'; }

/// Iterates the lines of a buffer; the line returned excludes "\n" and a trailing "\r".
class LineCursor {
 public:
  LineCursor(const char* begin, const char* end) : p_(begin), begin_(begin), end_(end) {}
  /// Next line; false at the end. `line_no` is 1-based.
  bool next(std::string_view& line) {
    if (p_ >= end_) return false;
    const char* start = p_;
    const void* nl = std::memchr(p_, '\n', static_cast<std::size_t>(end_ - p_));
    const char* stop = nl != nullptr ? static_cast<const char*>(nl) : end_;
    p_ = nl != nullptr ? stop + 1 : end_;
    if (stop > start && stop[-1] == '\r') --stop;
    line_start_ = start;
    ++line_no_;
    line = std::string_view(start, static_cast<std::size_t>(stop - start));
    return true;
  }
  [[nodiscard]] std::uint64_t line_no() const { return line_no_; }
  /// Byte offset (from the buffer start) of the line last returned.
  [[nodiscard]] std::uint64_t line_offset() const {
    return static_cast<std::uint64_t>(line_start_ - begin_);
  }
  [[nodiscard]] const char* position() const { return p_; }

 private:
  const char* p_;
  const char* begin_;
  const char* end_;
  const char* line_start_ = nullptr;
  std::uint64_t line_no_ = 0;
};

/// Parses a number spanning exactly [b, e) (a leading '+' allowed, "nan"/"inf"
/// accepted); false when the token is not a number. Out-of-range values become
/// +-inf or 0 as strtod would give them.
template <typename T>
bool parse_number(const char* b, const char* e, T& out) {
  if (b < e && *b == '+') ++b;
  if (b >= e) return false;
  auto [ptr, ec] = std::from_chars(b, e, out);
  if (ptr != e) return false;
  if (ec == std::errc()) return true;
  if (ec != std::errc::result_out_of_range) return false;
  char buf[128];
  const auto n = static_cast<std::size_t>(e - b);
  if (n >= sizeof(buf)) return false;
  std::memcpy(buf, b, n);
  buf[n] = '\0';
  if constexpr (std::is_same_v<T, float>) {
    out = std::strtof(buf, nullptr);
  } else {
    out = static_cast<T>(std::strtod(buf, nullptr));
  }
  return true;
}

/// Splits a line into tokens separated by spaces, tabs and (when `commas`) ',' or ';'.
/// Calls fn(begin, end) for each token; stops early when fn returns false.
template <typename Fn>
void for_each_token(std::string_view line, bool commas, Fn&& fn) {
  const char* p = line.data();
  const char* e = p + line.size();
  auto sep = [commas](char c) { return is_space(c) || (commas && (c == ',' || c == ';')); };
  while (p < e) {
    while (p < e && is_space(*p)) ++p;
    if (p >= e) break;
    const char* b = p;
    while (p < e && !sep(*p)) ++p;
    if (!fn(b, p)) return;
    // one comma/semicolon (with surrounding spaces) separates two tokens
    while (p < e && is_space(*p)) ++p;
    if (p < e && commas && (*p == ',' || *p == ';')) ++p;
  }
}

/// Trims spaces/tabs/CR from both ends.
inline std::string_view trim(std::string_view s) {
  while (!s.empty() && is_space(s.front())) s.remove_prefix(1);
  while (!s.empty() && is_space(s.back())) s.remove_suffix(1);
  return s;
}

}  // namespace lex3d::io::detail
