// lex3d.scans and lex3d.Scan: the scans of a file one at a time (a raw capture's turns, a
// bag topic's scans, a sequence file's models; any other file's one scan), as the library's
// readers give them, without holding the file; and the conversions of a cloud to numpy that
// decompress shares.

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <cctype>
#include <memory>
#include <string>
#include <string_view>

#include "common.hpp"
#include "lex3d/codec/cloud_bytes.hpp"
#include "lex3d/codec/codec.hpp"
#include "lex3d/io/rosbag.hpp"
#include "lex3d/io/sensor_log.hpp"
#include "lex3d/lex3d.hpp"

namespace lex3d::python {

namespace {

/// A named field's values as a numpy array of T, its source type (float fields from their keys).
template <typename T>
py::array_t<T> typed_field(const IntegerField& x) {
  py::array_t<T> a(static_cast<py::ssize_t>(x.values.size()));
  auto w = a.template mutable_unchecked<1>();
  for (std::size_t i = 0; i < x.values.size(); ++i) w(static_cast<py::ssize_t>(i)) = static_cast<T>(x.value(i));
  return a;
}

}  // namespace

py::array points_array(const Cloud& cloud) {
  py::array out;
  if (cloud.georef) {
    // true coordinates, in the CRS's units (as the command's writers give them)
    py::array_t<double> a({static_cast<py::ssize_t>(cloud.size()), py::ssize_t{3}});
    auto w = a.mutable_unchecked<2>();
    for (std::size_t i = 0; i < cloud.size(); ++i) {
      const Eigen::Vector3d t = cloud.georef->to_crs(cloud.points[i]);
      for (py::ssize_t k = 0; k < 3; ++k) w(static_cast<py::ssize_t>(i), k) = t[k];
    }
    out = std::move(a);
  } else {
    py::array_t<float> a({static_cast<py::ssize_t>(cloud.size()), py::ssize_t{3}});
    auto w = a.mutable_unchecked<2>();
    for (std::size_t i = 0; i < cloud.size(); ++i)
      for (py::ssize_t k = 0; k < 3; ++k) w(static_cast<py::ssize_t>(i), k) = cloud.points[i][k];
    out = std::move(a);
  }
  return out;
}

py::dict fields_dict(const Cloud& cloud) {
  const auto n = static_cast<py::ssize_t>(cloud.size());
  py::dict fields;
  // (intensity and ring in the integer type their source gave them, where the file records one)
  const auto as_source = [n](const SourceField& src, auto&& value) -> py::object {
    IntegerField x{src.name, std::vector<std::int32_t>(static_cast<std::size_t>(n)), src.type};
    for (py::ssize_t i = 0; i < n; ++i) x.values[static_cast<std::size_t>(i)] = static_cast<std::int32_t>(value(i));
    switch (src.type) {
      case FieldType::kInt8: return typed_field<std::int8_t>(x);
      case FieldType::kUint8: return typed_field<std::uint8_t>(x);
      case FieldType::kInt16: return typed_field<std::int16_t>(x);
      case FieldType::kUint16: return typed_field<std::uint16_t>(x);
      case FieldType::kInt32: return typed_field<std::int32_t>(x);
      case FieldType::kUint32: return typed_field<std::uint32_t>(x);
      default: return py::none();
    }
  };
  const auto integral = [](const SourceField& s) { return s.given() && !is_float_type(s.type); };
  if (cloud.has_intensity()) {
    py::object typed = integral(cloud.intensity_source)
                           ? as_source(cloud.intensity_source, [&](py::ssize_t i) { return cloud.intensity[static_cast<std::size_t>(i)]; })
                           : py::none();
    fields["intensity"] = typed.is_none() ? py::object(py::array_t<float>(n, cloud.intensity.data())) : typed;
  }
  if (cloud.has_rings()) {
    py::object typed = integral(cloud.ring_source)
                           ? as_source(cloud.ring_source, [&](py::ssize_t i) { return cloud.ring[static_cast<std::size_t>(i)]; })
                           : py::none();
    fields["ring"] = typed.is_none() ? py::object(py::array_t<std::uint16_t>(n, cloud.ring.data())) : typed;
  }
  if (cloud.has_time()) {
    // (in the type its source gave it: float32 seconds, integer nanoseconds; else float64 seconds)
    const FieldType t = cloud.time_source.given() ? cloud.time_source.type : FieldType::kFloat64;
    const auto ns = [&](py::ssize_t i) { return std::llround(cloud.time[static_cast<std::size_t>(i)] * 1e9); };
    py::object typed = t == FieldType::kFloat32  ? py::object(py::array_t<float>(py::array_t<double>(n, cloud.time.data())))
                       : is_float_type(t)           ? py::none()
                                                    : as_source(cloud.time_source, ns);
    fields["time"] = typed.is_none() ? py::object(py::array_t<double>(n, cloud.time.data())) : typed;
  }
  if (cloud.has_rgb()) {
    py::array_t<std::uint8_t> rgb({n, py::ssize_t{3}});
    auto c = rgb.mutable_unchecked<2>();
    for (py::ssize_t i = 0; i < n; ++i)
      for (py::ssize_t k = 0; k < 3; ++k) c(i, k) = cloud.rgb[static_cast<std::size_t>(i)][static_cast<std::size_t>(k)];
    fields["rgb"] = rgb;
  }
  // (each in its source type: uint16 as numpy.uint16, float32 as numpy.float32...)
  for (const IntegerField& x : cloud.fields) {
    if (x.values.size() != cloud.size()) continue;
    switch (x.type) {
      case FieldType::kInt8: fields[py::str(x.name)] = typed_field<std::int8_t>(x); break;
      case FieldType::kUint8: fields[py::str(x.name)] = typed_field<std::uint8_t>(x); break;
      case FieldType::kInt16: fields[py::str(x.name)] = typed_field<std::int16_t>(x); break;
      case FieldType::kUint16: fields[py::str(x.name)] = typed_field<std::uint16_t>(x); break;
      case FieldType::kUint32: fields[py::str(x.name)] = typed_field<std::uint32_t>(x); break;
      case FieldType::kFloat32: fields[py::str(x.name)] = typed_field<float>(x); break;
      case FieldType::kFloat64: fields[py::str(x.name)] = typed_field<double>(x); break;
      default: fields[py::str(x.name)] = py::array_t<std::int32_t>(n, x.values.data()); break;
    }
  }
  return fields;
}

py::object stamp_dict(const std::optional<ScanStamp>& s) {
  if (!s) return py::none();
  py::dict d;
  d["sec"] = s->sec;
  d["nsec"] = s->nsec;
  d["frame_id"] = s->frame_id;
  d["source"] = s->source == ScanStamp::Source::kCapture ? "capture" : "message";
  return std::move(d);
}

namespace {

/// What holds a file's scans: a raw capture (its turns), a ROS bag (a topic's scans), a
/// sequence file (its models), or one point cloud.
enum class Holder { kCapture, kBag, kSequence, kCloud };

Holder holder_of(const std::string& path, io::Format format) {
  if (format == io::Format::kPcap || (format == io::Format::kAuto && io::is_sensor_log(path))) return Holder::kCapture;
  if (format == io::Format::kAuto && io::is_rosbag(path)) return Holder::kBag;
  std::string ext = path.size() >= 7 ? path.substr(path.size() - 7) : "";
  for (auto& ch : ext) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
  return ext == ".lex3dq" ? Holder::kSequence : Holder::kCloud;
}

/// The scans of one file, read one at a time (the GIL released while reading).
class PyScans {
 public:
  PyScans(std::string path, io::ReadOptions options) : path_(std::move(path)), options_(std::move(options)) {
    const Holder h = holder_of(path_, options_.format);
    Status opened;
    {
      py::gil_scoped_release unlocked;
      opened = open(h == Holder::kCapture, h == Holder::kBag, h == Holder::kSequence);
    }
    if (!opened.ok()) raise(opened);
  }

  /// The names next() gives, where the file lists its scans up front (a sequence file); None
  /// for a capture, a bag or a one-cloud file, whose scans are known only by reading them.
  py::object names() const {
    if (!sequence_) return py::none();
    py::list out;
    for (std::size_t k = 0; k < sequence_->model_files.size(); ++k) out.append(scan_name(k));
    return std::move(out);
  }

  PyScan next() {
    PyScan s;
    if (log_) {
      StatusOr<std::optional<io::SensorTurn>> t = Status(ErrorCode::kBadData, "");
      {
        py::gil_scoped_release unlocked;
        t = log_->next();
      }
      if (!t.ok()) raise(t.status());
      if (!t.value()) throw py::stop_iteration();
      s.name = path_ + " turn " + std::to_string(k_) + " (frame " + std::to_string(t.value()->frame_id) + ")";
      s.cloud = std::move(t.value()->cloud);
    } else if (bag_) {
      StatusOr<std::optional<io::BagScan>> b = Status(ErrorCode::kBadData, "");
      {
        py::gil_scoped_release unlocked;
        b = bag_->next();
      }
      if (!b.ok()) raise(b.status());
      if (!b.value()) {
        // never drop silently: what the topic's messages held that lex3d does not keep
        const io::BagScans& sum = bag_->summary();
        if (!sum.dropped_fields.empty()) {
          std::string list;
          for (const auto& f : sum.dropped_fields) list += (list.empty() ? "" : ", ") + f;
          warn(path_ + ": fields not kept (lex3d keeps x y z, intensity, ring, time, colour and single integer and float fields): " + list);
        }
        for (const auto& n : sum.notes) warn(path_ + ": " + n);
        throw py::stop_iteration();
      }
      s.name = path_ + " " + bag_->summary().topic + " scan " + std::to_string(k_);
      s.cloud = std::move(b.value()->cloud);
    } else if (sequence_) {
      if (k_ >= sequence_->model_files.size()) throw py::stop_iteration();
      StatusOr<DecompressResult> d = Status(ErrorCode::kBadData, "");
      {
        py::gil_scoped_release unlocked;
        d = decompress(sequence_->model_files[k_], &sequence_->alphabet_file);
      }
      if (!d.ok()) raise(Status(d.status().code(), path_ + ": scan " + std::to_string(k_) + ": " + d.status().message()));
      s.name = scan_name(k_);
      s.cloud = std::move(d.value().cloud);
    } else {
      if (k_ > 0) throw py::stop_iteration();
      s.cloud = scan_from(py::str(path_), nullptr, path_, options_);
      s.name = path_;
    }
    ++k_;
    return s;
  }

 private:
  /// The reader of a capture, a bag or a sequence file (none for any other file).
  Status open(bool log, bool bag, bool sequence) {
    if (log) {
      auto r = io::SensorLogReader::open(path_, options_);
      if (!r.ok()) return r.status();
      log_ = std::move(r).value();
    } else if (bag) {
      auto r = io::BagReader::open(path_, options_.bag_topic, options_);
      if (!r.ok()) return r.status();
      bag_ = std::move(r).value();
    } else if (sequence) {
      auto bytes = io::read_file(path_);
      if (!bytes.ok()) return bytes.status();
      auto seq = codec::decode_sequence(bytes.value());
      if (!seq.ok()) return Status(seq.status().code(), path_ + ": " + seq.status().message());
      sequence_ = std::make_unique<codec::SequenceData>(std::move(seq).value());
    }
    return {};
  }

  std::string scan_name(std::size_t k) const {
    return path_ + " " + (k < sequence_->names.size() ? sequence_->names[k] : "scan " + std::to_string(k));
  }

  std::string path_;
  io::ReadOptions options_;
  std::unique_ptr<io::SensorLogReader> log_;
  std::unique_ptr<io::BagReader> bag_;
  std::unique_ptr<codec::SequenceData> sequence_;
  std::size_t k_ = 0;
};

}  // namespace

void bind_scans(py::module_& m) {
  py::class_<PyScan>(m, "Scan", R"(One scan of a file, as lex3d.scans gives it. lex3d.compress, learn_alphabet and
PlaceDatabase take it as they take an array or a path, with everything its file gave (intensity,
ring, time, named fields, the stamp).)")
      .def_property_readonly("name", [](const PyScan& s) { return s.name; }, "The file and where in it.")
      .def_property_readonly("points", [](const PyScan& s) { return points_array(s.cloud); },
                             "(N, 3) float32 metres, or float64 true coordinates of a georeferenced scan (LAS).")
      .def_property_readonly("fields", [](const PyScan& s) { return fields_dict(s.cloud); },
                             "Its per-point fields by name, as decompress(attributes=True) gives them.")
      .def_property_readonly("stamp", [](const PyScan& s) { return stamp_dict(s.cloud.stamp); },
                             "When and in which frame it was taken ({sec, nsec, frame_id, source}), or None.")
      .def("__len__", [](const PyScan& s) { return s.cloud.size(); })
      // (pickled whole, so that a scan read in one process is coded in another: a Dask task)
      .def(py::pickle(
          [](const PyScan& s) {
            std::vector<std::uint8_t> b;
            {
              py::gil_scoped_release unlocked;
              b = codec::cloud_to_bytes(s.cloud);
            }
            return py::make_tuple(s.name, py::bytes(reinterpret_cast<const char*>(b.data()), b.size()));
          },
          [](const py::tuple& t) {
            if (t.size() != 2) throw py::value_error("lex3d.Scan: not a pickled scan");
            PyScan s;
            s.name = t[0].cast<std::string>();
            const std::string_view b = t[1].cast<py::bytes>();
            auto cloud = codec::cloud_from_bytes(reinterpret_cast<const std::uint8_t*>(b.data()), b.size());
            if (!cloud.ok()) raise(Status(cloud.status().code(), "lex3d.Scan " + s.name + ": " + cloud.status().message()));
            s.cloud = std::move(cloud).value();
            return s;
          }))
      .def("__repr__", [](const PyScan& s) { return "<lex3d.Scan " + s.name + ": " + std::to_string(s.cloud.size()) + " points>"; });
  py::class_<PyScans>(m, "Scans", "An iterator over the scans of a file (lex3d.scans).")
      .def("__iter__", [](PyScans& s) -> PyScans& { return s; })
      .def("__next__", &PyScans::next)
      .def_property_readonly("names", &PyScans::names,
                             "The scans' names, where the file lists them up front (a sequence file); else None.");
  m.def(
      "holds_scans",
      [](const py::object& path) {
        if (!is_path(path)) throw py::value_error("holds_scans takes a path (str or os.PathLike)");
        const std::string p = path_of(path);
        switch (holder_of(p, io::Format::kAuto)) {
          case Holder::kCapture: return "capture";
          case Holder::kBag: return "bag";
          case Holder::kSequence: return "sequence";
          default: return "";
        }
      },
      py::arg("path"),
      R"(What holds several scans in `path`, as lex3d.scans reads it: "capture" (a raw Ouster or
Velodyne capture, one scan a turn), "bag" (a ROS bag, one a message), "sequence" (a .lex3dq file,
one a model), or "" for a file of one point cloud. Decided from the name and the first bytes.)");
  m.def(
      "scans",
      [](const py::object& path, const std::string& metadata, const std::string& topic, bool single_return,
         const std::string& sensor_model) {
        if (!is_path(path)) throw py::value_error("scans takes a path (str or os.PathLike)");
        io::ReadOptions o;
        o.metadata_path = metadata;
        o.bag_topic = topic;
        o.single_return = single_return;
        o.sensor_model = sensor_model;
        return PyScans(path_of(path), o);
      },
      py::arg("path"), py::kw_only(), py::arg("metadata") = "", py::arg("topic") = "", py::arg("single_return") = false,
      py::arg("sensor_model") = "",
      R"(The scans of a file, one at a time: a raw Ouster or Velodyne capture's turns, a ROS bag
topic's scans, a sequence file's (.lex3dq) decoded scans, any other point cloud file's one scan
(as `lex3d compress PATH` reads them). The file is never held whole: a capture or bag of any
length iterates in the memory of a few scans.

    for scan in lex3d.scans("drive.pcap"):
        data = lex3d.compress(scan, max_error=0.02)

metadata: an Ouster capture's metadata JSON or a Velodyne calibration (default: beside the
capture), or the JSON a bag's Ouster packets need. topic: a bag's topic (default: its only point
cloud topic). single_return: a dual-return capture's first returns only. sensor_model: a
Velodyne model to read the capture as ("vlp16", "puck-hires", "hdl32e", "vlp32c", "hdl64e").
Raises OSError for a file that cannot be read, ValueError for one lex3d cannot read (the error
of a damaged part comes from the iteration that reaches it, after the scans before it).)");
}

}  // namespace lex3d::python
