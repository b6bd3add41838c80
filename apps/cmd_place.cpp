// lex3d place build|add|query|eval: place recognition on word instances.

#include <CLI/CLI.hpp>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <functional>
#include <iostream>
#include <map>
#include <set>

#include "lex3d/codec/codec.hpp"
#include "lex3d/io/mapped_file.hpp"
#include "lex3d/residual/residual.hpp"
#include "allocator.hpp"
#include "cli_common.hpp"
#include "json.hpp"
#include "place_pictures.hpp"
#include "lex3d/core/timer.hpp"
#include "lex3d/place/gravity.hpp"
#include "lex3d/place/place.hpp"
#include "progress.hpp"

namespace lex3d::cli {

namespace {

namespace fs = std::filesystem;

PlaceParams default_query_params() {
  PlaceParams p;
  p.threads = 2;  // candidates are verified in parallel
  return p;
}

struct PlaceOptions {
  std::string db;
  std::vector<std::string> inputs;
  std::string alphabet;
  std::string poses;
  std::string times;
  std::string format = "auto";
  std::string png;  // --png PREFIX: no pictures without it
  std::string dump;
  std::string cache;
  std::string model_alphabet;
  int learn_scans = 5;
  int iterations = 200;
  int top = 5;
  double min_gap = 20.0;
  double radius = 4.0;
  bool json = false;
  bool ground = false;
  double max_distance = -1.0;  // < 0: not given
  PlaceParams params = default_query_params();
  PlaceStorageParams storage;
  /// Up direction of the scans: auto (a scan's pose when given, else its points), poses,
  /// points (estimated even when a pose is given: eval measures the no-pose case so), none.
  std::string gravity = "auto";
  std::string retrieval = "default";   // --retrieval
  std::string vocabulary;              // --vocabulary FROM.lex3dp
  int vocabulary_words = 0;            // --vocabulary-words N (0: none learned)
  int vocabulary_scans = 1000;         // --vocabulary-scans
  int list_retrieved = 0;              // --list-retrieved N
  std::string descriptor;              // --descriptor patch|vdlsd (empty: build/eval patch, query/add the database's)
};

PlaceDescriptor parse_descriptor(const std::string& s) {
  return s == "vdlsd" ? PlaceDescriptor::kVdlsd : PlaceDescriptor::kPatch;
}

// A database described with another descriptor than --descriptor asks for: a bad-data error.
void check_descriptor(const PlaceOptions& o, const std::string& path, const PlaceDatabase& db) {
  if (o.descriptor.empty() || parse_descriptor(o.descriptor) == db.storage().descriptor) return;
  throw CliError(2, path + ": its features are described with " + to_string(db.storage().descriptor) + ", not " +
                        o.descriptor + " (--descriptor)");
}

PlaceRetrieval parse_retrieval(const std::string& s) {
  if (s == "tfidf-alphabet") return PlaceRetrieval::kTfidfAlphabet;
  if (s == "tfidf") return PlaceRetrieval::kTfidf;
  if (s == "fabmap") return PlaceRetrieval::kFabmap;
  return PlaceRetrieval::kDefault;
}

ModelParams model_params(int threads) {
  ModelParams mp;
  mp.threads = threads;
  return mp;
}

// How scans are described: their up direction (--gravity) and the worker threads (--threads).
struct Describing {
  std::string gravity = "auto";
  int threads = 1;
};

Describing describing(const PlaceOptions& o) { return {o.gravity, o.params.threads}; }

std::string stem(const std::string& path) { return fs::path(path).stem().string(); }

// Opens a database without decoding its entries: the file is mapped and only the header,
// alphabet and index are read.
PlaceDatabase read_db(const std::string& path, bool need_alphabet = true) {
  auto file = io::MappedFile::open(path);
  if (!file.ok()) throw CliError(3, file.status().to_string());
  SharedBytes b;
  b.data = file.value()->data();
  b.size = file.value()->size();
  b.owner = file.value();
  auto db = PlaceDatabase::open(b);
  if (!db.ok()) throw CliError(2, path + ": " + db.status().to_string());
  if (need_alphabet && !db.value().has_alphabet()) throw CliError(2, path + ": the database holds no alphabet");
  if (db.value().file_info().ignored_tail_bytes > 0)
    std::fprintf(stderr, "note: %s: %llu bytes after the committed database (an add that did not finish) are ignored\n",
                 path.c_str(), static_cast<unsigned long long>(db.value().file_info().ignored_tail_bytes));
  return std::move(db).value();
}

// The scans of the inputs one at a time: point clouds (any format `io` reads, raw logs
// as one scan a turn), lex3d model files (.lex3dm) and sequences (.lex3dq), decoded
// (words and residual layer) when asked. With --poses, pose k goes to scan k in this order.
class PlaceInputs {
 public:
  PlaceInputs(const std::vector<std::string>& paths, const std::string& format, const std::string& poses_path,
              const std::string& model_alphabet) {
    if (!model_alphabet.empty()) {
      auto a = io::read_file(model_alphabet);
      if (!a.ok()) throw CliError(3, a.status().to_string());
      alphabet_file_ = std::move(a).value();
    }
    const io::Format f = parse_format_option(format);
    for (const auto& path : paths) {
      const std::string ext = lower_extension(path);
      if (ext == ".lex3dq") {
        const auto shared = read_sequence(path);
        for (std::size_t k = 0; k < shared->model_files.size(); ++k) {
          char buf[32];
          std::snprintf(buf, sizeof buf, "_%03zu", k);
          entries_.push_back({path, stem(path) + buf, nullptr, shared, k});
        }
      } else if (ext == ".lex3dm") {
        entries_.push_back({path, stem(path), nullptr, nullptr, 0});
      } else {
        auto loader = std::make_shared<const ScanLoader>(std::vector<std::string>{path}, f, "", false);
        for (std::size_t k = 0; k < loader->size(); ++k)
          entries_.push_back({path, loader->size() == 1 ? stem(path) : stem(path) + "_" + std::to_string(k), loader, nullptr, k});
      }
    }
    make_names_unique({});
    if (poses_path.empty()) return;
    poses_ = read_scan_poses(poses_path, entries_.size());
  }
  /// Names are what a query answers with: two entries (or an entry and a scan of the database
  /// added to, `taken`) of the same name are told apart by their folder ("kitti00/000000"),
  /// then by a count ("000000#2"). Returns how many were renamed.
  std::size_t make_names_unique(const std::vector<std::string>& taken) {
    // Compared by the file name part, so "scan" is told apart from a stored "first/scan" too.
    const auto base = [](const std::string& n) {
      const std::size_t slash = n.rfind('/');
      const std::string tail = slash == std::string::npos ? n : n.substr(slash + 1);
      return tail.substr(0, tail.find('#'));
    };
    std::map<std::string, std::size_t> count;
    for (const auto& t : taken) ++count[base(t)];
    for (const auto& e : entries_) ++count[base(e.name)];
    std::size_t renamed = 0;
    std::set<std::string> used(taken.begin(), taken.end());
    for (const auto& e : entries_)
      if (count[base(e.name)] == 1) used.insert(e.name);
    for (auto& e : entries_) {
      if (count[base(e.name)] == 1) continue;
      const std::string folder = fs::path(e.path).parent_path().filename().string();
      const std::string first = folder.empty() ? e.name : folder + "/" + e.name;
      std::string name = first;
      for (int k = 2; used.count(name) != 0; ++k) name = first + "#" + std::to_string(k);
      used.insert(name);
      e.name = name;
      ++renamed;
    }
    return renamed;
  }
  [[nodiscard]] std::size_t size() const { return entries_.size(); }
  [[nodiscard]] const std::string& name(std::size_t i) const { return entries_.at(i).name; }
  [[nodiscard]] Cloud load(std::size_t i) const {
    const Entry& e = entries_.at(i);
    Cloud cloud;
    if (e.loader) {
      cloud = e.loader->load(e.k);
    } else {
      std::vector<std::uint8_t> bytes;
      const std::vector<std::uint8_t>* model = nullptr;
      const std::vector<std::uint8_t>* alphabet = alphabet_file_.empty() ? nullptr : &alphabet_file_;
      std::string what = e.path;
      if (e.sequence) {
        model = &e.sequence->model_files[e.k];
        alphabet = &e.sequence->alphabet_file;
        what += ": scan " + std::to_string(e.k);
      } else {
        auto b = io::read_file(e.path);
        if (!b.ok()) throw CliError(3, b.status().to_string());
        bytes = std::move(b).value();
        model = &bytes;
      }
      auto d = codec::decode_model(*model, alphabet);
      if (!d.ok()) {
        const bool needs = d.status().code() == ErrorCode::kInvalidArgument;
        throw CliError(needs ? 1 : 2, what + ": " + d.status().to_string() + (needs ? " (give --model-alphabet)" : ""));
      }
      auto c = residual::decode_cloud(d.value());
      if (!c.ok()) throw CliError(2, what + ": " + c.status().to_string());
      cloud = std::move(c).value();
      cloud.T_cloud_sensor = d.value().T_cloud_sensor;  // where the sensor was (the range image's viewpoint)
    }
    if (!poses_.empty()) {
      cloud.T_world_cloud = poses_[i];
      cloud.has_world_pose = true;
    }
    return cloud;
  }

 private:
  struct Entry {
    std::string path;
    std::string name;
    std::shared_ptr<const ScanLoader> loader;  // point clouds
    std::shared_ptr<const codec::SequenceData> sequence;
    std::size_t k = 0;
  };
  std::vector<Entry> entries_;
  std::vector<Pose> poses_;
  std::vector<std::uint8_t> alphabet_file_;
};

// Scan i of a set of n, read when asked: building a database of a long drive holds one
// scan (and the scans the alphabet is learnt from) in memory, not all of them.
using GetScan = std::function<Cloud(std::size_t)>;

Alphabet learn_on(std::size_t n, const GetScan& get, const PlaceOptions& o) {
  LearnParams p;
  p.model = model_params(o.params.threads);
  p.max_iterations = o.iterations;
  ProgressBar bar("learning alphabet");
  return learn_place_alphabet(n, get, static_cast<std::size_t>(o.learn_scans), p, [&](const LearnProgress& pr) {
    bar.update(pr.iteration, pr.max_iterations, std::to_string(pr.alphabet_size) + " words");
  });
}

// The alphabet file given with --alphabet.
Alphabet read_alphabet(const std::string& path) {
  auto bytes = io::read_file(path);
  if (!bytes.ok()) throw CliError(2, bytes.status().to_string());
  auto a = codec::decode_alphabet(bytes.value());
  if (!a.ok()) throw CliError(2, path + ": " + a.status().to_string());
  return std::move(a).value();
}

// Sets the up direction of `cloud` as --gravity asks; returns where it came from.
GravitySource upright(Cloud& cloud, const std::string& gravity, const RangeImageParams& range) {
  if (gravity == "points" || gravity == "none") {
    cloud.has_world_pose = false;
    cloud.T_world_cloud = Pose::Identity();
    if (gravity == "none") return GravitySource::kNone;
  } else if (gravity == "poses" && !cloud.has_world_pose) {
    throw CliError(1, "--gravity poses: the scans have no poses (give --poses)");
  }
  return apply_gravity(cloud, range);
}

PlaceScan describe(Cloud cloud, const std::string& name, const Alphabet& alphabet,
                   const PlaceStorageParams& storage, const Describing& how, GravitySource* source = nullptr) {
  const ModelParams mp = model_params(how.threads);
  const GravitySource g = upright(cloud, how.gravity, mp.features.range);
  if (source != nullptr) *source = g;
  return make_place_scan(cloud, alphabet, storage, mp, name);
}

PlaceVocabulary learn_place_vocabulary(const std::vector<PlaceScan>& train, int words) {
  std::vector<const PlaceScan*> ptrs;
  for (const auto& s : train) ptrs.push_back(&s);
  VocabularyParams vp;
  vp.words = words;
  VocabularyStats vs;
  try {
    PlaceVocabulary v = learn_vocabulary(ptrs, vp, &vs);
    std::fprintf(stderr, "recognition vocabulary: %zu leaves (%zu nodes) from %zu descriptors of %zu scans, "
                 "%zu Chow-Liu edges, %.0f ms\n", vs.leaves, vs.nodes, vs.training_descriptors, vs.training_scans,
                 vs.chow_liu_edges, vs.learn_ms);
    return v;
  } catch (const std::invalid_argument& e) {
    throw CliError(2, std::string("cannot learn a recognition vocabulary: ") + e.what());
  }
}

std::vector<PlaceScan> describe_all(std::size_t n, const GetScan& get, const std::vector<std::string>& names,
                                    const Alphabet& alphabet, const PlaceStorageParams& storage, double* prepare_ms,
                                    const Describing& how, std::vector<GravitySource>* sources = nullptr) {
  std::vector<PlaceScan> out;
  ProgressBar bar("preparing scans");
  Stopwatch sw;
  for (std::size_t i = 0; i < n; ++i) {
    GravitySource g = GravitySource::kNone;
    out.push_back(describe(get(i), names[i], alphabet, storage, how, &g));
    if (sources != nullptr) sources->push_back(g);
    bar.update(static_cast<long>(i + 1), static_cast<long>(n), names[i]);
  }
  if (prepare_ms != nullptr) *prepare_ms = sw.elapsed_ms();
  return out;
}

struct WriteStats {
  std::size_t scans = 0;      // in the database after the write
  std::size_t added = 0;
  std::uint64_t bytes = 0;    // file size after the write
  double prepare_ms = 0.0;
  bool rewritten = false;     // a new file (temporary + rename), not an append
};

// Adds the inputs' scans through `w`, one at a time, handing each piece to `put`.
template <typename Put>
void add_inputs(PlaceFileWriter& w, const PlaceInputs* inputs, const Alphabet& alphabet,
                const PlaceStorageParams& storage, const Put& put, WriteStats& st, const Describing& how) {
  if (inputs == nullptr) return;
  ProgressBar bar("adding scans");
  Stopwatch sw;
  std::size_t empty = 0;
  for (std::size_t i = 0; i < inputs->size(); ++i) {
    const PlaceScan s = describe(inputs->load(i), inputs->name(i), alphabet, storage, how);
    empty += s.empty_descriptors;
    put(w.add(s));
    ++st.added;
    bar.update(static_cast<long>(i + 1), static_cast<long>(inputs->size()), inputs->name(i));
  }
  st.prepare_ms = sw.elapsed_ms();
  bar.finish();
  if (empty > 0)
    std::fprintf(stderr, "note: %zu stored features had too few points around them for a VD-LSD (stored empty)\n", empty);
}

// Writes a whole new database file (format 2.0) to a temporary name and renames it over
// `path`: the stored scans of `from` copied as they are, then the inputs' scans.
WriteStats write_new_db(const std::string& path, const PlaceStorageParams& storage, const Alphabet& alphabet,
                        const PlaceDatabase* from, const PlaceInputs* inputs, const Describing& how,
                        std::shared_ptr<const PlaceVocabulary> vocabulary = nullptr) {
  const std::string tmp = io::temporary_path_for(path);
  auto f = io::PositionalFile::create_new(tmp);
  if (!f.ok()) throw CliError(3, f.status().to_string());
  struct Cleanup {
    std::string path;
    bool armed = true;
    ~Cleanup() {
      if (armed) io::remove_file_quietly(path);
    }
  } cleanup{tmp};
  WriteStats st;
  std::uint64_t end = 0;
  auto put = [&](const PlaceFileWriter::Piece& p) {
    throw_if_error(f.value()->write_at(p.offset, p.bytes.data(), p.bytes.size()));
    end = std::max<std::uint64_t>(end, p.offset + p.bytes.size());
  };
  const int dim = detail::stored_descriptor_dim(storage, &alphabet);
  PlaceFileWriter w(storage, &alphabet, dim);
  if (vocabulary != nullptr && vocabulary->descriptor_dim != dim)
    throw CliError(2, "the recognition vocabulary's descriptors have " + std::to_string(vocabulary->descriptor_dim) +
                          " values, the database's " + to_string(storage.descriptor) + " descriptors " +
                          std::to_string(dim));
  w.set_vocabulary(std::move(vocabulary));
  put(w.begin());
  if (from != nullptr)
    for (std::size_t i = 0; i < from->stored_count(); ++i) {
      auto p = w.copy(*from, i);
      if (!p.ok()) throw CliError(2, p.status().to_string());
      put(p.value());
    }
  add_inputs(w, inputs, alphabet, storage, put, st, how);
  const auto [idx, commit] = w.finish();
  put(idx);
  throw_if_error(f.value()->sync());
  put(commit);
  throw_if_error(f.value()->sync());
  throw_if_error(f.value()->close());
  throw_if_error(io::rename_file(tmp, path));
  cleanup.armed = false;
  st.scans = w.size();
  st.bytes = end;
  st.rewritten = true;
  return st;
}

// Appends the inputs' scans to a 2.x database in place: new SCAN chunks and a new index after
// the committed end, synced, then the other commit record, synced. A crash before the commit
// record is written leaves the committed database as it was (formats/place_db.md §5).
WriteStats append_db(io::PositionalFile& file, const PlaceDatabase& db, const PlaceInputs& inputs,
                     const Describing& how) {
  PlaceFileWriter w(db);
  WriteStats st;
  std::uint64_t end = w.start();
  auto put = [&](const PlaceFileWriter::Piece& p) {
    throw_if_error(file.write_at(p.offset, p.bytes.data(), p.bytes.size()));
    end = std::max<std::uint64_t>(end, p.offset + p.bytes.size());
  };
  try {
    add_inputs(w, &inputs, db.alphabet(), db.storage(), put, st, how);
  } catch (...) {
    // Nothing was committed: take back what was written after the committed end.
    (void)file.truncate(w.start());
    throw;
  }
  const auto [idx, commit] = w.finish();
  put(idx);
  throw_if_error(file.truncate(end));  // drops what an unfinished add left after the committed end
  throw_if_error(file.sync());
  put(commit);
  throw_if_error(file.sync());
  throw_if_error(file.close());
  st.scans = w.size();
  st.bytes = end;
  return st;
}

void print_write(const PlaceOptions& o, const WriteStats& st, std::size_t words, const char* how) {
  if (o.json) {
    Json j;
    j.begin_object().value("scans", st.scans).value("added", st.added).value("bytes", st.bytes);
    j.value("alphabet_words", words).value("prepare_ms", st.prepare_ms).value("rewritten", st.rewritten);
    j.end_object();
    std::cout << j.str() << "\n";
  } else {
    std::printf("%s: %s %zu scans, %zu in all, %zu words, %llu bytes (%.1f KB a scan)\n", o.db.c_str(), how, st.added,
                st.scans, words, static_cast<unsigned long long>(st.bytes),
                st.scans ? static_cast<double>(st.bytes) / 1024.0 / static_cast<double>(st.scans) : 0.0);
  }
}

// Checked before any work: the database is not a scan, the poses or an alphabet given,
// under any spelling of its path (file identity).
void check_db_output(const PlaceOptions& o, const std::string& db) {
  OutputSet files;
  files.inputs(o.inputs, "input");
  files.input(o.poses, "--poses");
  files.input(o.alphabet, "--alphabet");
  files.input(o.model_alphabet, "--model-alphabet");
  files.output(db, "db");
  check_output_kind(db, "db", "database");
}

void run_build(const PlaceOptions& o) {
  check_db_output(o, o.db);
  check_output_path(o.db, o.inputs);
  const PlaceInputs inputs(o.inputs, o.format, o.poses, o.model_alphabet);
  Alphabet alphabet;
  if (!o.alphabet.empty()) {
    alphabet = read_alphabet(o.alphabet);
  } else {
    alphabet = learn_on(inputs.size(), [&](std::size_t i) { return inputs.load(i); }, o);
  }
  std::shared_ptr<const PlaceVocabulary> vocabulary;
  if (!o.vocabulary.empty()) {
    vocabulary = read_db(o.vocabulary, false).vocabulary();
    if (vocabulary == nullptr) throw CliError(2, o.vocabulary + ": has no recognition vocabulary (--vocabulary)");
  } else if (o.vocabulary_words > 0) {
    // Learned on the inputs' place features (evenly spaced, at most --vocabulary-scans), described
    // here and again when written: only the training scans' features are held.
    const std::size_t n = inputs.size(), k = std::min<std::size_t>(n, static_cast<std::size_t>(o.vocabulary_scans));
    std::vector<PlaceScan> train;
    ProgressBar bar("vocabulary scans");
    for (std::size_t i = 0; i < k; ++i) {
      PlaceScan s = describe(inputs.load(i * n / k), inputs.name(i * n / k), alphabet, o.storage, describing(o));
      s.coarse = RangeImage{};
      s.dense_points.clear(), s.dense_normals.clear(), s.dense_index.clear(), s.pairs.clear();
      train.push_back(std::move(s));
      bar.update(static_cast<long>(i + 1), static_cast<long>(k), inputs.name(i * n / k));
    }
    bar.finish();
    vocabulary = std::make_shared<const PlaceVocabulary>(learn_place_vocabulary(train, o.vocabulary_words));
  }
  const WriteStats st = write_new_db(o.db, o.storage, alphabet, nullptr, &inputs, describing(o), vocabulary);
  print_write(o, st, alphabet.size(), "built from");
}

void run_add(const PlaceOptions& o) {
  check_db_output(o, o.db);
  check_output_path(o.db, o.inputs);
  PlaceInputs inputs(o.inputs, o.format, o.poses, o.model_alphabet);
  // Locked before it is read: a second `place add` on the same file waits for nothing and fails.
  auto file = io::PositionalFile::open_existing(o.db);
  if (!file.ok()) throw CliError(3, file.status().to_string());
  const PlaceDatabase db = read_db(o.db);
  {
    std::vector<std::string> taken;
    for (std::size_t i = 0; i < db.size(); ++i) taken.push_back(db.name(i));
    inputs.make_names_unique(taken);
  }
  check_descriptor(o, o.db, db);
  const PlaceFileInfo& fi = db.file_info();
  // In place when the format allows it (2.x) and earlier indexes left behind by appends
  // are under a quarter of the file; otherwise a compact new file replaces it.
  if (fi.major >= 2 && fi.dead_bytes * 4 <= fi.committed_bytes) {
    print_write(o, append_db(*file.value(), db, inputs, describing(o)), db.alphabet().size(), "appended");
    return;
  }
  if (fi.major < 2)
    std::fprintf(stderr, "note: %s is format %d.%d: rewritten as format 2.0\n", o.db.c_str(), fi.major, fi.minor);
  print_write(o, write_new_db(o.db, db.storage(), db.alphabet(), &db, &inputs, describing(o), db.vocabulary()),
              db.alphabet().size(), "added");
}

void run_upgrade(const PlaceOptions& o) {
  if (o.inputs.size() != 1) throw CliError(1, "place upgrade OLD NEW: give one output file");
  const std::string& out = o.inputs[0];
  check_output_path(out, {o.db});
  const PlaceDatabase db = read_db(o.db, false);
  const WriteStats st = write_new_db(out, db.storage(), db.alphabet(), &db, nullptr, Describing{}, db.vocabulary());
  if (o.json) {
    Json j;
    j.begin_object().value("scans", st.scans).value("bytes", st.bytes).value("from_major", db.file_info().major);
    j.value("from_minor", db.file_info().minor).end_object();
    std::cout << j.str() << "\n";
  } else {
    std::printf("%s: %zu scans, format %d.%d -> %s: format 2.0, %llu bytes\n", o.db.c_str(), st.scans,
                db.file_info().major, db.file_info().minor, out.c_str(), static_cast<unsigned long long>(st.bytes));
  }
}

// The first stage asked for, checked against the database (a vocabulary method needs one).
PlaceRetrieval retrieval_for(const PlaceOptions& o, const PlaceDatabase& db) {
  const PlaceRetrieval r = parse_retrieval(o.retrieval);
  if ((r == PlaceRetrieval::kTfidf || r == PlaceRetrieval::kFabmap) && !db.has_vocabulary())
    throw CliError(1, "--retrieval " + o.retrieval + ": " + (o.db.empty() ? std::string("the database") : o.db) +
                          " has no recognition vocabulary (build it with --vocabulary-words N or --vocabulary FILE)");
  return r;
}

void pose_json(Json& j, const Pose& T) {
  const Eigen::Matrix4d m = T.matrix();
  j.begin_array("T_match_query");
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 4; ++c) j.value({}, m(r, c));
  j.end_array();
}

void run_query(const PlaceOptions& o) {
  keep_heap_on_huge_pages();  // one scan at a time to describe and match
  Stopwatch open_sw;
  const PlaceDatabase db = read_db(o.db);
  const double open_ms = open_sw.elapsed_ms();
  check_descriptor(o, o.db, db);
  const PlaceInputs inputs(o.inputs, o.format, o.poses, o.model_alphabet);
  PlaceParams p = o.params;
  p.ground_vehicle = o.ground;
  p.max_distance = std::max(0.0, o.max_distance);
  p.retrieval = retrieval_for(o, db);
  auto cpu_ms = [] { return 1000.0 * static_cast<double>(std::clock()) / CLOCKS_PER_SEC; };
  for (std::size_t qi = 0; qi < inputs.size(); ++qi) {
    Stopwatch sw;
    const double c0 = cpu_ms();
    GravitySource gravity = GravitySource::kNone;
    const PlaceScan scan = describe(inputs.load(qi), inputs.name(qi), db.alphabet(), db.storage(), describing(o), &gravity);
    const double prep = sw.elapsed_ms();
    const double c1 = cpu_ms();
    PlaceQueryResult r;
    try {
      r = db.query(scan, p);
    } catch (const PlaceDataError& e) {
      throw CliError(2, o.db + ": " + e.status().to_string());
    }
    const double c2 = cpu_ms();
    const std::size_t k = std::min<std::size_t>(r.matches.size(), static_cast<std::size_t>(o.top));
    if (o.json) {
      Json j;
      j.begin_object().value("query", scan.name).value("accepted", r.accepted).value("gravity", to_string(gravity));
      j.value("prepare_ms", prep).value("retrieval_ms", r.retrieval_ms).value("verification_ms", r.verification_ms);
      j.value("decode_ms", r.decode_ms).value("decoded", r.decoded).value("database_open_ms", open_ms).value("database_scans", db.size());
      // Process CPU time (all threads) of the two stages: what the wall times are on an idle machine.
      j.value("prepare_cpu_ms", c1 - c0).value("query_cpu_ms", c2 - c1);
      j.value("retrieval", to_string(r.retrieval));
      if (r.new_place_probability >= 0.0) j.value("new_place_probability", r.new_place_probability);
      if (o.list_retrieved > 0) {
        // The first stage's ranking (what verification would see with --candidates N).
        const auto ranked = db.retrieve(scan, static_cast<std::size_t>(o.list_retrieved), p.retrieval, p);
        j.begin_array("retrieved");
        for (const auto& [s, v] : ranked) j.value({}, db.name(s));
        j.end_array();
      }
      j.begin_array("matches");
      for (std::size_t i = 0; i < k; ++i) {
        const PlaceMatch& m = r.matches[i];
        j.begin_object().value("scan", db.name(m.scan)).value("score", m.score).value("valid", m.valid);
        j.value("accepted", m.valid && m.score >= p.accept_score).value("inliers", m.inliers);
        j.value("similarity", m.retrieval_similarity).value("sensor_distance_m", m.sensor_distance_m);
        j.value("rejected_distance", m.rejected_distance).value("rejected_ground", m.rejected_ground);
        j.value("rejected_conflict", m.rejected_conflict).value("rejected_score", m.rejected_score);
        pose_json(j, m.T_match_query);
        j.end_object();
      }
      j.end_array().end_object();
      std::cout << j.str() << "\n" << std::flush;
      continue;
    }
    std::printf("%s: %s (prepare %.0f ms, query %.1f ms)\n", scan.name.c_str(), r.accepted ? "known place" : "unknown place",
                prep, r.retrieval_ms + r.verification_ms);
    for (std::size_t i = 0; i < k; ++i) {
      const PlaceMatch& m = r.matches[i];
      const Eigen::Vector3d t = m.T_match_query.translation();
      const Eigen::Vector3d ypr = m.T_match_query.linear().eulerAngles(2, 1, 0) * 180.0 / M_PI;
      std::printf("  %-12s score %.3f  inliers %3zu  t = (%.3f, %.3f, %.3f) m  ypr = (%.2f, %.2f, %.2f) deg%s\n",
                  db.name(m.scan).c_str(), m.score, m.inliers, t.x(), t.y(), t.z(), ypr.x(), ypr.y(), ypr.z(),
                  m.valid               ? ""
                  : m.rejected_distance ? "  (rejected: sensors farther apart than --max-distance)"
                  : m.rejected_ground   ? "  (rejected: ground-vehicle check)"
                  : m.rejected_conflict ? "  (rejected: points in the other scan's free space)"
                  : m.rejected_score    ? "  (rejected: scored too low to be aligned densely)"
                                        : "  (no transform)");
    }
    std::fflush(stdout);
  }
}

// --- eval ---

struct QueryRecord {
  std::size_t query = 0;
  bool has_db = false;
  double score = 0.0;  // best score (0 when nothing valid)
  std::size_t match = 0;
  bool valid = false;
  Pose T = Pose::Identity();
  double nearest_m = 1e9;  // planar distance to the nearest database scan
  double query_ms = 0.0;
  double query_cpu_ms = 0.0;  // process CPU time (all threads)
  std::vector<std::pair<std::size_t, double>> scores;  // all verified candidates
  PlaceMatch best;
};

std::string retrieval_name(PlaceRetrieval r) {
  switch (r) {
    case PlaceRetrieval::kTfidf: return "tfidf";
    case PlaceRetrieval::kFabmap: return "fabmap";
    default: return "tfidf-alphabet";
  }
}

double planar(const Pose& a, const Pose& b) { return (a.translation() - b.translation()).head<2>().norm(); }

void run_eval(const PlaceOptions& o) {
  // Scans: frames.txt order when present, else the sorted .bin/.pcd/.ply files.
  std::vector<std::string> files;
  const fs::path dir(o.inputs.at(0));
  if (fs::exists(dir / "frames.txt")) {
    auto list = io::read_file((dir / "frames.txt").string());
    if (!list.ok()) throw CliError(3, list.status().to_string());
    std::string s(list.value().begin(), list.value().end()), line;
    for (std::size_t i = 0; i <= s.size(); ++i) {
      if (i == s.size() || s[i] == '\n') {
        if (!line.empty()) files.push_back((dir / line).string());
        line.clear();
      } else if (s[i] != '\r') {
        line += s[i];
      }
    }
  } else {
    std::error_code ec;
    for (const auto& e : fs::directory_iterator(dir, ec)) {
      const auto ext = e.path().extension().string();
      if (ext == ".bin" || ext == ".pcd" || ext == ".ply" || ext == ".lex3dm") files.push_back(e.path().string());
    }
    if (ec) throw CliError(3, o.inputs[0] + ": " + ec.message());
    std::sort(files.begin(), files.end());
  }
  if (files.empty()) throw CliError(2, o.inputs[0] + ": no scans");
  // Checked before any work: no output is a scan, the poses, times or alphabet, nor another
  // output; all of them (the cache too, when made) are written together at the end.
  OutputSet outs;
  outs.inputs(files, "input");
  outs.input(o.poses, "--poses");
  outs.input(o.times, "--times");
  outs.input(o.alphabet, "--alphabet");
  const bool make_cache = !o.cache.empty() && !fs::exists(o.cache);
  if (make_cache) {
    outs.output(o.cache, "--cache");
    check_output_kind(o.cache, "--cache", "database");
  } else {
    outs.input(o.cache, "--cache");
  }
  outs.output(o.dump, "--dump");
  if (!o.png.empty()) {
    outs.output(o.png + "_confusion.png", "--png");
    outs.output(o.png + "_pr.png", "--png");
  }
  std::vector<Cloud> clouds;
  {
    // Point clouds and lex3d model files (decoded on the fly), one pose a scan.
    const PlaceInputs inputs(files, o.format, o.poses, o.model_alphabet);
    if (inputs.size() != files.size()) throw CliError(1, o.inputs[0] + ": a scan file holds more than one scan");
    for (std::size_t i = 0; i < inputs.size(); ++i) clouds.push_back(inputs.load(i));
  }
  std::vector<double> times(clouds.size());
  for (std::size_t i = 0; i < times.size(); ++i) times[i] = static_cast<double>(i);
  if (!o.times.empty()) {
    auto t = io::read_number_list(o.times);
    if (!t.ok()) throw CliError(2, t.status().to_string());
    if (t.value().size() != clouds.size()) throw CliError(1, o.times + ": one time a scan expected");
    times = t.value();
  }
  std::vector<std::string> names;
  for (const auto& f : files) names.push_back(stem(f));
  Stopwatch sw;
  Alphabet alphabet;
  std::vector<PlaceScan> cached;
  std::shared_ptr<const PlaceVocabulary> cached_vocabulary;
  if (!o.cache.empty() && !make_cache) {
    // The scans as a database stores them (a database of these scans, written by an earlier
    // eval with the same --cache): skips learning and feature extraction.
    PlaceDatabase c = read_db(o.cache);
    if (c.storage().descriptor != o.storage.descriptor)
      throw CliError(2, o.cache + ": its features are described with " + to_string(c.storage().descriptor) + ", not " +
                            to_string(o.storage.descriptor) + " (--descriptor)");
    if (c.size() != clouds.size()) throw CliError(2, o.cache + ": holds " + std::to_string(c.size()) + " scans, not " + std::to_string(clouds.size()));
    for (std::size_t i = 0; i < c.size(); ++i) {
      if (c.name(i) != names[i]) throw CliError(2, o.cache + ": scan " + std::to_string(i) + " is " + c.name(i));
      auto s = c.read_scan(i);
      if (!s.ok()) throw CliError(2, o.cache + ": " + s.status().to_string());
      cached.push_back(std::move(s).value());
    }
    alphabet = c.alphabet();
    cached_vocabulary = c.vocabulary();
  } else if (!o.alphabet.empty()) {
    alphabet = read_alphabet(o.alphabet);
  } else {
    alphabet = learn_on(clouds.size(), [&](std::size_t i) { return clouds[i]; }, o);
  }
  const double learn_ms = sw.lap_ms();
  double prep_ms = 0;
  std::vector<GravitySource> sources;
  const auto scans = cached.empty() ? describe_all(clouds.size(), [&](std::size_t i) { return clouds[i]; }, names,
                                                   alphabet, o.storage, &prep_ms, describing(o), &sources)
                                    : cached;
  std::size_t from_points = 0, from_none = 0, empty_descriptors = 0;
  for (const auto& s : scans) empty_descriptors += s.empty_descriptors;
  for (const GravitySource g : sources) {
    from_points += g == GravitySource::kPoints ? 1 : 0;
    from_none += g == GravitySource::kNone ? 1 : 0;
  }
  std::shared_ptr<const PlaceVocabulary> vocabulary = cached_vocabulary;
  if (!o.vocabulary.empty()) {
    vocabulary = read_db(o.vocabulary, false).vocabulary();
    if (vocabulary == nullptr) throw CliError(2, o.vocabulary + ": has no recognition vocabulary (--vocabulary)");
  } else if (vocabulary == nullptr && o.vocabulary_words > 0) {
    vocabulary = std::make_shared<const PlaceVocabulary>(learn_place_vocabulary(scans, o.vocabulary_words));
  }
  if (make_cache) {
    PlaceDatabase c(o.storage);
    c.set_alphabet(alphabet);
    if (vocabulary != nullptr) c.set_vocabulary(*vocabulary);
    for (const auto& s : scans) c.add(s);
    throw_if_error(io::write_file_atomic(outs.staged(o.cache), c.save()));
  }
  PlaceParams p = o.params;
  p.ground_vehicle = o.ground;
  // A revisit is a scan recorded within --radius: the recogniser is asked the same question.
  p.max_distance = o.max_distance >= 0.0 ? o.max_distance : o.radius;

  // Queries in time order against the scans at least min_gap seconds older.
  std::vector<std::size_t> order(scans.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return times[a] < times[b]; });
  PlaceDatabase db(o.storage);
  db.set_alphabet(alphabet);
  if (vocabulary != nullptr) db.set_vocabulary(*vocabulary);
  p.retrieval = retrieval_for(o, db);
  std::vector<std::size_t> db_to_scan;
  std::size_t next = 0;
  std::vector<QueryRecord> recs;
  std::size_t db_bytes = 0;
  ProgressBar bar("querying");
  for (std::size_t qi = 0; qi < order.size(); ++qi) {
    const std::size_t q = order[qi];
    while (next < order.size() && times[order[next]] <= times[q] - o.min_gap) {
      db_bytes += stored_bytes(scans[order[next]]);
      db.add(scans[order[next]]);
      db_to_scan.push_back(order[next]);
      ++next;
    }
    QueryRecord r;
    r.query = q;
    r.has_db = db.size() > 0;
    for (const auto j : db_to_scan) r.nearest_m = std::min(r.nearest_m, planar(clouds[q].T_world_cloud, clouds[j].T_world_cloud));
    if (r.has_db) {
      const std::clock_t c0 = std::clock();
      const auto res = db.query(scans[q], p);
      r.query_ms = res.retrieval_ms + res.verification_ms;
      r.query_cpu_ms = 1000.0 * static_cast<double>(std::clock() - c0) / CLOCKS_PER_SEC;
      if (const PlaceMatch* b = res.best(); b != nullptr && b->valid) {
        r.valid = true;
        r.score = b->score;
        r.match = db_to_scan[b->scan];
        r.T = b->T_match_query;
        r.best = *b;
      }
      for (const auto& m : res.matches) r.scores.emplace_back(db_to_scan[m.scan], m.valid ? m.score : 0.0);
      recs.push_back(r);
    }
    bar.update(static_cast<long>(qi + 1), static_cast<long>(order.size()), names[q]);
  }
  bar.finish();
  const double query_total_ms = sw.lap_ms();

  auto correct = [&](const QueryRecord& r, double radius) {
    return r.valid && planar(clouds[r.query].T_world_cloud, clouds[r.match].T_world_cloud) <= radius;
  };
  auto counts = [&](double thr, double radius, std::size_t& tp, std::size_t& fp, std::size_t& pos) {
    tp = fp = pos = 0;
    for (const auto& r : recs) {
      if (r.nearest_m <= radius) ++pos;
      if (!(r.valid && r.score >= thr)) continue;
      if (correct(r, radius)) ++tp;
      else ++fp;
    }
  };
  std::size_t tp = 0, fp = 0, pos = 0;
  counts(p.accept_score, o.radius, tp, fp, pos);
  // First stage: queries with a revisit within the radius that have one among their candidates.
  std::size_t retrieved_true = 0;
  for (const auto& r : recs) {
    if (!(r.nearest_m <= o.radius)) continue;
    for (const auto& sc : r.scores)
      if (planar(clouds[r.query].T_world_cloud, clouds[sc.first].T_world_cloud) <= o.radius) {
        ++retrieved_true;
        break;
      }
  }
  const double retrieval_recall = pos > 0 ? static_cast<double>(retrieved_true) / static_cast<double>(pos) : 0.0;
  const double precision = tp + fp > 0 ? static_cast<double>(tp) / static_cast<double>(tp + fp) : 1.0;
  const double recall = pos > 0 ? static_cast<double>(tp) / static_cast<double>(pos) : 0.0;
  // PR curve over thresholds at the distinct scores.
  std::vector<double> thr{1.01};
  for (const auto& r : recs)
    if (r.valid) thr.push_back(r.score);
  std::sort(thr.begin(), thr.end(), std::greater<double>());
  std::vector<std::array<double, 3>> curve;  // threshold, precision, recall
  double max_f1 = 0, recall_at_p1 = 0;
  for (const double t : thr) {
    std::size_t a = 0, b = 0, c = 0;
    counts(t, o.radius, a, b, c);
    const double pr = a + b > 0 ? static_cast<double>(a) / static_cast<double>(a + b) : 1.0;
    const double rc = c > 0 ? static_cast<double>(a) / static_cast<double>(c) : 0.0;
    curve.push_back({t, pr, rc});
    if (pr + rc > 0) max_f1 = std::max(max_f1, 2 * pr * rc / (pr + rc));
    if (b == 0) recall_at_p1 = std::max(recall_at_p1, rc);
  }
  // Pose errors of accepted true matches.
  std::vector<double> et, er;
  for (const auto& r : recs) {
    if (!(r.valid && r.score >= p.accept_score && correct(r, o.radius))) continue;
    const Pose truth = clouds[r.match].T_world_cloud.inverse() * clouds[r.query].T_world_cloud;
    const Pose d = truth.inverse() * r.T;
    et.push_back(d.translation().norm());
    er.push_back(Eigen::AngleAxisd(d.linear()).angle() * 180.0 / M_PI);
  }
  // Accepted matches whose transform is wrong (more than 1 m or 5 degrees off the ground
  // truth), whatever the distance between the scans: what a threshold on the score can
  // separate, unlike a far but correctly aligned scan.
  std::size_t wrong_pose = 0, right_pose = 0;
  for (const auto& r : recs) {
    if (!(r.valid && r.score >= p.accept_score)) continue;
    const Pose d = (clouds[r.match].T_world_cloud.inverse() * clouds[r.query].T_world_cloud).inverse() * r.T;
    if (d.translation().norm() > 1.0 || Eigen::AngleAxisd(d.linear()).angle() * 180.0 / M_PI > 5.0) ++wrong_pose;
    else ++right_pose;
  }
  auto median = [](std::vector<double> v) {
    if (v.empty()) return std::nan("");
    std::sort(v.begin(), v.end());
    return v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
  };
  std::vector<double> qms, qcpu;
  for (const auto& r : recs) {
    qms.push_back(r.query_ms);
    qcpu.push_back(r.query_cpu_ms);
  }
  double bytes_all = 0;
  for (const auto& s : scans) bytes_all += static_cast<double>(stored_bytes(s));
  const double kb_per_scan = bytes_all / 1024.0 / static_cast<double>(scans.size());

  // PNGs (--png): the precision-recall curve and the score matrix.
  if (!o.png.empty()) {
    EvalPictures e;
    const fs::path folder(o.inputs[0]);
    e.data_name = (folder.filename().empty() ? folder.parent_path() : folder).filename().string();
    e.method = "lex3d, " + retrieval_name(p.retrieval) + " retrieval";
    e.radius_m = o.radius;
    e.threshold = p.accept_score;
    e.min_gap_s = o.min_gap;
    e.set_scans(scans.size());
    for (const auto& r : recs) {
      for (std::size_t j = 0; j < scans.size(); ++j)
        if (times[j] <= times[r.query] - o.min_gap)
          e.in_database(r.query, j, planar(clouds[r.query].T_world_cloud, clouds[j].T_world_cloud) <= o.radius);
      for (const auto& [j, sc] : r.scores) e.set_score(r.query, j, sc);
      if (r.valid && r.score >= p.accept_score) e.accepted.push_back({r.query, r.match});
    }
    e.curve = curve;
    e.recall_at_precision_1 = recall_at_p1;
    e.precision = precision;
    e.recall = recall;
    e.positives = pos;
    const plot::Canvas pr = draw_precision_recall(e);
    throw_if_error(io::write_png_rgb(outs.staged(o.png + "_pr.png"), pr.width(), pr.height(), pr.rgb()));
    const plot::Canvas cm = draw_score_matrix(e);
    throw_if_error(io::write_png_rgb(outs.staged(o.png + "_confusion.png"), cm.width(), cm.height(), cm.rgb()));
  }

  std::vector<std::array<double, 3>> by_distance;  // radius, tp, positives
  for (const double rr : {1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0}) {
    std::size_t a = 0, b = 0, c = 0;
    counts(p.accept_score, rr, a, b, c);
    by_distance.push_back({rr, static_cast<double>(a), static_cast<double>(c)});
  }
  std::vector<std::array<double, 2>> fp_by_thr;
  for (int k = 0; k <= 12; ++k) {
    std::size_t a = 0, b = 0, c = 0;
    const double t = 0.05 * k;
    counts(t, o.radius, a, b, c);
    fp_by_thr.push_back({t, static_cast<double>(b)});
  }
  if (!o.dump.empty()) {
    // One line a query: query, planar distance to the nearest database scan, best match, its
    // planar distance, score, pose error (m, deg), query ms, then every verified candidate
    // as name:distance:score.
    std::string text;
    char buf[256];
    for (const auto& r : recs) {
      const Pose& Tq = clouds[r.query].T_world_cloud;
      double te = std::nan(""), re = std::nan(""), dist = std::nan(""), tf = std::nan(""), rf = std::nan("");
      if (r.valid) {
        const Pose truth = clouds[r.match].T_world_cloud.inverse() * Tq;
        const Pose d = truth.inverse() * r.T;
        te = d.translation().norm();
        re = Eigen::AngleAxisd(d.linear()).angle() * 180.0 / M_PI;
        const Pose d2 = truth.inverse() * r.best.T_feature;
        tf = d2.translation().norm();
        rf = Eigen::AngleAxisd(d2.linear()).angle() * 180.0 / M_PI;
        dist = planar(Tq, clouds[r.match].T_world_cloud);
      }
      const auto& a = r.best.dense_q;
      const auto& b = r.best.dense_m;
      std::snprintf(buf, sizeof buf, "%s %.2f %s %.2f %.4f %.3f %.2f %.1f | feat %.3f %.2f | rms %.3f used %zu | q %zu %zu %zu %zu | m %zu %zu %zu %zu | inl %zu %zu %zu %.3f %.3f |",
                    names[r.query].c_str(), r.nearest_m, r.valid ? names[r.match].c_str() : "-", dist, r.score, te, re,
                    r.query_ms, tf, rf, r.best.dense_rms_m, r.best.dense_used, a.points, a.visible, a.support, a.conflict,
                    b.points, b.visible, b.support, b.conflict, r.best.inliers, r.best.descriptor_inliers,
                    r.best.correspondences, r.best.score_query_in_match, r.best.score_match_in_query);
      text += buf;
      for (const auto& [j, sc] : r.scores) {
        std::snprintf(buf, sizeof buf, " %s:%.2f:%.4f", names[j].c_str(), planar(Tq, clouds[j].T_world_cloud), sc);
        text += buf;
      }
      text += "\n";
    }
    throw_if_error(io::write_file_atomic(outs.staged(o.dump), std::vector<std::uint8_t>(text.begin(), text.end())));
  }
  outs.commit();
  if (o.json) {
    Json j;
    j.begin_object().value("scans", scans.size()).value("queries", recs.size()).value("positives", pos);
    j.value("radius_m", o.radius).value("min_gap_s", o.min_gap).value("threshold", p.accept_score);
    j.value("max_distance_m", p.max_distance).value("max_conflict", p.max_conflict);
    j.value("gravity", o.gravity).value("gravity_from_points", from_points).value("gravity_none", from_none);
    j.value("true_positives", tp).value("false_positives", fp).value("precision", precision).value("recall", recall);
    j.value("max_f1", max_f1).value("recall_at_precision_1", recall_at_p1);
    j.value("accepted_right_pose", right_pose).value("accepted_wrong_pose", wrong_pose);
    j.value("median_translation_error_m", median(et)).value("median_rotation_error_deg", median(er));
    j.value("median_query_ms", median(qms)).value("median_query_cpu_ms", median(qcpu)).value("kb_per_scan", kb_per_scan);
    j.value("alphabet_words", alphabet.size()).value("learn_ms", learn_ms).value("prepare_ms", prep_ms);
    j.value("query_total_ms", query_total_ms).value("descriptor", to_string(o.storage.descriptor));
    j.value("empty_descriptors", empty_descriptors).value("retrieval_recall", retrieval_recall);
    j.begin_array("recall_by_distance");
    for (const auto& d : by_distance) j.begin_object().value("radius_m", d[0]).value("tp", d[1]).value("positives", d[2]).end_object();
    j.end_array().begin_array("false_positives_by_threshold");
    for (const auto& f : fp_by_thr) j.begin_object().value("threshold", f[0]).value("fp", f[1]).end_object();
    j.end_array().end_object();
    std::cout << j.str() << "\n";
    return;
  }
  std::printf("scans %zu, queries with a database %zu, with a true revisit within %.1f m: %zu\n", scans.size(), recs.size(),
              o.radius, pos);
  std::printf("descriptor %s", to_string(o.storage.descriptor));
  if (cached.empty() && !scans.empty())
    std::printf(", scans described in %.1f ms each (learning excluded; %zu features with an empty descriptor)",
                prep_ms / static_cast<double>(scans.size()), empty_descriptors);
  std::printf("\n");
  if (o.gravity == "points" || o.gravity == "none")
    std::printf("up direction: --gravity %s (poses used as ground truth only): %zu scans from their points, %zu none%s\n",
                o.gravity.c_str(), from_points, from_none, cached.empty() ? "" : " (scans from --cache: as it was made)");
  if (p.max_distance > 0.0) std::printf("transforms limited to sensors within %.1f m (--max-distance)\n", p.max_distance);
  if (p.max_conflict < 1.0) std::printf("transforms with more than %.3f of the points in free space rejected (--max-conflict)\n", p.max_conflict);
  std::printf("threshold %.2f: TP %zu FP %zu  precision %.3f recall %.3f\n", p.accept_score, tp, fp, precision, recall);
  std::printf("max F1 %.3f, recall at 100%% precision %.3f\n", max_f1, recall_at_p1);
  std::printf("first stage (%s): a true revisit among the %d candidates for %zu of %zu queries (recall %.3f)\n",
              retrieval_name(p.retrieval).c_str(), p.top_k, retrieved_true, pos, retrieval_recall);
  std::printf("accepted: %zu with the right transform (within 1 m, 5 deg), %zu with a wrong one, any distance\n",
              right_pose, wrong_pose);
  std::printf("accepted true matches: median error %.3f m, %.2f deg (%zu)\n", median(et), median(er), et.size());
  std::printf("query (excluding feature extraction): median %.1f ms (CPU %.1f ms, %d threads); database %.1f KB a scan; alphabet %zu words\n",
              median(qms), median(qcpu), p.threads, kb_per_scan, alphabet.size());
  std::printf("recall against distance:");
  for (const auto& d : by_distance) std::printf("  %.0fm %g/%g", d[0], d[1], d[2]);
  std::printf("\nfalse positives against threshold:");
  for (const auto& f : fp_by_thr) std::printf("  %.2f:%g", f[0], f[1]);
  std::printf("\n");
  if (!o.png.empty()) std::printf("wrote %s_pr.png %s_confusion.png\n", o.png.c_str(), o.png.c_str());
}

void add_common(CLI::App* sub, PlaceOptions& o) {
  sub->add_option("--descriptor", o.descriptor,
                  "Descriptor of the stored features: patch (range-image patch) or vdlsd (collier2012's VD-LSD); "
                  "build and eval: default patch; query and add: must be the database's")
      ->check(CLI::IsMember({"patch", "vdlsd"}));
  sub->add_option("--format", o.format, "Input format: auto, kitti, binxyz, pcd, ply, xyz, uos");
  sub->add_option("--model-alphabet", o.model_alphabet,
                  "Alphabet file of .lex3dm inputs that reference one (inputs may be lex3d model .lex3dm and "
                  "sequence .lex3dq files, decoded on the fly)");
  sub->add_option("--poses", o.poses, "World <- sensor pose of each scan (KITTI poses.txt layout); gives upright features");
  sub->add_flag("--json", o.json, "Print one JSON object");
  sub->add_option("--gravity", o.gravity,
                  "Up direction of the scans: auto (the pose when given, else estimated from the points), poses, "
                  "points (estimated, poses ignored for it), none (the sensor's spin axis)")
      ->check(CLI::IsMember({"auto", "poses", "points", "none"}));
}

}  // namespace

void register_place(CLI::App& app) {
  auto o = std::make_shared<PlaceOptions>();
  CLI::App* sub = app.add_subcommand("place", "Place recognition from word instances");
  sub->require_subcommand(1);

  CLI::App* build = sub->add_subcommand("build", "Build a place database from scans");
  build->footer("Examples:\n  lex3d place build map.lex3dp drive/*.bin --poses poses.txt\n  lex3d place build map.lex3dp drive/*.lex3dm --vocabulary-words 4096");
  build->add_option("db", o->db, "Database file to write")->required();
  build->add_option("scans", o->inputs, "Point clouds")->required();
  build->add_option("--alphabet", o->alphabet, "Use this alphabet (else one is learned on --learn-scans of the inputs)");
  build->add_option("--learn-scans", o->learn_scans, "Scans (evenly spaced) the alphabet is learned on")->check(CLI::Range(1, 100000));
  build->add_option("--iterations", o->iterations, "Candidate words drawn at most when learning")->check(CLI::Range(1, 1000000));
  build->add_option("--descriptor-bits", o->storage.descriptor_bits, "Bits a stored descriptor value: 4 or 8");
  auto add_vocabulary = [&](CLI::App* s) {
    auto* from = s->add_option("--vocabulary", o->vocabulary, "Use the recognition vocabulary of this place database");
    s->add_option("--vocabulary-words", o->vocabulary_words,
                  "Learn a recognition vocabulary of at most N leaf words on the scans' place features")
        ->check(CLI::Range(2, 1 << 20))
        ->excludes(from);
    s->add_option("--vocabulary-scans", o->vocabulary_scans, "Scans (evenly spaced) the vocabulary is learned on at most")
        ->check(CLI::Range(1, 10000000));
  };
  add_vocabulary(build);
  add_common(build, *o);
  add_threads_option(*build, o->params.threads, "Worker threads describing the scans and learning the alphabet");
  build->callback([o] {
    o->storage.descriptor = parse_descriptor(o->descriptor);
    run_build(*o);
  });

  CLI::App* add = sub->add_subcommand("add", "Add scans to a place database");
  add->footer("Examples:\n  lex3d place add map.lex3dp today/*.bin --poses today_poses.txt");
  add->add_option("db", o->db, "Database file (appended to in place; a format 1.0 file is rewritten as 2.0)")->required();
  add->add_option("scans", o->inputs, "Point clouds")->required();
  add_common(add, *o);
  add_threads_option(*add, o->params.threads, "Worker threads describing the scans");
  add->callback([o] { run_add(*o); });

  CLI::App* up = sub->add_subcommand("upgrade", "Rewrite a place database in the current format (2.0), compacted");
  up->footer("Examples:\n  lex3d place upgrade old.lex3dp new.lex3dp");
  up->add_option("old", o->db, "Database file to read (format 1.0 or 2.x)")->required();
  up->add_option("new", o->inputs, "Database file to write")->required()->expected(1);
  up->add_flag("--json", o->json, "Print one JSON object");
  up->callback([o] { run_upgrade(*o); });

  auto add_match = [&](CLI::App* s) {
    s->add_option("--threshold", o->params.accept_score, "Acceptance threshold on the score")->check(CLI::Range(0.0, 1.0));
    s->add_option("--candidates", o->params.top_k, "Scans retrieved by tf-idf and verified")->check(CLI::Range(1, 1000000));
    s->add_flag("--ground-vehicle", o->ground, "Reject large roll/pitch or vertical offsets");
    s->add_option("--max-distance", o->max_distance,
                  "Reject transforms that put the two sensors farther apart than this, m (0 = any distance; "
                  "default: any for a query, --radius for place eval)")
        ->check(CLI::Range(0.0, 1e4));
    s->add_option("--max-conflict", o->params.max_conflict,
                  "Reject a densely aligned transform when more than this share of either scan's visible points lies "
                  "in the other's free space (1 = off)")
        ->check(CLI::Range(1e-6, 1.0));
    s->add_option("--dense-iterations", o->params.dense_iterations, "Dense alignment iterations (0 = none)")->check(CLI::Range(0, 100));
    s->add_option("--dense-points", o->params.dense_points, "Dense points a scan at most")->check(CLI::Range(16, 1000000));
    s->add_option("--dense-candidates", o->params.dense_candidates, "Candidates aligned densely")->check(CLI::Range(1, 1000000));
    s->add_option("--dense-hypotheses", o->params.dense_hypotheses,
                  "Transforms of a candidate aligned densely in turn while the aligned one fails the free-space or distance check")
        ->check(CLI::Range(1, 100));
    s->add_option("--dense-score-ratio", o->params.dense_score_ratio,
                  "Align a transform densely only when its feature-stage score reaches this share of --threshold")
        ->check(CLI::Range(0.0, 1.0));
    s->add_option("--more-candidates", o->params.more_candidates,
                  "Further candidates verified when none of the first --candidates is accepted (0 = none)")
        ->check(CLI::Range(0, 1000000));
    s->add_option("--surface-yaws", o->params.surface_yaws, "Yaw candidates of the surface hypotheses (0 = none)")->check(CLI::Range(0, 36));
    s->add_option("--gravity-pairs", o->params.gravity_pairs, "Query feature pairs tried as upright 2-point hypotheses")->check(CLI::Range(0, 100000));
    s->add_option("--validation-points", o->params.validation_points, "Validation points a scan (steder2010: 100)")->check(CLI::Range(1, 4096));
    add_threads_option(*s, o->params.threads, "Worker threads describing the scans and verifying a query's candidates");
    s->add_option("--retrieval", o->retrieval,
                  "First stage: tfidf-alphabet (compression alphabet), tfidf or fabmap (recognition vocabulary); "
                  "default: tfidf-alphabet")
        ->check(CLI::IsMember({"default", "tfidf-alphabet", "tfidf", "fabmap"}));
  };
  CLI::App* query = sub->add_subcommand("query", "Find the place of each scan in a database (one database load)");
  query->footer("Examples:\n  lex3d place query map.lex3dp scan.bin --json\n  lex3d place query map.lex3dp a.bin b.bin --gravity points --max-distance 8");
  query->add_option("db", o->db, "Database file")->required();
  query->add_option("scans", o->inputs, "Query point clouds (or .lex3dm / .lex3dq files)")->required();
  query->add_option("--top", o->top, "Matches printed")->check(CLI::Range(1, 1000000));
  query->add_option("--list-retrieved", o->list_retrieved, "With --json: the first stage's best N scans, in order (\"retrieved\")")
      ->check(CLI::Range(1, 1000000));
  add_match(query);
  add_common(query, *o);
  query->get_option("--json")->description("Print one JSON object a scan (JSON Lines)");
  query->callback([o] { run_query(*o); });

  CLI::App* ev = sub->add_subcommand("eval", "Evaluate place recognition on a sequence with poses");
  ev->footer("Examples:\n  lex3d place eval balm/ --poses balm/poses.txt --times balm/times.txt --min-gap 20 --radius 8 --png balm_eval");
  ev->add_option("dir", o->inputs, "Folder of scans (frames.txt order when present)")->required()->expected(1);
  ev->add_option("--times", o->times, "Time of each scan, seconds (default: 1 s apart)");
  ev->add_option("--min-gap", o->min_gap, "A query's database holds the scans at least this much older, s")->check(CLI::Range(0.0, 1e9));
  ev->add_option("--radius", o->radius, "A match is true within this planar distance, m")->check(CLI::Range(0.0, 1e6));
  ev->add_option("--alphabet", o->alphabet, "Use this alphabet (else one is learned on --learn-scans of the scans)");
  ev->add_option("--learn-scans", o->learn_scans, "Scans (evenly spaced) the alphabet is learned on")->check(CLI::Range(1, 100000));
  ev->add_option("--iterations", o->iterations, "Candidate words drawn at most when learning")->check(CLI::Range(1, 1000000));
  ev->add_option("--cache", o->cache, "Place database of the scans: read when it exists (no learning, no feature extraction), else written");
  ev->add_option("--dump", o->dump, "Write one line a query (best match, distances, scores, pose error) to this file");
  ev->add_option("--png", o->png,
                 "Draw the precision-recall curve (PREFIX_pr.png) and the score matrix (PREFIX_confusion.png); "
                 "default: no pictures")
      ->type_name("PREFIX");
  add_vocabulary(ev);
  add_match(ev);
  add_common(ev, *o);
  ev->get_option("--poses")->required();
  ev->callback([o] {
    o->storage.descriptor = parse_descriptor(o->descriptor);
    run_eval(*o);
  });
}

}  // namespace lex3d::cli
