// Conversions shared by the Python module's files (common.hpp).

#include "common.hpp"

#include <cmath>
#include <string_view>

#include "lex3d/codec/codec.hpp"
#include "lex3d/io/io.hpp"
#include "lex3d/residual/residual.hpp"

namespace lex3d::python {

std::string dtype_of(const py::array& a) { return py::str(a.dtype()).cast<std::string>(); }

py::array per_point_array(const py::handle& obj, std::size_t n, const std::string& what) {
  if (!py::isinstance<py::array>(obj)) throw py::value_error(what + " must be a numpy array of shape (N,)");
  auto a = py::reinterpret_borrow<py::array>(obj);
  if (a.ndim() != 1 || static_cast<std::size_t>(a.shape(0)) != n)
    throw py::value_error(what + " must have shape (" + std::to_string(n) + ",), got " + shape_of(a));
  return a;
}

std::string shape_of(const py::array& a) {
  std::string s = "(";
  for (py::ssize_t d = 0; d < a.ndim(); ++d) s += (d ? ", " : "") + std::to_string(a.shape(d));
  return s + (a.ndim() == 1 ? ",)" : ")");
}

namespace {


/// float32 or float64 (either byte order).
bool is_float(const py::array& a) {
  return a.dtype().kind() == 'f' && (a.dtype().itemsize() == 4 || a.dtype().itemsize() == 8);
}

/// The rows of an (N, 3) array as T, each finite (else ValueError naming the row).
template <typename T>
std::vector<Eigen::Matrix<T, 3, 1>> finite_rows(const py::array& a, const std::string& what) {
  const py::array_t<T, py::array::forcecast> values(a);  // (a converted copy kept alive while read)
  const auto v = values.template unchecked<2>();
  std::vector<Eigen::Matrix<T, 3, 1>> rows(static_cast<std::size_t>(v.shape(0)));
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const auto k = static_cast<py::ssize_t>(i);
    const T x = v(k, 0), y = v(k, 1), z = v(k, 2);
    if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z))
      throw py::value_error(what + ": row " + std::to_string(i) + " is not finite (" + std::to_string(x) + ", " +
                            std::to_string(y) + ", " + std::to_string(z) + ")");
    rows[i] = {x, y, z};
  }
  return rows;
}

Cloud decode_model_file(const std::vector<std::uint8_t>& bytes, const std::vector<std::uint8_t>* alphabet,
                        const std::string& what) {
  StatusOr<Cloud> cloud = Status(ErrorCode::kBadData, "");
  {
    py::gil_scoped_release unlocked;
    auto d = codec::decode_model(bytes, alphabet);
    if (!d.ok()) {
      cloud = d.status();
    } else {
      cloud = residual::decode_cloud(d.value());
      if (cloud.ok()) cloud.value().T_cloud_sensor = d.value().T_cloud_sensor;  // the range image's viewpoint
    }
  }
  if (!cloud.ok()) {
    const Status& st = cloud.status();
    raise(Status(st.code(), what + ": " + st.message() +
                                (st.code() == ErrorCode::kInvalidArgument ? " (give its alphabet)" : ""),
                 st.offset()));
  }
  return std::move(cloud).value();
}

}  // namespace

Cloud to_cloud(const py::handle& points_obj, const py::object& intensity_obj, const std::string& what) {
  if (!py::isinstance<py::array>(points_obj))
    throw py::value_error(what + " must be a numpy array of shape (N, 3), got " +
                          py::str(py::type::of(points_obj)).cast<std::string>());
  const auto points = py::reinterpret_borrow<py::array>(points_obj);
  if (points.ndim() != 2 || points.shape(1) != 3)
    throw py::value_error(what + " must have shape (N, 3), got " + shape_of(points));
  if (!is_float(points)) throw py::value_error(what + " must be float32 or float64, got " + dtype_of(points));
  Cloud cloud;
  if (points.dtype().itemsize() == 4) {
    cloud.points = finite_rows<float>(points, what);
  } else {
    // float64: kept to its precision where float32 would round it (coordinates far from the
    // frame's origin, a UTM cloud): relative to an origin the model keeps (Cloud::georef)
    const Status st = io::set_double_points(cloud, finite_rows<double>(points, what), what, "metre (the array's unit)");
    if (!st.ok()) throw py::value_error(st.message());
  }
  if (!intensity_obj.is_none()) {
    const std::string iwhat = what == "points" ? "intensity" : what + " intensity";
    const py::array in = per_point_array(intensity_obj, cloud.size(), iwhat);
    // (an 8- or 16-bit integer intensity is kept as its values and comes back in its dtype)
    const char kind = in.dtype().kind();
    const auto size = in.dtype().itemsize();
    const bool small_int = (kind == 'i' || kind == 'u') && (size == 1 || size == 2);
    if (!is_float(in) && !small_int)
      throw py::value_error(iwhat + " must be float32, float64 or an 8- or 16-bit integer, got " + dtype_of(in));
    if (small_int)
      cloud.intensity_source = {"intensity", kind == 'i' ? (size == 1 ? FieldType::kInt8 : FieldType::kInt16)
                                                         : (size == 1 ? FieldType::kUint8 : FieldType::kUint16)};
    // (the converted array kept alive while it is read: a float64 intensity is a copy)
    const py::array_t<float, py::array::forcecast> values(in);
    const auto v = values.unchecked<1>();
    cloud.intensity.resize(cloud.size());
    for (std::size_t i = 0; i < cloud.size(); ++i) {
      const float x = v(static_cast<py::ssize_t>(i));
      if (!std::isfinite(x)) throw py::value_error(iwhat + ": value " + std::to_string(i) + " is not finite");
      cloud.intensity[i] = x;
    }
  }
  return cloud;
}

bool is_path(const py::handle& obj) {
  if (py::isinstance<py::str>(obj)) return true;
  return py::hasattr(obj, "__fspath__");
}

std::string path_of(const py::handle& obj) {
  const py::object p = py::module_::import("os").attr("fspath")(obj);
  if (!py::isinstance<py::str>(p)) throw py::value_error("a path must be a str, got bytes");
  return p.cast<std::string>();
}

Cloud scan_from(const py::handle& scan, const std::vector<std::uint8_t>* alphabet, const std::string& what,
                const io::ReadOptions& options) {
  if (py::isinstance<PyScan>(scan)) return scan.cast<const PyScan&>().cloud;
  if (py::isinstance<py::bytes>(scan)) return decode_model_file(to_vector(py::reinterpret_borrow<py::bytes>(scan)), alphabet, what);
  if (!is_path(scan)) return to_cloud(scan, py::none(), what);
  const std::string path = path_of(scan);
  std::string ext = path.size() >= 7 ? path.substr(path.size() - 7) : "";
  for (auto& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (ext == ".lex3dm") {
    auto bytes = io::read_file(path);
    if (!bytes.ok()) raise(bytes.status());
    return decode_model_file(bytes.value(), alphabet, path);
  }
  StatusOr<io::ReadResult> r = Status(ErrorCode::kBadData, "");
  {
    py::gil_scoped_release unlocked;
    r = io::read_cloud(path, options);
  }
  if (!r.ok()) raise(r.status());
  // never drop silently: what the file holds that lex3d does not keep, and what the reader noticed
  if (!r.value().dropped_fields.empty()) {
    std::string list;
    for (const auto& f : r.value().dropped_fields) list += (list.empty() ? "" : ", ") + f;
    warn(path + ": fields not kept (lex3d keeps x y z, intensity, ring, time, colour and single integer and float fields): " + list);
  }
  for (const auto& n : r.value().notes) warn(path + ": " + n);
  return std::move(r.value().cloud);
}

std::vector<std::uint8_t> to_vector(const py::bytes& b) {
  const std::string_view s = b;  // pybind11 >= 2.6
  return {s.begin(), s.end()};
}

py::bytes to_bytes(const std::vector<std::uint8_t>& v) { return {reinterpret_cast<const char*>(v.data()), v.size()}; }

void raise(const Status& st) {
  if (st.code() == ErrorCode::kIoError) {
    PyErr_SetString(PyExc_OSError, st.to_string().c_str());
    throw py::error_already_set();
  }
  throw py::value_error(st.to_string());
}

Pose to_pose(const py::handle& obj, const std::string& what) {
  if (!py::isinstance<py::array>(obj)) throw py::value_error(what + " must be a 4x4 numpy array");
  const auto a = py::reinterpret_borrow<py::array>(obj);
  if (a.ndim() != 2 || a.shape(0) != 4 || a.shape(1) != 4 || !is_float(a))
    throw py::value_error(what + " must be a 4x4 float array, got " + shape_of(a) + " " + dtype_of(a));
  const py::array_t<double, py::array::forcecast> values(a);  // (kept alive while read)
  const auto v = values.unchecked<2>();
  Eigen::Matrix4d m;
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) {
      m(r, c) = v(r, c);
      if (!std::isfinite(m(r, c))) throw py::value_error(what + " is not finite");
    }
  const Eigen::Matrix3d R = m.topLeftCorner<3, 3>();
  if ((R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() > 1e-3 || R.determinant() < 0.0 ||
      (m.row(3) - Eigen::RowVector4d(0, 0, 0, 1)).cwiseAbs().maxCoeff() > 1e-9)
    throw py::value_error(what + " is not a rigid transform (rotation orthonormal within 1e-3, last row 0 0 0 1)");
  Pose T = Pose::Identity();
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(R, Eigen::ComputeFullU | Eigen::ComputeFullV);
  T.linear() = svd.matrixU() * svd.matrixV().transpose();  // re-orthonormalised
  T.translation() = m.topRightCorner<3, 1>();
  return T;
}

py::array_t<double> from_pose(const Pose& T) {
  py::array_t<double> out({py::ssize_t{4}, py::ssize_t{4}});
  auto w = out.mutable_unchecked<2>();
  const Eigen::Matrix4d m = T.matrix();
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) w(r, c) = m(r, c);
  return out;
}

void warn(const std::string& message) {
  if (PyErr_WarnEx(PyExc_UserWarning, message.c_str(), 1) != 0) throw py::error_already_set();
}

}  // namespace lex3d::python
