// Distributed alphabet learning from Python (lex3d._lex3d.learning): one scan's side of the
// learner (LearnScan) and the BIC loop's (LearnDecisions) of lex3d/model/learn.hpp, so that
// lex3d.dask can keep the scans on workers and take the decisions in the driver. A candidate
// word travels between processes as bytes (encode_word / decode_word below).

#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <cstring>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "common.hpp"
#include "lex3d/codec/codec.hpp"
#include "lex3d/lex3d.hpp"
#include "lex3d/model/learn.hpp"

namespace lex3d::python {

namespace {

// A word as bytes: u32 point count n, u32 descriptor length d, then 3n + d float32 values
// (the points' x y z, then the descriptor), all little-endian.
void put_u32(std::string& out, std::uint32_t v) {
  for (int k = 0; k < 4; ++k) out.push_back(static_cast<char>((v >> (8 * k)) & 0xFFU));
}
void put_f32(std::string& out, float f) {
  std::uint32_t v = 0;
  std::memcpy(&v, &f, 4);
  put_u32(out, v);
}
std::uint32_t get_u32(const unsigned char* p) {
  return static_cast<std::uint32_t>(p[0]) | static_cast<std::uint32_t>(p[1]) << 8 |
         static_cast<std::uint32_t>(p[2]) << 16 | static_cast<std::uint32_t>(p[3]) << 24;
}
float get_f32(const unsigned char* p) {
  const std::uint32_t v = get_u32(p);
  float f = 0.0F;
  std::memcpy(&f, &v, 4);
  return f;
}

py::bytes encode_word(const Word& w) {
  std::string out;
  out.reserve(8 + 4 * (3 * w.points.size() + w.descriptor.size()));
  put_u32(out, static_cast<std::uint32_t>(w.points.size()));
  put_u32(out, static_cast<std::uint32_t>(w.descriptor.size()));
  for (const auto& p : w.points)
    for (int k = 0; k < 3; ++k) put_f32(out, p[k]);
  for (const float d : w.descriptor) put_f32(out, d);
  return py::bytes(out);
}

Word decode_word(const py::bytes& b) {
  const std::string_view s = static_cast<std::string_view>(b);
  const auto* p = reinterpret_cast<const unsigned char*>(s.data());
  if (s.size() < 8) throw py::value_error("a learning word of " + std::to_string(s.size()) + " bytes (at least 8)");
  const std::uint64_t n = get_u32(p), d = get_u32(p + 4);
  if ((s.size() - 8) % 4 != 0 || (s.size() - 8) / 4 != 3 * n + d)
    throw py::value_error("a learning word of " + std::to_string(n) + " points and " + std::to_string(d) +
                          " descriptor values in " + std::to_string(s.size()) + " bytes");
  Word w;
  w.points.resize(n);
  w.descriptor.resize(d);
  p += 8;
  for (std::uint64_t i = 0; i < n; ++i, p += 12) w.points[i] = Eigen::Vector3f(get_f32(p), get_f32(p + 4), get_f32(p + 8));
  for (std::uint64_t i = 0; i < d; ++i, p += 4) w.descriptor[i] = get_f32(p);
  return w;
}

ModelParams model_params(double word_radius, int threads) {
  ModelParams m;
  m.word_radius = word_radius;
  m.threads = threads;
  m.validate();
  return m;
}

// One scan on a worker: the cloud until prepare(), then its LearnScan.
class PyLearnScan {
 public:
  PyLearnScan(const py::handle& scan, double word_radius, int threads, const std::string& what)
      : params_(model_params(word_radius, threads)) {
    cloud_ = scan_from(scan, nullptr, what);
    check_cloud(cloud_, what);
    points_ = cloud_.size();
  }
  [[nodiscard]] std::size_t points() const { return points_; }
  [[nodiscard]] double set_word_radius() const { return learn_word_radius(params_, &cloud_); }
  void prepare(double radius) {
    if (!(radius > 0.0)) throw py::value_error("prepare: the word radius must be positive");
    {
      py::gil_scoped_release unlocked;
      scan_.emplace(prepare_scan(cloud_, params_, radius), params_.threads);
    }
    cloud_ = Cloud{};  // the prepared scan holds its own copy
  }
  LearnScan& scan() {
    if (!scan_) throw py::value_error("the scan is not prepared yet");
    return *scan_;
  }
  ModelParams params_;
  Cloud cloud_;
  std::size_t points_ = 0;
  std::optional<LearnScan> scan_;
};

LearnParams learn_params(int iterations, int patience, std::uint64_t seed, double word_radius) {
  LearnParams p;
  p.model.word_radius = word_radius;
  p.max_iterations = iterations;
  p.patience = patience;
  p.seed = seed;
  p.validate();
  return p;
}

}  // namespace

void bind_learning(py::module_& m) {
  py::module_ l = m.def_submodule("learning", R"(The alphabet learner in two halves (lex3d/model/learn.hpp):
LearnScan, one scan's prepared state on whichever process holds it, and LearnDecisions, the
seeded candidate order and the BIC decisions. Summing LearnScan.evaluate over the scans in
scan order, from 0.0, gives the decisions, and so the alphabet, of lex3d.learn_alphabet.)");

  py::class_<PyLearnScan>(l, "LearnScan", "One scan's side of learning.")
      .def(py::init<const py::handle&, double, int, const std::string&>(), py::arg("scan"), py::kw_only(),
           py::arg("word_radius") = 0.0, py::arg("threads") = 1, py::arg("what") = "scan",
           "Reads the scan (an (N, 3) array or a path, as lex3d.learn_alphabet reads it).")
      .def_property_readonly("points", &PyLearnScan::points)
      .def("set_word_radius", &PyLearnScan::set_word_radius,
           "The word radius of a set whose first scan with points is this one (word_radius when given).")
      .def("prepare", &PyLearnScan::prepare, py::arg("word_radius"), "Features, σ and neighbourhoods with the set's radius.")
      .def_property_readonly("features", [](PyLearnScan& s) { return s.scan().feature_count(); })
      .def_property_readonly("descriptor_dim", [](PyLearnScan& s) { return s.scan().scan().features.descriptor_dim; })
      .def_property_readonly("log_likelihood", [](PyLearnScan& s) { return s.scan().log_likelihood(); })
      .def("cut_word", [](PyLearnScan& s, std::size_t f, double spacing) {
             return encode_word(s.scan().cut_word(f, spacing)); },
           py::arg("feature"), py::arg("point_spacing"), "The candidate word cut around a feature (bytes).")
      .def("evaluate", [](PyLearnScan& s, const py::bytes& word, std::int32_t id) {
             const Word w = decode_word(word);
             py::gil_scoped_release unlocked;
             return s.scan().evaluate(w, id); },
           py::arg("word"), py::arg("word_id"), "Δ ln L of the scan were the word added as word word_id.")
      .def("commit", [](PyLearnScan& s, bool accept) {
             py::gil_scoped_release unlocked;
             return s.scan().commit(accept); },
           py::arg("accept"), "Applies (or forgets) the last evaluated word; returns ln L.");

  py::class_<LearnDecisions>(l, "LearnDecisions", "The BIC loop's side of learning.")
      .def(py::init([](const std::vector<std::size_t>& features, const std::vector<std::size_t>& points,
                       const std::vector<double>& log_ls, int iterations, int patience, std::uint64_t seed) {
             return LearnDecisions(learn_params(iterations, patience, seed, 0.0), features, points, log_ls); }),
           py::arg("features"), py::arg("points"), py::arg("log_likelihoods"), py::kw_only(),
           py::arg("iterations") = LearnParams{}.max_iterations, py::arg("patience") = LearnParams{}.patience,
           py::arg("seed") = LearnParams{}.seed)
      .def("next", [](const LearnDecisions& d) -> py::object {
             const LearnCandidate* c = d.next();
             if (c == nullptr) return py::none();
             return py::make_tuple(c->scan, c->feature); },
           "The next candidate (scan, feature), or None when the loop is over.")
      .def("upcoming", [](const LearnDecisions& d, std::size_t count) {
             std::vector<std::pair<std::uint32_t, std::uint32_t>> out;
             const auto& c = d.candidates();
             for (std::size_t i = static_cast<std::size_t>(d.iteration()); i < c.size() && out.size() < count; ++i)
               out.emplace_back(c[i].scan, c[i].feature);
             return out; },
           py::arg("count"), "The next `count` candidates in order (the loop may stop before them).")
      .def_static("evaluates", [](const py::bytes& w) { return LearnDecisions::evaluates(decode_word(w)); })
      .def("accepts", [](const LearnDecisions& d, const py::bytes& w, double delta) { return d.accepts(decode_word(w), delta); },
           py::arg("word"), py::arg("delta_log_likelihood"))
      .def("accept", [](LearnDecisions& d, const py::bytes& w, double log_l) { d.accept(decode_word(w), log_l); },
           py::arg("word"), py::arg("log_likelihood"))
      .def("reject", &LearnDecisions::reject)
      .def_property_readonly("iteration", &LearnDecisions::iteration)
      .def_property_readonly("bic", &LearnDecisions::bic)
      .def_property_readonly("accepted", &LearnDecisions::accepted)
      .def_property_readonly("rejected", &LearnDecisions::rejected)
      .def_property_readonly("candidates", [](const LearnDecisions& d) { return d.candidates().size(); })
      .def_property_readonly("bic_history", &LearnDecisions::bic_history);

  l.def("word_radius_default", [] { return learn_word_radius(ModelParams{}, nullptr); },
        "The word radius of a set with no points.");
  l.def("alphabet_file", [](double word_radius, double point_spacing, int descriptor_dim, const std::vector<py::bytes>& words) {
          Alphabet a;
          a.word_radius = word_radius;
          a.point_spacing = point_spacing;
          a.descriptor_dim = descriptor_dim;
          for (const auto& w : words) a.words.push_back(decode_word(w));
          return to_bytes(codec::encode_alphabet(a)); },
        py::arg("word_radius"), py::arg("point_spacing"), py::arg("descriptor_dim"), py::arg("words"),
        "The alphabet file (bytes) of the accepted words, as lex3d.learn_alphabet writes it.");
  l.def("point_spacing", [](double word_radius) { return ModelParams{}.word_spacing_factor * word_radius; },
        py::arg("word_radius"), "Word points' spacing for a word radius (the learner's).");
}

}  // namespace lex3d::python
