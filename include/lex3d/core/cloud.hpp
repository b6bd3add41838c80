#pragma once
/// \file
/// The one point cloud type that flows through lex3d: contiguous arrays of
/// positions (metres, sensor or world frame as the producer documents) with
/// optional per-point intensity. Conversions to and from pcl::PointCloud live
/// in lex3d/core/pcl_conversions.hpp (header-only), so that PCL headers stay out of here.

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

// The public API: exported by liblex3d.so, which hides everything else.
#pragma GCC visibility push(default)

namespace lex3d {

/// A rigid 6-DoF transform (rotation + translation), double precision.
using Pose = Eigen::Isometry3d;

/// The beam layout of a spinning lidar: one entry per laser (a row of its range image)
/// and an azimuth grid of `columns` steps a turn. A point of laser `l` in column `c` at
/// beam length `r` (metres from the beam's origin) lies, in the sensor head's frame, at
///
///     α = azimuth0 + direction · 2π · c / columns + column_azimuth[l]
///     o = radial_offset[l] · (cos α, sin α, 0) + (0, 0, z_offset[l])
///     u = (cos(α + beam_azimuth[l]) cos φ, sin(α + beam_azimuth[l]) cos φ, sin φ),  φ = elevation[l]
///     p = o + r · u
///
/// and in the cloud's sensor frame at `T_sensor_head · p`. Readers of raw sensor logs fill
/// it exactly from the sensor's metadata; the residual layer estimates it from the points
/// when no reader did (formats/model.md describes how it is stored).
struct SensorGeometry {
  std::vector<double> elevation;       ///< φ per laser, radians
  std::vector<double> beam_azimuth;    ///< beam azimuth relative to its column, radians
  std::vector<double> column_azimuth;  ///< azimuth shift of the laser's columns (stagger, firing time), radians
  std::vector<double> z_offset;        ///< height of the beam origin, metres
  std::vector<double> radial_offset;   ///< distance of the beam origin from the spin axis, metres
  std::uint32_t columns = 0;           ///< azimuth steps a full turn
  double azimuth0 = 0.0;               ///< azimuth of column 0, radians
  int direction = 1;                   ///< +1: azimuth grows with the column; -1: it falls
  Pose T_sensor_head = Pose::Identity();
  std::string source;                  ///< where it came from: "metadata", "model table", "estimated", ...
  std::string sensor;                  ///< the sensor's name when known (e.g. "OS-1-128", "VLP-16")

  [[nodiscard]] std::size_t lasers() const noexcept { return elevation.size(); }
};

/// One coordinate-reference-system record carried through from a source file untouched
/// (a LAS GeoTIFF-keys or OGC WKT VLR/EVLR), so that a writer can give it back.
struct CrsRecord {
  std::string user_id;                 ///< LAS VLR user id (e.g. "LASF_Projection"), at most 16 bytes
  std::uint16_t record_id = 0;         ///< LAS VLR record id (34735 GeoKeys, 34736 doubles, 34737 ASCII, 2112 WKT)
  std::string description;             ///< at most 32 bytes
  std::vector<std::uint8_t> data;      ///< the record's bytes
  bool extended = false;               ///< stored as an EVLR (LAS 1.4) in the source
};

/// Where a cloud's local frame sits in a projected (or any large) coordinate frame.
/// A point's true coordinates, in metres along the CRS axes, are `origin + point`
/// (computed in double); in the CRS's own units they are `(origin + point) / unit_m`
/// for x and y and `(origin.z + point.z) / vertical_unit_m` for z.
/// Readers of large coordinates (LAS always; PCD/PLY double fields, text with large
/// values) choose the origin and store float32 positions relative to it.
struct Georeference {
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();  ///< metres, CRS axes
  double unit_m = 1.0;                 ///< metres per CRS unit (0.3048 international foot, 1200/3937 US survey foot)
  std::string unit_name = "metre";     ///< the CRS's linear unit as named by the source
  double vertical_unit_m = 1.0;        ///< metres per unit of z (the horizontal unit unless the CRS says otherwise)
  std::string crs_name;                ///< the CRS's name when the source gives one; empty otherwise
  std::uint32_t epsg = 0;              ///< EPSG code of the projected CRS when known; 0 otherwise
  std::vector<CrsRecord> crs_records;  ///< the source's CRS records, byte for byte
  /// The LAS container a writer gives back (zeros when the source was not LAS):
  Eigen::Vector3d las_scale = Eigen::Vector3d::Zero();   ///< CRS units a step; 0: not LAS
  Eigen::Vector3d las_offset = Eigen::Vector3d::Zero();  ///< CRS units
  std::uint8_t las_version_minor = 0;  ///< 2, 3 or 4 (major is 1)
  std::uint8_t las_point_format = 0;   ///< point data record format 0..10
  std::uint16_t las_global_encoding = 0;
  std::string las_system_id;           ///< at most 32 bytes
  std::string las_software;            ///< at most 32 bytes
  /// Largest distance, metres, between a point's true position and origin + its float32 position,
  /// measured when the file was read (informative; not stored in model files).
  double representation_error_m = 0.0;

  [[nodiscard]] bool is_las() const noexcept { return las_scale.x() > 0.0; }
  /// Metres per CRS unit along x, y, z.
  [[nodiscard]] Eigen::Vector3d units() const noexcept { return {unit_m, unit_m, vertical_unit_m}; }
  /// True coordinates of a local point in the CRS's units.
  [[nodiscard]] Eigen::Vector3d to_crs(const Eigen::Vector3f& p) const {
    return (origin + p.cast<double>()).cwiseQuotient(units());
  }
};

/// A point cloud: positions and, when the source has them, per-point attributes
/// (intensity, laser, column, time, colour), each either empty or one a point.
/// The type a named field had in its source file, so that it is written back as it came
/// (formats/model.md §2.10): kUnspecified is a 32-bit signed integer.
enum class FieldType : std::uint8_t {
  kUnspecified = 0,
  kInt8 = 1,
  kUint8 = 2,
  kInt16 = 3,
  kUint16 = 4,
  kInt32 = 5,
  kUint32 = 6,
  kFloat32 = 7,
  kFloat64 = 8,  ///< double-precision values that float32 holds exactly
};

/// Whether fields of type `t` hold floating-point values (IntegerField::values then hold
/// each float's order key, float_key).
[[nodiscard]] constexpr bool is_float_type(FieldType t) noexcept {
  return t == FieldType::kFloat32 || t == FieldType::kFloat64;
}
/// The name of a field type as the model file's `info` and the docs give it ("uint16").
[[nodiscard]] const char* field_type_name(FieldType t) noexcept;
/// The values an integer field of type `t` holds, lowest and highest (kUint32: those
/// within 31 bits, as IntegerField keeps them; kUnspecified and the float types: int32's).
[[nodiscard]] std::pair<std::int64_t, std::int64_t> field_type_range(FieldType t) noexcept;

/// A float's order key: its bit pattern as a signed 32-bit integer that orders as the
/// floats do (bits for a positive sign, -(bits without the sign) - 1 for a negative
/// one); every bit pattern, NaN included, maps to one key and back (key_float).
[[nodiscard]] std::int32_t float_key(float v) noexcept;
/// The float whose order key is `key` (the inverse of float_key).
[[nodiscard]] float key_float(std::int32_t key) noexcept;

/// A per-point field that no other member of Cloud holds (a LAS file's classification,
/// return number, scan angle; a PCD or PLY file's other integer and floating-point
/// fields): its name, its source type and one value a point. Integer types hold the values
/// themselves; floating-point types hold each value's float_key (value(i) gives it back).
struct IntegerField {
  std::string name;
  std::vector<std::int32_t> values;
  FieldType type = FieldType::kUnspecified;

  /// Point i's value: the integer, or for a floating-point field the float.
  [[nodiscard]] double value(std::size_t i) const noexcept {
    return is_float_type(type) ? static_cast<double>(key_float(values[i])) : static_cast<double>(values[i]);
  }
};

/// Whether `name` may name an IntegerField: 1-64 letters, digits or underscores, as a PCD or
/// PLY header and a model file (formats/model.md §2.10) take it.
[[nodiscard]] bool is_field_name(const std::string& name) noexcept;

/// How a source stored the ring, intensity or time of its points: the field's name and type
/// (a driver's uint8 `ring`, a uint16 `intensity`, an Ouster driver's uint32 `t`), so that
/// the writers give it back as it came. Not given (an empty name, kUnspecified): the
/// writers' own (`ring` uint16, `intensity` float32, `time` float64). An integer time
/// field counts nanoseconds; Cloud::time holds seconds either way.
struct SourceField {
  std::string name;
  FieldType type = FieldType::kUnspecified;
  [[nodiscard]] bool given() const noexcept { return type != FieldType::kUnspecified && !name.empty(); }
};

/// When and in which frame a scan was taken, as its source gives it: a ROS message's
/// header (its stamp and frame_id), or a raw capture's turn (the capture time of the turn's
/// first packet: the recording host's clock, not the sensor's). Kept through a model file
/// (its optional `scan` chunk, formats/model.md §2.13) and written back into a bag.
struct ScanStamp {
  enum class Source : std::uint8_t {
    kMessage = 1,  ///< a message header's stamp (a PointCloud2's, or a packet message's)
    kCapture = 2,  ///< the capture time of the turn's first packet (a pcap record's)
  };
  Source source = Source::kMessage;
  std::uint64_t sec = 0;   ///< seconds since the Unix epoch
  std::uint32_t nsec = 0;  ///< [0, 1e9)
  std::string frame_id;    ///< the header's frame_id; empty where the source names none
};

struct Cloud {
  /// Point positions in metres.
  std::vector<Eigen::Vector3f> points;
  /// Per-point intensity; empty when the source had none, else points.size().
  std::vector<float> intensity;
  /// Directions (unit vectors, cloud frame) of beams that returned no echo,
  /// when the source format records them (e.g. the 3DTK `.3d` no-return value).
  std::vector<Eigen::Vector3f> no_return_directions;
  /// Pose of the sensor in the frame the points are expressed in: a PCD file's
  /// VIEWPOINT; identity for the other formats, whose scans are stored in the
  /// sensor frame. Written back as the VIEWPOINT of a PCD file.
  Pose T_cloud_sensor = Pose::Identity();
  /// Pose of the cloud frame in a world frame, when the data provides one
  /// (a `.pose` file, a poses.txt line); identity otherwise.
  Pose T_world_cloud = Pose::Identity();
  /// True when T_world_cloud came from the data rather than the default.
  bool has_world_pose = false;
  /// Laser (range-image row) of each point when the source knows it (an organised
  /// cloud's row, a `ring` field, a raw sensor log); empty otherwise, else points.size().
  std::vector<std::uint16_t> ring;
  /// Azimuth column of each point when the source knows it (an organised cloud's
  /// column, a raw sensor log's measurement column); empty otherwise, else points.size().
  std::vector<std::uint32_t> column;
  /// Range-image shape of an organised source (rows × columns, no-return pixels
  /// not counted as points); 0 × 0 for an unorganised one.
  std::uint32_t rows = 0;
  std::uint32_t columns = 0;
  /// Time of each point, seconds, when the source records it (a PCD/PLY `time`, `t` or
  /// `timestamp` field, LAS GPS time, a raw log's firing time); empty otherwise, else
  /// points.size(). The epoch is the source's (LAS: GPS time; raw logs: the turn's first
  /// measurement, as the sensors' ROS drivers give it).
  std::vector<double> time;
  /// The name and type the source gave the ring, intensity and time fields (SourceField;
  /// kept through a model file since format 1.16).
  SourceField ring_source, intensity_source, time_source;
  /// RGB colour of each point when the source has one (PCD `rgb`/`rgba`, PLY `red green
  /// blue`, LAS formats with colour, scaled to 8 bits); empty otherwise, else points.size().
  std::vector<std::array<std::uint8_t, 3>> rgb;
  /// The sensor's beam layout when the source gives it (raw logs with metadata).
  std::optional<SensorGeometry> geometry;
  /// Where the local frame sits in a georeferenced (projected) frame, when the source's
  /// coordinates are large (a LAS file, a UTM cloud): true coordinates are origin + point.
  std::optional<Georeference> georef;
  /// When and in which frame the scan was taken, where the source says (ScanStamp).
  std::optional<ScanStamp> stamp;
  /// Further per-point fields by name, each with points.size() values and its source type
  /// (a LAS file's classification, return_number, scan_angle_rank...; a PCD's or PLY's other
  /// integer and float fields; a raw Ouster capture's signal and near_ir; see
  /// formats/model.md §2.10 for how they are kept).
  std::vector<IntegerField> fields;

  /// The field named `name`, or nullptr.
  [[nodiscard]] const IntegerField* field(const std::string& name) const noexcept {
    for (const IntegerField& f : fields)
      if (f.name == name) return &f;
    return nullptr;
  }

  [[nodiscard]] bool has_rings() const noexcept { return !ring.empty() && ring.size() == points.size(); }
  [[nodiscard]] bool has_columns() const noexcept { return !column.empty() && column.size() == points.size(); }
  [[nodiscard]] bool has_time() const noexcept { return !time.empty() && time.size() == points.size(); }
  [[nodiscard]] bool has_rgb() const noexcept { return !rgb.empty() && rgb.size() == points.size(); }

  [[nodiscard]] std::size_t size() const noexcept { return points.size(); }
  [[nodiscard]] bool empty() const noexcept { return points.empty(); }
  [[nodiscard]] bool has_intensity() const noexcept {
    return !intensity.empty() && intensity.size() == points.size();
  }
};

/// Axis-aligned bounds of a cloud; for an empty cloud both corners are zero
/// and `valid` is false.
struct Bounds {
  Eigen::Vector3f min = Eigen::Vector3f::Zero();
  Eigen::Vector3f max = Eigen::Vector3f::Zero();
  bool valid = false;
};

[[nodiscard]] Bounds compute_bounds(const Cloud& cloud);

/// Returns a copy of `cloud` with every point mapped by `T` (float math); the
/// sensor pose moves with the points and the world pose is kept consistent.
[[nodiscard]] Cloud transformed(const Cloud& cloud, const Pose& T);

}  // namespace lex3d

#pragma GCC visibility pop
