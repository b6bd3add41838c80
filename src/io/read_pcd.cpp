// Reader of PCL's PCD v0.7 files: ascii, binary and binary_compressed (LZF,
// column-major). Every length read from the header is checked against the
// bytes left before anything is allocated.

#include <algorithm>
#include <cmath>
#include <cstring>
#include <initializer_list>
#include <limits>
#include <string>
#include <vector>

#include <lzf.h>

#include "io/internal.hpp"
#include "lex3d/io/io.hpp"

namespace lex3d::io::detail {

namespace {

constexpr std::uint64_t kMaxFieldCount = 1U << 20;  // COUNT cap

/// The raw bits of a 4-byte value (for packed rgb fields).
std::uint32_t load_bits32(const std::uint8_t* p, bool swap) { return load<std::uint32_t>(p, swap); }

Rgb unpack_rgb(std::uint32_t v) {
  return {static_cast<std::uint8_t>((v >> 16) & 0xFFU), static_cast<std::uint8_t>((v >> 8) & 0xFFU),
          static_cast<std::uint8_t>(v & 0xFFU)};
}

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

/// The value type of a field of TYPE `type` (upper case) and SIZE `size`.
bool pcd_scalar(char type, unsigned size, Scalar& out) {
  static const struct {
    char type;
    unsigned size;
    Scalar scalar;
  } kTypes[] = {{'F', 4, Scalar::kF32}, {'F', 8, Scalar::kF64}, {'I', 1, Scalar::kI8},
                {'I', 2, Scalar::kI16}, {'I', 4, Scalar::kI32}, {'I', 8, Scalar::kI64},
                {'U', 1, Scalar::kU8},  {'U', 2, Scalar::kU16}, {'U', 4, Scalar::kU32},
                {'U', 8, Scalar::kU64}};
  for (const auto& t : kTypes) {
    if (t.type == type && t.size == size) {
      out = t.scalar;
      return true;
    }
  }
  return false;
}

/// Where the fields the reader needs sit, and how to step from point to point.
struct PcdAccess {
  const PcdField* field = nullptr;
  std::uint64_t base = 0;    // byte offset of point 0's value in the data block
  std::uint64_t stride = 0;  // bytes from one point's value to the next
};

}  // namespace

Status read_pcd(const std::string& path, const std::uint8_t* data, std::size_t size, ReadResult& r) {
  const char* text = reinterpret_cast<const char*>(data);
  const std::size_t header_limit = std::min(size, kMaxHeaderBytes);
  LineCursor lines(text, text + header_limit);

  std::vector<std::string_view> names, sizes, types, counts;
  std::uint64_t width = 0, height = 1, points = 0;
  bool have_fields = false, have_size = false, have_type = false, have_count = false;
  bool have_width = false, have_height = false, have_points = false, have_data = false;
  std::string encoding;
  std::size_t data_start = 0;
  Pose viewpoint = Pose::Identity();

  std::string_view line;
  while (lines.next(line)) {
    const std::string_view t = trim(line);
    if (t.empty() || t.front() == '#') continue;
    const auto tok = split_ws(t);
    const std::string key = to_lower(tok[0]);
    const std::string where = "header line " + std::to_string(lines.line_no()) + ": ";
    // each keyword but VERSION and VIEWPOINT may appear once
    auto once = [&](bool& seen) -> Status {
      if (seen) return bad_data(msg(path, where + "duplicate " + printable(tok[0], 16)), lines.line_offset());
      seen = true;
      return {};
    };
    auto list = [&](bool& seen, std::vector<std::string_view>& out) -> Status {
      if (Status s = once(seen); !s.ok()) return s;
      out.assign(tok.begin() + 1, tok.end());
      return {};
    };
    auto number = [&](bool& seen, std::uint64_t& out) -> Status {
      if (Status s = once(seen); !s.ok()) return s;
      if (tok.size() != 2 || !parse_u64(tok[1], out)) {
        return bad_data(msg(path, where + printable(tok[0], 16) +
                                      " needs one non-negative integer, got " +
                                      quoted(trim(t.substr(tok[0].size())))),
                        lines.line_offset());
      }
      return {};
    };
    if (key == "version") continue;
    if (key == "viewpoint") {
      // The sensor's pose in the points' frame: tx ty tz qw qx qy qz (as PCL writes its
      // sensor_origin_ and sensor_orientation_); the last one counts.
      double v[7];
      bool ok = tok.size() == 8;
      for (std::size_t k = 0; ok && k < 7; ++k)
        ok = parse_number(tok[k + 1].data(), tok[k + 1].data() + tok[k + 1].size(), v[k]) && std::isfinite(v[k]);
      const double qn = ok ? std::sqrt(v[3] * v[3] + v[4] * v[4] + v[5] * v[5] + v[6] * v[6]) : 0.0;
      if (!ok || !(std::max({std::abs(v[0]), std::abs(v[1]), std::abs(v[2])}) <= kMaxCoordinateM) || !(qn > 0.5 && qn < 2.0)) {
        return bad_data(msg(path, where + "VIEWPOINT needs tx ty tz qw qx qy qz (finite, a unit quaternion), got " +
                                      quoted(trim(t.substr(tok[0].size())))),
                        lines.line_offset());
      }
      viewpoint = Pose::Identity();
      viewpoint.linear() = Eigen::Quaterniond(v[3], v[4], v[5], v[6]).normalized().toRotationMatrix();
      viewpoint.translation() = Eigen::Vector3d(v[0], v[1], v[2]);
      continue;
    }
    if (key == "data") {
      if (tok.size() != 2) {
        return bad_data(msg(path, where + "DATA needs one of ascii, binary, binary_compressed"),
                        lines.line_offset());
      }
      encoding = to_lower(tok[1]);
      if (encoding != "ascii" && encoding != "binary" && encoding != "binary_compressed") {
        return bad_data(msg(path, where + "unknown DATA encoding " + quoted(tok[1])),
                        lines.line_offset());
      }
      have_data = true;
      data_start = static_cast<std::size_t>(lines.position() - text);
      break;
    }
    Status s;
    if (key == "fields" || key == "columns") s = list(have_fields, names);
    else if (key == "size") s = list(have_size, sizes);
    else if (key == "type") s = list(have_type, types);
    else if (key == "count") s = list(have_count, counts);
    else if (key == "width") s = number(have_width, width);
    else if (key == "height") s = number(have_height, height);
    else if (key == "points") s = number(have_points, points);
    else s = bad_data(msg(path, where + "unknown header keyword " + quoted(tok[0])), lines.line_offset());
    if (!s.ok()) return s;
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
        if (to_lower(f.name) == w) return &f;
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
  const PcdField* fr = find({"ring", "laser_id", "ring_id"});
  const PcdField* fc = find({"rgb", "rgba"});
  const PcdField* ft = find({"time", "t", "timestamp"});
  if (fc != nullptr && fc->size != 4) fc = nullptr;  // only packed 32-bit colours
  // Every other field: a single integer of up to 32 bits (an unsigned 32-bit one while its
  // values fit in 31 bits) with a plain name is kept as a named field (Cloud::fields); the
  // rest are named as not kept (PCL's "_" padding fields hold nothing).
  std::vector<const PcdField*> extras;
  std::vector<FieldSpec> extra_names;
  for (const PcdField& f : fields) {
    const PcdField* p = &f;
    if (p == fx || p == fy || p == fz || p == fi || p == fr || p == fc || p == ft || f.name == "_") continue;
    if (offer_field(f.name, f.scalar, f.count, extra_names, r.dropped_fields)) extras.push_back(p);
  }

  r.encoding = encoding;
  r.cloud.T_cloud_sensor = viewpoint;
  const std::uint64_t avail = size - data_start;
  // double coordinates may be georeferenced (Builder::finish)
  const bool wide = fx->scalar == Scalar::kF64 || fy->scalar == Scalar::kF64 || fz->scalar == Scalar::kF64;
  Builder out(r, fi != nullptr, fc != nullptr, wide);
  out.set_time(ft != nullptr, ft != nullptr ? time_unit(ft->scalar) : 1.0);
  if (ft != nullptr && time_unit(ft->scalar) != 1.0)
    r.notes.push_back("the integer time field " + quoted(ft->name) + " is read as nanoseconds (the ouster_ros convention)");
  // (how the ring, intensity and time were stored, for the writers to give them back so)
  if (fr != nullptr) r.cloud.ring_source = source_field(fr->name, fr->scalar);
  if (fi != nullptr) r.cloud.intensity_source = source_field(fi->name, fi->scalar);
  if (ft != nullptr) r.cloud.time_source = source_field(ft->name, ft->scalar);
  out.set_fields(extra_names);
  // An organised cloud (HEIGHT > 1): rows are lasers, columns azimuth steps, NaN or (0, 0, 0)
  // pixels no-returns; a ring field gives each point's laser.
  const bool organised = height > 1 && height <= 0xFFFF && width <= 0xFFFFFFFFULL;
  if (organised) {
    r.cloud.rows = static_cast<std::uint32_t>(height);
    r.cloud.columns = static_cast<std::uint32_t>(width);
  }
  out.set_layout(organised || fr != nullptr, organised, organised);
  const std::uint64_t row_width = std::max<std::uint64_t>(width, 1);
  // The laser of point i: its ring field, else its row.
  auto ring_of = [&](std::uint64_t i, double ring_value, std::uint16_t& ring) -> Status {
    if (fr == nullptr) {
      ring = static_cast<std::uint16_t>(i / row_width);
      return {};
    }
    if (!(ring_value >= 0.0 && ring_value <= 65535.0) || ring_value != std::floor(ring_value))
      return bad_data(msg(path, "point " + std::to_string(i) + ": " + fr->name + " value is not a laser index in [0, 65535]"));
    ring = static_cast<std::uint16_t>(ring_value);
    return {};
  };

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
    LineCursor data_lines(text + data_start, text + size);
    const std::uint64_t first_line = lines.line_no() + 1;
    std::uint64_t done = 0;
    std::string_view dl;
    while (done < points && data_lines.next(dl)) {
      const std::string_view t = trim(dl);
      if (t.empty()) continue;
      float v[4] = {0.0F, 0.0F, 0.0F, 0.0F};
      double ring_value = 0.0, time_value = 0.0;
      double w[3] = {0.0, 0.0, 0.0};
      std::uint32_t rgb_bits = 0;
      std::size_t k = 0;
      std::string_view bad;
      const bool ok = parse_tokens(t, false, k, bad, [&](std::size_t col, const char* b, const char* e) {
        if (fc != nullptr && col == fc->token) {
          // PCL writes the packed rgb float as its unsigned integer bits
          std::uint64_t u = 0;
          if (parse_u64(std::string_view(b, static_cast<std::size_t>(e - b)), u) && u <= 0xFFFFFFFFULL) {
            rgb_bits = static_cast<std::uint32_t>(u);
            return true;
          }
          float fv = 0.0F;
          const bool parsed = parse_number(b, e, fv);
          std::memcpy(&rgb_bits, &fv, 4);
          return parsed;
        }
        float* slot = nullptr;
        if (wide && (col == fx->token || col == fy->token || col == fz->token))
          return parse_number(b, e, w[col == fx->token ? 0 : col == fy->token ? 1 : 2]);
        if (col == fx->token) slot = &v[0];
        else if (col == fy->token) slot = &v[1];
        else if (col == fz->token) slot = &v[2];
        else if (fi != nullptr && col == fi->token) slot = &v[3];
        else if (fr != nullptr && col == fr->token) return parse_number(b, e, ring_value);
        else if (ft != nullptr && col == ft->token) return parse_number(b, e, time_value);
        for (std::size_t x = 0; x < extras.size(); ++x)
          if (col == extras[x]->token) {
            return out.parse_field(x, b, e);
          }
        return slot != nullptr ? parse_number(b, e, *slot) : is_number(b, e);
      });
      const std::uint64_t line_no = first_line + data_lines.line_no() - 1;
      const std::uint64_t off = data_start + data_lines.line_offset();
      if (!ok) return bad_data(msg(path, not_a_number(line_no, bad)), off);
      if (k != tokens_per_point) {
        return bad_data(msg(path, line_prefix(line_no) + "expected " + std::to_string(tokens_per_point) +
                                      " values, found " + std::to_string(k)),
                        off);
      }
      std::uint16_t ring = 0;
      Status rs = ring_of(done, ring_value, ring);
      if (!rs.ok()) return rs;
      out.next_time(time_value);
      if (wide)
        out.add_wide(w[0], w[1], w[2], v[3], unpack_rgb(rgb_bits), ring, static_cast<std::uint32_t>(done % row_width));
      else out.add_at(v[0], v[1], v[2], v[3], unpack_rgb(rgb_bits), ring, static_cast<std::uint32_t>(done % row_width));
      ++done;
    }
    if (done < points) {
      return bad_data(msg(path, "truncated ascii data: " + std::to_string(done) +
                                    " points, header says " + std::to_string(points)),
                      size);
    }
    return out.finish(path);
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
      const unsigned got = lzf_decompress(data + data_start + 8, comp, decompressed.data(),
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
  const PcdAccess ax = access(fx), ay = access(fy), az = access(fz), ai = access(fi), ac = access(fc),
                  ar = access(fr), at = access(ft);
  std::vector<PcdAccess> extra_at;
  for (const PcdField* f : extras) extra_at.push_back(access(f));
  out.reserve(static_cast<std::size_t>(points));
  const bool swap = kHostBigEndian;
  for (std::uint64_t i = 0; i < points; ++i) {
    const float x = load_float(block + ax.base + i * ax.stride, fx->scalar, swap);
    const float y = load_float(block + ay.base + i * ay.stride, fy->scalar, swap);
    const float z = load_float(block + az.base + i * az.stride, fz->scalar, swap);
    const float in = fi != nullptr ? load_float(block + ai.base + i * ai.stride, fi->scalar, swap) : 0.0F;
    Rgb c{};
    if (fc != nullptr) c = unpack_rgb(load_bits32(block + ac.base + i * ac.stride, swap));
    std::uint16_t ring = 0;
    Status rs = ring_of(i, fr != nullptr ? load_scalar(block + ar.base + i * ar.stride, fr->scalar, swap) : 0.0, ring);
    if (!rs.ok()) return rs;
    if (ft != nullptr) out.next_time(load_scalar(block + at.base + i * at.stride, ft->scalar, swap));
    for (std::size_t e = 0; e < extras.size(); ++e)
      out.next_field(e, load_scalar(block + extra_at[e].base + i * extra_at[e].stride, extras[e]->scalar, swap));
    if (wide)
      out.add_wide(load_scalar(block + ax.base + i * ax.stride, fx->scalar, swap),
                   load_scalar(block + ay.base + i * ay.stride, fy->scalar, swap),
                   load_scalar(block + az.base + i * az.stride, fz->scalar, swap), in, c, ring,
                   static_cast<std::uint32_t>(i % row_width));
    else out.add_at(x, y, z, in, c, ring, static_cast<std::uint32_t>(i % row_width));
  }
  return out.finish(path);
}

}  // namespace lex3d::io::detail
