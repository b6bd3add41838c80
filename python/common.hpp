#pragma once
// Conversions shared by the Python module's files: numpy arrays, bytes and paths to lex3d
// clouds, and library errors to Python exceptions with the library's one-line message.

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "lex3d/core/cloud.hpp"
#include "lex3d/core/status.hpp"
#include "lex3d/io/io.hpp"

namespace lex3d::python {

namespace py = pybind11;

std::string shape_of(const py::array& a);
/// An array's dtype as numpy names it ("float32").
std::string dtype_of(const py::array& a);
/// `obj` as an array of one value a point (shape (n,)); ValueError naming `what` otherwise.
py::array per_point_array(const py::handle& obj, std::size_t n, const std::string& what);

/// An (N, 3) float array (and optional (N,) intensity) as a Cloud; ValueError naming
/// `what` and what is wrong otherwise.
Cloud to_cloud(const py::handle& points, const py::object& intensity, const std::string& what);

/// A scan given as an (N, 3) float array, a path (str or os.PathLike: any point cloud
/// format lex3d reads, or a .lex3dm model file) or the bytes of a model file. `alphabet`:
/// the alphabet file a model references (may be null). A file's notes and the fields it
/// drops become UserWarnings naming the file. `options`: how a path is read (a capture's
/// metadata, a bag's topic, a dual-return capture's single_return).
Cloud scan_from(const py::handle& scan, const std::vector<std::uint8_t>* alphabet, const std::string& what,
                const io::ReadOptions& options = {});

/// One scan of a file, as lex3d.scans gives it (lex3d.Scan): everything the file's reader
/// gives, which lex3d.compress and the others take as they take an array or a path.
struct PyScan {
  Cloud cloud;
  std::string name;  ///< the file, and where in it ("PATH turn 3 (frame 1453)")
};

/// The points of `cloud` as Python sees them: (N, 3) float32 metres, or float64 true
/// coordinates for a georeferenced cloud (as decompress gives them).
py::array points_array(const Cloud& cloud);
/// Its per-point fields as decompress(attributes=True) gives them: a dict by name.
py::dict fields_dict(const Cloud& cloud);
/// Its stamp as a dict {"sec", "nsec", "frame_id", "source"}, or None.
py::object stamp_dict(const std::optional<ScanStamp>& s);

void bind_scans(py::module_& m);

/// True for str and os.PathLike objects.
bool is_path(const py::handle& obj);
std::string path_of(const py::handle& obj);

std::vector<std::uint8_t> to_vector(const py::bytes& b);
py::bytes to_bytes(const std::vector<std::uint8_t>& v);

/// A non-ok Status as a Python exception: OSError for I/O, ValueError otherwise.
[[noreturn]] void raise(const Status& st);
/// A 4x4 float array as a rigid transform (ValueError naming `what` when it is not one).
Pose to_pose(const py::handle& m, const std::string& what);
py::array_t<double> from_pose(const Pose& T);

/// A UserWarning; throws error_already_set when warnings are errors.
void warn(const std::string& message);

void bind_place(py::module_& m);
void bind_learning(py::module_& m);

}  // namespace lex3d::python
