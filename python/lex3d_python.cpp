// The Python module `lex3d`: the one-call API of lex3d/lex3d.hpp on numpy arrays and bytes.
// Points are an (N, 3) float32 or float64 array (metres), intensity an optional (N,) array;
// model and alphabet files are bytes. Bad arrays and undecodable data raise ValueError
// with the library's one-line message.

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <cmath>
#include <cstring>
#include <optional>
#include <string>
#include <vector>

#include "lex3d/lex3d.hpp"

namespace py = pybind11;

namespace {

std::string shape_of(const py::array& a) {
  std::string s = "(";
  for (py::ssize_t d = 0; d < a.ndim(); ++d) s += (d ? ", " : "") + std::to_string(a.shape(d));
  return s + (a.ndim() == 1 ? ",)" : ")");
}

std::string dtype_of(const py::array& a) { return py::str(a.dtype()).cast<std::string>(); }

/// float32 or float64 (either byte order).
bool is_float(const py::array& a) {
  return a.dtype().kind() == 'f' && (a.dtype().itemsize() == 4 || a.dtype().itemsize() == 8);
}

template <typename T>
void copy_points(const py::array& a, lex3d::Cloud& cloud, const std::string& what) {
  const auto v = py::array_t<T, py::array::forcecast>(a).template unchecked<2>();
  const auto n = static_cast<std::size_t>(v.shape(0));
  cloud.points.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    const auto k = static_cast<py::ssize_t>(i);
    const T x = v(k, 0), y = v(k, 1), z = v(k, 2);
    if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z))
      throw py::value_error(what + ": row " + std::to_string(i) + " is not finite (" + std::to_string(x) + ", " +
                            std::to_string(y) + ", " + std::to_string(z) + ")");
    cloud.points[i] = Eigen::Vector3f(static_cast<float>(x), static_cast<float>(y), static_cast<float>(z));
  }
}

/// An (N, 3) float array (and optional (N,) intensity) as a Cloud; ValueError naming
/// what is wrong otherwise.
lex3d::Cloud to_cloud(const py::handle& points_obj, const py::object& intensity_obj, const std::string& what) {
  if (!py::isinstance<py::array>(points_obj))
    throw py::value_error(what + " must be a numpy array of shape (N, 3), got " +
                          py::str(py::type::of(points_obj)).cast<std::string>());
  const auto points = py::reinterpret_borrow<py::array>(points_obj);
  if (points.ndim() != 2 || points.shape(1) != 3)
    throw py::value_error(what + " must have shape (N, 3), got " + shape_of(points));
  if (!is_float(points))
    throw py::value_error(what + " must be float32 or float64, got " + dtype_of(points));
  lex3d::Cloud cloud;
  if (points.dtype().itemsize() == 4) copy_points<float>(points, cloud, what);
  else copy_points<double>(points, cloud, what);
  if (!intensity_obj.is_none()) {
    const std::string iwhat = what == "points" ? "intensity" : what + " intensity";
    if (!py::isinstance<py::array>(intensity_obj))
      throw py::value_error(iwhat + " must be a numpy array of shape (N,)");
    const auto in = py::reinterpret_borrow<py::array>(intensity_obj);
    if (in.ndim() != 1 || static_cast<std::size_t>(in.shape(0)) != cloud.size())
      throw py::value_error(iwhat + " must have shape (" + std::to_string(cloud.size()) + ",), got " + shape_of(in));
    if (!is_float(in)) throw py::value_error(iwhat + " must be float32 or float64, got " + dtype_of(in));
    const auto v = py::array_t<float, py::array::forcecast>(in).unchecked<1>();
    cloud.intensity.resize(cloud.size());
    for (std::size_t i = 0; i < cloud.size(); ++i) {
      const float x = v(static_cast<py::ssize_t>(i));
      if (!std::isfinite(x)) throw py::value_error(iwhat + ": value " + std::to_string(i) + " is not finite");
      cloud.intensity[i] = x;
    }
  }
  return cloud;
}

std::vector<std::uint8_t> to_vector(const py::bytes& b) {
  const std::string_view s = b;  // pybind11 >= 2.6
  return {s.begin(), s.end()};
}

py::bytes to_bytes(const std::vector<std::uint8_t>& v) {
  return {reinterpret_cast<const char*>(v.data()), v.size()};
}

/// A non-ok Status as a Python exception: ValueError for bad data and wrong arguments,
/// OSError for I/O.
[[noreturn]] void raise(const lex3d::Status& st) {
  if (st.code() == lex3d::ErrorCode::kIoError) throw std::runtime_error(st.to_string());
  throw py::value_error(st.to_string());
}

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
  throw py::value_error("layer_coding must be 'auto', 'spherical', 'voxel' or 'laser', got '" + s + "'");
}

py::bytes compress(const py::object& points, const py::object& intensity, std::optional<double> max_error,
                   std::optional<double> target_bpp, const std::optional<std::string>& words,
                   const std::string& coding, bool keep_all_points, const std::optional<py::bytes>& alphabet,
                   double word_radius, int iterations, std::uint64_t seed, int threads) {
  const lex3d::Cloud cloud = to_cloud(points, intensity, "points");
  lex3d::CompressOptions o;
  o.max_error = max_error;
  o.target_bpp = target_bpp.value_or(0.0);
  if (target_bpp && *target_bpp <= 0.0) throw py::value_error("target_bpp must be positive, got " + std::to_string(*target_bpp));
  o.words = words_mode(words);
  o.layer_coding = layer_coding(coding);
  o.keep_all_points = keep_all_points;
  if (alphabet) o.alphabet = to_vector(*alphabet);
  o.model.word_radius = word_radius;
  o.max_iterations = iterations;
  o.seed = seed;
  o.threads = threads;
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
    if (PyErr_WarnEx(PyExc_UserWarning, (a + " is not kept in this model file (attributes need a residual layer: "
                                         "give max_error or target_bpp): " + std::to_string(c.input_points) +
                                         " values dropped").c_str(), 1) != 0)
      throw py::error_already_set();
  return to_bytes(c.bytes);
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
  py::array_t<float> out({static_cast<py::ssize_t>(cloud.size()), py::ssize_t{3}});
  auto w = out.mutable_unchecked<2>();
  for (std::size_t i = 0; i < cloud.size(); ++i)
    for (py::ssize_t k = 0; k < 3; ++k) w(static_cast<py::ssize_t>(i), k) = cloud.points[i][k];
  if (!attributes) return std::move(out);
  // The per-point fields the file keeps (formats/model.md §2.10), by name.
  const auto n = static_cast<py::ssize_t>(cloud.size());
  py::dict fields;
  if (cloud.has_intensity()) fields["intensity"] = py::array_t<float>(n, cloud.intensity.data());
  if (cloud.has_rings()) fields["ring"] = py::array_t<std::uint16_t>(n, cloud.ring.data());
  if (cloud.has_time()) fields["time"] = py::array_t<double>(n, cloud.time.data());
  if (cloud.has_rgb()) {
    py::array_t<std::uint8_t> rgb({n, py::ssize_t{3}});
    auto c = rgb.mutable_unchecked<2>();
    for (py::ssize_t i = 0; i < n; ++i)
      for (py::ssize_t k = 0; k < 3; ++k) c(i, k) = cloud.rgb[static_cast<std::size_t>(i)][static_cast<std::size_t>(k)];
    fields["rgb"] = rgb;
  }
  return py::make_tuple(out, fields);
}

py::bytes learn_alphabet(const py::list& clouds, double word_radius, int iterations, int patience,
                         std::uint64_t seed, bool prune, int threads) {
  std::vector<lex3d::Cloud> scans;
  for (std::size_t i = 0; i < clouds.size(); ++i)
    scans.push_back(to_cloud(clouds[i], py::none(), "clouds[" + std::to_string(i) + "]"));
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

PYBIND11_MODULE(lex3d, m) {
  m.doc() =
      "lex3d: compress lidar scans with a learned alphabet of local 3D structures and a bounded-error "
      "residual layer.\n\n"
      "    data = lex3d.compress(points, max_error=0.014)   # points: (N, 3) float32/float64, metres\n"
      "    back = lex3d.decompress(data)                    # (M, 3) float32\n\n"
      "The bytes are those `lex3d compress` writes for the same settings (formats/model.md).";
  m.attr("__version__") = LEX3D_VERSION_STRING;
  m.def("compress", &compress, py::arg("points"), py::arg("intensity") = py::none(), py::kw_only(),
        py::arg("max_error") = py::none(), py::arg("target_bpp") = py::none(), py::arg("words") = py::none(),
        py::arg("layer_coding") = "auto", py::arg("keep_all_points") = false, py::arg("alphabet") = py::none(),
        py::arg("word_radius") = 0.0, py::arg("iterations") = lex3d::LearnParams{}.max_iterations,
        py::arg("seed") = lex3d::LearnParams{}.seed, py::arg("threads") = 2,
        R"(Compresses one scan into a model file (bytes), as `lex3d compress` does.

points: (N, 3) float32 or float64 array, metres, sensor frame; every value finite.
intensity: optional (N,) float array; model files do not store it (a UserWarning says so).
max_error: residual-layer bound in metres, [1e-4, 10]: every point has a decoded point within it
    and vice versa. None: words only (an alphabet is learned on the scan), unless target_bpp.
target_bpp: bits per point the file should fit; the smallest bound that fits is taken.
words: None (off with a residual layer, on without), 'on', 'off' or 'auto' (the smaller file).
layer_coding: 'auto', 'spherical', 'voxel' or 'laser'.
keep_all_points: give every input point its own decoded point.
alphabet: an alphabet file (bytes, from learn_alphabet) to reuse; the model then references it.
word_radius: metres, 0 derives it from the scan. iterations, seed: the learner's.
threads: worker threads, [1, 64]; the bytes do not depend on it.
Raises ValueError for a bad array or option, or an alphabet that does not decode.)");
  m.def("decompress", &decompress, py::arg("data"), py::arg("alphabet") = py::none(), py::kw_only(),
        py::arg("attributes") = false,
        R"(Decodes a model file (bytes) into an (M, 3) float32 array of points (metres).

alphabet: the alphabet file (bytes) the model references, if it references one.
attributes: also return the per-point fields the file keeps, as (points, fields) with fields a
dict of (M,) arrays by name: "intensity" (float32), "ring" (uint16), "time" (float64, seconds)
and "rgb" ((M, 3) uint8).
Raises ValueError for a malformed, truncated or corrupt file (the message names the byte offset)
or a missing or mismatched alphabet.)");
  m.def("learn_alphabet", &learn_alphabet, py::arg("clouds"), py::kw_only(), py::arg("word_radius") = 0.0,
        py::arg("iterations") = lex3d::LearnParams{}.max_iterations,
        py::arg("patience") = lex3d::LearnParams{}.patience, py::arg("seed") = lex3d::LearnParams{}.seed,
        py::arg("prune") = true, py::arg("threads") = 2,
        R"(Learns one alphabet for a list of (N, 3) float arrays and returns its file (bytes), as
`lex3d learn` does; pass it to compress(..., alphabet=...) and decompress(..., alphabet=...).)");
}
