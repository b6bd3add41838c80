// The compiled part of the Python package `lex3d` (lex3d._lex3d, re-exported by
// lex3d/__init__.py): the one-call API of lex3d/lex3d.hpp on numpy arrays, paths and bytes,
// and the place database (place.cpp). Points are an (N, 3) float32 or float64 array (metres),
// intensity an optional (N,) array; model and alphabet files are bytes. Bad arrays and
// undecodable data raise ValueError, files that cannot be read OSError, with the library's
// one-line message.

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "common.hpp"
#include "lex3d/codec/codec.hpp"
#include "lex3d/io/io.hpp"
#include "lex3d/lex3d.hpp"
#include "lex3d/residual/sensor_profile.hpp"

namespace py = pybind11;

namespace {

using lex3d::python::raise;
using lex3d::python::to_bytes;
using lex3d::python::to_vector;

lex3d::WordsMode words_mode(const std::optional<std::string>& words) {
  if (!words) return lex3d::WordsMode::kDefault;
  if (*words == "on") return lex3d::WordsMode::kOn;
  if (*words == "off") return lex3d::WordsMode::kOff;
  if (*words == "auto") return lex3d::WordsMode::kAuto;
  throw py::value_error("words must be None, 'on', 'off' or 'auto', got '" + *words + "'");
}

lex3d::LayerCoding layer_coding(const std::string& s) {
  if (s == "auto") return lex3d::LayerCoding::kAuto;
  if (s == "spherical") return lex3d::LayerCoding::kSpherical;
  if (s == "voxel") return lex3d::LayerCoding::kVoxel;
  if (s == "laser") return lex3d::LayerCoding::kLaser;
  if (s == "acquisition") return lex3d::LayerCoding::kAcquisition;
  if (s == "lattice") return lex3d::LayerCoding::kLattice;
  throw py::value_error("layer_coding must be 'auto', 'spherical', 'voxel', 'laser', 'acquisition' or 'lattice', got '" + s +
                        "'");
}

/// Adds `fields` (a dict: name -> (N,) numpy array) to `cloud` as named fields in their
/// dtypes' types: int8 to uint32 (a uint32 within 31 bits), float32, float64 that float32
/// holds. ValueError for a bad name, shape, dtype or value.
void add_fields(lex3d::Cloud& cloud, const py::object& fields) {
  if (!py::isinstance<py::dict>(fields)) throw py::value_error("fields must be a dict of name -> numpy array");
  for (const auto& item : py::reinterpret_borrow<py::dict>(fields)) {
    if (!py::isinstance<py::str>(item.first)) throw py::value_error("fields: a name is not a str");
    const auto name = item.first.cast<std::string>();
    const std::string what = "fields['" + name + "']";
    if (!lex3d::is_field_name(name)) throw py::value_error(what + ": the name is not 1-64 letters, digits or underscores");
    for (const char* taken : {"intensity", "ring", "time", "rgb"})
      if (name == taken) throw py::value_error(what + ": " + name + " is not a named field (intensity= gives the intensity)");
    if (cloud.field(name) != nullptr) throw py::value_error(what + " is given twice");
    const py::array a = lex3d::python::per_point_array(item.second, cloud.size(), what);
    const char kind = a.dtype().kind();
    const auto size = a.dtype().itemsize();
    lex3d::IntegerField x{name, std::vector<std::int32_t>(cloud.size()), lex3d::FieldType::kUnspecified};
    if (kind == 'f' && (size == 4 || size == 8)) {
      x.type = size == 4 ? lex3d::FieldType::kFloat32 : lex3d::FieldType::kFloat64;
      const py::array_t<double, py::array::forcecast> values(a);  // (kept alive while read)
      const auto v = values.unchecked<1>();
      for (std::size_t i = 0; i < cloud.size(); ++i) {
        const double d = v(static_cast<py::ssize_t>(i));
        const auto f = static_cast<float>(d);
        if (size == 8 && static_cast<double>(f) != d && !std::isnan(d))
          throw py::value_error(what + ": value " + std::to_string(i) + " is a double that float32 does not hold");
        x.values[i] = lex3d::float_key(f);
      }
    } else if ((kind == 'i' || kind == 'u') && size <= 4) {
      x.type = kind == 'i' ? (size == 1 ? lex3d::FieldType::kInt8 : size == 2 ? lex3d::FieldType::kInt16 : lex3d::FieldType::kInt32)
                           : (size == 1 ? lex3d::FieldType::kUint8 : size == 2 ? lex3d::FieldType::kUint16 : lex3d::FieldType::kUint32);
      const py::array_t<std::int64_t, py::array::forcecast> values(a);
      const auto v = values.unchecked<1>();
      for (std::size_t i = 0; i < cloud.size(); ++i) {
        const std::int64_t k = v(static_cast<py::ssize_t>(i));
        if (k > 2147483647LL) throw py::value_error(what + ": value " + std::to_string(i) + " is above 2^31 - 1");
        x.values[i] = static_cast<std::int32_t>(k);
      }
    } else {
      throw py::value_error(what + " must be an integer array of up to 32 bits or float32/float64, got " +
                            lex3d::python::dtype_of(a));
    }
    cloud.fields.push_back(std::move(x));
  }
}

/// Sets `cloud`'s ring from `ring`: an (N,) integer array of laser numbers in 0..65535 (its
/// dtype kept as the source's type where it is not uint16). ValueError otherwise.
void add_ring(lex3d::Cloud& cloud, const py::object& ring) {
  const py::array a = lex3d::python::per_point_array(ring, cloud.size(), "ring");
  const char kind = a.dtype().kind();
  if (kind != 'i' && kind != 'u') throw py::value_error("ring must be an integer array, got " + lex3d::python::dtype_of(a));
  const py::array_t<std::int64_t, py::array::forcecast> values(a);
  const auto v = values.unchecked<1>();
  cloud.ring.resize(cloud.size());
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const std::int64_t k = v(static_cast<py::ssize_t>(i));
    if (k < 0 || k > 65535) throw py::value_error("ring: value " + std::to_string(i) + " is outside 0..65535");
    cloud.ring[i] = static_cast<std::uint16_t>(k);
  }
  if (kind == 'u' && a.dtype().itemsize() == 1) cloud.ring_source = {"ring", lex3d::FieldType::kUint8};
}

/// Sets `cloud`'s time from `time`: an (N,) float32 or float64 array of seconds, or an
/// integer one of nanoseconds (as ouster_ros's `t`), its dtype kept as the source's type
/// (float32: `time`, as velodyne_pointcloud's; integers: `t`). ValueError otherwise.
void add_time(lex3d::Cloud& cloud, const py::object& time) {
  const py::array a = lex3d::python::per_point_array(time, cloud.size(), "time");
  const char kind = a.dtype().kind();
  const auto size = a.dtype().itemsize();
  cloud.time.resize(cloud.size());
  if (kind == 'f' && (size == 4 || size == 8)) {
    const py::array_t<double, py::array::forcecast> values(a);
    const auto v = values.unchecked<1>();
    for (std::size_t i = 0; i < cloud.size(); ++i) cloud.time[i] = v(static_cast<py::ssize_t>(i));
    if (size == 4) cloud.time_source = {"time", lex3d::FieldType::kFloat32};
  } else if ((kind == 'i' || kind == 'u') && size <= 4) {
    const py::array_t<std::int64_t, py::array::forcecast> values(a);
    const auto v = values.unchecked<1>();
    for (std::size_t i = 0; i < cloud.size(); ++i) cloud.time[i] = static_cast<double>(v(static_cast<py::ssize_t>(i))) * 1e-9;
    cloud.time_source = {"t", kind == 'u' ? (size == 4 ? lex3d::FieldType::kUint32 : size == 2 ? lex3d::FieldType::kUint16 : lex3d::FieldType::kUint8)
                                        : (size == 4 ? lex3d::FieldType::kInt32 : size == 2 ? lex3d::FieldType::kInt16 : lex3d::FieldType::kInt8)};
  } else {
    throw py::value_error("time must be float32/float64 seconds or integer nanoseconds of up to 32 bits, got " +
                          lex3d::python::dtype_of(a));
  }
  for (std::size_t i = 0; i < cloud.size(); ++i)
    if (!std::isfinite(cloud.time[i])) throw py::value_error("time: value " + std::to_string(i) + " is not finite");
}

/// Sets `cloud`'s stamp from a dict {"sec": int, "nsec": int, "frame_id": str} (nsec and
/// frame_id optional), as a ROS message header's. ValueError otherwise.
void set_stamp(lex3d::Cloud& cloud, const py::object& stamp) {
  if (!py::isinstance<py::dict>(stamp)) throw py::value_error("stamp must be a dict with 'sec', 'nsec' and 'frame_id'");
  const auto d = stamp.cast<py::dict>();
  for (const auto& item : d) {
    const std::string key = py::str(item.first);
    if (key != "sec" && key != "nsec" && key != "frame_id")
      throw py::value_error("stamp: unknown key '" + key + "' (sec, nsec, frame_id)");
  }
  if (!d.contains("sec")) throw py::value_error("stamp needs 'sec' (seconds since the Unix epoch)");
  lex3d::ScanStamp s;
  const auto whole = [&](const char* key, long long most) {
    const py::object v = d[key];
    if (!py::isinstance<py::int_>(v)) throw py::value_error(std::string("stamp: '") + key + "' must be an integer");
    const long long x = v.cast<long long>();
    if (x < 0 || x > most) throw py::value_error(std::string("stamp: '") + key + "' is outside 0.." + std::to_string(most));
    return x;
  };
  s.sec = static_cast<std::uint64_t>(whole("sec", std::numeric_limits<long long>::max()));
  if (d.contains("nsec")) s.nsec = static_cast<std::uint32_t>(whole("nsec", 999999999LL));
  if (d.contains("frame_id")) {
    s.frame_id = py::str(d["frame_id"]);
    if (s.frame_id.size() > 1024 || s.frame_id.find('\0') != std::string::npos)
      throw py::value_error("stamp: 'frame_id' must be at most 1024 bytes, without NUL");
  }
  cloud.stamp = std::move(s);
}

py::object compress(const py::object& points, const py::object& intensity, std::optional<double> max_error,
                    std::optional<double> target_bpp, const std::optional<std::string>& words,
                    const std::string& coding, bool keep_all_points, const std::optional<py::bytes>& alphabet,
                    double word_radius, int iterations, std::uint64_t seed, int threads, bool report,
                    const py::object& sensor, const py::object& fields, const std::vector<std::string>& drop_fields,
                    const py::object& ring, const py::object& time, const py::object& stamp,
                    const std::string& metadata, const std::string& topic, bool single_return, bool fast,
                    const std::string& objective) {
  // A path is read as `lex3d compress PATH` reads it (its attributes and sensor pose kept); a
  // lex3d.Scan gives everything its file gave.
  const bool from_file = lex3d::python::is_path(points);
  const bool scan = py::isinstance<lex3d::python::PyScan>(points);
  const char* given = from_file ? "a path" : "a lex3d.Scan";
  if ((from_file || scan) && !intensity.is_none())
    throw py::value_error(std::string("intensity goes with an array of points, not ") + given);
  if ((from_file || scan) && !fields.is_none()) throw py::value_error(std::string("fields go with an array of points, not ") + given);
  if ((from_file || scan) && (!ring.is_none() || !time.is_none()))
    throw py::value_error(std::string("ring and time go with an array of points, not ") + given);
  if (!from_file && (!metadata.empty() || !topic.empty() || single_return))
    throw py::value_error(std::string("metadata, topic and single_return go with a path, not ") +
                          (scan ? "a lex3d.Scan (give them to lex3d.scans)" : "an array of points"));
  lex3d::io::ReadOptions read;
  read.metadata_path = metadata;
  read.bag_topic = topic;
  read.single_return = single_return;
  lex3d::Cloud cloud = from_file || scan ? lex3d::python::scan_from(points, nullptr, "points", read)
                                         : lex3d::python::to_cloud(points, intensity, "points");
  if (!fields.is_none()) add_fields(cloud, fields);
  if (!ring.is_none()) add_ring(cloud, ring);
  if (!time.is_none()) add_time(cloud, time);
  if (!stamp.is_none()) set_stamp(cloud, stamp);
  lex3d::CompressOptions o;
  o.max_error = max_error;
  o.target_bpp = target_bpp.value_or(0.0);
  if (target_bpp && *target_bpp <= 0.0) throw py::value_error("target_bpp must be positive, got " + std::to_string(*target_bpp));
  o.words = words_mode(words);
  o.layer_coding = layer_coding(coding);
  o.keep_all_points = keep_all_points;
  o.fast = fast;
  if (objective != "bound" && objective != "mse")
    throw py::value_error("objective must be 'bound' or 'mse', got '" + objective + "'");
  o.mse = objective == "mse";
  if (alphabet) o.alphabet = to_vector(*alphabet);
  o.model.word_radius = word_radius;
  o.max_iterations = iterations;
  o.seed = seed;
  o.threads = threads;
  o.attributes.drop = drop_fields;
  if (!sensor.is_none()) {  // a sensor profile file (formats/sensor_profile.md)
    if (!lex3d::python::is_path(sensor)) throw py::value_error("sensor must be the path of a sensor profile file");
    const std::string path = lex3d::python::path_of(sensor);
    auto bytes = lex3d::io::read_file(path, 16ULL << 20);
    if (!bytes.ok()) raise(bytes.status());
    const auto& b = bytes.value();
    auto profile = lex3d::residual::parse_sensor_profile(std::string_view(reinterpret_cast<const char*>(b.data()), b.size()), path);
    if (!profile.ok()) raise(profile.status());
    o.sensor_profile = std::move(profile).value();
  }
  o.validate();
  std::optional<lex3d::StatusOr<lex3d::CompressResult>> r;
  {
    py::gil_scoped_release unlocked;
    r.emplace(lex3d::compress(cloud, o));
  }
  if (!r->ok()) raise(r->status());
  const lex3d::CompressResult& c = r->value();
  // Never drop an attribute silently.
  for (const auto& a : c.dropped_attributes)
    if (std::find(drop_fields.begin(), drop_fields.end(), a) == drop_fields.end() && PyErr_WarnEx(PyExc_UserWarning, (a + " is not kept in this model file (attributes need a residual layer: "
                                         "give max_error or target_bpp): " + std::to_string(c.input_points) +
                                         " values dropped").c_str(), 1) != 0)
      throw py::error_already_set();
  if (!report) return to_bytes(c.bytes);
  // What a manifest or a report needs: sizes, the bound, what was kept and dropped.
  py::dict info;
  info["points"] = c.input_points;
  info["bytes"] = c.bytes.size();
  info["bits_per_point"] = c.bits_per_point();
  info["max_error"] = c.max_error ? py::object(py::float_(*c.max_error)) : py::object(py::none());
  info["words"] = c.words;
  info["instances"] = c.instances;
  info["alphabet_words"] = c.alphabet_words;
  py::list kept;
  for (const auto& a : c.attributes) kept.append(a.name);
  info["attributes"] = kept;
  info["dropped_attributes"] = c.dropped_attributes;
  return py::make_tuple(to_bytes(c.bytes), info);
}

/// The stamp a model file keeps (its `scan` chunk), or None.
py::object stamp(const py::bytes& data, const std::optional<py::bytes>& alphabet) {
  const std::vector<std::uint8_t> bytes = to_vector(data);
  std::vector<std::uint8_t> alphabet_file;
  if (alphabet) alphabet_file = to_vector(*alphabet);
  auto d = lex3d::codec::decode_model(bytes, alphabet ? &alphabet_file : nullptr);
  if (!d.ok()) raise(d.status());
  return lex3d::python::stamp_dict(d.value().stamp);
}

py::object decompress(const py::bytes& data, const std::optional<py::bytes>& alphabet, bool attributes) {
  const std::vector<std::uint8_t> bytes = to_vector(data);
  std::vector<std::uint8_t> alphabet_file;
  if (alphabet) alphabet_file = to_vector(*alphabet);
  std::optional<lex3d::StatusOr<lex3d::DecompressResult>> r;
  {
    py::gil_scoped_release unlocked;
    r.emplace(lex3d::decompress(bytes, alphabet ? &alphabet_file : nullptr));
  }
  if (!r->ok()) raise(r->status());
  const lex3d::Cloud& cloud = r->value().cloud;
  py::array out = lex3d::python::points_array(cloud);
  if (!attributes) return std::move(out);
  // The per-point fields the file keeps (formats/model.md §2.10), by name.
  const py::dict fields = lex3d::python::fields_dict(cloud);
  return py::make_tuple(out, fields);
}

py::bytes learn_alphabet(const py::list& clouds, double word_radius, int iterations, int patience,
                         std::uint64_t seed, bool prune, int threads) {
  std::vector<lex3d::Cloud> scans;
  for (std::size_t i = 0; i < clouds.size(); ++i)
    scans.push_back(lex3d::python::scan_from(clouds[i], nullptr, "clouds[" + std::to_string(i) + "]"));
  if (scans.empty()) throw py::value_error("learn_alphabet needs at least one cloud");
  lex3d::AlphabetOptions o;
  o.model.word_radius = word_radius;
  o.model.threads = threads;
  o.max_iterations = iterations;
  o.patience = patience;
  o.seed = seed;
  o.prune = prune;
  o.validate();
  std::vector<std::uint8_t> bytes;
  {
    py::gil_scoped_release unlocked;
    bytes = lex3d::learn_alphabet(scans, o).bytes;
  }
  return to_bytes(bytes);
}

}  // namespace

PYBIND11_MODULE(_lex3d, m) {
  m.doc() =
      "lex3d: compress lidar scans with a learned alphabet of local 3D structures and a bounded-error "
      "residual layer.\n\n"
      "    data = lex3d.compress(points, max_error=0.014)   # points: (N, 3) float32/float64, metres\n"
      "    back = lex3d.decompress(data)                    # (M, 3) float32 (float64 if georeferenced)\n\n"
      "The bytes are those `lex3d compress` writes for the same settings (formats/model.md).";
  m.attr("__version__") = LEX3D_VERSION_STRING;
  m.def("compress", &compress, py::arg("points"), py::arg("intensity") = py::none(), py::kw_only(),
        py::arg("max_error") = py::none(), py::arg("target_bpp") = py::none(), py::arg("words") = py::none(),
        py::arg("layer_coding") = "auto", py::arg("keep_all_points") = false, py::arg("alphabet") = py::none(),
        py::arg("word_radius") = 0.0, py::arg("iterations") = lex3d::LearnParams{}.max_iterations,
        py::arg("seed") = lex3d::LearnParams{}.seed, py::arg("threads") = 2, py::arg("report") = false,
        py::arg("sensor") = py::none(), py::arg("fields") = py::none(),
        py::arg("drop_fields") = std::vector<std::string>{}, py::arg("ring") = py::none(), py::arg("time") = py::none(),
        py::arg("stamp") = py::none(), py::arg("metadata") = "", py::arg("topic") = "", py::arg("single_return") = false,
        py::arg("fast") = false, py::arg("objective") = "bound",
        R"(Compresses one scan into a model file (bytes), as `lex3d compress` does.

points: (N, 3) float32 or float64 array, metres, sensor frame; every value finite. float64
    coordinates that float32 would round (far from their frame's origin, as UTM ones) are kept
    relative to an origin the file stores; decompress gives them back as they were. Or a path
    (str or os.PathLike) of a point cloud file, read as `lex3d compress PATH` reads it (a
    capture's or bag's first scan), or a lex3d.Scan (lex3d.scans: every scan of a file).
intensity: optional (N,) float or 8- or 16-bit integer array (an integer one comes back in its dtype), kept with a residual layer (losslessly); without one
    a UserWarning says it was dropped.
fields: optional dict of name -> (N,) array, further per-point fields kept with a residual
    layer (losslessly), each given back by decompress(attributes=True) in its dtype: integers
    of up to 32 bits (uint32 values below 2^31), float32, float64 that float32 holds.
ring: optional (N,) integer array, each point's laser (0..65535), as a driver's `ring`.
time: optional (N,) array, each point's time: float32 or float64 seconds, or integer
    nanoseconds (as ouster_ros's `t`). With ring and time, a spinning lidar's columns come from
    the firing times (the sensor-geometry layer codes the scan as from its raw log) and the
    times cost about one value a firing. Both kept with a residual layer (losslessly; a float32
    time as float32); decompress(attributes=True) gives both back in their dtypes.
stamp: optional dict {"sec": int, "nsec": int, "frame_id": str} (nsec and frame_id optional):
    when and in which frame the scan was taken, as a ROS message header's; the file keeps it
    (lex3d.stamp reads it back). A path's own stamp (a bag's message, a capture's turn) is kept
    without it.
metadata, topic, single_return: how a path is read, as `lex3d compress`'s --metadata (a pcap's
    Ouster metadata JSON or Velodyne calibration), --topic (a ROS bag's) and --single-return (a
    dual-return capture's first returns only); a capture or bag gives its first scan.
drop_fields: names of fields not to keep ('intensity', 'ring', 'time', 'rgb' or a named
    field's, as report lists them), like `compress --drop-field`.
max_error: residual-layer bound in metres, [1e-4, 10]: every point has a decoded point within it
    and vice versa. None: words only (an alphabet is learned on the scan), unless target_bpp.
target_bpp: bits per point the file should fit; the smallest bound that fits is taken.
words: None (off with a residual layer, on without), 'on', 'off' or 'auto' (the smaller file).
layer_coding: 'auto', 'spherical', 'voxel', 'laser', 'acquisition' or 'lattice'.
keep_all_points: give every input point its own decoded point.
fast: sensor-rate encoding, as `lex3d compress --fast`: fewer codings and attribute methods
    tried; files a little larger.
objective: 'bound' (the fewest bits within max_error) or 'mse' (the fewest bits for the mean
    squared error, still within max_error), as `lex3d compress --objective`.
alphabet: an alphabet file (bytes, from learn_alphabet) to reuse; the model then references it.
word_radius: metres, 0 derives it from the scan. iterations, seed: the learner's.
threads: worker threads, [1, 64]; the bytes do not depend on it.
report: return (bytes, info) with info a dict: points, bytes, bits_per_point, max_error (None
    without a layer), words, instances, alphabet_words, attributes (kept), dropped_attributes.
sensor: path of a sensor profile (formats/sensor_profile.md: JSON or a Velodyne db.xml), the
    lidar's laser table for the residual layer; needs max_error or target_bpp.
Raises ValueError for a bad array or option, an alphabet that does not decode, a bad profile or a
scan that does not fit it.)");
  m.def("decompress", &decompress, py::arg("data"), py::arg("alphabet") = py::none(), py::kw_only(),
        py::arg("attributes") = false,
        R"(Decodes a model file (bytes) into an (M, 3) float32 array of points (metres), or, for a
file that keeps a georeference (a LAS file's, or coordinates far from their frame's origin such
as UTM ones), a float64 array of their true coordinates in the file's units.

alphabet: the alphabet file (bytes) the model references, if it references one.
attributes: also return the per-point fields the file keeps, as (points, fields) with fields a
dict of (M,) arrays by name: "intensity" (float32, or the integer dtype it was given in), "ring" (uint16, or
the integer type its source gave it), "time" (seconds as float64, or as the float32 its source gave;
integer nanoseconds in the integer type of a source such as ouster_ros's uint32 "t"),
"rgb" ((M, 3) uint8) and each named integer field (int32; a LAS file's "classification",
"return_number", "scan_angle_rank"...).
Raises ValueError for a malformed, truncated or corrupt file (the message names the byte offset)
or a missing or mismatched alphabet.)");
  m.def("stamp", &stamp, py::arg("data"), py::arg("alphabet") = py::none(),
        R"(When and in which frame the scan of a model file (bytes) was taken, as its source gave
it: a dict {"sec", "nsec", "frame_id", "source"} (source "message": a ROS message header's
stamp, or compress(stamp=); "capture": a raw capture's turn, the capture time of its first
packet), or None where the file keeps none.
alphabet: the alphabet file (bytes) the model references, if it references one.
Raises ValueError for a malformed, truncated or corrupt file.)");
  lex3d::python::bind_scans(m);
  lex3d::python::bind_place(m);
  lex3d::python::bind_learning(m);
  m.def("learn_alphabet", &learn_alphabet, py::arg("clouds"), py::kw_only(), py::arg("word_radius") = 0.0,
        py::arg("iterations") = lex3d::LearnParams{}.max_iterations,
        py::arg("patience") = lex3d::LearnParams{}.patience, py::arg("seed") = lex3d::LearnParams{}.seed,
        py::arg("prune") = true, py::arg("threads") = 2,
        R"(Learns one alphabet for a list of (N, 3) float arrays and returns its file (bytes), as
`lex3d learn`
(a cloud may also be a path of a point cloud file) does; pass it to compress(..., alphabet=...) and decompress(..., alphabet=...).)");
}
