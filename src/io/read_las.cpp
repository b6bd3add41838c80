// Reader of ASPRS LAS 1.0-1.4 files (point data record formats 0-10) and of the CRS
// records they carry (GeoTIFF keys, OGC WKT), which give the coordinates' units.
//
// Every length read from the file (header size, offset to the points, VLR and EVLR
// lengths, point count × record length) is checked against the file's size before it is
// used. Points are read into metres relative to an origin on the file's own grid, so a
// float32 position keeps the file's resolution; the reader measures the worst error of
// that representation and refuses a file whose extent is too large for it.

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>

#include "io/internal.hpp"
#include "io/las.hpp"
#include "lex3d/io/io.hpp"

namespace lex3d::io::detail {

namespace las {

namespace {

std::string c_string(const std::uint8_t* p, std::size_t n) {
  std::size_t len = 0;
  while (len < n && p[len] != 0) ++len;
  return std::string(reinterpret_cast<const char*>(p), len);
}

// ------------------------------------------------------------------------- units

struct Unit {
  double m;
  const char* name;
};

/// EPSG linear units that GeoTIFF keys and WKT authorities name.
bool epsg_unit(std::uint32_t code, Unit& u) {
  switch (code) {
    case 9001: u = {1.0, "metre"}; return true;
    case 9002: u = {0.3048, "international foot"}; return true;
    case 9003: u = {1200.0 / 3937.0, "US survey foot"}; return true;
    case 9005: u = {0.3047972654, "Clarke's foot"}; return true;
    case 9036: u = {1000.0, "kilometre"}; return true;
    default: return false;
  }
}

// ------------------------------------------------------------------------- WKT

/// A WKT node: KEYWORD[child, child, ...], children quoted strings, numbers/bare words, nodes.
struct WktNode {
  std::string keyword;
  std::vector<std::string> values;  // the leaf children in order (strings unquoted)
  std::vector<WktNode> nodes;
};

class WktParser {
 public:
  explicit WktParser(std::string_view s) : s_(s) {}
  bool parse(WktNode& out) { return node(out, 0) && (skip(), p_ == s_.size()); }

 private:
  void skip() {
    while (p_ < s_.size() && (s_[p_] == ' ' || s_[p_] == '\n' || s_[p_] == '\r' || s_[p_] == '\t' || s_[p_] == '\0'))
      ++p_;
  }
  bool node(WktNode& n, int depth) {
    if (depth > 32) return false;
    skip();
    const std::size_t b = p_;
    while (p_ < s_.size() && (std::isalnum(static_cast<unsigned char>(s_[p_])) || s_[p_] == '_')) ++p_;
    n.keyword = std::string(s_.substr(b, p_ - b));
    skip();
    if (n.keyword.empty() || p_ >= s_.size() || (s_[p_] != '[' && s_[p_] != '(')) return false;
    const char close = s_[p_] == '[' ? ']' : ')';
    ++p_;
    for (;;) {
      skip();
      if (p_ >= s_.size()) return false;
      if (s_[p_] == '"') {
        std::string v;
        ++p_;
        for (;;) {
          if (p_ >= s_.size()) return false;
          if (s_[p_] == '"') {
            if (p_ + 1 < s_.size() && s_[p_ + 1] == '"') {  // "" is a quote inside a string
              v.push_back('"');
              p_ += 2;
              continue;
            }
            ++p_;
            break;
          }
          v.push_back(s_[p_++]);
        }
        n.values.push_back(std::move(v));
      } else {
        std::size_t e = p_;
        while (e < s_.size() && s_[e] != ',' && s_[e] != ']' && s_[e] != ')' && s_[e] != '[' && s_[e] != '(') ++e;
        if (e < s_.size() && (s_[e] == '[' || s_[e] == '(')) {
          WktNode child;
          if (!node(child, depth + 1)) return false;
          n.nodes.push_back(std::move(child));
        } else {
          n.values.emplace_back(trim(s_.substr(p_, e - p_)));
          p_ = e;
        }
      }
      skip();
      if (p_ >= s_.size()) return false;
      if (s_[p_] == ',') {
        ++p_;
        continue;
      }
      if (s_[p_] == close) {
        ++p_;
        return true;
      }
      return false;
    }
  }
  std::string_view s_;
  std::size_t p_ = 0;
};

const WktNode* child(const WktNode& n, std::initializer_list<const char*> keywords) {
  for (const WktNode& c : n.nodes)
    for (const char* k : keywords)
      if (to_lower(c.keyword) == to_lower(k)) return &c;
  return nullptr;
}

/// The unit of a WKT CRS node: its UNIT / LENGTHUNIT child (WKT1), or that of its CS axes (WKT2).
bool wkt_unit(const WktNode& crs, Unit& u, std::string& name) {
  const WktNode* unit = child(crs, {"UNIT", "LENGTHUNIT"});
  if (unit == nullptr) {
    for (const WktNode& c : crs.nodes)
      if (to_lower(c.keyword) == "axis")
        if ((unit = child(c, {"UNIT", "LENGTHUNIT"})) != nullptr) break;
  }
  if (unit == nullptr || unit->values.size() < 2) return false;
  double f = 0.0;
  const std::string& v = unit->values[1];
  if (!parse_number(v.data(), v.data() + v.size(), f) || !(f > 0.0) || !std::isfinite(f)) return false;
  u.m = f;
  name = unit->values[0];
  u.name = nullptr;
  return true;
}

std::uint32_t wkt_epsg(const WktNode& crs) {
  const WktNode* a = child(crs, {"AUTHORITY", "ID"});
  if (a == nullptr || a->values.size() < 2 || to_lower(a->values[0]) != "epsg") return 0;
  std::uint64_t code = 0;
  if (!parse_u64(a->values[1], code) || code > 0xFFFFFFFFULL) return 0;
  return static_cast<std::uint32_t>(code);
}

bool read_wkt(const std::vector<std::uint8_t>& bytes, CrsInfo& out) {
  std::size_t len = 0;
  while (len < bytes.size() && bytes[len] != 0) ++len;
  WktNode root;
  WktParser parser(std::string_view(reinterpret_cast<const char*>(bytes.data()), len));
  if (!parser.parse(root)) return false;
  const std::string top = to_lower(root.keyword);
  const WktNode* horizontal = &root;
  const WktNode* vertical = nullptr;
  if (top == "compd_cs" || top == "compoundcrs") {
    horizontal = child(root, {"PROJCS", "PROJCRS", "PROJECTEDCRS", "GEOGCS", "GEOGCRS"});
    vertical = child(root, {"VERT_CS", "VERTCRS", "VERTICALCRS"});
    if (!root.values.empty()) out.name = root.values[0];
  }
  if (horizontal != nullptr) {
    const std::string k = to_lower(horizontal->keyword);
    if (out.name.empty() && !horizontal->values.empty()) out.name = horizontal->values[0];
    if (out.epsg == 0) out.epsg = wkt_epsg(*horizontal);
    Unit u{};
    std::string name;
    // a geographic CRS's unit is an angle: the coordinates are not lengths
    if ((k == "projcs" || k == "projcrs" || k == "projectedcrs") && wkt_unit(*horizontal, u, name)) {
      out.unit_m = u.m;
      out.unit_name = name;
    }
  }
  if (vertical != nullptr) {
    Unit u{};
    std::string name;
    if (wkt_unit(*vertical, u, name)) {
      out.vertical_unit_m = u.m;
      out.vertical_unit_name = name;
    }
  }
  return true;
}

// ------------------------------------------------------------------------- GeoTIFF keys

std::uint16_t u16_at(const std::vector<std::uint8_t>& b, std::size_t i) {
  return static_cast<std::uint16_t>(b[2 * i] | (b[2 * i + 1] << 8));
}

bool read_geokeys(const std::vector<CrsRecord>& records, CrsInfo& out) {
  const CrsRecord* keys = nullptr;
  const CrsRecord* doubles = nullptr;
  const CrsRecord* ascii = nullptr;
  for (const CrsRecord& r : records) {
    if (r.user_id != "LASF_Projection") continue;
    if (r.record_id == 34735) keys = &r;
    if (r.record_id == 34736) doubles = &r;
    if (r.record_id == 34737) ascii = &r;
  }
  if (keys == nullptr) return false;
  const std::vector<std::uint8_t>& k = keys->data;
  const std::size_t words = k.size() / 2;
  if (words < 4) {
    out.notes.push_back("GeoTIFF key directory shorter than its 8-byte header");
    return false;
  }
  const std::size_t n = u16_at(k, 3);
  if (4 + 4 * n > words) {
    out.notes.push_back("GeoTIFF key directory declares " + std::to_string(n) + " keys but holds " +
                        std::to_string((words - 4) / 4));
    return false;
  }
  auto ascii_value = [&](std::size_t count, std::size_t offset) -> std::string {
    if (ascii == nullptr || offset > ascii->data.size() || count > ascii->data.size() - offset) return {};
    std::string s(reinterpret_cast<const char*>(ascii->data.data() + offset), count);
    while (!s.empty() && (s.back() == '|' || s.back() == '\0')) s.pop_back();
    const std::size_t bar = s.find('|');
    return bar == std::string::npos ? s : s.substr(0, bar);
  };
  auto double_value = [&](std::size_t offset, double& v) {
    if (doubles == nullptr || offset >= doubles->data.size() / 8) return false;
    std::memcpy(&v, doubles->data.data() + 8 * offset, 8);
    return std::isfinite(v) && v > 0.0;
  };
  std::uint32_t linear = 0, vertical = 0;
  double linear_size = 0.0;
  std::string pcs_citation, gt_citation;
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint16_t id = u16_at(k, 4 + 4 * i), where = u16_at(k, 5 + 4 * i), count = u16_at(k, 6 + 4 * i),
                        value = u16_at(k, 7 + 4 * i);
    switch (id) {
      case 1026: if (where == 34737) gt_citation = ascii_value(count, value); break;
      case 3072: if (where == 0 && value != 0 && value != 32767) out.epsg = value; break;
      case 3073: if (where == 34737) pcs_citation = ascii_value(count, value); break;
      case 3076: if (where == 0) linear = value; break;
      case 3077: if (where == 34736) double_value(value, linear_size); break;
      case 4099: if (where == 0) vertical = value; break;
      default: break;
    }
  }
  if (out.name.empty()) out.name = !pcs_citation.empty() ? pcs_citation : gt_citation;
  Unit u{};
  if (linear != 0 && epsg_unit(linear, u)) {
    out.unit_m = u.m;
    out.unit_name = u.name;
  } else if (linear_size > 0.0) {
    out.unit_m = linear_size;
    out.unit_name = "unit of " + std::to_string(linear_size) + " m";
  } else if (linear != 0 && linear != 32767) {
    out.notes.push_back("GeoTIFF ProjLinearUnitsGeoKey " + std::to_string(linear) + " is not a unit lex3d knows");
  }
  if (vertical != 0 && epsg_unit(vertical, u)) {
    out.vertical_unit_m = u.m;
    out.vertical_unit_name = u.name;
  } else if (vertical != 0 && vertical != 32767) {
    out.notes.push_back("GeoTIFF VerticalUnitsGeoKey " + std::to_string(vertical) + " is not a unit lex3d knows");
  }
  return true;
}

}  // namespace

CrsInfo describe_crs(const std::vector<CrsRecord>& records, bool prefer_wkt) {
  CrsInfo geo, wkt;
  const bool has_geo = read_geokeys(records, geo);
  bool has_wkt = false;
  for (const CrsRecord& r : records) {
    if (r.record_id != 2112) continue;
    if (read_wkt(r.data, wkt)) {
      has_wkt = true;
      break;
    }
    wkt.notes.push_back("the OGC WKT record (" + r.user_id + " 2112) does not parse");
  }
  // the record the header designates, with what it leaves open filled from the other one
  const bool wkt_first = (prefer_wkt && has_wkt) || !has_geo;
  CrsInfo out = wkt_first ? wkt : geo;
  const CrsInfo& second = wkt_first ? geo : wkt;
  if (out.name.empty()) out.name = second.name;
  if (out.epsg == 0) out.epsg = second.epsg;
  if (out.unit_m == 0.0) {
    out.unit_m = second.unit_m;
    out.unit_name = second.unit_name;
  }
  if (out.vertical_unit_m == 0.0) {
    out.vertical_unit_m = second.vertical_unit_m;
    out.vertical_unit_name = second.vertical_unit_name;
  }
  out.notes.insert(out.notes.end(), second.notes.begin(), second.notes.end());
  return out;
}

std::vector<PointField> point_fields(int format) {
  std::vector<PointField> f;
  if (format <= 5) {
    f = {{"return_number", 14, 1, 0, 0x07, false, 1},
         {"number_of_returns", 14, 1, 3, 0x07, false, 1},
         {"scan_direction_flag", 14, 1, 6, 0x01, false, 0},
         {"edge_of_flight_line", 14, 1, 7, 0x01, false, 0},
         {"classification", 15, 1, 0, 0x1F, false, 0},
         {"classification_flags", 15, 1, 5, 0x07, false, 0},  // synthetic, key-point, withheld
         {"scan_angle_rank", 16, 1, 0, 0xFF, true, 0},         // degrees
         {"user_data", 17, 1, 0, 0xFF, false, 0},
         {"point_source_id", 18, 2, 0, 0xFFFF, false, 0}};
  } else {
    f = {{"return_number", 14, 1, 0, 0x0F, false, 1},
         {"number_of_returns", 14, 1, 4, 0x0F, false, 1},
         {"classification_flags", 15, 1, 0, 0x0F, false, 0},  // synthetic, key-point, withheld, overlap
         {"scanner_channel", 15, 1, 4, 0x03, false, 0},
         {"scan_direction_flag", 15, 1, 6, 0x01, false, 0},
         {"edge_of_flight_line", 15, 1, 7, 0x01, false, 0},
         {"classification", 16, 1, 0, 0xFF, false, 0},
         {"user_data", 17, 1, 0, 0xFF, false, 0},
         {"scan_angle", 18, 2, 0, 0xFFFF, true, 0},  // 0.006 degrees
         {"point_source_id", 20, 2, 0, 0xFFFF, false, 0}};
    if (format == 8 || format == 10) f.push_back({"nir", 36, 2, 0, 0xFFFF, false, 0});
  }
  return f;
}

}  // namespace las

namespace {

template <typename T>
T le(const std::uint8_t* p) {
  return load<T>(p, kHostBigEndian);
}

/// A part of a point record lex3d does not keep: where it is.
struct LasField {
  const char* name;
  std::uint16_t offset;
  std::uint16_t size;
};

/// What lex3d does not keep of a record: the waveform packets (formats 4, 5, 9, 10).
std::vector<LasField> dropped_fields_of(int format) {
  switch (format) {
    case 4: return {{"waveform packet", 28, 29}};
    case 5: return {{"waveform packet", 34, 29}};
    case 9: return {{"waveform packet", 30, 29}};
    case 10: return {{"waveform packet", 38, 29}};
    default: return {};
  }
}

/// The largest power of ten (times the grid step) not above half the extent: the origin is
/// rounded to it so that it reads well and stays on the file's grid.
std::int64_t round_centre(std::int64_t lo, std::int64_t hi) {
  const std::int64_t mid = lo + (hi - lo) / 2;
  std::int64_t p = 1;
  while (p * 10 <= (hi - lo) / 20 && p < (std::int64_t{1} << 40)) p *= 10;
  const std::int64_t r = (mid >= 0 ? (mid + p / 2) / p : -((-mid + p / 2) / p)) * p;
  return r;
}

}  // namespace

/// The extra values of `n` records (`extras`, from the Extra Bytes record) into the cloud:
/// each a field of its type (Cloud::fields) under its name (characters a field name cannot
/// hold as '_'; "extra_" before a name the cloud has already), a `ring` of small
/// non-negative integers its lasers (Cloud::ring); a scaled value (raw · scale + offset)
/// as float32. What a field cannot hold is listed as dropped: 64-bit integers beyond 31
/// bits, a double that float32 does not hold exactly, arrays and undocumented bytes.
void read_extra_bytes(const std::vector<las::ExtraBytes>& extras, const std::uint8_t* base, std::size_t n,
                      std::size_t record_len, ReadResult& r) {
  for (const las::ExtraBytes& x : extras) {
    std::string name;
    for (const char c : x.name) name += std::isalnum(static_cast<unsigned char>(c)) != 0 || c == '_' ? c : '_';
    if (name.empty()) name = "extra";
    if (name.size() > 64) name.resize(64);
    const std::string shown = "extra bytes \"" + printable(x.name, 32) + "\"";
    if (x.data_type == 0 || x.data_type > 10) {
      r.dropped_fields.push_back(shown + (x.data_type == 0 ? " (undocumented bytes)" : " (an array, deprecated in LAS 1.4)"));
      continue;
    }
    const auto raw = [&](std::size_t i) -> double {
      const std::uint8_t* p = base + i * record_len + x.at;
      switch (x.data_type) {
        case 1: return p[0];
        case 2: return static_cast<std::int8_t>(p[0]);
        case 3: return le<std::uint16_t>(p);
        case 4: return le<std::int16_t>(p);
        case 5: return le<std::uint32_t>(p);
        case 6: return le<std::int32_t>(p);
        case 7: return static_cast<double>(le<std::uint64_t>(p));
        case 8: return static_cast<double>(le<std::int64_t>(p));
        case 9: return le<float>(p);
        default: return le<double>(p);
      }
    };
    IntegerField f;
    f.values.resize(n);
    bool fits = true;
    if (x.scaled() || x.data_type == 9 || x.data_type == 10) {
      f.type = x.scaled() || x.data_type == 9 ? FieldType::kFloat32 : FieldType::kFloat64;
      for (std::size_t i = 0; i < n && fits; ++i) {
        const double v = x.scaled() ? raw(i) * x.scale + x.offset : raw(i);
        const auto v32 = static_cast<float>(v);
        fits = f.type == FieldType::kFloat32 || static_cast<double>(v32) == v || std::isnan(v);
        f.values[i] = float_key(v32);
      }
      if (x.scaled()) r.notes.push_back(shown + " read as float32 values (its scale and offset applied)");
    } else {
      static constexpr FieldType kType[9] = {FieldType::kUnspecified, FieldType::kUint8, FieldType::kInt8,
                                             FieldType::kUint16,      FieldType::kInt16, FieldType::kUint32,
                                             FieldType::kInt32,       FieldType::kInt32, FieldType::kInt32};
      f.type = kType[x.data_type];
      const auto [lo, hi] = field_type_range(f.type);
      for (std::size_t i = 0; i < n && fits; ++i) {
        const double v = raw(i);
        fits = v >= static_cast<double>(lo) && v <= static_cast<double>(hi) &&
               (x.data_type < 7 || v == std::floor(v));
        f.values[i] = fits ? static_cast<std::int32_t>(v) : 0;
      }
    }
    if (!fits) {
      r.dropped_fields.push_back(shown + (is_float_type(f.type) ? " (a double that float32 does not hold)"
                                                                 : " (a value beyond 31 bits)"));
      continue;
    }
    // (a laser number, as a PCD's `ring` is)
    std::string lower = name;
    for (char& ch : lower) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
    const bool ring = (lower == "ring" || lower == "laser_id" || lower == "ring_id") && !is_float_type(f.type) &&
                      !r.cloud.has_rings() && std::all_of(f.values.begin(), f.values.end(), [](std::int32_t v) {
                        return v >= 0 && v <= 65535;
                      });
    if (ring) {
      r.cloud.ring.assign(f.values.begin(), f.values.end());
      continue;
    }
    // (a name the point cloud formats give a meaning of their own, or one the cloud has: a
    // field of its own, after "extra_")
    static const char* const kReserved[] = {"x",   "y",         "z",         "intensity", "scalar_intensity", "reflectance",
                                            "ring", "laser_id", "ring_id",   "time",      "t",                "timestamp",
                                            "rgb", "rgba",      "red",       "green",     "blue",             "diffuse_red",
                                            "diffuse_green",    "diffuse_blue"};
    const bool reserved = std::any_of(std::begin(kReserved), std::end(kReserved), [&](const char* k) { return lower == k; });
    if (reserved || r.cloud.field(name) != nullptr) name = "extra_" + name;
    if (name.size() > 64) name.resize(64);
    if (r.cloud.field(name) != nullptr) {
      r.dropped_fields.push_back(shown + " (its name is taken twice)");
      continue;
    }
    f.name = name;
    r.cloud.fields.push_back(std::move(f));
  }
}

Status read_las(const std::string& path, const std::uint8_t* d, std::size_t size, ReadResult& r) {
  using namespace las;
  auto bad = [&](const std::string& what, std::uint64_t off) { return bad_data(msg(path, what), off); };
  if (size < 4 || std::memcmp(d, "LASF", 4) != 0) return bad("not a LAS file (no \"LASF\" signature)", 0);
  if (size < kHeader12)
    return bad("truncated LAS header (" + std::to_string(size) + " of at least 227 bytes)", size);
  const int major = d[24], minor = d[25];
  if (major != 1 || minor > 4)
    return bad("LAS version " + std::to_string(major) + "." + std::to_string(minor) +
                   " is not supported (this reader reads 1.0-1.4)",
               24);
  const std::uint16_t global_encoding = le<std::uint16_t>(d + 6);
  const std::uint16_t header_size = le<std::uint16_t>(d + 94);
  const std::uint32_t point_offset = le<std::uint32_t>(d + 96);
  const std::uint32_t vlr_count = le<std::uint32_t>(d + 100);
  const std::uint8_t format_byte = d[104];
  const std::uint16_t record_len = le<std::uint16_t>(d + 105);
  const std::size_t min_header = minor >= 4 ? kHeader14 : minor == 3 ? kHeader13 : kHeader12;
  if (header_size < min_header)
    return bad("header size " + std::to_string(header_size) + " is below the " + std::to_string(min_header) +
                   " bytes of a LAS 1." + std::to_string(minor) + " header",
               94);
  if (header_size > size)
    return bad("header size " + std::to_string(header_size) + " exceeds the file's " + std::to_string(size) +
                   " bytes",
               94);
  if (point_offset < header_size || point_offset > size)
    return bad("offset to point data " + std::to_string(point_offset) + " is outside [" +
                   std::to_string(header_size) + ", " + std::to_string(size) + "] (the header and the file size)",
               96);
  if ((format_byte & 0xC0U) != 0)
    return bad("compressed LAS (LAZ, point format byte " + std::to_string(format_byte) +
                   ") is not supported: decompress it to .las first",
               104);
  const int format = format_byte;
  if (format > kMaxFormat) return bad("point data record format " + std::to_string(format) + " is not defined (0-10)", 104);
  if (format >= 6 && minor < 4)
    return bad("point data record format " + std::to_string(format) + " needs LAS 1.4, the header says 1." +
                   std::to_string(minor),
               104);
  if (record_len < kMinRecord[format])
    return bad("point record length " + std::to_string(record_len) + " is below the " +
                   std::to_string(kMinRecord[format]) + " bytes of point format " + std::to_string(format),
               105);
  std::uint64_t count = le<std::uint32_t>(d + 107);
  if (minor >= 4) {
    const auto count64 = le<std::uint64_t>(d + 247);
    if (count64 != 0 && count != 0 && count64 != count)
      return bad("the legacy point count " + std::to_string(count) + " and the 64-bit count " +
                     std::to_string(count64) + " differ",
                 247);
    if (count64 != 0) count = count64;
  }
  Eigen::Vector3d scale, offset, hmax, hmin;
  for (int a = 0; a < 3; ++a) {
    scale[a] = le<double>(d + 131 + 8 * a);
    offset[a] = le<double>(d + 155 + 8 * a);
    hmax[a] = le<double>(d + 179 + 16 * a);
    hmin[a] = le<double>(d + 187 + 16 * a);
    if (!std::isfinite(scale[a]) || !(scale[a] > 0.0))
      return bad(std::string("scale factor of ") + "xyz"[a] + " is " + std::to_string(scale[a]) +
                     " (must be positive and finite)",
                 131 + 8 * static_cast<std::uint64_t>(a));
    if (!std::isfinite(offset[a]) || std::abs(offset[a]) > 1e15)
      return bad(std::string("offset of ") + "xyz"[a] + " is not a finite coordinate",
                 155 + 8 * static_cast<std::uint64_t>(a));
  }
  const std::uint64_t room = size - point_offset;
  if (count > room / record_len)
    return bad("truncated point data: " + std::to_string(room) + " bytes hold " +
                   std::to_string(room / record_len) + " records of " + std::to_string(record_len) +
                   " bytes, the header says " + std::to_string(count),
               size);

  // --- VLRs, between the header and the points
  Georeference g;
  std::size_t pos = header_size;
  const std::uint64_t vlr_room = point_offset - header_size;
  if (vlr_count > vlr_room / kVlrHeader)
    return bad(std::to_string(vlr_count) + " VLRs cannot fit in the " + std::to_string(vlr_room) +
                   " bytes before the point data",
               100);
  std::vector<std::string> not_carried;
  std::vector<std::uint8_t> extra_record;  // the Extra Bytes descriptors
  bool extra_records = false;
  auto take_record = [&](const std::uint8_t* h, const std::uint8_t* payload, std::uint64_t len, bool extended) {
    const std::string user = c_string(h + 2, 16);
    const std::uint16_t id = le<std::uint16_t>(h + 18);
    if (user == kExtraBytesUser && id == kExtraBytesRecord && !extra_records) {
      extra_records = true;
      extra_record.assign(payload, payload + len);
      return;
    }
    if (!is_crs_record(user, id)) {
      not_carried.push_back(printable(user, 16) + " " + std::to_string(id));
      return;
    }
    CrsRecord rec;
    rec.user_id = user;
    rec.record_id = id;
    rec.description = c_string(h + (extended ? 28 : 22), 32);
    rec.data.assign(payload, payload + len);
    rec.extended = extended;
    g.crs_records.push_back(std::move(rec));
  };
  for (std::uint32_t i = 0; i < vlr_count; ++i) {
    if (point_offset - pos < kVlrHeader)
      return bad("VLR " + std::to_string(i) + " header runs past the start of the point data", pos);
    const std::uint16_t len = le<std::uint16_t>(d + pos + 20);
    if (len > point_offset - pos - kVlrHeader)
      return bad("VLR " + std::to_string(i) + " length " + std::to_string(len) + " runs past the start of the point data (" +
                     std::to_string(point_offset - pos - kVlrHeader) + " bytes left)",
                 pos + 20);
    take_record(d + pos, d + pos + kVlrHeader, len, false);
    pos += kVlrHeader + len;
  }
  // --- EVLRs (1.4), after the points
  const std::uint64_t points_end = point_offset + count * record_len;
  if (minor >= 4) {
    const auto evlr_start = le<std::uint64_t>(d + 235);
    const std::uint32_t evlr_count = le<std::uint32_t>(d + 243);
    if (evlr_count > 0) {
      if (evlr_start < points_end || evlr_start > size)
        return bad("start of the first EVLR " + std::to_string(evlr_start) + " is outside [" +
                       std::to_string(points_end) + ", " + std::to_string(size) + "] (the end of the points, the file size)",
                   235);
      if (evlr_count > (size - evlr_start) / kEvlrHeader)
        return bad(std::to_string(evlr_count) + " EVLRs cannot fit in the " + std::to_string(size - evlr_start) +
                       " bytes after their start",
                   243);
      std::uint64_t at = evlr_start;
      for (std::uint32_t i = 0; i < evlr_count; ++i) {
        if (size - at < kEvlrHeader) return bad("EVLR " + std::to_string(i) + " header runs past the end of the file", at);
        const auto len = le<std::uint64_t>(d + at + 20);
        if (len > size - at - kEvlrHeader)
          return bad("EVLR " + std::to_string(i) + " length " + std::to_string(len) + " exceeds the " +
                         std::to_string(size - at - kEvlrHeader) + " bytes left",
                     at + 20);
        take_record(d + at, d + at + kEvlrHeader, len, true);
        at += kEvlrHeader + len;
      }
    }
  }

  // --- the CRS and its units
  const CrsInfo crs = describe_crs(g.crs_records, (global_encoding & 0x10U) != 0 || format >= 6);
  g.crs_name = crs.name;
  g.epsg = crs.epsg;
  if (crs.unit_m > 0.0) {
    g.unit_m = crs.unit_m;
    g.unit_name = crs.unit_name;
  } else {
    g.unit_m = 1.0;
    g.unit_name = g.crs_records.empty() ? "metre (assumed: the file names no CRS)"
                                        : "metre (assumed: the CRS records name no linear unit)";
  }
  g.vertical_unit_m = crs.vertical_unit_m > 0.0 ? crs.vertical_unit_m : g.unit_m;
  for (const std::string& n : crs.notes) r.notes.push_back(n);
  if (!not_carried.empty()) {
    std::string list;
    for (const auto& s : not_carried) list += (list.empty() ? "" : ", ") + s;
    r.notes.push_back(std::to_string(not_carried.size()) + " (E)VLRs that do not describe the CRS are not kept: " + list);
  }
  g.las_scale = scale;
  g.las_offset = offset;
  g.las_version_minor = static_cast<std::uint8_t>(std::max(minor, 2));
  g.las_point_format = static_cast<std::uint8_t>(format);
  g.las_global_encoding = global_encoding;
  g.las_system_id = c_string(d + 26, 32);
  g.las_software = c_string(d + 58, 32);

  // --- the extra values at the end of each record, as the Extra Bytes record describes them
  std::vector<ExtraBytes> extras;
  std::size_t described_end = kMinRecord[format];
  if (extra_records) {
    if (extra_record.size() % kExtraBytesDescriptor != 0)
      r.notes.push_back("the Extra Bytes record's " + std::to_string(extra_record.size()) +
                        " bytes are not whole 192-byte descriptors: the extra bytes are not read");
    else
      for (std::size_t k = 0; k < extra_record.size() / kExtraBytesDescriptor; ++k) {
        const std::uint8_t* e = extra_record.data() + k * kExtraBytesDescriptor;
        ExtraBytes x;
        x.data_type = e[2];
        x.options = e[3];
        x.name = c_string(e + 4, 32);
        x.size = x.data_type == 0 ? x.options : extra_bytes_size(x.data_type);
        x.at = described_end;
        if (x.size == 0 || x.at + x.size > record_len) {
          r.notes.push_back("the Extra Bytes record describes " + (x.size == 0 ? std::string("a value of type ") +
                                                                                    std::to_string(x.data_type)
                                                                              : std::to_string(x.at + x.size) + " bytes") +
                            " beyond the " + std::to_string(record_len) + "-byte records: the extra bytes from \"" +
                            printable(x.name, 32) + "\" on are not read");
          break;
        }
        if ((x.options & 0x08U) != 0) x.scale = le<double>(e + 112);
        if ((x.options & 0x10U) != 0) x.offset = le<double>(e + 136);
        described_end += x.size;
        extras.push_back(std::move(x));
      }
  }

  // --- points: integer bounds, origin on the grid, then metres relative to it
  const std::uint8_t* base = d + point_offset;
  const auto n = static_cast<std::size_t>(count);
  std::array<std::int64_t, 3> lo{0, 0, 0}, hi{0, 0, 0};
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint8_t* p = base + i * record_len;
    for (int a = 0; a < 3; ++a) {
      const std::int64_t v = le<std::int32_t>(p + 4 * a);
      if (i == 0 || v < lo[a]) lo[a] = v;
      if (i == 0 || v > hi[a]) hi[a] = v;
    }
  }
  std::array<std::int64_t, 3> n0{};
  Eigen::Vector3d units = g.units();
  for (int a = 0; a < 3; ++a) {
    n0[a] = round_centre(lo[a], hi[a]);
    g.origin[a] = (offset[a] + static_cast<double>(n0[a]) * scale[a]) * units[a];
  }
  if (n > 0) {  // the header's bounds should hold the points
    for (int a = 0; a < 3; ++a) {
      const double pmin = offset[a] + static_cast<double>(lo[a]) * scale[a];
      const double pmax = offset[a] + static_cast<double>(hi[a]) * scale[a];
      // No coordinate frame on Earth reaches 10^9 m (what PCD viewpoints allow too).
      const double reach = std::max(std::abs(pmin), std::abs(pmax)) * units[a];
      if (!(reach <= kMaxCoordinateM))
        return bad(std::string("the points reach ") + std::to_string(reach) + " m along " + "xyz"[a] +
                       ", beyond any coordinate frame on Earth (the limit is 1e9 m)",
                   point_offset);
      if (pmin < hmin[a] - scale[a] || pmax > hmax[a] + scale[a]) {
        r.notes.push_back(std::string("the header's ") + "xyz"[a] + " bounds [" + std::to_string(hmin[a]) + ", " +
                          std::to_string(hmax[a]) + "] do not hold the points' [" + std::to_string(pmin) + ", " +
                          std::to_string(pmax) + "]");
      }
    }
  }
  r.cloud.points.resize(n);
  r.cloud.intensity.resize(n);
  const int rgb_at = rgb_offset(format);
  // GPS time (formats 1 and 3-10) is each point's time (Cloud::time), kept when the file
  // holds one: a time other than zero, every one finite.
  const int time_at = format == 1 || (format >= 3 && format <= 5) ? 20 : format >= 6 ? 22 : -1;
  if (time_at >= 0) r.cloud.time.resize(n);
  bool time_seen = false, time_finite = true;
  std::vector<std::array<std::uint16_t, 3>> rgb16;
  if (rgb_at >= 0) rgb16.resize(n);
  std::uint16_t rgb_max = 0;
  const std::vector<LasField> fields = dropped_fields_of(format);
  std::vector<std::uint8_t> seen(fields.size(), 0);
  // the fields Cloud keeps: those with a value other than their plain one (read in a
  // second pass, so that a field never set costs no memory)
  const std::vector<PointField> kept_fields = point_fields(format);
  std::vector<std::uint8_t> kept_seen(kept_fields.size(), 0);
  bool extra_seen = false;
  double worst2 = 0.0;
  std::array<double, 3> worst_axis{0.0, 0.0, 0.0};
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint8_t* p = base + i * record_len;
    Eigen::Vector3f q;
    double e2 = 0.0;
    for (int a = 0; a < 3; ++a) {
      const std::int64_t v = le<std::int32_t>(p + 4 * a);
      const double local = static_cast<double>(v - n0[a]) * scale[a] * units[a];
      q[a] = static_cast<float>(local);
      const double e = std::abs(static_cast<double>(q[a]) - local);
      worst_axis[a] = std::max(worst_axis[a], e);
      e2 += e * e;
    }
    worst2 = std::max(worst2, e2);
    r.cloud.points[i] = q;
    r.cloud.intensity[i] = static_cast<float>(le<std::uint16_t>(p + 12));
    if (time_at >= 0) {
      const double t = le<double>(p + time_at);
      r.cloud.time[i] = t;
      time_seen = time_seen || t != 0.0;
      time_finite = time_finite && std::isfinite(t);
    }
    if (rgb_at >= 0) {
      for (int c = 0; c < 3; ++c) {
        rgb16[i][static_cast<std::size_t>(c)] = le<std::uint16_t>(p + rgb_at + 2 * c);
        rgb_max = std::max(rgb_max, rgb16[i][static_cast<std::size_t>(c)]);
      }
    }
    for (std::size_t k = 0; k < fields.size(); ++k)
      for (std::uint16_t b = 0; b < fields[k].size; ++b) seen[k] |= p[fields[k].offset + b];
    for (std::size_t k = 0; k < kept_fields.size(); ++k)
      kept_seen[k] |= static_cast<std::uint8_t>(kept_fields[k].get(p) != kept_fields[k].plain ? 1 : 0);
    if (!extra_seen)
      for (std::size_t b = described_end; b < record_len; ++b) extra_seen = extra_seen || p[b] != 0;
  }
  g.representation_error_m = std::sqrt(worst2);
  for (int a = 0; a < 3; ++a) {
    const double half_step = 0.5 * scale[a] * units[a];
    if (worst_axis[a] >= half_step)
      return bad(std::string("the points span ") + std::to_string(static_cast<double>(hi[a] - lo[a]) * scale[a]) +
                     " units along " + "xyz"[a] + ": float32 positions about one origin cannot keep the file's " +
                     std::to_string(scale[a]) + "-unit resolution (worst error " + std::to_string(worst_axis[a]) +
                     " m); split the file into smaller tiles",
                 point_offset);
  }
  if (rgb_at >= 0) {
    // 16-bit colours (the LAS convention) keep their high byte; files that store 8-bit values
    // in the 16-bit fields keep them as they are
    const int shift = rgb_max > 255 ? 8 : 0;
    r.colors.resize(n);
    for (std::size_t i = 0; i < n; ++i)
      for (std::size_t c = 0; c < 3; ++c) r.colors[i][c] = static_cast<std::uint8_t>(rgb16[i][c] >> shift);
    if (shift == 8) r.notes.push_back("RGB read as 8-bit colours (the high byte of each 16-bit value)");
  }
  for (std::size_t k = 0; k < fields.size(); ++k)
    if (seen[k] != 0) r.dropped_fields.emplace_back(fields[k].name);
  for (std::size_t k = 0; k < kept_fields.size(); ++k) {
    if (kept_seen[k] == 0) continue;
    IntegerField field{kept_fields[k].name, std::vector<std::int32_t>(n)};
    for (std::size_t i = 0; i < n; ++i) field.values[i] = kept_fields[k].get(base + i * record_len);
    r.cloud.fields.push_back(std::move(field));
  }
  if (time_seen && !time_finite) r.dropped_fields.emplace_back("GPS time (a value is not finite)");
  if (!time_seen || !time_finite) r.cloud.time.clear();
  if (extra_seen)
    r.dropped_fields.emplace_back("extra bytes (" + std::to_string(record_len - described_end) + " a record" +
                                  (extras.empty() ? "" : ", past the described ones") + ")");
  read_extra_bytes(extras, base, n, record_len, r);
  r.encoding = "LAS 1." + std::to_string(minor) + ", point format " + std::to_string(format);
  r.cloud.georef = std::move(g);
  return {};
}

}  // namespace lex3d::io::detail
