#pragma once
/// \file
/// Reading and writing point cloud files. The only library module (with codec)
/// that touches the file system. Readers are hardened: every length is checked
/// against the bytes left before anything is allocated, and a bad file gives
/// a Status naming the file and what is wrong, never a crash.

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "lex3d/core/cloud.hpp"
#include "lex3d/core/status.hpp"

// The public API: exported by liblex3d.so, which hides everything else.
#pragma GCC visibility push(default)

namespace lex3d::io {

/// Point cloud file formats lex3d reads (and, for some, writes).
enum class Format : std::uint8_t {
  kAuto,     ///< detect from extension and content
  kKitti,    ///< little-endian float32 x y z intensity, 16 bytes a point (`.bin`)
  kBinXyz,   ///< little-endian float32 x y z, 12 bytes a point (`.bin`, e.g. Newer College)
  kPcd,      ///< PCL PCD v0.7: ascii, binary or binary_compressed
  kPly,      ///< PLY: ascii, binary_little_endian or binary_big_endian
  kXyz,      ///< ASCII text, `x y z [more columns]` a line, metres (`.xyz`, `.txt`, `.asc`, `.csv`);
             ///< a 4th column is the intensity when lines have exactly 4, or when a first
             ///< line `x y z ... intensity ...` names the columns
  kUos3d,    ///< Osnabrueck/3DTK `.3d`: ASCII `x y z` in centimetres, left-handed (y up, z forward), optional `.pose`;
             ///< read into lex3d's right-handed metric frame: x = z_in/100, y = -x_in/100, z = y_in/100
  kPcap,     ///< a raw spinning-lidar log: libpcap capture of Ouster (with its metadata JSON) or
             ///< Velodyne (VLP-16, Puck Hi-Res, HDL-32E, VLP-32C; HDL-64E with its calibration) UDP packets; read_cloud gives its first complete turn,
             ///< read_sensor_log (sensor_log.hpp) every turn
  kLas,      ///< ASPRS LAS 1.0-1.4 (`.las`, magic "LASF"), point data record formats 0-10: x y z (scale and
             ///< offset, the CRS's units read into metres about a georeference origin), intensity, RGB as
             ///< colours; compressed LAS (`.laz`) is refused
};

/// Canonical lower-case name of a format ("kitti", "binxyz", "pcd", "ply", "xyz", "uos", "auto").
[[nodiscard]] std::string_view format_name(Format f) noexcept;
/// Parses a format name (as printed by format_name, case-insensitive; "3d" is an alias of "uos").
[[nodiscard]] std::optional<Format> parse_format(std::string_view name) noexcept;

/// Decides the format of an existing file from its extension, magic bytes and size.
/// `.bin` files whose size is a multiple of both 16 and 12 are read as KITTI
/// unless the fourth float of the first records is negative or not finite.
[[nodiscard]] StatusOr<Format> detect_format(const std::string& path);

struct ReadOptions {
  /// Format to read as; kAuto detects it (see detect_format).
  Format format = Format::kAuto;
  /// For kUos3d: read `<stem>.pose` beside the file into Cloud::T_world_cloud when it exists.
  bool load_pose = true;
  /// For kUos3d: points at or beyond this range (centimetres) are the scanner's
  /// no-return value; they are dropped, counted, and kept as no-return directions.
  float uos_no_return_cm = 3270.0F;
  /// For kPcap: the Ouster sensor metadata JSON, or a Velodyne calibration (db.xml, VeloView
  /// XML, the ROS driver's YAML; required for an HDL-64E); empty: `<stem>.json` (Ouster) or
  /// `<stem>.xml`/`.yaml`/`.yml` (Velodyne) beside the capture, the stem cut at its last
  /// '_' until one is found.
  std::string metadata_path;
  /// For kPcap (Velodyne): a key of velodyne_models() ("vlp16", "puck-hires", "hdl32e",
  /// "vlp32c", "hdl64e") to override the model the packets announce (and the packet timing
  /// check); empty: detected.
  std::string sensor_model;
  /// For a ROS bag (io/rosbag.hpp): the topic to read; empty: its only point cloud topic.
  std::string bag_topic;
  /// For a dual-return capture (kPcap, or a bag of packets): keep one return a pixel, the
  /// one a single-return capture gives (Ouster's strongest, Velodyne's last), as an
  /// organised turn; the second returns are counted (SensorLogInfo::second_returns), not
  /// kept. Off: they are points of their own with a `return` field.
  bool single_return = false;
};

struct ReadResult {
  Cloud cloud;                          ///< finite points only
  Format format = Format::kAuto;        ///< the format actually read
  std::string encoding;                 ///< e.g. "binary_compressed", "ascii", "binary_little_endian"
  std::size_t non_finite_dropped = 0;   ///< points with a NaN or Inf coordinate, dropped
  /// No-return readings dropped: kUos3d's no-return range, an organised cloud's NaN or exact
  /// (0, 0, 0) pixels, a `.bin`'s exact (0, 0, 0) records, a raw log's zero-range pixels.
  std::size_t no_return_dropped = 0;
  /// Points beyond any lidar's reach, dropped: farther from the sensor origin than
  /// `far_limit_m` = max(10 km, 100 x the 99th percentile of the points' distances). Not
  /// applied to georeferenced clouds (their extent is a map's, not a sensor's).
  std::size_t far_dropped = 0;
  double far_limit_m = 0.0;  ///< the limit applied; 0: none
  /// kPcap: the sensor ("OS-1-128", "VLP-16") and how many complete turns the log holds
  /// (the cloud is the first of them).
  std::string sensor;
  std::size_t scans_in_file = 0;
  /// Per-point RGB colour (one per point of `cloud`) when the file has one
  /// (PCD `rgb`/`rgba` field, PLY `red green blue` properties); empty otherwise.
  std::vector<std::array<std::uint8_t, 3>> colors;
  std::uint64_t file_bytes = 0;         ///< size of the file read
  /// Fields the file holds (with a value other than zero) that lex3d does not keep, e.g.
  /// "classification", "GPS time" (LAS); empty when every field was kept.
  std::vector<std::string> dropped_fields;
  /// What the reader noticed and the user should know (one line each), e.g. a LAS
  /// header whose bounds do not hold its points.
  std::vector<std::string> notes;
};

/// Reads a point cloud file. Errors: kIoError when the file cannot be opened or
/// read, kBadData when its content is empty, truncated or malformed; the message
/// names the file and what is wrong, in one line.
[[nodiscard]] StatusOr<ReadResult> read_cloud(const std::string& path, const ReadOptions& options = {});

/// Sets `cloud.points` from points known in double precision (metres), as the readers do with
/// a file's double coordinates: as float32 where float32 holds them to a millionth of their
/// extent, else relative to a round origin near their centre, which becomes the cloud's
/// georeference (Cloud::georef: true coordinates are origin + point; `unit_name` describes
/// its unit) and moves a sensor pose set before (not the identity) with it. kBadData naming `what` for a point beyond 1e9 m
/// from the frame's origin. The points must be finite.
[[nodiscard]] Status set_double_points(Cloud& cloud, const std::vector<Eigen::Vector3d>& points, const std::string& what,
                                       const std::string& unit_name);

/// How the PCD writer encodes the data section.
enum class PcdEncoding : std::uint8_t { kAscii, kBinary, kBinaryCompressed };

struct WriteOptions {
  /// kAuto picks from the extension: .pcd, .ply, .bin (KITTI), .xyz/.txt, .las.
  Format format = Format::kAuto;
  PcdEncoding pcd_encoding = PcdEncoding::kBinary;
  /// PLY: binary_little_endian when true, ascii otherwise.
  bool ply_binary = true;
  /// Write the intensity field when the cloud has one (PCD/PLY); KITTI always writes 4 floats.
  bool write_intensity = true;
  /// Optional per-point RGB colour (empty, or one per point); PCD/PLY/LAS only.
  std::vector<std::array<std::uint8_t, 3>> colors;
  /// A cloud with a georeference is written in its true coordinates (Georeference::to_crs):
  /// PCD/PLY with double x y z, text with enough digits, LAS with its scale and offset. The
  /// float32 binaries (KITTI, x y z) cannot hold them and get the local coordinates.
  bool true_coordinates = true;
};

/// Writes `cloud` to `path`: the bytes go to a temporary file in the same
/// directory which is renamed over `path` only once complete, so a failure
/// never leaves a partial file.
[[nodiscard]] Status write_cloud(const std::string& path, const Cloud& cloud,
                                 const WriteOptions& options = {});

/// The per-point attributes of `cloud` ("intensity", "ring", "time", "rgb") that the format
/// `path` is written in (options.format, else its extension) cannot hold: a KITTI `.bin`
/// keeps the intensity only, an x y z `.bin` nothing, text the intensity, LAS everything but
/// the ring; PCD and PLY keep them all. Empty when every one is written.
/// Each pixel's point of an organised cloud (rows × columns, every point's ring and column
/// known and in range), row by row, -1 at a no-return pixel; empty where the cloud is not
/// organised or a pixel holds two points (a dual-return turn's second returns), which the
/// writers (PCD, a bag's PointCloud2) then write unorganised.
[[nodiscard]] std::vector<std::int64_t> pixel_points(const Cloud& cloud);

[[nodiscard]] std::vector<std::string> fields_not_written(const std::string& path, const Cloud& cloud,
                                                          const WriteOptions& options = {});

/// Writes `bytes` to `path` atomically (temporary file + rename).
[[nodiscard]] Status write_file_atomic(const std::string& path, const std::vector<std::uint8_t>& bytes);

/// Reads a whole file into memory; kIoError when missing/unreadable; `max_bytes` caps the size.
[[nodiscard]] StatusOr<std::vector<std::uint8_t>> read_file(const std::string& path,
                                                            std::uint64_t max_bytes = (1ULL << 34));

/// Reads a KITTI-style pose list: one line a pose, 12 numbers, the row-major
/// 3x4 matrix [R | t]. Blank lines are not allowed; the rotation must be
/// orthonormal within 1e-3 (it is re-orthonormalised).
[[nodiscard]] StatusOr<std::vector<Pose>> read_pose_list(const std::string& path);

/// Reads a list of one number a line (e.g. KITTI times.txt).
[[nodiscard]] StatusOr<std::vector<double>> read_number_list(const std::string& path);

/// Writes an 8-bit RGB image (row-major, width*height*3 bytes) as PNG, atomically.
[[nodiscard]] Status write_png_rgb(const std::string& path, int width, int height,
                                   const std::vector<std::uint8_t>& rgb);

}  // namespace lex3d::io

namespace lex3d::io {

/// What write_octomap produced.
struct OctomapStats {
  std::size_t occupied_leaves = 0;
  std::size_t free_leaves = 0;
  std::uint64_t file_bytes = 0;
};

/// Builds an OctoMap occupancy tree of `cloud` at `resolution` metres, casting free
/// space along the rays from `sensor_origin` (the cloud's frame) to every point, or, with
/// no origin (a map merged from many viewpoints), marking the points' voxels occupied and
/// nothing free; writes it as a binary `.bt` file atomically. An empty cloud gives an
/// empty tree.
[[nodiscard]] StatusOr<OctomapStats> write_octomap(const std::string& path, const Cloud& cloud,
                                                   const std::optional<Eigen::Vector3d>& sensor_origin,
                                                   double resolution);

}  // namespace lex3d::io

#pragma GCC visibility pop
