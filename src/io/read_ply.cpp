// Reader of PLY files: ascii, binary_little_endian and binary_big_endian. The
// elements before `vertex` are skipped (checked against the bytes left); the
// `vertex` element gives x y z, an intensity and red green blue when present.

#include <algorithm>
#include <cmath>
#include <initializer_list>
#include <string>
#include <utility>
#include <vector>

#include "io/internal.hpp"
#include "lex3d/io/io.hpp"

namespace lex3d::io::detail {

namespace {

bool scalar_is_integer(Scalar s) { return s != Scalar::kF32 && s != Scalar::kF64; }

std::uint8_t to_u8(double v) {
  if (!(v > 0.0)) return 0;  // also NaN
  if (v >= 255.0) return 255;
  return static_cast<std::uint8_t>(std::lround(v));
}

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
  /// The next value, of type `s`, as a double; false when it ends past the end.
  bool scalar(Scalar s, double& v) {
    return take(s, [&](const std::uint8_t* p) { v = load_scalar(p, s, swap_); });
  }
  /// The next value, of type `s`, as a float (a float32 bit-exactly).
  bool as_float(Scalar s, float& v) {
    return take(s, [&](const std::uint8_t* p) { v = load_float(p, s, swap_); });
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
  /// Calls `load(p)` on the next value of type `s` and steps over it, when it fits.
  template <typename Load>
  bool take(Scalar s, Load&& load) {
    const unsigned n = scalar_size(s);
    if (n > left()) return false;
    load(p_);
    p_ += n;
    return true;
  }

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
    while (p_ < end_ && (is_space(*p_) || *p_ == '\n')) {
      if (*p_ == '\n') ++line_;
      ++p_;
    }
    if (p_ >= end_) return false;
    b = p_;
    while (p_ < end_ && !is_space(*p_) && *p_ != '\n') ++p_;
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
  const std::string l = to_lower(name);
  for (const char* o : options) {
    if (l == o) return true;
  }
  return false;
}

}  // namespace

Status read_ply(const std::string& path, const std::uint8_t* data, std::size_t size, ReadResult& r) {
  const char* text = reinterpret_cast<const char*>(data);
  const std::size_t header_limit = std::min(size, kMaxHeaderBytes);
  LineCursor lines(text, text + header_limit);
  std::string_view line;
  if (!lines.next(line) || line != "ply") return bad_data(msg(path, "not a PLY file (no 'ply' magic line)"), 0);

  std::string format;
  std::vector<PlyElement> elements;
  bool end_header = false;
  std::size_t data_start = 0;
  std::size_t total_props = 0;
  while (lines.next(line)) {
    const std::string where = "header line " + std::to_string(lines.line_no()) + ": ";
    const std::string_view t = trim(line);
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
  int ix = -1, iy = -1, iz = -1, ii = -1, ir = -1, ig = -1, ib = -1, il = -1, it = -1;
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
    else if (il < 0 && name_is(p.name, {"ring", "laser_id", "ring_id"})) il = kk;
    else if (it < 0 && name_is(p.name, {"time", "t", "timestamp"})) it = kk;
  }
  if (ix < 0 || iy < 0 || iz < 0) {
    return bad_data(msg(path, std::string("vertex element has no '") +
                                  (ix < 0 ? "x" : iy < 0 ? "y" : "z") + "' property"));
  }
  const bool color = ir >= 0 && ig >= 0 && ib >= 0;
  // Every other vertex property: a single integer of up to 32 bits (an unsigned 32-bit one
  // while its values fit in 31 bits) with a plain name is kept as a named field
  // (Cloud::fields); the rest are named as not kept.
  std::vector<int> extras;  // property indexes
  std::vector<FieldSpec> extra_names;
  for (std::size_t k = 0; k < vertex.props.size(); ++k) {
    const PlyProperty& p = vertex.props[k];
    const int kk = static_cast<int>(k);
    if (kk == ix || kk == iy || kk == iz || kk == ii || kk == il || kk == it || (color && (kk == ir || kk == ig || kk == ib)))
      continue;
    if (offer_field(p.name, p.type, p.is_list ? 0 : 1, extra_names, r.dropped_fields)) extras.push_back(kk);
  }
  // the named field of property index kk, or -1
  const auto extra_of = [&](int kk) {
    for (std::size_t x = 0; x < extras.size(); ++x)
      if (extras[x] == kk) return static_cast<int>(x);
    return -1;
  };
  r.encoding = format;
  // double coordinates may be georeferenced (Builder::finish)
  const bool wide = vertex.props[static_cast<std::size_t>(ix)].type == Scalar::kF64 ||
                    vertex.props[static_cast<std::size_t>(iy)].type == Scalar::kF64 ||
                    vertex.props[static_cast<std::size_t>(iz)].type == Scalar::kF64;
  Builder out(r, ii >= 0, color, wide);
  // A ring (laser) property gives each point's laser.
  const bool rings = il >= 0;
  out.set_layout(rings, false, false);
  // A time property gives each point's time (Cloud::time), seconds.
  const bool times = it >= 0;
  const auto prop = [&](int k) -> const PlyProperty& { return vertex.props[static_cast<std::size_t>(k)]; };
  out.set_time(times, times ? time_unit(prop(it).type) : 1.0);
  if (times && time_unit(prop(it).type) != 1.0)
    r.notes.push_back("the integer time property " + quoted(prop(it).name) + " is read as nanoseconds (the ouster_ros convention)");
  // (how the ring, intensity and time were stored, for the writers to give them back so)
  if (il >= 0) r.cloud.ring_source = source_field(prop(il).name, prop(il).type);
  if (ii >= 0) r.cloud.intensity_source = source_field(prop(ii).name, prop(ii).type);
  if (times) r.cloud.time_source = source_field(prop(it).name, prop(it).type);
  out.set_fields(extra_names);
  auto ring_of = [&](std::uint64_t item, double value, std::uint16_t& ring) -> Status {
    if (!(value >= 0.0 && value <= 65535.0) || value != std::floor(value))
      return bad_data(msg(path, "vertex " + std::to_string(item) + ": " + vertex.props[static_cast<std::size_t>(il)].name +
                                    " value is not a laser index in [0, 65535]"));
    ring = static_cast<std::uint16_t>(value);
    return {};
  };
  // A vertex parsed one property at a time (ascii, or binary with list properties).
  auto add_vertex = [&](std::uint64_t item, const float (&v)[4], const double (&w)[3], const double (&c)[3],
                        double lv, double tv) -> Status {
    out.next_time(tv);
    std::uint16_t ring = 0;
    if (rings) {
      Status rs = ring_of(item, lv, ring);
      if (!rs.ok()) return rs;
    }
    const Rgb rgb{to_u8(c[0]), to_u8(c[1]), to_u8(c[2])};
    if (wide) out.add_wide(w[0], w[1], w[2], v[3], rgb, ring);
    else out.add_at(v[0], v[1], v[2], v[3], rgb, ring, 0);
    return {};
  };
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
    auto token = [&]() { return std::string_view(b, static_cast<std::size_t>(e - b)); };
    auto not_number = [&]() {
      return bad_data(msg(path, not_a_number(tc.line(), token())), static_cast<std::uint64_t>(b - text));
    };
    auto bad_list_length = [&]() {
      return bad_data(msg(path, line_prefix(tc.line()) + "bad list length " + quoted(token())),
                      static_cast<std::uint64_t>(b - text));
    };
    auto read_list_count = [&](std::uint64_t& n) -> bool {
      double v = 0.0;
      if (!parse_number(b, e, v) || !(v >= 0.0) || v != std::floor(v) || v > 9.0e15) return false;
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
            if (!read_list_count(n)) return bad_list_length();
            for (std::uint64_t j = 0; j < n; ++j) {
              if (!tc.next(b, e)) return truncated(E, item);
            }
          } else if (!is_number(b, e)) {
            return not_number();
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
      double w[3] = {0.0, 0.0, 0.0};
      double c[3] = {0.0, 0.0, 0.0};
      double lv = 0.0, tv = 0.0;
      for (std::size_t k = 0; k < nprops; ++k) {
        const PlyProperty& p = vertex.props[k];
        if (!tc.next(b, e)) {
          return bad_data(msg(path, "truncated ascii data: vertex " + std::to_string(item) + " of " +
                                        std::to_string(vertex.count) + " is incomplete"),
                          size);
        }
        if (p.is_list) {
          std::uint64_t n = 0;
          if (!read_list_count(n)) return bad_list_length();
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
        if (wide && (kk == ix || kk == iy || kk == iz)) ok = parse_number(b, e, w[kk == ix ? 0 : kk == iy ? 1 : 2]);
        else if (kk == ix) ok = parse_number(b, e, v[0]);
        else if (kk == iy) ok = parse_number(b, e, v[1]);
        else if (kk == iz) ok = parse_number(b, e, v[2]);
        else if (kk == ii) ok = parse_number(b, e, v[3]);
        else if (color && kk == ir) ok = parse_number(b, e, c[0]);
        else if (color && kk == ig) ok = parse_number(b, e, c[1]);
        else if (color && kk == ib) ok = parse_number(b, e, c[2]);
        else if (rings && kk == il) ok = parse_number(b, e, lv);
        else if (times && kk == it) ok = parse_number(b, e, tv);
        else if (const int x = extra_of(kk); x >= 0) {
          ok = out.parse_field(static_cast<std::size_t>(x), b, e);
        } else ok = is_number(b, e);
        if (!ok) return not_number();
      }
      Status added = add_vertex(item, v, w, c, lv, tv);
      if (!added.ok()) return added;
    }
    return out.finish(path);
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
      std::uint16_t ring = 0;
      if (rings) {
        const auto u = static_cast<std::size_t>(il);
        Status rs = ring_of(item, load_scalar(p + offsets[u], vertex.props[u].type, swap), ring);
        if (!rs.ok()) return rs;
      }
      if (times) {
        const auto u = static_cast<std::size_t>(it);
        out.next_time(load_scalar(p + offsets[u], vertex.props[u].type, swap));
      }
      for (std::size_t e = 0; e < extras.size(); ++e) {
        const auto u = static_cast<std::size_t>(extras[e]);
        out.next_field(e, load_scalar(p + offsets[u], vertex.props[u].type, swap));
      }
      if (wide)
        out.add_wide(load_scalar(p + offsets[static_cast<std::size_t>(ix)], sx, swap),
                     load_scalar(p + offsets[static_cast<std::size_t>(iy)], sy, swap),
                     load_scalar(p + offsets[static_cast<std::size_t>(iz)], sz, swap), in, c, ring);
      else out.add_at(x, y, z, in, c, ring, 0);
    }
    return out.finish(path);
  }
  for (std::uint64_t item = 0; item < vertex.count; ++item) {
    float v[4] = {0.0F, 0.0F, 0.0F, 0.0F};
    double w[3] = {0.0, 0.0, 0.0};
    double c[3] = {0.0, 0.0, 0.0};
    double lv = 0.0, tv = 0.0;
    for (std::size_t k = 0; k < nprops; ++k) {
      const PlyProperty& p = vertex.props[k];
      const int kk = static_cast<int>(k);
      bool ok = true;
      if (p.is_list) {
        std::uint64_t n = 0;
        ok = bc.list_count(p.count_type, n) && n <= bc.left() / scalar_size(p.type) &&
             bc.skip(n * scalar_size(p.type));
      } else if (wide && (kk == ix || kk == iy || kk == iz)) ok = bc.scalar(p.type, w[kk == ix ? 0 : kk == iy ? 1 : 2]);
      else if (kk == ix) ok = bc.as_float(p.type, v[0]);
      else if (kk == iy) ok = bc.as_float(p.type, v[1]);
      else if (kk == iz) ok = bc.as_float(p.type, v[2]);
      else if (kk == ii) ok = bc.as_float(p.type, v[3]);
      else if (color && kk == ir) ok = bc.scalar(p.type, c[0]);
      else if (color && kk == ig) ok = bc.scalar(p.type, c[1]);
      else if (color && kk == ib) ok = bc.scalar(p.type, c[2]);
      else if (rings && kk == il) ok = bc.scalar(p.type, lv);
      else if (times && kk == it) ok = bc.scalar(p.type, tv);
      else if (const int x = extra_of(kk); x >= 0) {
        double value = 0.0;
        ok = bc.scalar(p.type, value);
        if (ok) out.next_field(static_cast<std::size_t>(x), value);
      } else ok = bc.skip(scalar_size(p.type));
      if (!ok) {
        return bad_data(msg(path, "truncated binary data: vertex " + std::to_string(item) + " of " +
                                      std::to_string(vertex.count) + " ends past the end of the file"),
                        bc.offset());
      }
    }
    Status added = add_vertex(item, v, w, c, lv, tv);
    if (!added.ok()) return added;
  }
  return out.finish(path);
}

}  // namespace lex3d::io::detail
