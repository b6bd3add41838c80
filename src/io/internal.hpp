#pragma once
// Private helpers shared by the io sources: message formatting, number
// parsing on byte buffers, line scanning, format sniffing, and what the
// readers (read.cpp, read_bin.cpp, read_pcd.cpp, read_ply.cpp, read_text.cpp)
// share. Not installed.

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
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

/// Keeps the points of `c` for which keep(i) holds (called once a point, in order), with
/// every per-point channel that holds one value a point: intensity, laser, column, time,
/// colour, named fields and `colors` where given (a reader's). Returns how many were kept.
template <class Keep>
std::size_t keep_cloud_points(Cloud& c, Keep keep, std::vector<std::array<std::uint8_t, 3>>* colors = nullptr) {
  const std::size_t n = c.points.size();
  const auto compact = [&](auto& channel, std::size_t i, std::size_t to) {
    if (channel.size() == n) channel[to] = channel[i];
  };
  std::size_t kept = 0;
  for (std::size_t i = 0; i < n; ++i) {
    if (!keep(i)) continue;
    c.points[kept] = c.points[i];
    compact(c.intensity, i, kept);
    compact(c.ring, i, kept);
    compact(c.column, i, kept);
    compact(c.time, i, kept);
    compact(c.rgb, i, kept);
    if (colors != nullptr) compact(*colors, i, kept);
    for (IntegerField& field : c.fields) compact(field.values, i, kept);
    ++kept;
  }
  const auto shrink = [&](auto& channel) {
    if (channel.size() == n) channel.resize(kept);
  };
  shrink(c.intensity);
  shrink(c.ring);
  shrink(c.column);
  shrink(c.time);
  shrink(c.rgb);
  if (colors != nullptr) shrink(*colors);
  for (IntegerField& field : c.fields) shrink(field.values);
  c.points.resize(kept);
  return kept;
}

/// `s` made safe for a one-line message: control and non-ASCII bytes become
/// '?', and it is cut to `max_len` characters (with "..." when cut).
std::string printable(std::string_view s, std::size_t max_len = 48);

/// The path as it appears in messages (printable, never more than one line).
inline std::string display_path(const std::string& path) { return printable(path, 4096); }

/// "<path>: <what>" — the shape of every error message of the module.
inline std::string msg(const std::string& path, const std::string& what) {
  return display_path(path) + ": " + what;
}

/// "'<s>'": a token of the file quoted for a message (printable, at most 32 characters).
inline std::string quoted(std::string_view s) { return "'" + printable(s, 32) + "'"; }

/// "line <n>: " — the start of a message about one line of a text file.
inline std::string line_prefix(std::uint64_t line_no) { return "line " + std::to_string(line_no) + ": "; }

/// "line <n>: '<tok>' is not a number" — every text reader's message for a bad token.
inline std::string not_a_number(std::uint64_t line_no, std::string_view tok) {
  return line_prefix(line_no) + quoted(tok) + " is not a number";
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

/// Parses a named integer field's value spanning exactly [b, e): a number that is an integer
/// within [-2^31, 2^32 - 1] (an unsigned 32-bit field's value beyond int32 drops its field
/// when the reading ends, Builder::finish); false otherwise.
inline bool parse_field_value(const char* b, const char* e, std::int64_t& out) {
  double v = 0.0;
  if (!parse_number(b, e, v) || v != std::floor(v) || v < -2147483648.0 || v > 4294967295.0) return false;
  out = static_cast<std::int64_t>(v);
  return true;
}

/// True when [b, e) is a number as parse_number reads it (for a value that is not kept).
inline bool is_number(const char* b, const char* e) {
  double ignored = 0.0;
  return parse_number(b, e, ignored);
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

/// Parses the tokens of one data line (split as by for_each_token; with
/// `commas`, a token may be empty) left to right: `parse(k, b, e)` takes token k
/// (0-based) and returns false when it is not a number. `count` is how many
/// tokens parsed; at the first that does not, returns false with it in `bad`.
template <typename Fn>
bool parse_tokens(std::string_view line, bool commas, std::size_t& count, std::string_view& bad,
                  Fn&& parse) {
  bool ok = true;
  count = 0;
  for_each_token(line, commas, [&](const char* b, const char* e) {
    if (!parse(count, b, e)) {
      bad = std::string_view(b, static_cast<std::size_t>(e - b));
      ok = false;
      return false;
    }
    ++count;
    return true;
  });
  return ok;
}

/// Splits a line at spaces and tabs.
std::vector<std::string_view> split_ws(std::string_view line);

/// A whole non-negative decimal integer (no sign, no spaces).
inline bool parse_u64(std::string_view s, std::uint64_t& out) {
  if (s.empty()) return false;
  auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), out);
  return ec == std::errc() && ptr == s.data() + s.size();
}

/// Trims spaces/tabs/CR from both ends.
inline std::string_view trim(std::string_view s) {
  while (!s.empty() && is_space(s.front())) s.remove_prefix(1);
  while (!s.empty() && is_space(s.back())) s.remove_suffix(1);
  return s;
}

// ---------------------------------------------------------------- binary values

constexpr bool kHostBigEndian = __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__;

/// The value types of binary PCD fields and PLY properties.
enum class Scalar : std::uint8_t { kI8, kU8, kI16, kU16, kI32, kU32, kI64, kU64, kF32, kF64 };

inline unsigned scalar_size(Scalar s) {
  switch (s) {
    case Scalar::kI8: case Scalar::kU8: return 1;
    case Scalar::kI16: case Scalar::kU16: return 2;
    case Scalar::kI32: case Scalar::kU32: case Scalar::kF32: return 4;
    case Scalar::kI64: case Scalar::kU64: case Scalar::kF64: return 8;
  }
  return 1;
}

/// The T stored at `p`, byte-swapped when `swap`.
template <typename T>
T load(const std::uint8_t* p, bool swap) {
  std::array<std::uint8_t, sizeof(T)> b{};
  std::memcpy(b.data(), p, sizeof(T));
  if (swap) std::reverse(b.begin(), b.end());
  T v;
  std::memcpy(&v, b.data(), sizeof(T));
  return v;
}

/// The value at `p` as a double (integers converted exactly up to 2^53).
inline double load_scalar(const std::uint8_t* p, Scalar s, bool swap) {
  switch (s) {
    case Scalar::kI8: return static_cast<double>(static_cast<std::int8_t>(p[0]));
    case Scalar::kU8: return static_cast<double>(p[0]);
    case Scalar::kI16: return static_cast<double>(load<std::int16_t>(p, swap));
    case Scalar::kU16: return static_cast<double>(load<std::uint16_t>(p, swap));
    case Scalar::kI32: return static_cast<double>(load<std::int32_t>(p, swap));
    case Scalar::kU32: return static_cast<double>(load<std::uint32_t>(p, swap));
    case Scalar::kI64: return static_cast<double>(load<std::int64_t>(p, swap));
    case Scalar::kU64: return static_cast<double>(load<std::uint64_t>(p, swap));
    case Scalar::kF32: return static_cast<double>(load<float>(p, swap));
    case Scalar::kF64: return load<double>(p, swap);
  }
  return 0.0;
}

/// The value at `p` as a float (a float32 is copied bit-exactly).
inline float load_float(const std::uint8_t* p, Scalar s, bool swap) {
  if (s == Scalar::kF32) return load<float>(p, swap);
  return static_cast<float>(load_scalar(p, s, swap));
}

// ---------------------------------------------------------------- readers

/// No coordinate frame on Earth reaches this far (metres): a PCD viewpoint or a LAS point beyond it is bad data.
constexpr double kMaxCoordinateM = 1e9;
constexpr std::size_t kMaxHeaderBytes = 1U << 20;  // PCD / PLY header cap
constexpr std::size_t kMaxFields = 1U << 16;       // fields (PCD) / properties (PLY) / columns (text) cap

using Rgb = std::array<std::uint8_t, 3>;

/// The bytes a named field of type `t` takes in a PCD, PLY or PointCloud2 record (a field
/// whose type is not recorded: an int32's).
inline unsigned field_bytes(FieldType t) {
  switch (t) {
    case FieldType::kInt8: case FieldType::kUint8: return 1;
    case FieldType::kInt16: case FieldType::kUint16: return 2;
    case FieldType::kFloat64: return 8;
    default: return 4;
  }
}

/// Stores point i's value of named field `x` at `dst` in the field's type (a float field's
/// float, a float64 one's widened), in the host's byte order; returns field_bytes(x.type).
inline unsigned store_field(std::uint8_t* dst, const IntegerField& x, std::size_t i) {
  const std::int32_t v = x.values[i];
  const auto put = [dst](auto value) {
    std::memcpy(dst, &value, sizeof value);
    return static_cast<unsigned>(sizeof value);
  };
  switch (x.type) {
    case FieldType::kInt8: return put(static_cast<std::int8_t>(v));
    case FieldType::kUint8: return put(static_cast<std::uint8_t>(v));
    case FieldType::kInt16: return put(static_cast<std::int16_t>(v));
    case FieldType::kUint16: return put(static_cast<std::uint16_t>(v));
    case FieldType::kUint32: return put(static_cast<std::uint32_t>(v));
    case FieldType::kFloat32: return put(key_float(v));
    case FieldType::kFloat64: return put(static_cast<double>(key_float(v)));
    default: return put(v);
  }
}

/// Seconds a unit of a time field of scalar `s`: an integer one counts nanoseconds (the
/// ouster_ros convention), a float one seconds.
inline double time_unit(Scalar s) { return s == Scalar::kF32 || s == Scalar::kF64 ? 1.0 : 1e-9; }

/// A named field a reader keeps: its name and its type in the file.
struct FieldSpec {
  std::string name;
  FieldType type;
};

/// The type a named field of scalar `s` keeps, or nullopt for one it cannot (64-bit integers).
inline std::optional<FieldType> field_type_of(Scalar s) {
  switch (s) {
    case Scalar::kI8: return FieldType::kInt8;
    case Scalar::kU8: return FieldType::kUint8;
    case Scalar::kI16: return FieldType::kInt16;
    case Scalar::kU16: return FieldType::kUint16;
    case Scalar::kI32: return FieldType::kInt32;
    case Scalar::kU32: return FieldType::kUint32;
    case Scalar::kF32: return FieldType::kFloat32;
    case Scalar::kF64: return FieldType::kFloat64;
    default: return std::nullopt;
  }
}

/// The source of a reader's ring, intensity or time field named `name` of scalar `s`
/// (Cloud::ring_source, ...; a 64-bit integer's type is not recorded).
inline SourceField source_field(const std::string& name, Scalar s) {
  const std::optional<FieldType> t = field_type_of(s);
  return t && *t != FieldType::kUnspecified ? SourceField{name, *t} : SourceField{};
}

/// Whether a reader's field that no other Cloud member holds, `values` a point (0: a PLY
/// list), is kept as a named field (Cloud::fields; its name and type appended to `kept`):
/// one value a point, a name is_field_name takes, not kept already, and an integer of up to
/// 32 bits (an unsigned 32-bit one only while its values fit in 31 bits) or a float (a
/// double only where float32 holds every value); Builder::finish drops those that do not
/// hold, naming them. Else its name and why go to `not_kept`. True when kept.
inline bool offer_field(const std::string& name, Scalar type, std::uint64_t values, std::vector<FieldSpec>& kept,
                        std::vector<std::string>& not_kept) {
  const std::optional<FieldType> t = field_type_of(type);
  const bool named = std::find_if(kept.begin(), kept.end(), [&](const FieldSpec& f) { return f.name == name; }) != kept.end();
  if (values == 1 && t && is_field_name(name) && !named) {
    kept.push_back({name, *t});
    return true;
  }
  std::string why;
  if (values == 0) why = " (a list)";
  else if (values > 1) why = " (" + std::to_string(values) + " values a point)";
  else if (!t) why = " (64-bit integers)";
  not_kept.push_back(printable(name, 64) + why);
  return false;
}

/// The ring, intensity and time of `cloud` as their source stored them (Cloud::ring_source,
/// ...): each one whose source is given and whose every value that type holds, as a named
/// field of the source's name and type (an integer time in nanoseconds), which the PCD, PLY
/// and PointCloud2 writers put in place of their default column; the others empty, written
/// as `ring` uint16, `intensity` float32 and `time` float64 (that one under its source's name
/// where the source gave a float64).
struct SourceColumns {
  std::optional<IntegerField> ring, intensity, time;
  std::string time_name = "time";
};
SourceColumns source_columns(const Cloud& cloud);

/// kInvalidArgument naming `path` when a named field of `cloud` does not hold a value a
/// point or has a name is_field_name refuses (write.cpp).
Status check_fields(const std::string& path, const Cloud& cloud);

/// Where double-precision points lie too far from their frame's origin for float32 to hold
/// them to a millionth of their extent (a UTM cloud): a round origin near their centre (to
/// the power of ten below their extent); nullopt where float32 holds them as they are.
std::optional<Eigen::Vector3d> wide_origin(const std::vector<Eigen::Vector3d>& points);

/// kBadData naming `path` when a point lies beyond kMaxCoordinateM of its frame's origin.
Status check_reach(const std::vector<Eigen::Vector3d>& points, const std::string& path);

/// Sets `cloud.points` to `points` less `origin` in float32 and `cloud.georef` to that origin
/// (with `unit_name` and the worst rounding), moving a sensor pose given with the points
/// (not the identity) with them.
void set_relative_points(Cloud& cloud, const std::vector<Eigen::Vector3d>& points, const Eigen::Vector3d& origin,
                         const std::string& unit_name);

/// Collects the finite points of a file into a ReadResult. With `wide` (a file whose
/// coordinates are doubles) the points are kept in double until finish(), which either
/// rounds them to float32 or, when they lie far from their frame's origin, stores them
/// relative to a georeference origin (Cloud::georef; see finish()).
class Builder {
 public:
  Builder(ReadResult& r, bool intensity, bool color, bool wide = false)
      : r_(r), intensity_(intensity), color_(color), wide_(wide) {}

  void reserve(std::size_t n) {
    if (wide_) wide_points_.reserve(n);
    else r_.cloud.points.reserve(n);
    if (intensity_) r_.cloud.intensity.reserve(n);
    if (color_) r_.colors.reserve(n);
  }

  void add(float x, float y, float z, float i = 0.0F, const Rgb& c = {}) {
    if (wide_) {
      add_wide(x, y, z, i, c);
      return;
    }
    if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z)) {
      ++r_.non_finite_dropped;
      return;
    }
    r_.cloud.points.emplace_back(x, y, z);
    if (intensity_) r_.cloud.intensity.push_back(i);
    if (color_) r_.colors.push_back(c);
    if (time_) r_.cloud.time.push_back(next_time_);
    push_fields();
  }

  /// Records each point's time (Cloud::time, seconds): the value given to next_time before
  /// its add, times `unit` (seconds a unit of the source's field: 1e-9 for nanoseconds).
  void set_time(bool on, double unit = 1.0) {
    time_ = on;
    time_unit_ = unit;
  }
  void next_time(double t) { next_time_ = t * time_unit_; }
  /// Records named fields (Cloud::fields) `specs`: field k of each point is the value given
  /// to next_field(k, ...) before its add.
  void set_fields(const std::vector<FieldSpec>& specs) {
    for (const FieldSpec& f : specs) r_.cloud.fields.push_back({f.name, {}, f.type});
    next_fields_.assign(specs.size(), 0);
    unfit_.assign(specs.size(), false);
  }
  /// Field k's value at the next point: an integer field's (a value beyond int32, as an
  /// unsigned 32-bit field may hold, drops the field at finish), a float field's as its
  /// float_key (a double that float32 does not hold drops a float64 field at finish).
  void next_field(std::size_t k, double v) {
    const FieldType t = r_.cloud.fields[k].type;
    if (!is_float_type(t)) {
      const bool fits = v >= -2147483648.0 && v <= 2147483647.0;
      if (!fits) unfit_[k] = true;
      next_fields_[k] = fits ? static_cast<std::int32_t>(v) : 0;
      return;
    }
    const auto f = static_cast<float>(v);
    if (t == FieldType::kFloat64 && static_cast<double>(f) != v && !std::isnan(v)) unfit_[k] = true;
    next_fields_[k] = float_key(f);
  }
  /// Reads field k's value at the next point from the text [b, e): an integer field's an
  /// integer, a float field's any number; false where it is not one.
  bool parse_field(std::size_t k, const char* b, const char* e) {
    double v = 0.0;
    if (is_float_type(r_.cloud.fields[k].type)) {
      if (!parse_number(b, e, v)) return false;
    } else {
      std::int64_t i = 0;
      if (!parse_field_value(b, e, i)) return false;
      v = static_cast<double>(i);
    }
    next_field(k, v);
    return true;
  }

  /// Records each point's laser (`rings`) and column (`columns`) from add_at; with
  /// `organised`, NaN/Inf and exact (0, 0, 0) points are the sensor's no-returns (counted in
  /// no_return_dropped, not in non_finite_dropped).
  void set_layout(bool rings, bool columns, bool organised) {
    rings_ = rings;
    columns_ = columns;
    organised_ = organised;
  }

  void add_at(float x, float y, float z, float i, const Rgb& c, std::uint16_t ring, std::uint32_t column) {
    const bool finite = std::isfinite(x) && std::isfinite(y) && std::isfinite(z);
    if (organised_ && (!finite || (x == 0.0F && y == 0.0F && z == 0.0F))) {
      ++r_.no_return_dropped;
      return;
    }
    const std::size_t before = r_.cloud.points.size();
    add(x, y, z, i, c);
    if (r_.cloud.points.size() == before) return;
    if (rings_) r_.cloud.ring.push_back(ring);
    if (columns_) r_.cloud.column.push_back(column);
  }

  /// A point whose coordinates are doubles (only in `wide` mode), with its laser and column
  /// as add_at records them.
  void add_wide(double x, double y, double z, float i = 0.0F, const Rgb& c = {}, std::uint16_t ring = 0,
                std::uint32_t column = 0) {
    const bool finite = std::isfinite(x) && std::isfinite(y) && std::isfinite(z);
    if (organised_ && (!finite || (x == 0.0 && y == 0.0 && z == 0.0))) {
      ++r_.no_return_dropped;
      return;
    }
    if (!finite) {
      ++r_.non_finite_dropped;
      return;
    }
    wide_points_.emplace_back(x, y, z);
    if (intensity_) r_.cloud.intensity.push_back(i);
    if (color_) r_.colors.push_back(c);
    if (time_) r_.cloud.time.push_back(next_time_);
    push_fields();
    if (rings_) r_.cloud.ring.push_back(ring);
    if (columns_) r_.cloud.column.push_back(column);
  }

  [[nodiscard]] bool wide() const { return wide_; }

  /// Ends the reading (read.cpp): in `wide` mode, chooses the georeference.
  Status finish(const std::string& path);

 private:
  void push_fields() {
    for (std::size_t k = 0; k < next_fields_.size(); ++k) r_.cloud.fields[k].values.push_back(next_fields_[k]);
  }
  /// Drops the named fields a value of which the field cannot keep (next_field), naming them
  /// in dropped_fields.
  void drop_unfit_fields();
  std::vector<std::int32_t> next_fields_;
  std::vector<bool> unfit_;
  bool time_ = false;
  double next_time_ = 0.0;
  double time_unit_ = 1.0;
  ReadResult& r_;
  bool intensity_;
  bool color_;
  bool rings_ = false;
  bool columns_ = false;
  bool organised_ = false;
  bool wide_;
  std::vector<Eigen::Vector3d> wide_points_;
};

// Each reader gets the whole file (`data`, `size` bytes, not empty), fills `r`
// (all but `format` and `file_bytes`) and returns the first error, a one-line
// message "<path>: <what>" with a byte offset where one is meaningful.

/// KITTI (`format` kKitti: x y z intensity) or x y z (kBinXyz) float32 records;
/// `detected` says the format was guessed, which the size error mentions.
Status read_float_binary(const std::string& path, const std::uint8_t* data, std::size_t size,
                         Format format, bool detected, ReadResult& r);  // read_bin.cpp

/// PCD v0.7: ascii, binary or binary_compressed.
Status read_pcd(const std::string& path, const std::uint8_t* data, std::size_t size,
                ReadResult& r);  // read_pcd.cpp

/// PLY: ascii, binary_little_endian or binary_big_endian.
Status read_ply(const std::string& path, const std::uint8_t* data, std::size_t size,
                ReadResult& r);  // read_ply.cpp

/// x y z text in metres, or (`uos`) 3DTK `.3d` in centimetres, left-handed.
Status read_text(const std::string& path, const std::uint8_t* data, std::size_t size, bool uos,
                 const ReadOptions& options, ReadResult& r);  // read_text.cpp

/// ASPRS LAS 1.0-1.4, point formats 0-10 (read_las.cpp).
Status read_las(const std::string& path, const std::uint8_t* data, std::size_t size,
                ReadResult& r);  // read_las.cpp

/// A LAS file of `cloud` (write_las.cpp): the version, point format, scale, offset and CRS
/// records of its georeference when it came from LAS, else LAS 1.2 format 0 (2 with colours).
/// The named fields of `cloud` (Cloud::fields) that build_las has no place for in the point
/// format it writes.
std::vector<std::string> las_fields_not_written(const Cloud& cloud, const WriteOptions& o);
Status build_las(const std::string& path, const Cloud& cloud, const WriteOptions& o,
                 std::vector<std::uint8_t>& out);  // write_las.cpp

}  // namespace lex3d::io::detail
