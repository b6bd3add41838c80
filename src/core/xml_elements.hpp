#pragma once
// The few XML reads vendor calibration files need (Velodyne db.xml and VeloView's
// calibration XML, boost-serialization archives): an element's text by name and a number
// as an element's whole text. Not a general XML parser: no entities, comments or CDATA.

#include <cctype>
#include <cstddef>
#include <cstdlib>
#include <optional>
#include <string>
#include <string_view>
#include <utility>

namespace lex3d::detail {

/// The text between `<name>` (or `<name attributes>`) and `</name>` in [begin, end), and
/// where the element ends; nullopt when absent.
inline std::optional<std::pair<std::string_view, std::size_t>> xml_element(std::string_view s, std::string_view name,
                                                                           std::size_t begin = 0) {
  std::size_t at = begin;
  while (true) {
    at = s.find('<', at);
    if (at == std::string_view::npos) return std::nullopt;
    const std::size_t n = at + 1;
    if (s.compare(n, name.size(), name) == 0 && n + name.size() < s.size() &&
        (s[n + name.size()] == '>' || s[n + name.size()] == ' ' || s[n + name.size()] == '\t' ||
         s[n + name.size()] == '\n' || s[n + name.size()] == '\r')) {
      const std::size_t open_end = s.find('>', n);
      if (open_end == std::string_view::npos) return std::nullopt;
      const std::string close = "</" + std::string(name) + ">";
      const std::size_t close_at = s.find(close, open_end + 1);
      if (close_at == std::string_view::npos) return std::nullopt;
      return std::make_pair(s.substr(open_end + 1, close_at - open_end - 1), close_at + close.size());
    }
    at = n;
  }
}

/// A number as the whole text `t` (surrounding blanks allowed); nullopt otherwise.
inline std::optional<double> text_number(std::string_view t) {
  while (!t.empty() && std::isspace(static_cast<unsigned char>(t.front()))) t.remove_prefix(1);
  while (!t.empty() && std::isspace(static_cast<unsigned char>(t.back()))) t.remove_suffix(1);
  if (t.empty() || t.size() > 64) return std::nullopt;
  const std::string s(t);
  char* end = nullptr;
  const double v = std::strtod(s.c_str(), &end);
  if (end != s.c_str() + s.size()) return std::nullopt;
  return v;
}

}  // namespace lex3d::detail
