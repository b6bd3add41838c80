// lex3d.PlaceDatabase: the place database (lex3d/place/place.hpp) from Python. Scans are
// given as (N, 3) arrays, paths of point cloud or model files, or model file bytes; a query
// returns the verified candidates, best first, each with the matched scan's name, its score
// and the 4x4 transform T_match_query as a numpy array. The long calls release the GIL.

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <algorithm>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "common.hpp"
#include "lex3d/codec/codec.hpp"
#include "lex3d/io/io.hpp"
#include "lex3d/io/mapped_file.hpp"
#include "lex3d/model/model.hpp"
#include "lex3d/place/gravity.hpp"
#include "lex3d/place/place.hpp"

namespace lex3d::python {

namespace {

/// Worker threads of a `threads=` argument: 0 is every core (as the command's --threads), else
/// [1, 64].
int worker_threads(int threads) {
  if (threads < 0 || threads > 64)
    throw py::value_error("threads must be 0 (every core) to 64, got " + std::to_string(threads));
  if (threads > 0) return threads;
  return static_cast<int>(std::clamp(std::thread::hardware_concurrency(), 1U, 64U));  // 0 where unknown
}

/// The settings `lex3d place` prepares scans with, on `threads` workers.
ModelParams place_model_params(int threads) {
  ModelParams mp;
  mp.threads = threads;
  return mp;
}

/// Where a scan stands in the world: a 4x4 pose (T_world_cloud), or only the direction of
/// gravity in the scan's frame (the up direction, for upright features; no position).
void set_frame(Cloud& cloud, const py::object& pose, const py::object& gravity) {
  if (!pose.is_none() && !gravity.is_none()) throw py::value_error("give pose or gravity, not both");
  if (!pose.is_none()) {
    cloud.T_world_cloud = to_pose(pose, "pose");
    cloud.has_world_pose = true;
  } else if (!gravity.is_none()) {
    const auto g = py::array_t<double, py::array::forcecast>(gravity);
    if (g.ndim() != 1 || g.shape(0) != 3) throw py::value_error("gravity must be a 3-vector, got " + shape_of(g));
    const Eigen::Vector3d down(g.at(0), g.at(1), g.at(2));
    if (!down.allFinite() || down.norm() < 1e-9) throw py::value_error("gravity must be a finite, non-zero 3-vector");
    cloud.T_world_cloud = Pose::Identity();
    cloud.T_world_cloud.linear() =
        Eigen::Quaterniond::FromTwoVectors(down.normalized(), -Eigen::Vector3d::UnitZ()).toRotationMatrix();
    cloud.has_world_pose = true;
  }
}

std::string default_name(const py::handle& scan, std::size_t index) {
  if (is_path(scan)) {
    std::string p = path_of(scan);
    const auto slash = p.find_last_of('/');
    if (slash != std::string::npos) p = p.substr(slash + 1);
    const auto dot = p.find_last_of('.');
    return dot == std::string::npos || dot == 0 ? p : p.substr(0, dot);
  }
  return "scan_" + std::to_string(index);
}

class PyPlaceDatabase {
 public:
  PyPlaceDatabase(PlaceDatabase db, std::string path, int threads)
      : db_(std::move(db)), path_(std::move(path)), threads_(threads) {}

  static PyPlaceDatabase open(const py::object& path_obj, int threads) {
    threads = worker_threads(threads);
    const std::string path = path_of(path_obj);
    StatusOr<PlaceDatabase> db = Status(ErrorCode::kBadData, "");
    {
      py::gil_scoped_release unlocked;
      auto file = io::MappedFile::open(path);
      if (!file.ok()) {
        db = file.status();
      } else {
        SharedBytes b;
        b.data = file.value()->data();
        b.size = file.value()->size();
        b.owner = file.value();
        db = PlaceDatabase::open(b);
      }
    }
    if (!db.ok()) {
      const Status& st = db.status();
      raise(st.code() == ErrorCode::kIoError ? st : Status(st.code(), path + ": " + st.message(), st.offset()));
    }
    if (!db.value().has_alphabet()) throw py::value_error(path + ": the database holds no alphabet");
    if (db.value().file_info().ignored_tail_bytes > 0)
      warn(path + ": " + std::to_string(db.value().file_info().ignored_tail_bytes) +
           " bytes after the committed database (an add that did not finish) are ignored");
    return {std::move(db).value(), path, threads};
  }

  /// A new database of `scans`, with `alphabet` (bytes) or one learned on `learn_scans`
  /// evenly spaced scans, as `lex3d place build`.
  static PyPlaceDatabase build(const py::list& scans, const std::optional<std::vector<std::string>>& names,
                               const py::object& poses, const std::optional<py::bytes>& alphabet_file,
                               const std::optional<py::bytes>& model_alphabet, int learn_scans, int iterations,
                               std::uint64_t seed, int threads) {
    threads = worker_threads(threads);
    const std::size_t n = scans.size();
    if (names && names->size() != n)
      throw py::value_error("names has " + std::to_string(names->size()) + " entries for " + std::to_string(n) + " scans");
    if (!poses.is_none() && py::len(poses) != n)
      throw py::value_error("poses has " + std::to_string(py::len(poses)) + " entries for " + std::to_string(n) + " scans");
    if (learn_scans < 1) throw py::value_error("learn_scans must be at least 1, got " + std::to_string(learn_scans));
    std::vector<std::uint8_t> model_alpha;
    if (model_alphabet) model_alpha = to_vector(*model_alphabet);
    auto load = [&](std::size_t i) {
      Cloud c = scan_from(scans[i], model_alphabet ? &model_alpha : nullptr, "scans[" + std::to_string(i) + "]");
      if (!poses.is_none()) set_frame(c, py::reinterpret_borrow<py::object>(poses[py::int_(i)]), py::none());
      return c;
    };
    Alphabet alphabet;
    if (alphabet_file) {
      auto a = codec::decode_alphabet(to_vector(*alphabet_file));
      if (!a.ok()) raise(Status(a.status().code(), "alphabet: " + a.status().message(), a.status().offset()));
      alphabet = std::move(a).value();
    } else {
      if (n == 0) throw py::value_error("build needs at least one scan to learn an alphabet on (or give alphabet=)");
      LearnParams p;
      p.model = place_model_params(threads);
      p.max_iterations = iterations;
      p.seed = seed;
      p.validate();
      py::gil_scoped_release unlocked;
      alphabet = learn_place_alphabet(
          n,
          [&](std::size_t i) {
            py::gil_scoped_acquire locked;  // the scans are Python objects
            return load(i);
          },
          static_cast<std::size_t>(learn_scans), p);
    }
    PlaceDatabase db;
    db.set_alphabet(std::move(alphabet));
    PyPlaceDatabase out(std::move(db), "", threads);
    for (std::size_t i = 0; i < n; ++i) out.add_cloud(load(i), names ? (*names)[i] : default_name(scans[i], i));
    return out;
  }

  std::size_t add(const py::object& scan, const std::optional<std::string>& name, const py::object& pose,
                  const py::object& gravity, const std::optional<py::bytes>& model_alphabet) {
    std::vector<std::uint8_t> alpha;
    if (model_alphabet) alpha = to_vector(*model_alphabet);
    Cloud c = scan_from(scan, model_alphabet ? &alpha : nullptr, "scan");
    set_frame(c, pose, gravity);
    return add_cloud(std::move(c), name ? *name : default_name(scan, db_.size()));
  }

  py::list query(const py::object& scan, const py::object& pose, const py::object& gravity, int top,
                 std::optional<double> max_distance, bool ground_vehicle, int top_k, std::optional<int> threads,
                 const std::optional<py::bytes>& model_alphabet) const {
    if (top < 1) throw py::value_error("top must be at least 1, got " + std::to_string(top));
    std::vector<std::uint8_t> alpha;
    if (model_alphabet) alpha = to_vector(*model_alphabet);
    Cloud c = scan_from(scan, model_alphabet ? &alpha : nullptr, "scan");
    set_frame(c, pose, gravity);
    PlaceParams p;
    p.threads = threads ? worker_threads(*threads) : threads_;
    p.top_k = top_k;
    p.ground_vehicle = ground_vehicle;
    p.max_distance = max_distance.value_or(0.0);
    p.validate();
    PlaceQueryResult r;
    std::optional<Status> error;
    {
      py::gil_scoped_release unlocked;
      const PlaceScan q = describe(c, "query", p.threads);
      try {
        r = db_.query(q, p);
      } catch (const PlaceDataError& e) {
        error = Status(e.status().code(), where() + e.status().message(), e.status().offset());
      }
    }
    if (error) raise(*error);
    py::list out;
    const std::size_t k = std::min<std::size_t>(r.matches.size(), static_cast<std::size_t>(top));
    for (std::size_t i = 0; i < k; ++i) out.append(match_dict(r.matches[i], p));
    return out;
  }

  /// The query scan described once, as bytes for every shard (encode_place_query).
  py::bytes prepare_query(const py::object& scan, const py::object& pose, const py::object& gravity,
                          const std::optional<py::bytes>& model_alphabet) const {
    std::vector<std::uint8_t> alpha;
    if (model_alphabet) alpha = to_vector(*model_alphabet);
    Cloud c = scan_from(scan, model_alphabet ? &alpha : nullptr, "scan");
    set_frame(c, pose, gravity);
    std::vector<std::uint8_t> bytes;
    {
      py::gil_scoped_release unlocked;
      bytes = encode_place_query(describe(c, "query", threads_), db_.storage());
    }
    return {reinterpret_cast<const char*>(bytes.data()), bytes.size()};
  }

  /// (entries, document frequency per word id as uint64 array).
  py::tuple word_statistics() const {
    const PlaceWordStatistics st = db_.word_statistics();
    py::array_t<std::uint64_t> df(static_cast<py::ssize_t>(st.df.size()));
    std::copy(st.df.begin(), st.df.end(), df.mutable_data());
    return py::make_tuple(st.scans, df);
  }

  py::list retrieve(const py::bytes& query, int top_k, const py::object& stats) const {
    if (top_k < 1) throw py::value_error("top_k must be at least 1, got " + std::to_string(top_k));
    PlaceWordStatistics global;
    if (stats.is_none()) {
      global = db_.word_statistics();
    } else {
      const auto t = stats.cast<py::tuple>();
      if (t.size() != 2) throw py::value_error("stats must be (entries, df) as word_statistics() gives");
      global.scans = t[0].cast<std::uint64_t>();
      const auto df = py::array_t<std::uint64_t, py::array::forcecast>(t[1]);
      if (df.ndim() != 1) throw py::value_error("stats: df must be one-dimensional, got " + shape_of(df));
      global.df.assign(df.data(), df.data() + df.shape(0));
    }
    const PlaceScan q = query_of(query);
    std::vector<std::pair<std::size_t, double>> r;
    std::optional<std::string> error;
    {
      py::gil_scoped_release unlocked;
      try {
        r = db_.retrieve(q, static_cast<std::size_t>(top_k), global);
      } catch (const std::invalid_argument& e) {
        error = where() + e.what();
      }
    }
    if (error) throw py::value_error(*error);
    py::list out;
    for (const auto& [i, score] : r) out.append(py::make_tuple(i, score));
    return out;
  }

  /// PlaceDatabase::verify of (index, similarity) candidates: {"matches": [...], "refined": [...],
  /// "decoded": n, "decode_ms": t}, each match a dict as query() gives plus "dense_refined".
  py::dict verify(const py::bytes& query, const std::vector<std::pair<std::size_t, double>>& candidates,
                  std::optional<double> max_distance, bool ground_vehicle, std::optional<int> threads,
                  bool second_round) const {
    PlaceParams p;
    p.threads = threads ? worker_threads(*threads) : threads_;
    p.ground_vehicle = ground_vehicle;
    p.max_distance = max_distance.value_or(0.0);
    p.validate();
    for (const auto& c : candidates)
      if (c.first >= db_.size())
        throw py::value_error(where() + "candidate " + std::to_string(c.first) + " of a database of " +
                              std::to_string(db_.size()) + " scans");
    const PlaceScan q = query_of(query);
    PlaceVerified v;
    std::optional<Status> error;
    {
      py::gil_scoped_release unlocked;
      try {
        v = db_.verify(q, candidates, p, second_round);
      } catch (const PlaceDataError& e) {
        error = Status(e.status().code(), where() + e.status().message(), e.status().offset());
      }
    }
    if (error) raise(*error);
    py::list matches, refined;
    for (const auto& m : v.matches) matches.append(match_dict(m, p));
    for (const auto& m : v.refined) refined.append(match_dict(m, p));
    py::dict d;
    d["matches"] = matches;
    d["refined"] = refined;
    d["decoded"] = v.decoded;
    d["decode_ms"] = v.decode_ms;
    d["dense_candidates"] = p.dense_iterations > 0 ? p.dense_candidates : 0;
    d["accept_score"] = p.accept_score;
    d["more_candidates"] = p.more_candidates;
    return d;
  }

  /// The alphabet file of the database (bytes), as `lex3d` writes alphabets.
  py::bytes alphabet_file() const {
    const std::vector<std::uint8_t> b = codec::encode_alphabet(db_.alphabet());
    return {reinterpret_cast<const char*>(b.data()), b.size()};
  }

  /// Writes the whole database (format 2.0) to `path`, atomically (temporary file + rename).
  void save(const py::object& path_obj) const {
    const std::string path = path_of(path_obj);
    Status st;
    {
      py::gil_scoped_release unlocked;
      try {
        st = io::write_file_atomic(path, db_.save());
      } catch (const PlaceDataError& e) {
        st = Status(e.status().code(), where() + e.status().message(), e.status().offset());
      }
    }
    if (!st.ok()) raise(st);
  }

  [[nodiscard]] std::size_t size() const { return db_.size(); }
  [[nodiscard]] std::vector<std::string> names() const {
    std::vector<std::string> out;
    for (std::size_t i = 0; i < db_.size(); ++i) out.push_back(db_.name(i));
    return out;
  }
  [[nodiscard]] std::size_t alphabet_words() const { return db_.alphabet().size(); }
  [[nodiscard]] const std::string& path() const { return path_; }
  [[nodiscard]] int threads() const { return threads_; }

 private:
  [[nodiscard]] std::string where() const { return path_.empty() ? std::string{} : path_ + ": "; }

  py::dict match_dict(const PlaceMatch& m, const PlaceParams& p) const {
    py::dict d;
    d["scan"] = db_.name(m.scan);
    d["index"] = m.scan;
    d["score"] = m.score;
    d["valid"] = m.valid;
    d["accepted"] = m.valid && m.score >= p.accept_score;
    d["inliers"] = m.inliers;
    d["similarity"] = m.retrieval_similarity;
    d["sensor_distance_m"] = m.sensor_distance_m;
    d["dense_refined"] = m.dense_refined;
    d["pose"] = from_pose(m.T_match_query);
    return d;
  }

  PlaceScan query_of(const py::bytes& query) const {
    const std::string b = query;
    auto q = decode_place_query(reinterpret_cast<const std::uint8_t*>(b.data()), b.size(), db_.storage());
    if (!q.ok()) raise(Status(q.status().code(), "query: " + q.status().message(), q.status().offset()));
    return std::move(q).value();
  }

  /// As `lex3d place` describes a scan (--gravity auto): a scan without a pose or gravity
  /// takes the up direction its surfaces give (apply_gravity).
  PlaceScan describe(Cloud cloud, const std::string& name, int threads) const {
    const ModelParams mp = place_model_params(threads);
    apply_gravity(cloud, mp.features.range);
    return make_place_scan(cloud, db_.alphabet(), db_.storage(), mp, name);
  }

  std::size_t add_cloud(Cloud cloud, const std::string& name) {
    py::gil_scoped_release unlocked;
    return db_.add(describe(cloud, name, threads_));
  }

  PlaceDatabase db_;
  std::string path_;
  int threads_ = 2;  // worker threads: describing scans, learning, verifying
};

}  // namespace

void bind_place(py::module_& m) {
  py::class_<PyPlaceDatabase>(m, "PlaceDatabase", R"(A place database (formats/place_db.md), as `lex3d place`.

    db = lex3d.PlaceDatabase.open("map.lex3dp")          # or PlaceDatabase.build([...])
    for match in db.query(points):                         # (N, 3) array, path or model bytes
        print(match["scan"], match["score"], match["pose"])  # pose: 4x4 T_match_query

A scan is an (N, 3) float array (metres, the scan's frame), a path of a point cloud or a
.lex3dm model file, or the bytes of a model file (model_alphabet= the alphabet it references).
pose= (4x4, T_world_cloud) or gravity= (3-vector, the direction of gravity in the scan's frame)
make the features upright as an IMU would; without them the scan's z axis is up.
threads= (open, build): the worker threads describing scans (build, add, query, prepare_query),
learning the alphabet and verifying candidates; 0 = every core, as the command's --threads;
default 2. Results do not depend on it. query() and verify() take their own threads= (default:
the database's).
Bad input raises ValueError (OSError for files that cannot be read or written) with one line.)")
      .def_static("open", &PyPlaceDatabase::open, py::arg("path"), py::kw_only(), py::arg("threads") = 2,
                  "Opens a database file (memory-mapped; entries are decoded when a query verifies them).\n"
                  "threads: worker threads (0 = every core); results do not depend on it.")
      .def_static("build", &PyPlaceDatabase::build, py::arg("scans"), py::kw_only(), py::arg("names") = py::none(),
                  py::arg("poses") = py::none(), py::arg("alphabet") = py::none(),
                  py::arg("model_alphabet") = py::none(), py::arg("learn_scans") = 5, py::arg("iterations") = 200,
                  py::arg("seed") = LearnParams{}.seed, py::arg("threads") = 2,
                  R"(A new database (in memory; save() writes it) of a list of scans, as `lex3d place build`:
with alphabet= (an alphabet file, bytes), or one learned on learn_scans evenly spaced scans.
names: one a scan (default: the file's stem, or scan_<i>); poses: one 4x4 T_world_cloud a scan.
threads: worker threads describing the scans and learning (0 = every core); the database, its
alphabet and every later result do not depend on it.)")
      .def("add", &PyPlaceDatabase::add, py::arg("scan"), py::kw_only(), py::arg("name") = py::none(),
           py::arg("pose") = py::none(), py::arg("gravity") = py::none(), py::arg("model_alphabet") = py::none(),
           "Adds a scan (in memory; save() writes the database) and returns its index.")
      .def("query", &PyPlaceDatabase::query, py::arg("scan"), py::kw_only(), py::arg("pose") = py::none(),
           py::arg("gravity") = py::none(), py::arg("top") = 5, py::arg("max_distance") = py::none(),
           py::arg("ground_vehicle") = false, py::arg("top_k") = PlaceParams{}.top_k, py::arg("threads") = py::none(),
           py::arg("model_alphabet") = py::none(),
           R"(The verified candidates for a scan, best first (at most `top`): dicts with "scan" (name),
"index", "score", "valid", "accepted" (valid and score >= 0.25), "inliers", "similarity",
"sensor_distance_m" and "pose", the 4x4 float64 T_match_query (query frame -> matched scan's frame).
max_distance: metres, reject transforms that put the sensors farther apart. top_k: candidates verified.
threads: worker threads describing the scan and verifying (0 = every core; default: the database's).)")
      .def("prepare_query", &PyPlaceDatabase::prepare_query, py::arg("scan"), py::kw_only(),
           py::arg("pose") = py::none(), py::arg("gravity") = py::none(), py::arg("model_alphabet") = py::none(),
           R"(The staged query's first step: the scan described once (as query() describes it), as bytes
that retrieve() and verify() of any database with this alphabet and storage take.)")
      .def("word_statistics", &PyPlaceDatabase::word_statistics,
           R"((entries, df): the first stage's statistics, df[w] the entries holding word w (uint64).
Summed over the shards of a sharded database they are those of one database of all the scans.)")
      .def("retrieve", &PyPlaceDatabase::retrieve, py::arg("query"), py::kw_only(), py::arg("top_k") = PlaceParams{}.top_k,
           py::arg("stats") = py::none(),
           R"(The first stage (tf-idf over the alphabet's words) of a prepared query: [(index, similarity)],
best first, at most top_k. stats: the (entries, df) of the whole this database is a shard of
(default: its own), giving the scores one database of all the scans gives.)")
      .def("verify", &PyPlaceDatabase::verify, py::arg("query"), py::arg("candidates"), py::kw_only(),
           py::arg("max_distance") = py::none(), py::arg("ground_vehicle") = false, py::arg("threads") = py::none(),
           py::arg("second_round") = false,
           R"(Verifies (index, similarity) candidates of a prepared query: {"matches": the candidates' matches
with the feature transform, best first; "refined": the first of them densely aligned, as query()
aligns them; "decoded", "decode_ms", "dense_candidates" (how many of all the shards' best take
their aligned form), "accept_score" and "more_candidates" (query()'s second round: where no
match of the first top_k reaches accept_score, the next more_candidates are verified with
second_round=True, the surface hypotheses alone)}. Each match a dict as query() gives, plus
"dense_refined". threads: 0 = every core; default: the database's.)")
      .def("alphabet_file", &PyPlaceDatabase::alphabet_file, "The database's alphabet as an alphabet file (bytes).")
      .def("save", &PyPlaceDatabase::save, py::arg("path"),
           "Writes the database (format 2.0) to path, atomically: a failure leaves no partial file.")
      .def("__len__", &PyPlaceDatabase::size)
      .def_property_readonly("names", &PyPlaceDatabase::names, "The scans' names, in index order.")
      .def_property_readonly("alphabet_words", &PyPlaceDatabase::alphabet_words)
      .def_property_readonly("path", &PyPlaceDatabase::path, "The file it was opened from ('' when built in memory).")
      .def_property_readonly("threads", &PyPlaceDatabase::threads,
                             "The worker threads it describes, learns and verifies with (0 given: the core count).")
      .def("__repr__", [](const PyPlaceDatabase& d) {
        return "<lex3d.PlaceDatabase " + std::to_string(d.size()) + " scans, " + std::to_string(d.alphabet_words()) +
               " words" + (d.path().empty() ? std::string{} : ", " + d.path()) + ">";
      });
}

}  // namespace lex3d::python
