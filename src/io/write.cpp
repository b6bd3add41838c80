// Writers (PCD, PLY, KITTI / x y z binaries, x y z text) and atomic file writes.
//
// Output is deterministic: the same cloud and options give the same bytes.
// Text uses the shortest decimal form that reads back to the same float
// (std::to_chars), so text round trips are bit-exact.

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <charconv>
#include <cstdio>
#include <cstring>
#include <limits>
#include <new>
#include <string>

#include <lzf.h>

#include "io/internal.hpp"
#include "lex3d/io/io.hpp"
#include "lex3d/io/rosbag.hpp"

namespace lex3d::io {

using detail::kHostBigEndian;
using detail::msg;

namespace {

/// A PCD VIEWPOINT: the sensor pose as tx ty tz qw qx qy qz (qw >= 0), to round-trip
/// precision ("0 0 0 1 0 0 0" for the identity).
std::string viewpoint_of(const Pose& T) {
  Eigen::Quaterniond q(T.linear());
  if (q.w() < 0.0) q.coeffs() = -q.coeffs();
  const double v[7] = {T.translation().x(), T.translation().y(), T.translation().z(), q.w(), q.x(), q.y(), q.z()};
  std::string out;
  char buf[32];
  for (int k = 0; k < 7; ++k) {
    std::snprintf(buf, sizeof buf, "%.17g", v[k] == 0.0 ? 0.0 : v[k]);  // no "-0"
    out += (k > 0 ? " " : "") + std::string(buf);
  }
  return out;
}

Status invalid(const std::string& path, const std::string& what) {
  return {ErrorCode::kInvalidArgument, msg(path, what)};
}

/// How a named field of type t is declared: its PCD TYPE and its PLY type (its size:
/// detail::field_bytes).
struct FieldDecl {
  const char* pcd_type;
  const char* ply_type;
};
FieldDecl declaration(FieldType t) {
  switch (t) {
    case FieldType::kInt8: return {"I", "char"};
    case FieldType::kUint8: return {"U", "uchar"};
    case FieldType::kInt16: return {"I", "short"};
    case FieldType::kUint16: return {"U", "ushort"};
    case FieldType::kUint32: return {"U", "uint"};
    case FieldType::kFloat32: return {"F", "float"};
    case FieldType::kFloat64: return {"F", "double"};
    default: return {"I", "int"};  // int32, and a field whose type is not recorded
  }
}

}  // namespace

namespace detail {

SourceColumns source_columns(const Cloud& cloud) {
  SourceColumns out;
  const std::size_t n = cloud.size();
  // values `v(i)` as a field of `src`'s name and type where all of them hold in it
  const auto typed = [n](const SourceField& src, auto&& v) -> std::optional<IntegerField> {
    if (!src.given() || !is_field_name(src.name)) return std::nullopt;
    IntegerField f{src.name, std::vector<std::int32_t>(n), src.type};
    const auto [lo, hi] = field_type_range(src.type);
    for (std::size_t i = 0; i < n; ++i) {
      const double x = v(i);
      if (is_float_type(src.type)) {
        const auto as_float = static_cast<float>(x);
        // (a float64 one only where float32 holds each value: a named field holds float keys)
        if (src.type == FieldType::kFloat64 && static_cast<double>(as_float) != x && !std::isnan(x)) return std::nullopt;
        f.values[i] = float_key(as_float);
      } else {
        if (!(x >= static_cast<double>(lo) && x <= static_cast<double>(hi)) || x != std::floor(x)) return std::nullopt;
        f.values[i] = static_cast<std::int32_t>(x);
      }
    }
    return f;
  };
  if (cloud.has_rings()) out.ring = typed(cloud.ring_source, [&](std::size_t i) { return static_cast<double>(cloud.ring[i]); });
  if (cloud.has_intensity())
    out.intensity = typed(cloud.intensity_source, [&](std::size_t i) { return static_cast<double>(cloud.intensity[i]); });
  if (cloud.has_time()) {
    const bool ns = cloud.time_source.given() && !is_float_type(cloud.time_source.type);
    out.time = typed(cloud.time_source, [&](std::size_t i) { return ns ? std::nearbyint(cloud.time[i] * 1e9) : cloud.time[i]; });
    if (!out.time && cloud.time_source.given() && cloud.time_source.type == FieldType::kFloat64 &&
        is_field_name(cloud.time_source.name))
      out.time_name = cloud.time_source.name;
  }
  return out;
}

}  // namespace detail

namespace {

/// The bytes a point's named fields take in a binary PCD or PLY file.
std::size_t named_bytes(const Cloud& cloud) {
  std::size_t k = 0;
  for (const IntegerField& x : cloud.fields) k += detail::field_bytes(x.type);
  return k;
}

class Bytes {
 public:
  // (a buffer kept larger than what is written, n_ bytes: a value is copied in, not
  // inserted, which costs several times more for a few bytes)
  explicit Bytes(std::size_t reserve) : b_(std::max<std::size_t>(reserve, 64)) {}
  void put(const void* data, std::size_t k) {
    if (k == 0) return;  // (data may then be null, which memcpy must not see)
    if (b_.size() - n_ < k) b_.resize(std::max(2 * b_.size(), n_ + k));
    std::memcpy(b_.data() + n_, data, k);
    n_ += k;
  }
  void str(std::string_view s) { put(s.data(), s.size()); }
  void u8(std::uint8_t v) { put(&v, 1); }
  template <typename T>
  void le(T v) {
    std::uint8_t tmp[sizeof(T)];
    std::memcpy(tmp, &v, sizeof(T));
    if (kHostBigEndian) std::reverse(tmp, tmp + sizeof(T));
    put(tmp, sizeof(T));
  }
  void f32(float v) { le(v); }
  void f64(double v) { le(v); }
  /// x y z of point i: float32, or with `g` the true coordinates as doubles.
  void xyz(const Cloud& cloud, std::size_t i, const Georeference* g) {
    const auto& p = cloud.points[i];
    if (g != nullptr) {
      const Eigen::Vector3d t = g->to_crs(p);
      f64(t.x());
      f64(t.y());
      f64(t.z());
    } else {
      f32(p.x());
      f32(p.y());
      f32(p.z());
    }
  }
  /// Shortest round-trip decimal of a float.
  void text(float v) {
    char buf[32];
    const auto res = std::to_chars(buf, buf + sizeof(buf), v);
    put(buf, static_cast<std::size_t>(res.ptr - buf));
  }
  void text(double v) {
    char buf[32];
    const auto res = std::to_chars(buf, buf + sizeof(buf), v);
    put(buf, static_cast<std::size_t>(res.ptr - buf));
  }
  void text(std::uint64_t v) {
    char buf[24];
    const auto res = std::to_chars(buf, buf + sizeof(buf), v);
    put(buf, static_cast<std::size_t>(res.ptr - buf));
  }
  /// "x y z" of point i, then " intensity" when `with_i` (no end of line); with `g`, the
  /// true coordinates (doubles) of the georeference.
  void text_point(const Cloud& cloud, std::size_t i, bool with_i, const Georeference* g = nullptr,
                  const IntegerField* typed_i = nullptr) {
    const auto& p = cloud.points[i];
    if (g != nullptr) {
      const Eigen::Vector3d t = g->to_crs(p);
      text(t.x());
      u8(' ');
      text(t.y());
      u8(' ');
      text(t.z());
    } else {
      text(p.x());
      u8(' ');
      text(p.y());
      u8(' ');
      text(p.z());
    }
    if (with_i) {
      u8(' ');
      if (typed_i != nullptr) value_text(*typed_i, i);
      else text(cloud.intensity[i]);
    }
  }
  /// " ring time" of point i as text, each when asked (no end of line), each in its source's
  /// type where `sc` has it.
  void ring_time(const Cloud& cloud, std::size_t i, bool with_r, bool with_t, const detail::SourceColumns& sc) {
    if (with_r) {
      u8(' ');
      if (sc.ring) value_text(*sc.ring, i);
      else text(static_cast<std::uint64_t>(cloud.ring[i]));
    }
    if (with_t) {
      u8(' ');
      if (sc.time) value_text(*sc.time, i);
      else text(cloud.time[i]);
    }
  }
  /// " v1 v2 ..." of point i's named fields as text (no end of line).
  void named(const Cloud& cloud, std::size_t i) {
    for (const IntegerField& x : cloud.fields) {
      u8(' ');
      value_text(x, i);
    }
  }
  /// Point i's value of named field x as text: a float field's value as the shortest
  /// decimal that reads back to it (a float64 field's as a double's).
  void value_text(const IntegerField& x, std::size_t i) {
    const std::int32_t v = x.values[i];
    if (x.type == FieldType::kFloat32) {
      text(key_float(v));
    } else if (x.type == FieldType::kFloat64) {
      text(static_cast<double>(key_float(v)));
    } else {
      if (v < 0) u8('-');
      text(static_cast<std::uint64_t>(v < 0 ? -static_cast<std::int64_t>(v) : v));
    }
  }
  /// Point i's value of named field x in the field's own type, little-endian.
  void field(const IntegerField& x, std::size_t i) {
    std::uint8_t tmp[8];
    const unsigned k = detail::store_field(tmp, x, i);
    if (kHostBigEndian) std::reverse(tmp, tmp + k);
    put(tmp, k);
  }
  std::vector<std::uint8_t>& vec() {
    b_.resize(n_);
    return b_;
  }

 private:
  std::vector<std::uint8_t> b_;
  std::size_t n_ = 0;
};

/// PCL packs colour as 0xAARRGGBB (alpha 255) in the bits of the float `rgb` field.
std::uint32_t pack_rgb(const std::array<std::uint8_t, 3>& c) {
  return 0xFF000000U | (static_cast<std::uint32_t>(c[0]) << 16) |
         (static_cast<std::uint32_t>(c[1]) << 8) | static_cast<std::uint32_t>(c[2]);
}

Status build_pcd(const std::string& path, const Cloud& cloud, const WriteOptions& o, bool with_i,
                 bool with_c, const Georeference* g, std::vector<std::uint8_t>& out, std::size_t height = 1) {
  const std::size_t n = cloud.size();
  const bool with_r = cloud.has_rings(), with_t = cloud.has_time();
  const detail::SourceColumns sc = detail::source_columns(cloud);
  const IntegerField* typed_i = with_i && sc.intensity ? &*sc.intensity : nullptr;
  const auto bytes_of = [](const std::optional<IntegerField>& f, std::size_t otherwise) {
    return f ? static_cast<std::size_t>(detail::field_bytes(f->type)) : otherwise;
  };
  const std::size_t point_size = (g != nullptr ? 24 : 12) + (with_i ? bytes_of(sc.intensity, 4) : 0) + (with_c ? 4 : 0) +
                                 (with_r ? bytes_of(sc.ring, 2) : 0) + (with_t ? bytes_of(sc.time, 8) : 0) +
                                 named_bytes(cloud);
  Bytes b(256 + n * point_size + (o.pcd_encoding == PcdEncoding::kAscii ? n * 40 : 0));
  std::string fields = "x y z", sizes = g != nullptr ? "8 8 8" : "4 4 4", types = "F F F", counts = "1 1 1";
  const auto declare = [&](const IntegerField& x) {
    fields += " " + x.name;
    sizes += " " + std::to_string(detail::field_bytes(x.type));
    types += std::string(" ") + declaration(x.type).pcd_type;
    counts += " 1";
  };
  if (typed_i != nullptr) {
    declare(*typed_i);
  } else if (with_i) {
    fields += " intensity";
    sizes += " 4";
    types += " F";
    counts += " 1";
  }
  if (with_c) {
    // PCL declares the packed colour F (a float holding the bits 0xAARRGGBB) in
    // binary files, and U in ascii files where it writes the integer
    fields += " rgb";
    sizes += " 4";
    types += o.pcd_encoding == PcdEncoding::kAscii ? " U" : " F";
    counts += " 1";
  }
  if (with_r && sc.ring) {
    declare(*sc.ring);
  } else if (with_r) {  // the laser, as Velodyne's and Ouster's ROS drivers name it
    fields += " ring";
    sizes += " 2";
    types += " U";
    counts += " 1";
  }
  if (with_t && sc.time) {
    declare(*sc.time);
  } else if (with_t) {
    fields += " " + sc.time_name;
    sizes += " 8";
    types += " F";
    counts += " 1";
  }
  for (const IntegerField& x : cloud.fields) declare(x);  // named fields (a LAS classification...) in their types
  // true coordinates: the viewpoint moves with the points (in the CRS's units when they are metres)
  Pose viewpoint = cloud.T_cloud_sensor;
  if (g != nullptr) viewpoint.translation() = g->to_crs(cloud.T_cloud_sensor.translation().cast<float>());
  const char* enc = o.pcd_encoding == PcdEncoding::kAscii    ? "ascii"
                    : o.pcd_encoding == PcdEncoding::kBinary ? "binary"
                                                             : "binary_compressed";
  b.str("# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS " + fields + "\nSIZE " +
        sizes + "\nTYPE " + types + "\nCOUNT " + counts + "\nWIDTH " + std::to_string(n / height) +
        "\nHEIGHT " + std::to_string(height) + "\nVIEWPOINT " + viewpoint_of(viewpoint) + "\nPOINTS " + std::to_string(n) +
        "\nDATA " + enc + "\n");
  switch (o.pcd_encoding) {
    case PcdEncoding::kAscii:
      for (std::size_t i = 0; i < n; ++i) {
        b.text_point(cloud, i, with_i, g, typed_i);
        if (with_c) {  // as PCL does: the packed colour written as an unsigned integer
          b.u8(' ');
          b.text(static_cast<std::uint64_t>(pack_rgb(o.colors[i])));
        }
        b.ring_time(cloud, i, with_r, with_t, sc);
        b.named(cloud, i);
        b.u8('\n');
      }
      break;
    case PcdEncoding::kBinary:
      for (std::size_t i = 0; i < n; ++i) {
        b.xyz(cloud, i, g);
        if (typed_i != nullptr) b.field(*typed_i, i);
        else if (with_i) b.f32(cloud.intensity[i]);
        if (with_c) b.le(pack_rgb(o.colors[i]));
        if (with_r && sc.ring) b.field(*sc.ring, i);
        else if (with_r) b.le(cloud.ring[i]);
        if (with_t && sc.time) b.field(*sc.time, i);
        else if (with_t) b.f64(cloud.time[i]);
        for (const IntegerField& x : cloud.fields) b.field(x, i);
      }
      break;
    case PcdEncoding::kBinaryCompressed: {
      const std::uint64_t raw_size = static_cast<std::uint64_t>(n) * point_size;
      if (raw_size * 3 / 2 + 64 > std::numeric_limits<std::uint32_t>::max()) {
        return invalid(path, "cloud too large for PCD binary_compressed (" + std::to_string(raw_size) +
                                 " bytes; the format has 32-bit sizes)");
      }
      // column-major: all x, then all y, ... (as PCL stores binary_compressed)
      Bytes raw(static_cast<std::size_t>(raw_size));
      for (int a = 0; a < 3; ++a) {
        for (std::size_t i = 0; i < n; ++i) {
          if (g != nullptr) raw.f64(g->to_crs(cloud.points[i])[a]);
          else raw.f32(cloud.points[i][a]);
        }
      }
      if (typed_i != nullptr) {
        for (std::size_t i = 0; i < n; ++i) raw.field(*typed_i, i);
      } else if (with_i) {
        for (std::size_t i = 0; i < n; ++i) raw.f32(cloud.intensity[i]);
      }
      if (with_c) {
        for (std::size_t i = 0; i < n; ++i) raw.le(pack_rgb(o.colors[i]));
      }
      if (with_r && sc.ring) {
        for (std::size_t i = 0; i < n; ++i) raw.field(*sc.ring, i);
      } else if (with_r) {
        for (std::size_t i = 0; i < n; ++i) raw.le(cloud.ring[i]);
      }
      if (with_t && sc.time) {
        for (std::size_t i = 0; i < n; ++i) raw.field(*sc.time, i);
      } else if (with_t) {
        for (std::size_t i = 0; i < n; ++i) raw.f64(cloud.time[i]);
      }
      for (const IntegerField& x : cloud.fields)
        for (std::size_t i = 0; i < n; ++i) raw.field(x, i);
      std::vector<std::uint8_t> comp;
      unsigned comp_size = 0;
      if (raw_size > 0) {
        comp.resize(static_cast<std::size_t>(raw_size * 3 / 2 + 64));
        comp_size = lzf_compress(raw.vec().data(), static_cast<unsigned>(raw_size), comp.data(),
                                 static_cast<unsigned>(comp.size()));
        if (comp_size == 0) return io_error(msg(path, "LZF compression failed"));
      }
      b.le(static_cast<std::uint32_t>(comp_size));
      b.le(static_cast<std::uint32_t>(raw_size));
      b.put(comp.data(), comp_size);
      break;
    }
  }
  out = std::move(b.vec());
  return {};
}

void build_ply(const Cloud& cloud, const WriteOptions& o, bool with_i, bool with_c, const Georeference* g,
               std::vector<std::uint8_t>& out) {
  const std::size_t n = cloud.size();
  Bytes b(256 + n * (o.ply_binary ? 31 : 60));
  const char* coord = g != nullptr ? "double" : "float";
  std::string h = "ply\nformat ";
  h += o.ply_binary ? "binary_little_endian" : "ascii";
  h += " 1.0\ncomment written by lex3d\nelement vertex " + std::to_string(n) +
       "\nproperty " + coord + " x\nproperty " + coord + " y\nproperty " + coord + " z\n";
  const detail::SourceColumns sc = detail::source_columns(cloud);
  const IntegerField* typed_i = with_i && sc.intensity ? &*sc.intensity : nullptr;
  const auto declare = [&h](const IntegerField& x) {
    h += std::string("property ") + declaration(x.type).ply_type + " " + x.name + "\n";
  };
  if (typed_i != nullptr) declare(*typed_i);
  else if (with_i) h += "property float intensity\n";
  if (with_c) h += "property uchar red\nproperty uchar green\nproperty uchar blue\n";
  const bool with_r = cloud.has_rings(), with_t = cloud.has_time();
  if (with_r && sc.ring) declare(*sc.ring);
  else if (with_r) h += "property ushort ring\n";
  if (with_t && sc.time) declare(*sc.time);
  else if (with_t) h += "property double " + sc.time_name + "\n";
  for (const IntegerField& x : cloud.fields) declare(x);
  h += "end_header\n";
  b.str(h);
  for (std::size_t i = 0; i < n; ++i) {
    if (o.ply_binary) {
      b.xyz(cloud, i, g);
      if (typed_i != nullptr) b.field(*typed_i, i);
      else if (with_i) b.f32(cloud.intensity[i]);
      if (with_c) {
        b.u8(o.colors[i][0]);
        b.u8(o.colors[i][1]);
        b.u8(o.colors[i][2]);
      }
      if (with_r && sc.ring) b.field(*sc.ring, i);
      else if (with_r) b.le(cloud.ring[i]);
      if (with_t && sc.time) b.field(*sc.time, i);
      else if (with_t) b.f64(cloud.time[i]);
      for (const IntegerField& x : cloud.fields) b.field(x, i);
    } else {
      b.text_point(cloud, i, with_i, g, typed_i);
      if (with_c) {
        for (int ch = 0; ch < 3; ++ch) {
          b.u8(' ');
          b.text(static_cast<std::uint64_t>(o.colors[i][static_cast<std::size_t>(ch)]));
        }
      }
      b.ring_time(cloud, i, with_r, with_t, sc);
      b.named(cloud, i);
      b.u8('\n');
    }
  }
  out = std::move(b.vec());
}

void build_float_binary(const Cloud& cloud, bool kitti, std::vector<std::uint8_t>& out) {
  const std::size_t n = cloud.size();
  Bytes b(n * (kitti ? 16 : 12));
  const bool with_i = cloud.has_intensity();
  for (std::size_t i = 0; i < n; ++i) {
    const auto& p = cloud.points[i];
    b.f32(p.x());
    b.f32(p.y());
    b.f32(p.z());
    if (kitti) b.f32(with_i ? cloud.intensity[i] : 0.0F);
  }
  out = std::move(b.vec());
}

void build_xyz(const Cloud& cloud, bool with_i, const Georeference* g, std::vector<std::uint8_t>& out) {
  const std::size_t n = cloud.size();
  Bytes b(n * 48);
  for (std::size_t i = 0; i < n; ++i) {
    b.text_point(cloud, i, with_i, g);
    b.u8('\n');
  }
  out = std::move(b.vec());
}

std::atomic<unsigned> g_temp_counter{0};

Status write_atomic(const std::string& path, const std::uint8_t* data, std::size_t size) {
  const std::string tmp = path + ".tmp-" + std::to_string(::getpid()) + "-" +
                          std::to_string(g_temp_counter.fetch_add(1));
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
  if (fd < 0) {
    return io_error(msg(path, std::string("cannot create temporary file: ") + std::strerror(errno)));
  }
  auto fail = [&](const char* what, int err) {
    ::unlink(tmp.c_str());
    return io_error(msg(path, std::string(what) + ": " + std::strerror(err)));
  };
  std::size_t done = 0;
  while (done < size) {
    const ssize_t w = ::write(fd, data + done, std::min<std::size_t>(size - done, 1U << 30));
    if (w < 0) {
      if (errno == EINTR) continue;
      const int err = errno;
      ::close(fd);
      return fail("cannot write", err);
    }
    done += static_cast<std::size_t>(w);
  }
  // No fsync: rename gives atomicity against concurrent readers and failed
  // writes; durability across power loss is left to the caller.
  if (::close(fd) != 0) return fail("cannot write (close)", errno);
  if (::rename(tmp.c_str(), path.c_str()) != 0) return fail("cannot rename the temporary file", errno);
  return {};
}

/// The format a cloud is written as: options.format, else the one its extension names.
StatusOr<Format> output_format(const std::string& path, const WriteOptions& options) {
  if (options.format != Format::kAuto) return options.format;
  const std::string ext = detail::extension_lower(path);
  if (ext == ".pcd") return Format::kPcd;
  if (ext == ".ply") return Format::kPly;
  if (ext == ".bin") return Format::kKitti;
  if (ext == ".xyz" || ext == ".txt" || ext == ".asc" || ext == ".csv") return Format::kXyz;
  if (ext == ".las") return Format::kLas;
  if (ext == ".laz") return invalid(path, "writing compressed LAS (.laz) is not supported: use .las");
  return invalid(path, "cannot tell the output format from the extension '" + detail::printable(ext, 16) +
                           "' (use .pcd, .ply, .bin, .xyz, .txt or .las)");
}

Status write_cloud_impl(const std::string& path, const Cloud& cloud, const WriteOptions& options) {
  const auto format = output_format(path, options);
  if (!format.ok()) return format.status();
  const Format f = format.value();
  if (Status s = detail::check_fields(path, cloud); !s.ok()) return s;
  if (!cloud.intensity.empty() && cloud.intensity.size() != cloud.points.size()) {
    return invalid(path, "cloud has " + std::to_string(cloud.intensity.size()) + " intensities for " +
                             std::to_string(cloud.points.size()) + " points");
  }
  if (!options.colors.empty() && options.colors.size() != cloud.points.size()) {
    return invalid(path, "got " + std::to_string(options.colors.size()) + " colours for " +
                             std::to_string(cloud.points.size()) + " points");
  }
  const bool with_i = options.write_intensity && cloud.has_intensity();
  const bool with_c = !options.colors.empty();
  const Georeference* g = options.true_coordinates && cloud.georef ? &*cloud.georef : nullptr;
  std::vector<std::uint8_t> bytes;
  switch (f) {
    case Format::kPcd: {
      // An organised cloud (one point a pixel) is written organised: HEIGHT rows, NaN at
      // its no-return pixels.
      const std::vector<std::int64_t> at = pixel_points(cloud);
      const bool organised = !at.empty();
      Status s;
      if (organised) {
        Cloud grid;
        grid.T_cloud_sensor = cloud.T_cloud_sensor;
        grid.ring_source = cloud.ring_source;  // (each column as its source stored it)
        grid.intensity_source = cloud.intensity_source;
        grid.time_source = cloud.time_source;
        WriteOptions go = options;
        const float nan = std::numeric_limits<float>::quiet_NaN();
        grid.points.assign(at.size(), Eigen::Vector3f(nan, nan, nan));
        if (with_i) grid.intensity.assign(at.size(), 0.0F);
        if (with_c) go.colors.assign(at.size(), {0, 0, 0});
        grid.ring.resize(at.size());  // a no-return pixel keeps its row as its laser
        for (std::size_t k = 0; k < at.size(); ++k) grid.ring[k] = static_cast<std::uint16_t>(k / cloud.columns);
        if (cloud.has_time()) grid.time.assign(at.size(), 0.0);
        for (const IntegerField& x : cloud.fields) grid.fields.push_back({x.name, std::vector<std::int32_t>(at.size(), 0), x.type});
        for (std::size_t k = 0; k < at.size(); ++k) {
          if (at[k] < 0) continue;
          const auto i = static_cast<std::size_t>(at[k]);
          grid.points[k] = cloud.points[i];
          if (with_i) grid.intensity[k] = cloud.intensity[i];
          if (with_c) go.colors[k] = options.colors[i];
          if (cloud.has_time()) grid.time[k] = cloud.time[i];
          for (std::size_t x = 0; x < cloud.fields.size(); ++x) grid.fields[x].values[k] = cloud.fields[x].values[i];
        }
        s = build_pcd(path, grid, go, with_i, with_c, g, bytes, cloud.rows);
      } else {
        s = build_pcd(path, cloud, options, with_i, with_c, g, bytes);
      }
      if (!s.ok()) return s;
      break;
    }
    case Format::kLas: {
      Status s = detail::build_las(path, cloud, options, bytes);
      if (!s.ok()) return s;
      break;
    }
    case Format::kPly: build_ply(cloud, options, with_i, with_c, g, bytes); break;
    case Format::kKitti: build_float_binary(cloud, true, bytes); break;
    case Format::kBinXyz: build_float_binary(cloud, false, bytes); break;
    case Format::kXyz: build_xyz(cloud, with_i, g, bytes); break;
    case Format::kUos3d:
    case Format::kPcap:
    case Format::kAuto:
      return invalid(path, "writing format '" + std::string(format_name(f)) + "' is not supported");
  }
  return write_atomic(path, bytes.data(), bytes.size());
}

}  // namespace

std::vector<std::int64_t> pixel_points(const Cloud& cloud) {
  const std::uint64_t pixels = static_cast<std::uint64_t>(cloud.rows) * cloud.columns;
  if (!(cloud.rows > 1 && cloud.columns > 0 && cloud.has_rings() && cloud.has_columns() && pixels >= cloud.size() &&
        pixels <= (1ULL << 31)))
    return {};
  std::vector<std::int64_t> at(static_cast<std::size_t>(pixels), -1);
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    if (cloud.ring[i] >= cloud.rows || cloud.column[i] >= cloud.columns) return {};
    const std::uint64_t k = static_cast<std::uint64_t>(cloud.ring[i]) * cloud.columns + cloud.column[i];
    if (at[k] >= 0) return {};  // (two points a pixel: a dual-return turn)
    at[k] = static_cast<std::int64_t>(i);
  }
  return at;
}

std::vector<std::string> fields_not_written(const std::string& path, const Cloud& cloud, const WriteOptions& options) {
  const auto format = output_format(path, options);
  if (!format.ok()) return {};
  const Format f = format.value();
  std::vector<std::string> out;
  const bool text_or_bin = f == Format::kKitti || f == Format::kBinXyz || f == Format::kXyz;
  if (cloud.has_intensity() && (f == Format::kBinXyz || (!options.write_intensity && f != Format::kKitti)))
    out.emplace_back("intensity");
  if (cloud.has_rings() && text_or_bin) out.emplace_back("ring");
  if (cloud.has_time() && text_or_bin) out.emplace_back("time");
  if ((cloud.has_rgb() || !options.colors.empty()) && text_or_bin) out.emplace_back("rgb");
  if (text_or_bin)
    for (const IntegerField& x : cloud.fields) out.push_back(x.name);
  if (f == Format::kLas)
    for (std::string& name : detail::las_fields_not_written(cloud, options)) out.push_back(std::move(name));
  return out;
}

Status write_file_atomic(const std::string& path, const std::vector<std::uint8_t>& bytes) {
  return write_atomic(path, bytes.data(), bytes.size());
}

Status write_cloud(const std::string& path, const Cloud& cloud, const WriteOptions& options_in) {
  // the cloud's own colours when the caller gives none
  const bool own_colors = options_in.colors.empty() && cloud.has_rgb();
  WriteOptions with_rgb;
  if (own_colors) {
    with_rgb = options_in;
    with_rgb.colors = cloud.rgb;
  }
  const WriteOptions& options = own_colors ? with_rgb : options_in;
  try {
    if (options.format == Format::kAuto && detail::extension_lower(path) == ".bag") {  // one PointCloud2 message
      std::vector<BagScan> one(1);
      one[0].cloud = cloud;
      if (!own_colors && !options.colors.empty() && options.colors.size() == cloud.size()) one[0].cloud.rgb = options.colors;
      return write_bag(path, one);
    }
    return write_cloud_impl(path, cloud, options);
  } catch (const std::bad_alloc&) {
    return out_of_memory(msg(path, "out of memory building the file"));
  } catch (const std::length_error&) {
    return out_of_memory(msg(path, "out of memory building the file"));
  }
}

namespace detail {

Status check_fields(const std::string& path, const Cloud& cloud) {
  for (const IntegerField& x : cloud.fields) {
    if (x.values.size() != cloud.points.size())
      return invalid(path, "field " + printable(x.name, 64) + " has " + std::to_string(x.values.size()) + " values for " +
                               std::to_string(cloud.points.size()) + " points");
    if (!is_field_name(x.name))
      return invalid(path, "field name '" + printable(x.name, 64) + "' is not 1-64 letters, digits or underscores");
    if (static_cast<unsigned>(x.type) > static_cast<unsigned>(FieldType::kFloat64))
      return invalid(path, "field " + printable(x.name, 64) + " has an unknown type");
    if (is_float_type(x.type)) continue;
    const auto [lo, hi] = field_type_range(x.type);
    for (const std::int32_t v : x.values)
      if (v < lo || v > hi)
        return invalid(path, "field " + printable(x.name, 64) + " holds " + std::to_string(v) + ", not a " +
                                 field_type_name(x.type) + " value");
  }
  return {};
}

}  // namespace detail

}  // namespace lex3d::io
