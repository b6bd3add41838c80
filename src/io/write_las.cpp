// Writer of ASPRS LAS files: LAS 1.2 point format 0 (2 with colours) for a cloud without a
// LAS georeference; otherwise the source's version and point format (waveform formats
// without their packets: 4 -> 1, 5 -> 3, 9 -> 6, 10 -> 8), its scale and offset (a new
// offset when the points would not fit 32-bit steps about it) and its CRS records, in the
// CRS's units. The point fields a cloud keeps by name (Cloud::fields: classification,
// return_number, ... as the reader names them) go back into their places; a scan angle
// kept in the other family's units (scan_angle_rank in degrees, scan_angle in 0.006°) is
// converted. Fields the cloud lacks are written as zeros, the return number as 1 of 1. The
// ring and every other field go into extra bytes (LAS 1.4's Extra Bytes record, in their
// own types), which makes the file LAS 1.4.
// Output is deterministic (no creation date is written).

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>

#include "io/internal.hpp"
#include "io/las.hpp"
#include "lex3d/io/io.hpp"

namespace lex3d::io::detail {

namespace {

class Out {
 public:
  std::vector<std::uint8_t> b;
  template <typename T>
  void le(T v) {
    std::uint8_t tmp[sizeof(T)];
    std::memcpy(tmp, &v, sizeof(T));
    if (kHostBigEndian) std::reverse(tmp, tmp + sizeof(T));
    b.insert(b.end(), tmp, tmp + sizeof(T));
  }
  void chars(const std::string& s, std::size_t n) {
    for (std::size_t i = 0; i < n; ++i) b.push_back(i < s.size() ? static_cast<std::uint8_t>(s[i]) : 0);
  }
  void zeros(std::size_t n) { b.insert(b.end(), n, 0); }
  template <typename T>
  void put_at(std::size_t at, T v) {
    std::uint8_t tmp[sizeof(T)];
    std::memcpy(tmp, &v, sizeof(T));
    if (kHostBigEndian) std::reverse(tmp, tmp + sizeof(T));
    std::memcpy(b.data() + at, tmp, sizeof(T));
  }
};

/// The smallest power of ten above the float32 spacing of `max_abs` metres: a step a float32
/// position can hold (read back, a point lands within half an ulp of its step, so within half
/// a step, which is what a reader needs to keep the file's resolution). A finer step would
/// store digits that float32 coordinates do not have, and the file would not read back.
double step_for(double max_abs) {
  const double ulp = std::max(static_cast<double>(std::nextafter(static_cast<float>(max_abs), INFINITY)) -
                                  static_cast<double>(static_cast<float>(max_abs)),
                              1e-9);
  return std::pow(10.0, std::floor(std::log10(ulp)) + 1.0);
}

/// The point format (and LAS minor version) build_las writes `cloud` in.
int output_format(const Cloud& cloud, const WriteOptions& o, int& minor) {
  const bool with_c = !o.colors.empty();
  const bool with_t = cloud.has_time();
  minor = 2;
  int format = with_t ? (with_c ? 3 : 1) : (with_c ? 2 : 0);
  if (o.true_coordinates && cloud.georef.has_value() && cloud.georef->is_las()) {
    const Georeference& g = *cloud.georef;
    minor = std::clamp<int>(g.las_version_minor, 2, 4);
    format = g.las_point_format;
    if (format == 4) format = 1;
    if (format == 5) format = 3;
    if (format == 9) format = 6;
    if (format == 10) format = 8;
    if (format > las::kMaxFormat) format = with_c ? 2 : 0;
    if (with_t && format == 0) format = 1;  // a format with GPS time for the points' times
    if (with_t && format == 2) format = 3;
    if (format >= 6) minor = 4;
  }
  return format;
}

/// The scan angle's name in the other family of point formats (0-5: degrees; 6-10: 0.006°).
std::string other_scan_angle(const std::string& name) {
  return name == "scan_angle" ? "scan_angle_rank" : name == "scan_angle_rank" ? "scan_angle" : "";
}

/// The cloud's integer field named `name` (a LAS record's field), or nullptr: a floating-point
/// field of that name is not one.
const IntegerField* integer_field(const Cloud& cloud, const std::string& name) {
  const IntegerField* f = cloud.field(name);
  return f != nullptr && !is_float_type(f->type) ? f : nullptr;
}

/// A value written as extra bytes: the cloud's ring, or a field the record has no place for.
struct ExtraOut {
  std::string name;
  std::uint8_t data_type = 0;  // LAS extra-bytes type (1-6, 9, 10)
  const IntegerField* field = nullptr;  // nullptr: the ring
};

/// The extra bytes build_las writes for `cloud` in `format`: its ring (ushort), then each
/// field no place of the record takes, in its own type (an unspecified one as a long).
std::vector<ExtraOut> extras_of(const Cloud& cloud, int format) {
  std::vector<ExtraOut> out;
  if (cloud.has_rings()) out.push_back({"ring", 3, nullptr});
  const std::vector<las::PointField> fields = las::point_fields(format);
  for (const IntegerField& x : cloud.fields) {
    bool placed = false;
    for (const las::PointField& f : fields)
      placed = placed || (!is_float_type(x.type) && (x.name == f.name || x.name == other_scan_angle(f.name)));
    if (placed || (x.name == "ring" && cloud.has_rings())) continue;
    std::uint8_t type = 6;
    switch (x.type) {
      case FieldType::kUint8: type = 1; break;
      case FieldType::kInt8: type = 2; break;
      case FieldType::kUint16: type = 3; break;
      case FieldType::kInt16: type = 4; break;
      case FieldType::kUint32: type = 5; break;
      case FieldType::kFloat32: type = 9; break;
      case FieldType::kFloat64: type = 10; break;
      default: type = 6; break;
    }
    out.push_back({x.name, type, &x});
  }
  return out;
}

}  // namespace

std::vector<std::string> las_fields_not_written(const Cloud& cloud, const WriteOptions& o) {
  int minor = 0;
  std::vector<std::string> out;
  // (the names the Extra Bytes record cannot hold: over its 32 characters)
  for (const ExtraOut& x : extras_of(cloud, output_format(cloud, o, minor)))
    if (x.name.size() > 32) out.push_back(x.name);
  return out;
}

Status build_las(const std::string& path, const Cloud& cloud, const WriteOptions& o, std::vector<std::uint8_t>& out) {
  auto invalid = [&](const std::string& what) { return Status{ErrorCode::kInvalidArgument, msg(path, what)}; };
  const std::size_t n = cloud.size();
  const bool with_c = !o.colors.empty();
  const bool georef = o.true_coordinates && cloud.georef.has_value();
  Georeference g;
  if (georef) g = *cloud.georef;
  else g = Georeference{};  // local coordinates, metres

  const bool with_t = cloud.has_time();
  int minor = 2;
  const int format = output_format(cloud, o, minor);
  const int rgb_at = las::rgb_offset(format);
  // The ring and the fields the record has no place for, as extra bytes (LAS 1.4's Extra
  // Bytes record: the file is then LAS 1.4, in the same point format); a name over the
  // record's 32 characters is not written (las_fields_not_written lists it).
  std::vector<ExtraOut> extras;
  for (ExtraOut& x : extras_of(cloud, format))
    if (x.name.size() <= 32) extras.push_back(std::move(x));
  std::size_t extra_size = 0;
  for (const ExtraOut& x : extras) extra_size += las::extra_bytes_size(x.data_type);
  if (!extras.empty()) minor = 4;
  if (las::kMinRecord[format] + extra_size > 65535) return invalid("the extra fields do not fit a LAS point record");
  const auto record_len = static_cast<std::uint16_t>(las::kMinRecord[format] + extra_size);
  for (const ExtraOut& x : extras)
    if (x.field != nullptr && x.field->values.size() != n)
      return invalid("field " + x.name + " has " + std::to_string(x.field->values.size()) + " values for " +
                     std::to_string(n) + " points");
  std::vector<std::uint8_t> extra_record;
  for (const ExtraOut& x : extras) {
    std::vector<std::uint8_t> e(las::kExtraBytesDescriptor, 0);
    e[2] = x.data_type;
    std::memcpy(e.data() + 4, x.name.data(), x.name.size());
    const std::string about = x.field == nullptr ? "laser (ring) number" : "lex3d field " + x.name;
    std::memcpy(e.data() + 160, about.data(), std::min<std::size_t>(about.size(), 32));
    extra_record.insert(extra_record.end(), e.begin(), e.end());
  }

  // The record's fields the cloud holds, each with its values (a scan angle converted from
  // the other family's units), checked to fit.
  struct Put {
    las::PointField field;
    std::vector<std::int32_t> values;
  };
  std::vector<Put> puts;
  for (const las::PointField& f : las::point_fields(format)) {
    Put put{f, {}};
    if (const IntegerField* have = integer_field(cloud, f.name)) {
      put.values = have->values;
    } else if (const IntegerField* other = integer_field(cloud, other_scan_angle(f.name))) {
      const double to = std::string(f.name) == "scan_angle" ? 1.0 / 0.006 : 0.006;
      for (const std::int32_t v : other->values)
        put.values.push_back(static_cast<std::int32_t>(std::clamp(std::round(v * to), f.size == 1 ? -128.0 : -32768.0,
                                                                  f.size == 1 ? 127.0 : 32767.0)));
    } else {
      continue;
    }
    if (put.values.size() != n)
      return invalid(std::string("field ") + f.name + " has " + std::to_string(put.values.size()) + " values for " +
                     std::to_string(n) + " points");
    for (std::size_t i = 0; i < n; ++i)
      if (!f.fits(put.values[i]))
        return invalid(std::string("field ") + f.name + " of point " + std::to_string(i) + " is " +
                       std::to_string(put.values[i]) + ", which LAS point format " + std::to_string(format) +
                       " cannot hold");
    puts.push_back(std::move(put));
  }
  // Points by return number (the header's counts): 1 of 1 where the cloud has no return number.
  const int returns = format >= 6 ? 15 : 5;
  std::vector<std::uint64_t> by_return(static_cast<std::size_t>(returns), 0);
  const IntegerField* return_number = integer_field(cloud, "return_number");  // every format has it (checked above)
  if (return_number == nullptr) by_return[0] = n;
  else
    for (const std::int32_t r : return_number->values)
      if (r >= 1 && r <= returns) ++by_return[static_cast<std::size_t>(r - 1)];

  // True coordinates (CRS units) of every point, computed in double.
  const Eigen::Vector3d units = g.units();
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (const auto& p : cloud.points) {
    const Eigen::Vector3d t = (g.origin + p.cast<double>()).cwiseQuotient(units);
    lo = lo.cwiseMin(t);
    hi = hi.cwiseMax(t);
  }
  if (n == 0) lo = hi = Eigen::Vector3d::Zero();
  if (!lo.allFinite() || !hi.allFinite()) return invalid("a point is not finite");
  Eigen::Vector3d scale = g.las_scale, offset = g.las_offset;
  for (int a = 0; a < 3; ++a) {
    if (!g.is_las()) {
      // no LAS source: steps at the float32 resolution of the local coordinates
      const double max_abs = std::max(std::abs(lo[a] - g.origin[a] / units[a]), std::abs(hi[a] - g.origin[a] / units[a]));
      scale[a] = step_for(max_abs * units[a]) / units[a];
      offset[a] = g.origin[a] / units[a];
    }
    // the points must fit 32-bit steps about the offset; else centre it, then coarsen
    auto fits = [&]() {
      const double a_lo = std::floor((lo[a] - offset[a]) / scale[a]), a_hi = std::ceil((hi[a] - offset[a]) / scale[a]);
      return a_lo >= -2147483647.0 && a_hi <= 2147483647.0;
    };
    if (!fits()) offset[a] = std::round(0.5 * (lo[a] + hi[a]));
    while (!fits() && scale[a] < 1e6) scale[a] *= 10.0;
    if (!fits()) return invalid("the points' coordinates do not fit LAS's 32-bit steps");
  }

  std::vector<const CrsRecord*> vlrs, evlrs;
  for (const CrsRecord& r : g.crs_records) {
    if (r.extended && minor >= 4) evlrs.push_back(&r);
    else if (r.data.size() <= 65535) vlrs.push_back(&r);
    else return invalid("a CRS record of " + std::to_string(r.data.size()) + " bytes does not fit a LAS 1." +
                        std::to_string(minor) + " VLR");
  }
  const std::size_t header_size = minor >= 4 ? las::kHeader14 : minor == 3 ? las::kHeader13 : las::kHeader12;
  std::size_t vlr_bytes = extras.empty() ? 0 : las::kVlrHeader + extra_record.size();
  if (extra_record.size() > 65535) return invalid("too many extra fields for a LAS Extra Bytes record");
  for (const CrsRecord* r : vlrs) vlr_bytes += las::kVlrHeader + r->data.size();
  const std::uint64_t point_offset = header_size + vlr_bytes;
  if (point_offset > 0xFFFFFFFFULL) return invalid("the CRS records are too large for a LAS header");
  if (minor < 4 && n > 0xFFFFFFFFULL) return invalid("more than 2^32 points need LAS 1.4");

  Out w;
  w.b.reserve(point_offset + n * record_len + 1024);
  w.chars("LASF", 4);
  w.le<std::uint16_t>(0);  // file source id
  std::uint16_t ge = g.las_global_encoding & 0x11U;  // GPS time type, WKT; no waveform packets
  if (format >= 6) ge |= 0x10U;
  w.le<std::uint16_t>(ge);
  w.zeros(16);  // project GUID
  w.b.push_back(1);
  w.b.push_back(static_cast<std::uint8_t>(minor));
  w.chars(g.las_system_id.empty() ? std::string("OTHER") : g.las_system_id, 32);
  w.chars("lex3d", 32);
  w.le<std::uint16_t>(0);  // creation day and year: not written (deterministic output)
  w.le<std::uint16_t>(0);
  w.le<std::uint16_t>(static_cast<std::uint16_t>(header_size));
  w.le<std::uint32_t>(static_cast<std::uint32_t>(point_offset));
  w.le<std::uint32_t>(static_cast<std::uint32_t>(vlrs.size() + (extras.empty() ? 0 : 1)));
  w.b.push_back(static_cast<std::uint8_t>(format));
  w.le<std::uint16_t>(record_len);
  const bool legacy = format < 6 && n <= 0xFFFFFFFFULL;
  w.le<std::uint32_t>(legacy ? static_cast<std::uint32_t>(n) : 0U);
  for (int k = 0; k < 5; ++k) w.le<std::uint32_t>(legacy ? static_cast<std::uint32_t>(by_return[static_cast<std::size_t>(k)]) : 0U);
  for (int a = 0; a < 3; ++a) w.le<double>(scale[a]);
  for (int a = 0; a < 3; ++a) w.le<double>(offset[a]);
  const std::size_t bounds_at = w.b.size();
  w.zeros(48);  // max x, min x, max y, min y, max z, min z: filled below
  if (minor >= 3) w.le<std::uint64_t>(0);  // waveform data packet record
  std::size_t evlr_at = 0;
  if (minor >= 4) {
    evlr_at = w.b.size();
    w.le<std::uint64_t>(0);
    w.le<std::uint32_t>(static_cast<std::uint32_t>(evlrs.size()));
    w.le<std::uint64_t>(n);
    for (int k = 0; k < 15; ++k) w.le<std::uint64_t>(k < returns ? by_return[static_cast<std::size_t>(k)] : 0U);
  }
  for (const CrsRecord* r : vlrs) {
    w.le<std::uint16_t>(0);
    w.chars(r->user_id, 16);
    w.le<std::uint16_t>(r->record_id);
    w.le<std::uint16_t>(static_cast<std::uint16_t>(r->data.size()));
    w.chars(r->description, 32);
    w.b.insert(w.b.end(), r->data.begin(), r->data.end());
  }
  if (!extras.empty()) {
    w.le<std::uint16_t>(0);
    w.chars(las::kExtraBytesUser, 16);
    w.le<std::uint16_t>(las::kExtraBytesRecord);
    w.le<std::uint16_t>(static_cast<std::uint16_t>(extra_record.size()));
    w.chars("extra bytes", 32);
    w.b.insert(w.b.end(), extra_record.begin(), extra_record.end());
  }

  Eigen::Vector3d qlo = Eigen::Vector3d::Zero(), qhi = Eigen::Vector3d::Zero();
  const bool with_i = cloud.has_intensity();
  for (std::size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d t = (g.origin + cloud.points[i].cast<double>()).cwiseQuotient(units);
    const std::size_t at = w.b.size();
    w.zeros(record_len);
    for (int a = 0; a < 3; ++a) {
      const double steps = std::round((t[a] - offset[a]) / scale[a]);
      const auto v = static_cast<std::int32_t>(steps);
      w.put_at<std::int32_t>(at + 4 * static_cast<std::size_t>(a), v);
      const double q = offset[a] + static_cast<double>(v) * scale[a];
      if (i == 0 || q < qlo[a]) qlo[a] = q;
      if (i == 0 || q > qhi[a]) qhi[a] = q;
    }
    if (with_i) {
      const float in = cloud.intensity[i];
      const double c = std::isfinite(in) ? std::clamp(std::round(static_cast<double>(in)), 0.0, 65535.0) : 0.0;
      w.put_at<std::uint16_t>(at + 12, static_cast<std::uint16_t>(c));
    }
    w.b[at + 14] = format >= 6 ? 0x11 : 0x09;  // return 1 of 1, unless the cloud says otherwise
    for (const Put& p : puts) p.field.put(w.b.data() + at, p.values[i]);
    if (with_t) w.put_at<double>(at + (format >= 6 ? 22U : 20U), cloud.time[i]);
    if (rgb_at >= 0 && with_c)
      for (std::size_t c = 0; c < 3; ++c)
        w.put_at<std::uint16_t>(at + static_cast<std::size_t>(rgb_at) + 2 * c,
                                static_cast<std::uint16_t>(o.colors[i][c] * 257U));
    std::size_t e = at + las::kMinRecord[format];
    for (const ExtraOut& x : extras) {
      if (x.field == nullptr) {
        w.put_at<std::uint16_t>(e, cloud.ring[i]);
      } else {
        const std::int32_t v = x.field->values[i];
        switch (x.data_type) {
          case 1: w.b[e] = static_cast<std::uint8_t>(v); break;
          case 2: w.b[e] = static_cast<std::uint8_t>(static_cast<std::int8_t>(v)); break;
          case 3: w.put_at<std::uint16_t>(e, static_cast<std::uint16_t>(v)); break;
          case 4: w.put_at<std::int16_t>(e, static_cast<std::int16_t>(v)); break;
          case 5: w.put_at<std::uint32_t>(e, static_cast<std::uint32_t>(v)); break;
          case 9: w.put_at<float>(e, key_float(v)); break;
          case 10: w.put_at<double>(e, static_cast<double>(key_float(v))); break;
          default: w.put_at<std::int32_t>(e, v); break;
        }
      }
      e += las::extra_bytes_size(x.data_type);
    }
  }
  for (int a = 0; a < 3; ++a) {
    w.put_at<double>(bounds_at + 16 * static_cast<std::size_t>(a), qhi[a]);
    w.put_at<double>(bounds_at + 16 * static_cast<std::size_t>(a) + 8, qlo[a]);
  }
  if (minor >= 4 && !evlrs.empty()) {
    w.put_at<std::uint64_t>(evlr_at, w.b.size());
    for (const CrsRecord* r : evlrs) {
      w.le<std::uint16_t>(0);
      w.chars(r->user_id, 16);
      w.le<std::uint16_t>(r->record_id);
      w.le<std::uint64_t>(r->data.size());
      w.chars(r->description, 32);
      w.b.insert(w.b.end(), r->data.begin(), r->data.end());
    }
  }
  out = std::move(w.b);
  return {};
}

}  // namespace lex3d::io::detail
