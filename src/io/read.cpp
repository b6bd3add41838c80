// Readers: KITTI / x y z float binaries, PCD (ascii, binary, binary_compressed),
// PLY (ascii, binary little/big endian), x y z text and 3DTK `.3d`.
//
// Every reader works on the whole file in memory and checks each length read
// from the file against the bytes left before it allocates or reads; errors
// are one-line messages "<path>: <what is wrong>" with a byte offset where one
// is meaningful.

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <limits>
#include <new>
#include <optional>

#include <pcl/io/lzf.h>

#include "io/internal.hpp"
#include "lex3d/io/io.hpp"

namespace lex3d::io {

using detail::msg;
using detail::printable;

namespace {

constexpr bool kHostBigEndian = __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__;
constexpr std::size_t kMaxHeaderBytes = 1U << 20;  // PCD / PLY header cap
constexpr std::size_t kMaxFields = 1U << 16;       // fields (PCD) / properties (PLY) cap
constexpr std::uint64_t kMaxFieldCount = 1U << 20; // PCD COUNT cap

using Rgb = std::array<std::uint8_t, 3>;

// ------------------------------------------------------------------ scalars

enum class Scalar : std::uint8_t { kI8, kU8, kI16, kU16, kI32, kU32, kI64, kU64, kF32, kF64 };

unsigned scalar_size(Scalar s) {
  switch (s) {
    case Scalar::kI8: case Scalar::kU8: return 1;
    case Scalar::kI16: case Scalar::kU16: return 2;
    case Scalar::kI32: case Scalar::kU32: case Scalar::kF32: return 4;
    case Scalar::kI64: case Scalar::kU64: case Scalar::kF64: return 8;
  }
  return 1;
}

bool scalar_is_integer(Scalar s) { return s != Scalar::kF32 && s != Scalar::kF64; }

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
double load_scalar(const std::uint8_t* p, Scalar s, bool swap) {
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
float load_float(const std::uint8_t* p, Scalar s, bool swap) {
  if (s == Scalar::kF32) return load<float>(p, swap);
  return static_cast<float>(load_scalar(p, s, swap));
}

/// The raw bits of a 4-byte value (for packed rgb fields).
std::uint32_t load_bits32(const std::uint8_t* p, bool swap) { return load<std::uint32_t>(p, swap); }

Rgb unpack_rgb(std::uint32_t v) {
  return {static_cast<std::uint8_t>((v >> 16) & 0xFFU), static_cast<std::uint8_t>((v >> 8) & 0xFFU),
          static_cast<std::uint8_t>(v & 0xFFU)};
}

std::uint8_t to_u8(double v) {
  if (!(v > 0.0)) return 0;  // also NaN
  if (v >= 255.0) return 255;
  return static_cast<std::uint8_t>(std::lround(v));
}

bool parse_u64(std::string_view s, std::uint64_t& out) {
  if (s.empty()) return false;
  auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), out);
  return ec == std::errc() && ptr == s.data() + s.size();
}

std::vector<std::string_view> split_ws(std::string_view line) {
  std::vector<std::string_view> out;
  detail::for_each_token(line, false, [&](const char* b, const char* e) {
    out.emplace_back(b, static_cast<std::size_t>(e - b));
    return true;
  });
  return out;
}

std::string quoted(std::string_view s) { return "'" + printable(s, 32) + "'"; }

// ------------------------------------------------------------------ output builder

/// Collects the finite points of a file into a ReadResult.
class Builder {
 public:
  Builder(ReadResult& r, bool intensity, bool color) : r_(r), intensity_(intensity), color_(color) {}

  void reserve(std::size_t n) {
    r_.cloud.points.reserve(n);
    if (intensity_) r_.cloud.intensity.reserve(n);
    if (color_) r_.colors.reserve(n);
  }

  void add(float x, float y, float z, float i = 0.0F, const Rgb& c = {}) {
    if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z)) {
      ++r_.non_finite_dropped;
      return;
    }
    r_.cloud.points.emplace_back(x, y, z);
    if (intensity_) r_.cloud.intensity.push_back(i);
    if (color_) r_.colors.push_back(c);
  }

 private:
  ReadResult& r_;
  bool intensity_;
  bool color_;
};

// ------------------------------------------------------------------ float binaries

Status read_float_binary(const std::string& path, const std::uint8_t* data, std::size_t size,
                         Format format, bool detected, ReadResult& r) {
  const std::size_t stride = format == Format::kKitti ? 16 : 12;
  if (size % stride != 0) {
    std::string what = "size " + std::to_string(size) + " is not a multiple of " +
                       std::to_string(stride) + " bytes";
    if (detected) {
      what += " (KITTI x y z intensity) nor of 12 bytes (x y z float32)";
    } else {
      what += format == Format::kKitti ? " (KITTI x y z intensity)" : " (x y z float32)";
    }
    return bad_data(msg(path, what), size - size % stride);
  }
  const std::size_t n = size / stride;
  r.encoding = "binary_little_endian";
  Builder b(r, format == Format::kKitti, false);
  b.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint8_t* p = data + i * stride;
    const float x = load<float>(p, kHostBigEndian);
    const float y = load<float>(p + 4, kHostBigEndian);
    const float z = load<float>(p + 8, kHostBigEndian);
    const float in = stride == 16 ? load<float>(p + 12, kHostBigEndian) : 0.0F;
    b.add(x, y, z, in);
  }
  return {};
}

// ------------------------------------------------------------------ PCD

struct PcdField {
  std::string name;
  unsigned size = 4;
  char type = 'F';
  std::uint64_t count = 1;
  Scalar scalar = Scalar::kF32;
  std::uint64_t offset = 0;  // byte offset within a row-major point
  std::uint64_t token = 0;   // first ascii column
};

char upper(char c) { return c >= 'a' && c <= 'z' ? static_cast<char>(c - 'a' + 'A') : c; }

bool pcd_scalar(char type, unsigned size, Scalar& out) {
  switch (type) {
    case 'F':
      if (size == 4) out = Scalar::kF32;
      else if (size == 8) out = Scalar::kF64;
      else return false;
      return true;
    case 'I':
      if (size == 1) out = Scalar::kI8;
      else if (size == 2) out = Scalar::kI16;
      else if (size == 4) out = Scalar::kI32;
      else if (size == 8) out = Scalar::kI64;
      else return false;
      return true;
    case 'U':
      if (size == 1) out = Scalar::kU8;
      else if (size == 2) out = Scalar::kU16;
      else if (size == 4) out = Scalar::kU32;
      else if (size == 8) out = Scalar::kU64;
      else return false;
      return true;
    default: return false;
  }
}

/// Where the fields the reader needs sit, and how to step from point to point.
struct PcdAccess {
  const PcdField* field = nullptr;
  std::uint64_t base = 0;    // byte offset of point 0's value in the data block
  std::uint64_t stride = 0;  // bytes from one point's value to the next
};

Status read_pcd(const std::string& path, const std::uint8_t* data, std::size_t size, ReadResult& r) {
  const char* text = reinterpret_cast<const char*>(data);
  const std::size_t header_limit = std::min(size, kMaxHeaderBytes);
  detail::LineCursor lines(text, text + header_limit);

  std::vector<std::string_view> names, sizes, types, counts;
  std::uint64_t width = 0, height = 1, points = 0;
  bool have_fields = false, have_size = false, have_type = false, have_count = false;
  bool have_width = false, have_height = false, have_points = false, have_data = false;
  std::string encoding;
  std::size_t data_start = 0;

  std::string_view line;
  while (lines.next(line)) {
    const std::string_view t = detail::trim(line);
    if (t.empty() || t.front() == '#') continue;
    const auto tok = split_ws(t);
    const std::string key = detail::to_lower(tok[0]);
    const std::string where = "header line " + std::to_string(lines.line_no()) + ": ";
    auto once = [&](bool& seen) -> bool {
      if (seen) return false;
      seen = true;
      return true;
    };
    auto dup = [&]() {
      return bad_data(msg(path, where + "duplicate " + printable(tok[0], 16)), lines.line_offset());
    };
    auto number = [&](std::uint64_t& out) -> Status {
      if (tok.size() != 2 || !parse_u64(tok[1], out)) {
        return bad_data(msg(path, where + printable(tok[0], 16) +
                                      " needs one non-negative integer, got " +
                                      quoted(detail::trim(t.substr(tok[0].size())))),
                        lines.line_offset());
      }
      return {};
    };
    if (key == "version") {
      continue;
    } else if (key == "fields" || key == "columns") {
      if (!once(have_fields)) return dup();
      names.assign(tok.begin() + 1, tok.end());
    } else if (key == "size") {
      if (!once(have_size)) return dup();
      sizes.assign(tok.begin() + 1, tok.end());
    } else if (key == "type") {
      if (!once(have_type)) return dup();
      types.assign(tok.begin() + 1, tok.end());
    } else if (key == "count") {
      if (!once(have_count)) return dup();
      counts.assign(tok.begin() + 1, tok.end());
    } else if (key == "width") {
      if (!once(have_width)) return dup();
      if (Status s = number(width); !s.ok()) return s;
    } else if (key == "height") {
      if (!once(have_height)) return dup();
      if (Status s = number(height); !s.ok()) return s;
    } else if (key == "points") {
      if (!once(have_points)) return dup();
      if (Status s = number(points); !s.ok()) return s;
    } else if (key == "viewpoint") {
      continue;  // readers leave T_cloud_sensor at identity (see cloud.hpp)
    } else if (key == "data") {
      if (tok.size() != 2) {
        return bad_data(msg(path, where + "DATA needs one of ascii, binary, binary_compressed"),
                        lines.line_offset());
      }
      encoding = detail::to_lower(tok[1]);
      if (encoding != "ascii" && encoding != "binary" && encoding != "binary_compressed") {
        return bad_data(msg(path, where + "unknown DATA encoding " + quoted(tok[1])),
                        lines.line_offset());
      }
      have_data = true;
      data_start = static_cast<std::size_t>(lines.position() - text);
      break;
    } else {
      return bad_data(msg(path, where + "unknown header keyword " + quoted(tok[0])),
                      lines.line_offset());
    }
  }
  if (!have_data) {
    if (size > kMaxHeaderBytes) {
      return bad_data(msg(path, "no DATA line in the first " + std::to_string(kMaxHeaderBytes) +
                                    " bytes (not a PCD header?)"));
    }
    return bad_data(msg(path, "header has no DATA line"), size);
  }
  // The DATA line of a binary file must end with '\n' (it is the data boundary).
  if (encoding != "ascii" && (data_start == 0 || text[data_start - 1] != '\n')) {
    return bad_data(msg(path, "DATA line has no end of line (truncated header?)"), data_start);
  }

  // --- fields
  if (!have_fields || names.empty()) return bad_data(msg(path, "header has no FIELDS"));
  if (names.size() > kMaxFields) {
    return bad_data(msg(path, "header declares " + std::to_string(names.size()) +
                                  " fields, more than the limit of " + std::to_string(kMaxFields)));
  }
  if (!have_size) return bad_data(msg(path, "header has no SIZE"));
  if (!have_type) return bad_data(msg(path, "header has no TYPE"));
  auto check_len = [&](const std::vector<std::string_view>& v, const char* what) -> Status {
    if (v.size() != names.size()) {
      return bad_data(msg(path, std::string("header inconsistent: ") + what + " has " +
                                    std::to_string(v.size()) + " entries, FIELDS has " +
                                    std::to_string(names.size())));
    }
    return {};
  };
  if (Status s = check_len(sizes, "SIZE"); !s.ok()) return s;
  if (Status s = check_len(types, "TYPE"); !s.ok()) return s;
  if (have_count) {
    if (Status s = check_len(counts, "COUNT"); !s.ok()) return s;
  }

  std::vector<PcdField> fields(names.size());
  std::uint64_t point_size = 0;
  std::uint64_t tokens_per_point = 0;
  for (std::size_t i = 0; i < names.size(); ++i) {
    PcdField& f = fields[i];
    f.name = std::string(names[i]);
    std::uint64_t sz = 0;
    if (!parse_u64(sizes[i], sz) || (sz != 1 && sz != 2 && sz != 4 && sz != 8)) {
      return bad_data(msg(path, "bad SIZE " + quoted(sizes[i]) + " for field " + quoted(names[i]) +
                                    " (must be 1, 2, 4 or 8)"));
    }
    f.size = static_cast<unsigned>(sz);
    if (types[i].size() != 1 || !pcd_scalar(upper(types[i][0]), f.size, f.scalar)) {
      return bad_data(msg(path, "bad TYPE " + quoted(types[i]) + " for field " + quoted(names[i]) +
                                    " of SIZE " + std::to_string(f.size)));
    }
    f.type = upper(types[i][0]);
    if (have_count) {
      if (!parse_u64(counts[i], f.count) || f.count == 0 || f.count > kMaxFieldCount) {
        return bad_data(msg(path, "bad COUNT " + quoted(counts[i]) + " for field " + quoted(names[i])));
      }
    }
    f.offset = point_size;
    f.token = tokens_per_point;
    point_size += f.size * f.count;
    tokens_per_point += f.count;
  }

  // --- sizes
  if (!have_width && !have_points) return bad_data(msg(path, "header has neither WIDTH nor POINTS"));
  if (!have_width) {
    width = points;
    height = 1;
  }
  if (height != 0 && width > std::numeric_limits<std::uint64_t>::max() / height) {
    return bad_data(msg(path, "absurd size: WIDTH " + std::to_string(width) + " x HEIGHT " +
                                  std::to_string(height) + " overflows"));
  }
  if (!have_points) points = width * height;
  if (points != width * height) {
    return bad_data(msg(path, "header inconsistent: WIDTH " + std::to_string(width) + " x HEIGHT " +
                                  std::to_string(height) + " != POINTS " + std::to_string(points)));
  }

  auto find = [&](std::initializer_list<const char*> wanted) -> const PcdField* {
    for (const char* w : wanted) {
      for (const PcdField& f : fields) {
        if (detail::to_lower(f.name) == w) return &f;
      }
    }
    return nullptr;
  };
  const PcdField* fx = find({"x"});
  const PcdField* fy = find({"y"});
  const PcdField* fz = find({"z"});
  if (fx == nullptr || fy == nullptr || fz == nullptr) {
    return bad_data(msg(path, std::string("header has no '") +
                                  (fx == nullptr ? "x" : fy == nullptr ? "y" : "z") + "' field"));
  }
  const PcdField* fi = find({"intensity"});
  const PcdField* fc = find({"rgb", "rgba"});
  if (fc != nullptr && fc->size != 4) fc = nullptr;  // only packed 32-bit colours

  r.encoding = encoding;
  const std::uint64_t avail = size - data_start;
  Builder out(r, fi != nullptr, fc != nullptr);

  // --- ascii
  if (encoding == "ascii") {
    // each value takes at least one character and one separator
    if (points > (avail + 1) / (2 * tokens_per_point)) {
      return bad_data(msg(path, "truncated ascii data: " + std::to_string(avail) +
                                    " bytes cannot hold the " + std::to_string(points) +
                                    " points the header declares"),
                      size);
    }
    out.reserve(static_cast<std::size_t>(points));
    detail::LineCursor data_lines(text + data_start, text + size);
    const std::uint64_t first_line = lines.line_no() + 1;
    std::uint64_t done = 0;
    std::string_view dl;
    while (done < points && data_lines.next(dl)) {
      const std::string_view t = detail::trim(dl);
      if (t.empty()) continue;
      float v[4] = {0.0F, 0.0F, 0.0F, 0.0F};
      std::uint32_t rgb_bits = 0;
      std::uint64_t k = 0;
      const char* bad_b = nullptr;
      const char* bad_e = nullptr;
      detail::for_each_token(t, false, [&](const char* b, const char* e) {
        bool ok = true;
        if (fc != nullptr && k == fc->token) {
          // PCL writes the packed rgb float as its unsigned integer bits
          std::uint64_t u = 0;
          const std::string_view tokv(b, static_cast<std::size_t>(e - b));
          if (parse_u64(tokv, u) && u <= 0xFFFFFFFFULL) {
            rgb_bits = static_cast<std::uint32_t>(u);
          } else {
            float fv = 0.0F;
            ok = detail::parse_number(b, e, fv);
            std::memcpy(&rgb_bits, &fv, 4);
          }
        } else {
          int slot = -1;
          if (k == fx->token) slot = 0;
          else if (k == fy->token) slot = 1;
          else if (k == fz->token) slot = 2;
          else if (fi != nullptr && k == fi->token) slot = 3;
          if (slot >= 0) {
            ok = detail::parse_number(b, e, v[slot]);
          } else {
            double dv = 0.0;
            ok = detail::parse_number(b, e, dv);
          }
        }
        if (!ok) {
          bad_b = b;
          bad_e = e;
          return false;
        }
        ++k;
        return true;
      });
      const std::uint64_t line_no = first_line + data_lines.line_no() - 1;
      const std::uint64_t off = data_start + data_lines.line_offset();
      if (bad_b != nullptr) {
        return bad_data(msg(path, "line " + std::to_string(line_no) + ": " +
                                      quoted(std::string_view(bad_b, static_cast<std::size_t>(bad_e - bad_b))) +
                                      " is not a number"),
                        off);
      }
      if (k != tokens_per_point) {
        return bad_data(msg(path, "line " + std::to_string(line_no) + ": expected " +
                                      std::to_string(tokens_per_point) + " values, found " +
                                      std::to_string(k)),
                        off);
      }
      out.add(v[0], v[1], v[2], v[3], unpack_rgb(rgb_bits));
      ++done;
    }
    if (done < points) {
      return bad_data(msg(path, "truncated ascii data: " + std::to_string(done) +
                                    " points, header says " + std::to_string(points)),
                      size);
    }
    return {};
  }

  // --- binary and binary_compressed: the data block
  if (points > std::numeric_limits<std::uint64_t>::max() / point_size) {
    return bad_data(msg(path, "absurd size: " + std::to_string(points) + " points of " +
                                  std::to_string(point_size) + " bytes"));
  }
  const std::uint64_t need = points * point_size;
  const std::uint8_t* block = nullptr;
  std::vector<std::uint8_t> decompressed;
  bool column_major = false;
  if (encoding == "binary") {
    if (need > avail) {
      return bad_data(msg(path, "truncated binary data: " + std::to_string(avail) +
                                    " bytes, header says " + std::to_string(need) + " (" +
                                    std::to_string(points) + " points x " +
                                    std::to_string(point_size) + " bytes)"),
                      size);
    }
    block = data + data_start;
  } else {
    if (avail < 8) {
      return bad_data(msg(path, "truncated binary_compressed data: " + std::to_string(avail) +
                                    " bytes, the 8-byte size header is missing"),
                      size);
    }
    const std::uint32_t comp = load<std::uint32_t>(data + data_start, kHostBigEndian);
    const std::uint32_t uncomp = load<std::uint32_t>(data + data_start + 4, kHostBigEndian);
    if (uncomp != need) {
      return bad_data(msg(path, "header inconsistent: compressed block unpacks to " +
                                    std::to_string(uncomp) + " bytes, header says " +
                                    std::to_string(need) + " (" + std::to_string(points) +
                                    " points x " + std::to_string(point_size) + " bytes)"),
                      data_start + 4);
    }
    if (comp > avail - 8) {
      return bad_data(msg(path, "truncated binary_compressed data: " + std::to_string(avail - 8) +
                                    " bytes, header says " + std::to_string(comp)),
                      size);
    }
    if (need > 0) {
      // LZF expands at most ~88x (264 bytes from a 3-byte back reference)
      if (comp == 0 || need > static_cast<std::uint64_t>(comp) * 100U + 64U) {
        return bad_data(msg(path, "corrupt binary_compressed data: " + std::to_string(comp) +
                                      " compressed bytes cannot unpack to " + std::to_string(need)),
                        data_start);
      }
      decompressed.resize(static_cast<std::size_t>(need));
      const unsigned got = pcl::lzfDecompress(data + data_start + 8, comp, decompressed.data(),
                                              static_cast<unsigned>(need));
      if (got != need) {
        return bad_data(msg(path, "corrupt binary_compressed data: LZF unpacked " +
                                      std::to_string(got) + " of " + std::to_string(need) + " bytes"),
                        data_start + 8);
      }
    }
    block = decompressed.data();
    column_major = true;
  }

  auto access = [&](const PcdField* f) {
    PcdAccess a;
    a.field = f;
    if (f == nullptr) return a;
    if (column_major) {
      // binary_compressed: all values of field 0, then of field 1, ...
      a.base = points * f->offset;
      a.stride = f->size * f->count;
    } else {
      a.base = f->offset;
      a.stride = point_size;
    }
    return a;
  };
  const PcdAccess ax = access(fx), ay = access(fy), az = access(fz), ai = access(fi), ac = access(fc);
  out.reserve(static_cast<std::size_t>(points));
  const bool swap = kHostBigEndian;
  for (std::uint64_t i = 0; i < points; ++i) {
    const float x = load_float(block + ax.base + i * ax.stride, fx->scalar, swap);
    const float y = load_float(block + ay.base + i * ay.stride, fy->scalar, swap);
    const float z = load_float(block + az.base + i * az.stride, fz->scalar, swap);
    const float in = fi != nullptr ? load_float(block + ai.base + i * ai.stride, fi->scalar, swap) : 0.0F;
    Rgb c{};
    if (fc != nullptr) c = unpack_rgb(load_bits32(block + ac.base + i * ac.stride, swap));
    out.add(x, y, z, in, c);
  }
  return {};
}

// ------------------------------------------------------------------ PLY

struct PlyProperty {
  std::string name;
  bool is_list = false;
  Scalar type = Scalar::kF32;        // value type (item type for lists)
  Scalar count_type = Scalar::kU8;   // lists only
};

struct PlyElement {
  std::string name;
  std::uint64_t count = 0;
  std::vector<PlyProperty> props;
};

bool ply_scalar(std::string_view name, Scalar& out) {
  static const std::pair<const char*, Scalar> kTypes[] = {
      {"char", Scalar::kI8},     {"int8", Scalar::kI8},     {"uchar", Scalar::kU8},
      {"uint8", Scalar::kU8},    {"short", Scalar::kI16},   {"int16", Scalar::kI16},
      {"ushort", Scalar::kU16},  {"uint16", Scalar::kU16},  {"int", Scalar::kI32},
      {"int32", Scalar::kI32},   {"uint", Scalar::kU32},    {"uint32", Scalar::kU32},
      {"float", Scalar::kF32},   {"float32", Scalar::kF32}, {"double", Scalar::kF64},
      {"float64", Scalar::kF64}};
  for (const auto& [n, s] : kTypes) {
    if (name == n) {
      out = s;
      return true;
    }
  }
  return false;
}

/// Bounds-checked cursor over binary PLY data.
class BinCursor {
 public:
  BinCursor(const std::uint8_t* begin, const std::uint8_t* p, const std::uint8_t* end, bool swap)
      : begin_(begin), p_(p), end_(end), swap_(swap) {}
  [[nodiscard]] std::uint64_t left() const { return static_cast<std::uint64_t>(end_ - p_); }
  [[nodiscard]] std::uint64_t offset() const { return static_cast<std::uint64_t>(p_ - begin_); }
  bool skip(std::uint64_t n) {
    if (n > left()) return false;
    p_ += n;
    return true;
  }
  bool scalar(Scalar s, double& v) {
    const unsigned n = scalar_size(s);
    if (n > left()) return false;
    v = load_scalar(p_, s, swap_);
    p_ += n;
    return true;
  }
  bool as_float(Scalar s, float& v) {
    const unsigned n = scalar_size(s);
    if (n > left()) return false;
    v = load_float(p_, s, swap_);
    p_ += n;
    return true;
  }
  /// A list length: an integer type, non-negative.
  bool list_count(Scalar s, std::uint64_t& n) {
    double v = 0.0;
    if (!scalar(s, v)) return false;
    if (!(v >= 0.0) || v > 9.0e15) return false;
    n = static_cast<std::uint64_t>(v);
    return true;
  }
  [[nodiscard]] const std::uint8_t* ptr() const { return p_; }

 private:
  const std::uint8_t* begin_;
  const std::uint8_t* p_;
  const std::uint8_t* end_;
  bool swap_;
};

/// Token cursor over ascii PLY data, tracking lines for messages.
class TokenCursor {
 public:
  TokenCursor(const char* begin, const char* p, const char* end, std::uint64_t line)
      : begin_(begin), p_(p), end_(end), line_(line) {}
  bool next(const char*& b, const char*& e) {
    while (p_ < end_ && (detail::is_space(*p_) || *p_ == '\n')) {
      if (*p_ == '\n') ++line_;
      ++p_;
    }
    if (p_ >= end_) return false;
    b = p_;
    while (p_ < end_ && !detail::is_space(*p_) && *p_ != '\n') ++p_;
    e = p_;
    return true;
  }
  [[nodiscard]] std::uint64_t line() const { return line_; }
  [[nodiscard]] std::uint64_t offset() const { return static_cast<std::uint64_t>(p_ - begin_); }
  [[nodiscard]] std::uint64_t left() const { return static_cast<std::uint64_t>(end_ - p_); }

 private:
  const char* begin_;
  const char* p_;
  const char* end_;
  std::uint64_t line_;
};

bool name_is(const std::string& name, std::initializer_list<const char*> options) {
  const std::string l = detail::to_lower(name);
  for (const char* o : options) {
    if (l == o) return true;
  }
  return false;
}

Status read_ply(const std::string& path, const std::uint8_t* data, std::size_t size, ReadResult& r) {
  const char* text = reinterpret_cast<const char*>(data);
  const std::size_t header_limit = std::min(size, kMaxHeaderBytes);
  detail::LineCursor lines(text, text + header_limit);
  std::string_view line;
  if (!lines.next(line) || line != "ply") return bad_data(msg(path, "not a PLY file (no 'ply' magic line)"), 0);

  std::string format;
  std::vector<PlyElement> elements;
  bool end_header = false;
  std::size_t data_start = 0;
  std::size_t total_props = 0;
  while (lines.next(line)) {
    const std::string where = "header line " + std::to_string(lines.line_no()) + ": ";
    const std::string_view t = detail::trim(line);
    if (t.empty()) continue;
    const auto tok = split_ws(t);
    const std::string_view key = tok[0];
    if (key == "end_header") {
      data_start = static_cast<std::size_t>(lines.position() - text);
      // the file may end right after "end_header"; otherwise the line must be complete
      if (text[data_start - 1] != '\n' && data_start < size) {
        return bad_data(msg(path, "header longer than " + std::to_string(kMaxHeaderBytes) + " bytes"),
                        data_start);
      }
      end_header = true;
      break;
    }
    if (key == "comment" || key == "obj_info") continue;
    if (key == "format") {
      if (tok.size() < 2) return bad_data(msg(path, where + "format has no value"), lines.line_offset());
      format = std::string(tok[1]);
      if (format != "ascii" && format != "binary_little_endian" && format != "binary_big_endian") {
        return bad_data(msg(path, where + "unknown format " + quoted(tok[1])), lines.line_offset());
      }
    } else if (key == "element") {
      std::uint64_t n = 0;
      if (tok.size() != 3 || !parse_u64(tok[2], n)) {
        return bad_data(msg(path, where + "element needs a name and a non-negative count, got " +
                                      quoted(t)),
                        lines.line_offset());
      }
      if (elements.size() >= kMaxFields) return bad_data(msg(path, where + "too many elements"));
      elements.push_back({std::string(tok[1]), n, {}});
    } else if (key == "property") {
      if (elements.empty()) {
        return bad_data(msg(path, where + "property before any element"), lines.line_offset());
      }
      if (++total_props > kMaxFields) return bad_data(msg(path, where + "too many properties"));
      PlyProperty p;
      if (tok.size() == 5 && tok[1] == "list") {
        p.is_list = true;
        if (!ply_scalar(tok[2], p.count_type) || !scalar_is_integer(p.count_type) ||
            !ply_scalar(tok[3], p.type)) {
          return bad_data(msg(path, where + "bad list property " + quoted(t)), lines.line_offset());
        }
        p.name = std::string(tok[4]);
      } else if (tok.size() == 3) {
        if (!ply_scalar(tok[1], p.type)) {
          return bad_data(msg(path, where + "unknown property type " + quoted(tok[1])),
                          lines.line_offset());
        }
        p.name = std::string(tok[2]);
      } else {
        return bad_data(msg(path, where + "bad property line " + quoted(t)), lines.line_offset());
      }
      elements.back().props.push_back(std::move(p));
    } else {
      return bad_data(msg(path, where + "unknown header keyword " + quoted(key)), lines.line_offset());
    }
  }
  if (!end_header) {
    if (size > kMaxHeaderBytes) {
      return bad_data(msg(path, "header has no 'end_header' in the first " +
                                    std::to_string(kMaxHeaderBytes) + " bytes"));
    }
    return bad_data(msg(path, "header has no 'end_header'"), size);
  }
  if (format.empty()) return bad_data(msg(path, "header has no 'format' line"));

  std::size_t vi = elements.size();
  for (std::size_t i = 0; i < elements.size(); ++i) {
    if (elements[i].name == "vertex") {
      vi = i;
      break;
    }
  }
  if (vi == elements.size()) return bad_data(msg(path, "header has no 'vertex' element"));
  const PlyElement& vertex = elements[vi];
  int ix = -1, iy = -1, iz = -1, ii = -1, ir = -1, ig = -1, ib = -1;
  for (std::size_t k = 0; k < vertex.props.size(); ++k) {
    const PlyProperty& p = vertex.props[k];
    const int kk = static_cast<int>(k);
    if (p.is_list) continue;
    if (p.name == "x" && ix < 0) ix = kk;
    else if (p.name == "y" && iy < 0) iy = kk;
    else if (p.name == "z" && iz < 0) iz = kk;
    else if (ii < 0 && name_is(p.name, {"intensity", "scalar_intensity", "reflectance"})) ii = kk;
    else if (ir < 0 && name_is(p.name, {"red", "diffuse_red"})) ir = kk;
    else if (ig < 0 && name_is(p.name, {"green", "diffuse_green"})) ig = kk;
    else if (ib < 0 && name_is(p.name, {"blue", "diffuse_blue"})) ib = kk;
  }
  if (ix < 0 || iy < 0 || iz < 0) {
    return bad_data(msg(path, std::string("vertex element has no '") +
                                  (ix < 0 ? "x" : iy < 0 ? "y" : "z") + "' property"));
  }
  const bool color = ir >= 0 && ig >= 0 && ib >= 0;
  r.encoding = format;
  Builder out(r, ii >= 0, color);
  const std::size_t nprops = vertex.props.size();

  // ---------------- ascii
  if (format == "ascii") {
    TokenCursor tc(text, text + data_start, text + size, lines.line_no() + 1);
    const char* b = nullptr;
    const char* e = nullptr;
    auto truncated = [&](const PlyElement& el, std::uint64_t item) {
      return bad_data(msg(path, "truncated ascii data: element '" + printable(el.name, 32) +
                                    "' item " + std::to_string(item) + " of " +
                                    std::to_string(el.count) + " is incomplete"),
                      size);
    };
    auto not_number = [&]() {
      return bad_data(msg(path, "line " + std::to_string(tc.line()) + ": " +
                                    quoted(std::string_view(b, static_cast<std::size_t>(e - b))) +
                                    " is not a number"),
                      static_cast<std::uint64_t>(b - text));
    };
    auto read_list_count = [&](std::uint64_t& n) -> bool {
      double v = 0.0;
      if (!detail::parse_number(b, e, v) || !(v >= 0.0) || v != std::floor(v) || v > 9.0e15) return false;
      n = static_cast<std::uint64_t>(v);
      return true;
    };
    for (std::size_t el = 0; el < vi; ++el) {
      const PlyElement& E = elements[el];
      if (E.props.empty()) continue;
      for (std::uint64_t item = 0; item < E.count; ++item) {
        for (const PlyProperty& p : E.props) {
          if (!tc.next(b, e)) return truncated(E, item);
          if (p.is_list) {
            std::uint64_t n = 0;
            if (!read_list_count(n)) {
              return bad_data(msg(path, "line " + std::to_string(tc.line()) + ": bad list length " +
                                            quoted(std::string_view(b, static_cast<std::size_t>(e - b)))),
                              static_cast<std::uint64_t>(b - text));
            }
            for (std::uint64_t j = 0; j < n; ++j) {
              if (!tc.next(b, e)) return truncated(E, item);
            }
          } else {
            double v = 0.0;
            if (!detail::parse_number(b, e, v)) return not_number();
          }
        }
      }
    }
    // each vertex needs at least one character and one separator per property
    if (vertex.count > (tc.left() + 1) / (2 * nprops)) {
      return bad_data(msg(path, "truncated ascii data: " + std::to_string(tc.left()) +
                                    " bytes cannot hold the " + std::to_string(vertex.count) +
                                    " vertices the header declares"),
                      size);
    }
    out.reserve(static_cast<std::size_t>(vertex.count));
    for (std::uint64_t item = 0; item < vertex.count; ++item) {
      float v[4] = {0.0F, 0.0F, 0.0F, 0.0F};
      double c[3] = {0.0, 0.0, 0.0};
      for (std::size_t k = 0; k < nprops; ++k) {
        const PlyProperty& p = vertex.props[k];
        if (!tc.next(b, e)) {
          return bad_data(msg(path, "truncated ascii data: vertex " + std::to_string(item) + " of " +
                                        std::to_string(vertex.count) + " is incomplete"),
                          size);
        }
        if (p.is_list) {
          std::uint64_t n = 0;
          if (!read_list_count(n)) {
            return bad_data(msg(path, "line " + std::to_string(tc.line()) + ": bad list length " +
                                          quoted(std::string_view(b, static_cast<std::size_t>(e - b)))),
                            static_cast<std::uint64_t>(b - text));
          }
          for (std::uint64_t j = 0; j < n; ++j) {
            if (!tc.next(b, e)) {
              return bad_data(msg(path, "truncated ascii data: vertex " + std::to_string(item) +
                                            " is incomplete"),
                              size);
            }
          }
          continue;
        }
        const int kk = static_cast<int>(k);
        bool ok = true;
        if (kk == ix) ok = detail::parse_number(b, e, v[0]);
        else if (kk == iy) ok = detail::parse_number(b, e, v[1]);
        else if (kk == iz) ok = detail::parse_number(b, e, v[2]);
        else if (kk == ii) ok = detail::parse_number(b, e, v[3]);
        else if (color && kk == ir) ok = detail::parse_number(b, e, c[0]);
        else if (color && kk == ig) ok = detail::parse_number(b, e, c[1]);
        else if (color && kk == ib) ok = detail::parse_number(b, e, c[2]);
        else {
          double dv = 0.0;
          ok = detail::parse_number(b, e, dv);
        }
        if (!ok) return not_number();
      }
      out.add(v[0], v[1], v[2], v[3], Rgb{to_u8(c[0]), to_u8(c[1]), to_u8(c[2])});
    }
    return {};
  }

  // ---------------- binary
  const bool big = format == "binary_big_endian";
  const bool swap = big != kHostBigEndian;
  BinCursor bc(data, data + data_start, data + size, swap);
  for (std::size_t el = 0; el < vi; ++el) {
    const PlyElement& E = elements[el];
    if (E.props.empty()) continue;
    std::uint64_t fixed = 0;
    bool has_list = false;
    for (const PlyProperty& p : E.props) {
      if (p.is_list) has_list = true;
      else fixed += scalar_size(p.type);
    }
    auto truncated = [&](std::uint64_t item) {
      return bad_data(msg(path, "truncated binary data: element '" + printable(E.name, 32) +
                                    "' item " + std::to_string(item) + " of " +
                                    std::to_string(E.count) + " ends past the end of the file"),
                      size);
    };
    if (!has_list) {
      if (E.count > bc.left() / fixed) return truncated(bc.left() / fixed);
      bc.skip(E.count * fixed);
      continue;
    }
    for (std::uint64_t item = 0; item < E.count; ++item) {  // each item takes >= 1 byte
      for (const PlyProperty& p : E.props) {
        if (p.is_list) {
          std::uint64_t n = 0;
          if (!bc.list_count(p.count_type, n)) return truncated(item);
          if (n > bc.left() / scalar_size(p.type)) return truncated(item);
          bc.skip(n * scalar_size(p.type));
        } else if (!bc.skip(scalar_size(p.type))) {
          return truncated(item);
        }
      }
    }
  }

  std::uint64_t fixed = 0;
  bool has_list = false;
  std::vector<std::uint64_t> offsets(nprops, 0);
  for (std::size_t k = 0; k < nprops; ++k) {
    const PlyProperty& p = vertex.props[k];
    offsets[k] = fixed;
    if (p.is_list) {
      has_list = true;
      fixed += scalar_size(p.count_type);
    } else {
      fixed += scalar_size(p.type);
    }
  }
  // `fixed` is the exact vertex size without lists, a lower bound with them
  if (vertex.count > bc.left() / fixed) {
    return bad_data(msg(path, "truncated binary data: " + std::to_string(bc.left()) +
                                  " bytes left for " + std::to_string(vertex.count) +
                                  " vertices of " + std::string(has_list ? "at least " : "") +
                                  std::to_string(fixed) + " bytes"),
                    size);
  }
  out.reserve(static_cast<std::size_t>(vertex.count));
  if (!has_list) {
    const std::uint8_t* base = bc.ptr();
    const auto sx = vertex.props[static_cast<std::size_t>(ix)].type;
    const auto sy = vertex.props[static_cast<std::size_t>(iy)].type;
    const auto sz = vertex.props[static_cast<std::size_t>(iz)].type;
    for (std::uint64_t item = 0; item < vertex.count; ++item) {
      const std::uint8_t* p = base + item * fixed;
      const float x = load_float(p + offsets[static_cast<std::size_t>(ix)], sx, swap);
      const float y = load_float(p + offsets[static_cast<std::size_t>(iy)], sy, swap);
      const float z = load_float(p + offsets[static_cast<std::size_t>(iz)], sz, swap);
      float in = 0.0F;
      if (ii >= 0) {
        in = load_float(p + offsets[static_cast<std::size_t>(ii)],
                        vertex.props[static_cast<std::size_t>(ii)].type, swap);
      }
      Rgb c{};
      if (color) {
        const int idx[3] = {ir, ig, ib};
        for (int ch = 0; ch < 3; ++ch) {
          const auto u = static_cast<std::size_t>(idx[ch]);
          c[static_cast<std::size_t>(ch)] = to_u8(load_scalar(p + offsets[u], vertex.props[u].type, swap));
        }
      }
      out.add(x, y, z, in, c);
    }
    return {};
  }
  for (std::uint64_t item = 0; item < vertex.count; ++item) {
    float v[4] = {0.0F, 0.0F, 0.0F, 0.0F};
    double c[3] = {0.0, 0.0, 0.0};
    for (std::size_t k = 0; k < nprops; ++k) {
      const PlyProperty& p = vertex.props[k];
      const int kk = static_cast<int>(k);
      bool ok = true;
      if (p.is_list) {
        std::uint64_t n = 0;
        ok = bc.list_count(p.count_type, n) && n <= bc.left() / scalar_size(p.type) &&
             bc.skip(n * scalar_size(p.type));
      } else if (kk == ix) ok = bc.as_float(p.type, v[0]);
      else if (kk == iy) ok = bc.as_float(p.type, v[1]);
      else if (kk == iz) ok = bc.as_float(p.type, v[2]);
      else if (kk == ii) ok = bc.as_float(p.type, v[3]);
      else if (color && kk == ir) ok = bc.scalar(p.type, c[0]);
      else if (color && kk == ig) ok = bc.scalar(p.type, c[1]);
      else if (color && kk == ib) ok = bc.scalar(p.type, c[2]);
      else ok = bc.skip(scalar_size(p.type));
      if (!ok) {
        return bad_data(msg(path, "truncated binary data: vertex " + std::to_string(item) + " of " +
                                      std::to_string(vertex.count) + " ends past the end of the file"),
                        bc.offset());
      }
    }
    out.add(v[0], v[1], v[2], v[3], Rgb{to_u8(c[0]), to_u8(c[1]), to_u8(c[2])});
  }
  return {};
}

// ------------------------------------------------------------------ text (xyz, .3d)

/// Column index of an intensity column in a header line "x y z ...", or -1.
bool parse_text_header(std::string_view line, int& intensity_col, std::size_t& columns) {
  std::vector<std::string> names;
  detail::for_each_token(line, true, [&](const char* b, const char* e) {
    names.push_back(detail::to_lower(std::string_view(b, static_cast<std::size_t>(e - b))));
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

/// x y z text (metres) or 3DTK `.3d` (centimetres, left-handed; see below).
Status read_text(const std::string& path, const std::uint8_t* data, std::size_t size, bool uos,
                 const ReadOptions& options, ReadResult& r) {
  const char* text = reinterpret_cast<const char*>(data);
  if (std::memchr(text, '\0', size) != nullptr) {
    const auto off = static_cast<std::uint64_t>(static_cast<const char*>(std::memchr(text, '\0', size)) - text);
    return bad_data(msg(path, "not a text file (NUL byte)"), off);
  }
  r.encoding = "ascii";
  detail::LineCursor lines(text, text + size);
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
    const std::string_view t = detail::trim(line);
    if (t.empty() || t.front() == '#') continue;
    if (first) {
      first = false;
      std::size_t header_cols = 0;
      if (parse_text_header(t, intensity_col, header_cols)) {
        columns = header_cols;
        columns_line = lines.line_no();
        out.emplace(r, intensity_col >= 0, false);
        out->reserve(estimate);
        continue;
      }
    }
    double v[4] = {0.0, 0.0, 0.0, 0.0};
    float f[4] = {0.0F, 0.0F, 0.0F, 0.0F};
    std::size_t k = 0;
    const char* bad_b = nullptr;
    const char* bad_e = nullptr;
    detail::for_each_token(t, true, [&](const char* b, const char* e) {
      bool ok = true;
      int slot = -1;
      if (k < 3) slot = static_cast<int>(k);
      else if (intensity_col >= 0 ? k == static_cast<std::size_t>(intensity_col)
                                  : (columns == 0 || columns == 4) && k == 3) slot = 3;
      if (slot >= 0 && !uos) ok = detail::parse_number(b, e, f[slot]);
      else if (slot >= 0) ok = detail::parse_number(b, e, v[slot]);
      else {
        double dv = 0.0;
        ok = detail::parse_number(b, e, dv);
      }
      if (!ok) {
        bad_b = b;
        bad_e = e;
        return false;
      }
      ++k;
      return true;
    });
    if (bad_b != nullptr) {
      return bad_data(msg(path, "line " + std::to_string(lines.line_no()) + ": " +
                                    quoted(std::string_view(bad_b, static_cast<std::size_t>(bad_e - bad_b))) +
                                    " is not a number"),
                      lines.line_offset());
    }
    if (k < 3) {
      return bad_data(msg(path, "line " + std::to_string(lines.line_no()) + ": expected at least 3 numbers (x y z), found " +
                                    std::to_string(k)),
                      lines.line_offset());
    }
    if (columns == 0) {
      columns = k;
      columns_line = lines.line_no();
      // without a header, a fourth column of exactly four is the intensity
      if (k == 4) intensity_col = 3;
      out.emplace(r, intensity_col >= 0, false);
      out->reserve(estimate);
    } else if (k != columns) {
      return bad_data(msg(path, "line " + std::to_string(lines.line_no()) + ": " + std::to_string(k) +
                                    " values, but line " + std::to_string(columns_line) + " has " +
                                    std::to_string(columns)),
                      lines.line_offset());
    }
    if (!uos) {
      out->add(f[0], f[1], f[2], f[3]);
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
    const Eigen::Vector3d p = detail::uos_to_lex3d(v[0], v[1], v[2]);
    if (range >= no_return) {
      ++r.no_return_dropped;
      if (range > 0.0) r.cloud.no_return_directions.push_back((p / (range / 100.0)).cast<float>());
      continue;
    }
    out->add(static_cast<float>(p.x()), static_cast<float>(p.y()), static_cast<float>(p.z()),
             static_cast<float>(v[3]));
  }
  return {};
}

/// `<dir>/<stem>.pose` for `<dir>/<stem>.3d`.
std::string pose_path_for(const std::string& path) {
  const std::size_t slash = path.find_last_of('/');
  const std::size_t dot = path.find_last_of('.');
  if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return path + ".pose";
  return path.substr(0, dot) + ".pose";
}

StatusOr<ReadResult> read_cloud_impl(const std::string& path, const ReadOptions& options) {
  auto file = read_file(path);
  if (!file.ok()) return file.status();
  const std::vector<std::uint8_t>& bytes = file.value();
  ReadResult r;
  r.file_bytes = bytes.size();
  if (bytes.empty()) return bad_data(msg(path, "file is empty"), 0);
  Format f = options.format;
  const bool detected = f == Format::kAuto;
  if (detected) {
    auto d = detail::detect_from_bytes(path, bytes.data(), std::min<std::size_t>(bytes.size(), 4096),
                                       bytes.size());
    if (!d.ok()) return d.status();
    f = d.value();
  }
  r.format = f;
  Status s;
  switch (f) {
    case Format::kKitti:
    case Format::kBinXyz:
      s = read_float_binary(path, bytes.data(), bytes.size(), f, detected, r);
      break;
    case Format::kPcd: s = read_pcd(path, bytes.data(), bytes.size(), r); break;
    case Format::kPly: s = read_ply(path, bytes.data(), bytes.size(), r); break;
    case Format::kXyz: s = read_text(path, bytes.data(), bytes.size(), false, options, r); break;
    case Format::kUos3d: s = read_text(path, bytes.data(), bytes.size(), true, options, r); break;
    case Format::kAuto: s = bad_data(msg(path, "cannot tell the format")); break;
  }
  if (!s.ok()) return s;
  if (f == Format::kUos3d && options.load_pose) {
    const std::string pose_path = pose_path_for(path);
    struct stat st {};
    if (::stat(pose_path.c_str(), &st) == 0) {
      auto pose = detail::read_uos_pose(pose_path);
      if (!pose.ok()) return pose.status();
      r.cloud.T_world_cloud = pose.value();
      r.cloud.has_world_pose = true;
    }
  }
  return r;
}

}  // namespace

StatusOr<std::vector<std::uint8_t>> read_file(const std::string& path, std::uint64_t max_bytes) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return io_error(msg(path, std::string("cannot open: ") + std::strerror(errno)));
  struct Closer {
    int fd;
    ~Closer() { ::close(fd); }
  } closer{fd};
  struct stat st {};
  if (::fstat(fd, &st) != 0) return io_error(msg(path, std::string("cannot stat: ") + std::strerror(errno)));
  if (S_ISDIR(st.st_mode)) return io_error(msg(path, "is a directory"));
  auto too_big = [&]() {
    return bad_data(msg(path, "file is larger than the limit of " + std::to_string(max_bytes) + " bytes"));
  };
  std::vector<std::uint8_t> buf;
  try {
    std::size_t want = 0;
    if (S_ISREG(st.st_mode)) {
      const auto sz = static_cast<std::uint64_t>(st.st_size);
      if (sz > max_bytes) return too_big();
      want = static_cast<std::size_t>(sz);
    }
    buf.resize(want);
    std::size_t got = 0;
    while (got < buf.size()) {
      const ssize_t r = ::read(fd, buf.data() + got, buf.size() - got);
      if (r < 0 && errno == EINTR) continue;
      if (r < 0) return io_error(msg(path, std::string("cannot read: ") + std::strerror(errno)));
      if (r == 0) break;  // the file shrank
      got += static_cast<std::size_t>(r);
    }
    if (got == buf.size()) {
      // the file grew, or it is a pipe: read the rest in chunks
      std::array<std::uint8_t, 1U << 14> chunk{};
      for (;;) {
        const ssize_t r = ::read(fd, chunk.data(), chunk.size());
        if (r < 0 && errno == EINTR) continue;
        if (r < 0) return io_error(msg(path, std::string("cannot read: ") + std::strerror(errno)));
        if (r == 0) break;
        const auto n = static_cast<std::size_t>(r);
        if (got + n > max_bytes) return too_big();
        buf.insert(buf.end(), chunk.begin(), chunk.begin() + r);
        got += n;
      }
    }
    buf.resize(got);
  } catch (const std::bad_alloc&) {
    return io_error(msg(path, "out of memory reading the file"));
  }
  return buf;
}

StatusOr<ReadResult> read_cloud(const std::string& path, const ReadOptions& options) {
  try {
    return read_cloud_impl(path, options);
  } catch (const std::bad_alloc&) {
    return io_error(msg(path, "out of memory reading the point cloud"));
  } catch (const std::length_error&) {
    return io_error(msg(path, "out of memory reading the point cloud"));
  }
}

}  // namespace lex3d::io
