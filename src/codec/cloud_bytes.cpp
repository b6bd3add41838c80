// A Cloud as bytes and back (lex3d/codec/cloud_bytes.hpp). Layout, little-endian: "L3DC",
// a version byte, then the members in a fixed order; a string or array is its u64 count
// followed by its elements; an optional member a u8 flag then its fields.

#include "lex3d/codec/cloud_bytes.hpp"

#include <cstring>
#include <string>
#include <utility>

#include "codec/bytes.hpp"

namespace lex3d::codec {

namespace {

constexpr char kMagic[4] = {'L', '3', 'D', 'C'};
constexpr std::uint8_t kVersion = 1;

namespace b = bytes;

bool little_endian() {
  const std::uint16_t one = 1;
  std::uint8_t first = 0;
  std::memcpy(&first, &one, 1);
  return first == 1;
}

/// Reverses the bytes of each S-sized scalar in [p, p + n) (a big-endian host's values to
/// the layout's little-endian order, and back).
template <typename S>
void swap_scalars(std::uint8_t* p, std::size_t n) {
  for (std::size_t at = 0; at + sizeof(S) <= n; at += sizeof(S))
    for (std::size_t i = 0, j = sizeof(S) - 1; i < j; ++i, --j) std::swap(p[at + i], p[at + j]);
}

class Writer {
 public:
  std::vector<std::uint8_t> out;

  void u8(std::uint8_t v) { out.push_back(v); }
  void u16(std::uint16_t v) { b::put_u16(out, v); }
  void u32(std::uint32_t v) { b::put_u32(out, v); }
  void u64(std::uint64_t v) { b::put_u64(out, v); }
  void f64(double v) { b::put_f64(out, v); }
  void str(const std::string& s) {
    u64(s.size());
    out.insert(out.end(), s.begin(), s.end());
  }
  void vec3(const Eigen::Vector3d& v) {
    for (int k = 0; k < 3; ++k) f64(v[k]);
  }
  void pose(const Pose& T) {
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 4; ++c) f64(T.matrix()(r, c));
  }
  template <typename T, typename Put>
  void array(const std::vector<T>& v, Put put) {
    u64(v.size());
    for (const T& x : v) put(x);
  }
  /// An array of T made of scalars S only (float, integers, Eigen::Vector3f...): its count,
  /// then its bytes as they are in memory on a little-endian host.
  template <typename S, typename T>
  void plain(const std::vector<T>& v) {
    static_assert(sizeof(T) % sizeof(S) == 0, "T is made of S");
    u64(v.size());
    const std::size_t at = out.size(), n = v.size() * sizeof(T);
    out.resize(at + n);
    if (n == 0) return;
    std::memcpy(out.data() + at, v.data(), n);
    if (!little_endian()) swap_scalars<S>(out.data() + at, n);
  }
  void doubles(const std::vector<double>& v) { plain<double>(v); }
};

/// Reads what Writer wrote; the first failure sticks (every later read gives zeros).
class Reader {
 public:
  Reader(const std::uint8_t* p, std::size_t n) : p_(p), n_(n) {}

  [[nodiscard]] bool ok() const { return error_.empty(); }
  [[nodiscard]] const std::string& error() const { return error_; }
  [[nodiscard]] std::size_t left() const { return ok() ? n_ - at_ : 0; }
  void fail(std::string what) {
    if (ok()) error_ = std::move(what) + " (at byte " + std::to_string(at_) + ")";
  }

  const std::uint8_t* take(std::size_t k, const char* what) {
    if (!ok()) return nullptr;
    if (k > n_ - at_) {
      fail(std::string("truncated in ") + what);
      return nullptr;
    }
    const std::uint8_t* q = p_ + at_;
    at_ += k;
    return q;
  }
  std::uint8_t u8(const char* what) {
    const std::uint8_t* q = take(1, what);
    return q ? q[0] : 0;
  }
  std::uint16_t u16(const char* what) {
    const std::uint8_t* q = take(2, what);
    return q ? b::ld_u16(q) : 0;
  }
  std::uint32_t u32(const char* what) {
    const std::uint8_t* q = take(4, what);
    return q ? b::ld_u32(q) : 0;
  }
  std::uint64_t u64(const char* what) {
    const std::uint8_t* q = take(8, what);
    return q ? b::ld_u64(q) : 0;
  }
  double f64(const char* what) {
    const std::uint8_t* q = take(8, what);
    return q ? b::ld_f64(q) : 0.0;
  }
  /// A byte that must be 0 or 1.
  bool flag(const char* what) {
    const std::uint8_t v = u8(what);
    if (v > 1) fail(std::string("a flag that is neither 0 nor 1 in ") + what);
    return v == 1;
  }
  /// A count of elements of `size` bytes each that the bytes left can hold.
  std::size_t count(std::size_t size, const char* what) {
    const std::uint64_t k = u64(what);
    if (ok() && k > left() / size) fail(std::string("a count beyond the bytes in ") + what);
    return ok() ? static_cast<std::size_t>(k) : 0;
  }
  std::string str(const char* what) {
    const std::size_t k = count(1, what);
    const std::uint8_t* q = take(k, what);
    return q ? std::string(reinterpret_cast<const char*>(q), k) : std::string();
  }
  Eigen::Vector3d vec3(const char* what) {
    Eigen::Vector3d v;
    for (int k = 0; k < 3; ++k) v[k] = f64(what);
    return v;
  }
  Pose pose(const char* what) {
    Pose T = Pose::Identity();
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 4; ++c) T.matrix()(r, c) = f64(what);
    return T;
  }
  /// An array of elements of at least `size` bytes each, read by get().
  template <typename T, typename Get>
  std::vector<T> array(std::size_t size, const char* what, Get get) {
    std::vector<T> v(count(size, what));
    for (T& x : v) x = get();
    return ok() ? std::move(v) : std::vector<T>();
  }
  /// What Writer::plain wrote.
  template <typename S, typename T>
  std::vector<T> plain(const char* what) {
    std::vector<T> v(count(sizeof(T), what));
    const std::size_t n = v.size() * sizeof(T);
    const std::uint8_t* q = take(n, what);
    if (q == nullptr) return {};
    if (n > 0) {
      std::memcpy(static_cast<void*>(v.data()), q, n);
      if (!little_endian()) swap_scalars<S>(reinterpret_cast<std::uint8_t*>(v.data()), n);
    }
    return v;
  }
  std::vector<double> doubles(const char* what) { return plain<double, double>(what); }

 private:
  const std::uint8_t* p_;
  std::size_t n_;
  std::size_t at_ = 0;
  std::string error_;
};

void put_source(Writer& w, const SourceField& s) {
  w.str(s.name);
  w.u8(static_cast<std::uint8_t>(s.type));
}

/// A FieldType byte (kUnspecified ... kFloat64).
FieldType get_field_type(Reader& r, const char* what) {
  const std::uint8_t t = r.u8(what);
  if (t > static_cast<std::uint8_t>(FieldType::kFloat64)) r.fail(std::string("an unknown field type in ") + what);
  return static_cast<FieldType>(t);
}

SourceField get_source(Reader& r, const char* what) {
  SourceField s;
  s.name = r.str(what);
  s.type = get_field_type(r, what);
  return s;
}

}  // namespace

std::vector<std::uint8_t> cloud_to_bytes(const Cloud& c) {
  Writer w;
  w.out.reserve(64 + c.size() * (12 + (c.has_intensity() ? 4 : 0) + (c.has_rings() ? 2 : 0) + (c.has_columns() ? 4 : 0) +
                                 (c.has_time() ? 8 : 0) + (c.has_rgb() ? 3 : 0) + 4 * c.fields.size()));
  w.out.insert(w.out.end(), kMagic, kMagic + 4);
  w.u8(kVersion);
  static_assert(sizeof(Eigen::Vector3f) == 3 * sizeof(float), "a point is three floats");
  w.plain<float>(c.points);
  w.plain<float>(c.intensity);
  w.plain<float>(c.no_return_directions);
  w.pose(c.T_cloud_sensor);
  w.pose(c.T_world_cloud);
  w.u8(c.has_world_pose ? 1 : 0);
  w.plain<std::uint16_t>(c.ring);
  w.plain<std::uint32_t>(c.column);
  w.u32(c.rows);
  w.u32(c.columns);
  w.doubles(c.time);
  put_source(w, c.ring_source);
  put_source(w, c.intensity_source);
  put_source(w, c.time_source);
  static_assert(sizeof(std::array<std::uint8_t, 3>) == 3, "a colour is three bytes");
  w.plain<std::uint8_t>(c.rgb);
  w.u8(c.geometry ? 1 : 0);
  if (c.geometry) {
    const SensorGeometry& g = *c.geometry;
    for (const auto* v : {&g.elevation, &g.beam_azimuth, &g.column_azimuth, &g.z_offset, &g.radial_offset}) w.doubles(*v);
    w.u32(g.columns);
    w.f64(g.azimuth0);
    w.u8(g.direction < 0 ? 0 : 1);
    w.pose(g.T_sensor_head);
    w.str(g.source);
    w.str(g.sensor);
  }
  w.u8(c.georef ? 1 : 0);
  if (c.georef) {
    const Georeference& g = *c.georef;
    w.vec3(g.origin);
    w.f64(g.unit_m);
    w.str(g.unit_name);
    w.f64(g.vertical_unit_m);
    w.str(g.crs_name);
    w.u32(g.epsg);
    w.array(g.crs_records, [&w](const CrsRecord& rec) {
      w.str(rec.user_id);
      w.u16(rec.record_id);
      w.str(rec.description);
      w.plain<std::uint8_t>(rec.data);
      w.u8(rec.extended ? 1 : 0);
    });
    w.vec3(g.las_scale);
    w.vec3(g.las_offset);
    w.u8(g.las_version_minor);
    w.u8(g.las_point_format);
    w.u16(g.las_global_encoding);
    w.str(g.las_system_id);
    w.str(g.las_software);
    w.f64(g.representation_error_m);
  }
  w.u8(c.stamp ? 1 : 0);
  if (c.stamp) {
    w.u8(static_cast<std::uint8_t>(c.stamp->source));
    w.u64(c.stamp->sec);
    w.u32(c.stamp->nsec);
    w.str(c.stamp->frame_id);
  }
  w.array(c.fields, [&w](const IntegerField& f) {
    w.str(f.name);
    w.u8(static_cast<std::uint8_t>(f.type));
    w.plain<std::int32_t>(f.values);
  });
  return std::move(w.out);
}

StatusOr<Cloud> cloud_from_bytes(const std::uint8_t* data, std::size_t size) {
  const auto bad = [](const std::string& what) { return Status(ErrorCode::kBadData, "not a lex3d cloud: " + what); };
  if (data == nullptr || size < 5 || std::memcmp(data, kMagic, 4) != 0) return bad("no L3DC signature");
  if (data[4] != kVersion)
    return bad("version " + std::to_string(data[4]) + " (this lex3d reads version " + std::to_string(kVersion) + ")");
  Reader r(data + 5, size - 5);
  Cloud c;
  c.points = r.plain<float, Eigen::Vector3f>("points");
  const std::size_t n = c.points.size();
  // (a per-point array holds none or one value a point)
  const auto per_point = [&r, n](std::size_t k, const char* what) {
    if (k != 0 && k != n) r.fail(std::string(what) + " holds " + std::to_string(k) + " values for " + std::to_string(n) + " points");
  };
  c.intensity = r.plain<float, float>("intensity");
  per_point(c.intensity.size(), "intensity");
  c.no_return_directions = r.plain<float, Eigen::Vector3f>("no-return directions");
  c.T_cloud_sensor = r.pose("the sensor pose");
  c.T_world_cloud = r.pose("the world pose");
  c.has_world_pose = r.flag("the world pose");
  c.ring = r.plain<std::uint16_t, std::uint16_t>("ring");
  per_point(c.ring.size(), "ring");
  c.column = r.plain<std::uint32_t, std::uint32_t>("column");
  per_point(c.column.size(), "column");
  c.rows = r.u32("the range-image shape");
  c.columns = r.u32("the range-image shape");
  c.time = r.doubles("time");
  per_point(c.time.size(), "time");
  c.ring_source = get_source(r, "the ring's source field");
  c.intensity_source = get_source(r, "the intensity's source field");
  c.time_source = get_source(r, "the time's source field");
  c.rgb = r.plain<std::uint8_t, std::array<std::uint8_t, 3>>("rgb");
  per_point(c.rgb.size(), "rgb");
  if (r.flag("the geometry flag")) {
    SensorGeometry g;
    for (auto* v : {&g.elevation, &g.beam_azimuth, &g.column_azimuth, &g.z_offset, &g.radial_offset}) {
      *v = r.doubles("the sensor geometry");
      if (r.ok() && v->size() != g.elevation.size()) r.fail("a sensor geometry whose per-laser arrays differ in length");
    }
    g.columns = r.u32("the sensor geometry");
    g.azimuth0 = r.f64("the sensor geometry");
    g.direction = r.flag("the sensor geometry") ? 1 : -1;
    g.T_sensor_head = r.pose("the sensor geometry");
    g.source = r.str("the sensor geometry");
    g.sensor = r.str("the sensor geometry");
    c.geometry = std::move(g);
  }
  if (r.flag("the georeference flag")) {
    Georeference g;
    g.origin = r.vec3("the georeference");
    g.unit_m = r.f64("the georeference");
    g.unit_name = r.str("the georeference");
    g.vertical_unit_m = r.f64("the georeference");
    g.crs_name = r.str("the georeference");
    g.epsg = r.u32("the georeference");
    g.crs_records = r.array<CrsRecord>(8 + 2 + 8 + 8 + 1, "the CRS records", [&r] {
      CrsRecord rec;
      rec.user_id = r.str("a CRS record");
      rec.record_id = r.u16("a CRS record");
      rec.description = r.str("a CRS record");
      rec.data = r.plain<std::uint8_t, std::uint8_t>("a CRS record");
      rec.extended = r.flag("a CRS record");
      return rec;
    });
    g.las_scale = r.vec3("the georeference");
    g.las_offset = r.vec3("the georeference");
    g.las_version_minor = r.u8("the georeference");
    g.las_point_format = r.u8("the georeference");
    g.las_global_encoding = r.u16("the georeference");
    g.las_system_id = r.str("the georeference");
    g.las_software = r.str("the georeference");
    g.representation_error_m = r.f64("the georeference");
    c.georef = std::move(g);
  }
  if (r.flag("the stamp flag")) {
    ScanStamp s;
    const std::uint8_t source = r.u8("the stamp");
    if (source != static_cast<std::uint8_t>(ScanStamp::Source::kMessage) &&
        source != static_cast<std::uint8_t>(ScanStamp::Source::kCapture))
      r.fail("an unknown stamp source");
    s.source = static_cast<ScanStamp::Source>(source);
    s.sec = r.u64("the stamp");
    s.nsec = r.u32("the stamp");
    if (s.nsec >= 1000000000U) r.fail("a stamp's nanoseconds past a second");
    s.frame_id = r.str("the stamp");
    c.stamp = std::move(s);
  }
  c.fields = r.array<IntegerField>(8 + 1 + 8, "the named fields", [&r, &per_point] {
    IntegerField f;
    f.name = r.str("a named field");
    f.type = get_field_type(r, "a named field");
    f.values = r.plain<std::int32_t, std::int32_t>("a named field");
    per_point(f.values.size(), ("field " + f.name).c_str());
    return f;
  });
  if (r.ok() && r.left() != 0) r.fail(std::to_string(r.left()) + " bytes after the cloud");
  if (!r.ok()) return bad(r.error());
  return c;
}

}  // namespace lex3d::codec
