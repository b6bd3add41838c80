// Reader of text point clouds: x y z [more columns] a line in metres, and
// 3DTK `.3d` (centimetres, left-handed) read into lex3d's metric frame.

#include <algorithm>
#include <cmath>
#include <cstring>
#include <optional>
#include <string>
#include <vector>

#include "io/internal.hpp"
#include "lex3d/io/io.hpp"

namespace lex3d::io::detail {

namespace {

/// Reads a header line "x y z ..." naming the columns: their number and the
/// intensity column (-1 when there is none); false when `line` is not one.
bool parse_text_header(std::string_view line, int& intensity_col, std::size_t& columns) {
  std::vector<std::string> names;
  for_each_token(line, true, [&](const char* b, const char* e) {
    names.push_back(to_lower(std::string_view(b, static_cast<std::size_t>(e - b))));
    return names.size() <= kMaxFields;
  });
  if (names.size() < 3 || names[0] != "x" || names[1] != "y" || names[2] != "z") return false;
  intensity_col = -1;
  for (std::size_t i = 3; i < names.size(); ++i) {
    if (names[i] == "intensity" || names[i] == "i" || names[i] == "scalar_intensity" ||
        names[i] == "reflectance") {
      intensity_col = static_cast<int>(i);
      break;
    }
  }
  columns = names.size();
  return true;
}

}  // namespace

/// x y z text (metres) or 3DTK `.3d` (centimetres, left-handed; see below).
Status read_text(const std::string& path, const std::uint8_t* data, std::size_t size, bool uos,
                 const ReadOptions& options, ReadResult& r) {
  const char* text = reinterpret_cast<const char*>(data);
  if (std::memchr(text, '\0', size) != nullptr) {
    const auto off = static_cast<std::uint64_t>(static_cast<const char*>(std::memchr(text, '\0', size)) - text);
    return bad_data(msg(path, "not a text file (NUL byte)"), off);
  }
  r.encoding = "ascii";
  LineCursor lines(text, text + size);
  std::string_view line;
  std::size_t columns = 0;       // fixed by the first data line
  std::uint64_t columns_line = 0;
  int intensity_col = -1;
  bool first = true;
  // Builder created once the column layout is known
  std::optional<Builder> out;
  // one point a line, and a data line takes at least 6 bytes ("1 2 3\n")
  const std::size_t estimate =
      std::min(static_cast<std::size_t>(std::count(text, text + size, '\n')) + 1, size / 6 + 1);
  const double no_return = static_cast<double>(options.uos_no_return_cm);

  while (lines.next(line)) {
    const std::string_view t = trim(line);
    if (t.empty() || t.front() == '#') continue;
    if (first) {
      first = false;
      std::size_t header_cols = 0;
      if (parse_text_header(t, intensity_col, header_cols)) {
        columns = header_cols;
        columns_line = lines.line_no();
        out.emplace(r, intensity_col >= 0, false, !uos);
        out->reserve(estimate);
        continue;
      }
    }
    double v[4] = {0.0, 0.0, 0.0, 0.0};
    float f[4] = {0.0F, 0.0F, 0.0F, 0.0F};
    std::size_t k = 0;
    std::string_view bad;
    const bool ok = parse_tokens(t, true, k, bad, [&](std::size_t col, const char* b, const char* e) {
      int slot = -1;
      if (col < 3) slot = static_cast<int>(col);
      else if (intensity_col >= 0 ? col == static_cast<std::size_t>(intensity_col)
                                  : (columns == 0 || columns == 4) && col == 3) slot = 3;
      if (slot < 0) return is_number(b, e);
      // x y z as doubles (a text file may hold projected coordinates; Builder::finish)
      return uos || slot < 3 ? parse_number(b, e, v[slot]) : parse_number(b, e, f[slot]);
    });
    if (!ok) return bad_data(msg(path, not_a_number(lines.line_no(), bad)), lines.line_offset());
    if (k < 3) {
      return bad_data(msg(path, line_prefix(lines.line_no()) + "expected at least 3 numbers (x y z), found " +
                                    std::to_string(k)),
                      lines.line_offset());
    }
    if (columns == 0) {
      columns = k;
      columns_line = lines.line_no();
      // without a header, a fourth column of exactly four is the intensity
      if (k == 4) intensity_col = 3;
      out.emplace(r, intensity_col >= 0, false, !uos);
      out->reserve(estimate);
    } else if (k != columns) {
      return bad_data(msg(path, line_prefix(lines.line_no()) + std::to_string(k) +
                                    " values, but line " + std::to_string(columns_line) + " has " +
                                    std::to_string(columns)),
                      lines.line_offset());
    }
    if (!uos) {
      out->add_wide(v[0], v[1], v[2], f[3]);
      continue;
    }
    // 3DTK frame: left-handed, x right, y up, z forward, centimetres. lex3d:
    // right-handed, x forward, y left, z up, metres:
    //   x_out = z_in / 100,  y_out = -x_in / 100,  z_out = y_in / 100.
    if (!std::isfinite(v[0]) || !std::isfinite(v[1]) || !std::isfinite(v[2])) {
      ++r.non_finite_dropped;
      continue;
    }
    const double range = std::hypot(v[0], v[1], v[2]);  // no overflow for huge values
    const Eigen::Vector3d p = uos_to_lex3d(v[0], v[1], v[2]);
    if (range >= no_return) {
      ++r.no_return_dropped;
      if (range > 0.0) r.cloud.no_return_directions.push_back((p / (range / 100.0)).cast<float>());
      continue;
    }
    out->add(static_cast<float>(p.x()), static_cast<float>(p.y()), static_cast<float>(p.z()),
             static_cast<float>(v[3]));
  }
  return out ? out->finish(path) : Status{};
}

}  // namespace lex3d::io::detail
