#include "cli_common.hpp"

#include "lex3d/codec/codec.hpp"
#include "lex3d/io/rosbag.hpp"
#include "lex3d/lex3d.hpp"
#include "lex3d/io/sensor_log.hpp"

#include <CLI/CLI.hpp>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <map>
#include <mutex>
#include <optional>
#include <sstream>
#include <sys/stat.h>
#include <thread>
#include <unistd.h>

namespace lex3d::cli {

void throw_if_error(const Status& status) {
  if (!status.ok()) throw CliError(exit_code_for(status.code()), status.to_string());
}

io::Format parse_format_option(const std::string& name) {
  const auto f = io::parse_format(name);
  if (!f)
    throw CliError(1, "unknown --format '" + name + "' (expected auto, kitti, binxyz, pcd, ply, xyz, uos or las)");
  return *f;
}

io::ReadResult load_cloud(const std::string& path, io::Format format) {
  io::ReadOptions opt;
  opt.format = format;
  return load_cloud(path, opt);
}

io::ReadOptions read_options(io::Format format, const std::string& metadata, const std::string& sensor_model) {
  io::ReadOptions opt;
  opt.format = format;
  opt.metadata_path = metadata;
  opt.sensor_model = sensor_model;
  const std::vector<std::string> models = io::velodyne_models();
  if (!sensor_model.empty() && std::find(models.begin(), models.end(), sensor_model) == models.end()) {
    std::string list;
    for (const std::string& m : models) list += (list.empty() ? "" : ", ") + m;
    throw CliError(1, "unknown --sensor-model '" + sensor_model + "' (expected one of " + list + ")");
  }
  return opt;
}

residual::SensorProfile read_sensor_profile(const std::string& path) {
  check_input_file(path);
  auto bytes = io::read_file(path, 16ULL << 20);  // the largest vendor tables are a few hundred KB
  if (!bytes.ok()) throw CliError(bytes.status().code() == ErrorCode::kOutOfMemory ? 4 : 2, bytes.status().to_string());
  const std::vector<std::uint8_t>& b = bytes.value();
  auto profile = residual::parse_sensor_profile(std::string_view(reinterpret_cast<const char*>(b.data()), b.size()), path);
  if (!profile.ok()) throw CliError(2, profile.status().to_string());
  return std::move(profile).value();
}

io::ReadResult load_cloud(const std::string& path, const io::ReadOptions& opt) {
  set_current_file(path);
  check_input_file(path);
  auto r = io::read_cloud(path, opt);
  // Any input that cannot be read (missing, unreadable, malformed) is bad input: exit 2;
  // one too large for the memory there is: exit 4.
  if (!r.ok()) throw CliError(r.status().code() == ErrorCode::kOutOfMemory ? 4 : 2, r.status().to_string());
  const io::ReadResult& res = r.value();
  // A KITTI pose list (12 numbers a line, each a rotation and a translation) also parses as
  // a 12-column text cloud: refuse it rather than report its translations as points.
  if (res.format == io::Format::kXyz && opt.format == io::Format::kAuto && io::read_pose_list(path).ok())
    throw CliError(2, path + ": a pose list (12 numbers a line: a rotation and a translation), not a point cloud; "
                             "give it with --poses, or --format xyz to read it as points");
  // never drop silently: what the file holds that lex3d does not keep, and what the reader noticed
  if (!res.dropped_fields.empty()) {
    std::string list;
    for (const auto& f : res.dropped_fields) list += (list.empty() ? "" : ", ") + f;
    std::fprintf(stderr, "note: %s: fields not kept (lex3d keeps x y z, intensity, ring, time, colour and single integer and float fields): %s\n", path.c_str(), list.c_str());
  }
  for (const auto& n : res.notes) std::fprintf(stderr, "note: %s: %s\n", path.c_str(), n.c_str());
  return std::move(r).value();
}

void check_output_path(const std::string& output, const std::vector<std::string>& inputs) {
  OutputSet files;
  files.inputs(inputs, "input");
  files.output(output, "output");
}

namespace {

namespace fs = std::filesystem;

/// The directory entry a path names: its canonical directory (symbolic links resolved) and
/// its own name, so `x`, `./x` and `dir/../x` agree. A path that is itself a symbolic link is
/// followed (writing through it would reach the target).
std::string entry_of(const std::string& path) {
  std::error_code ec;
  fs::path p = fs::absolute(path, ec);
  if (ec) p = path;
  const fs::path resolved = fs::weakly_canonical(p, ec);
  if (!ec) p = resolved;
  return p.lexically_normal().string();
}

/// True when both paths exist and are one file (same device and inode: hard links too).
bool same_existing_file(const std::string& a, const std::string& b) {
  struct stat sa {}, sb {};
  if (::stat(a.c_str(), &sa) != 0 || ::stat(b.c_str(), &sb) != 0) return false;
  return sa.st_dev == sb.st_dev && sa.st_ino == sb.st_ino;
}

std::atomic<unsigned> g_staged_counter{0};

std::string g_current_file;

}  // namespace

void set_current_file(const std::string& path) { g_current_file = path; }
const std::string& current_file() { return g_current_file; }

OutputSet::~OutputSet() {
  for (const auto& [tmp, final_path] : staged_) {
    (void)final_path;
    std::error_code ec;
    fs::remove(tmp, ec);
  }
}

void check_input_file(const std::string& path) {
  struct stat st {};
  if (path.empty() || ::stat(path.c_str(), &st) != 0) return;  // a missing file is reported by its reader
  if (S_ISREG(st.st_mode) || S_ISDIR(st.st_mode)) return;
  const char* what = S_ISFIFO(st.st_mode) ? "a pipe or FIFO" : S_ISCHR(st.st_mode) || S_ISBLK(st.st_mode) ? "a device" : "a socket";
  throw CliError(2, path + ": not a regular file (" + what +
                        "); lex3d reads inputs from regular files only: save the stream to a file first");
}

void OutputSet::input(const std::string& path, const std::string& option) {
  if (path.empty()) return;
  check_input_file(path);
  files_.push_back({path, option, false});
}

void OutputSet::inputs(const std::vector<std::string>& paths, const std::string& option) {
  for (const auto& p : paths) input(p, option);
}

void OutputSet::output(const std::string& path, const std::string& option) {
  if (path.empty()) return;
  const std::string entry = entry_of(path);
  for (const Entry& f : files_) {
    if (!same_existing_file(path, f.path) && entry != entry_of(f.path)) continue;
    if (f.is_output)
      throw CliError(1, option + " " + path + " and " + f.option + " " + f.path +
                            " are the same file: give each output its own name");
    throw CliError(1, "refusing to overwrite input file " + f.path + " (" + f.option + ") with " + option + " " + path);
  }
  // Where it goes, checked before any work is done.
  std::error_code ec;
  if (fs::is_directory(path, ec)) throw CliError(3, path + ": " + option + " names a directory, not a file");
  const fs::path dir = fs::path(entry).parent_path();
  if (!fs::is_directory(dir, ec))
    throw CliError(3, path + ": cannot write " + option + ": directory " + dir.string() + " does not exist");
  if (::access(dir.c_str(), W_OK | X_OK) != 0)
    throw CliError(3, path + ": cannot write " + option + ": directory " + dir.string() + " is not writable");
  files_.push_back({path, option, true});
}

std::string OutputSet::staged(const std::string& path) {
  const fs::path p(path);
  const std::string name = ".lex3d-" + std::to_string(::getpid()) + "-" + std::to_string(g_staged_counter.fetch_add(1)) +
                           "-" + p.filename().string();
  const std::string tmp = (p.parent_path() / name).string();
  staged_.emplace_back(tmp, path);
  return tmp;
}

void OutputSet::commit() {
  for (std::size_t i = 0; i < staged_.size(); ++i) {
    const auto& [tmp, final_path] = staged_[i];
    std::error_code ec;
    if (!fs::exists(tmp, ec)) continue;  // nothing was written for it
    fs::rename(tmp, final_path, ec);
    if (ec) {
      std::string done;
      for (const auto& w : written_) done += (done.empty() ? "" : ", ") + w;
      throw CliError(3, final_path + ": cannot rename the finished file into place: " + ec.message() +
                            (done.empty() ? std::string(" (nothing written)") : " (already written: " + done + ")"));
    }
    written_.push_back(final_path);
  }
  staged_.clear();
}

namespace {

/// Extensions of point-cloud files (what write_cloud picks a format from).
bool is_cloud_extension(std::string ext) {
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return ext == ".pcd" || ext == ".ply" || ext == ".bin" || ext == ".xyz" || ext == ".txt" || ext == ".las" ||
         ext == ".laz" || ext == ".asc" || ext == ".csv" || ext == ".3d" || ext == ".pcap" || ext == ".bag";
}

const char* extension_of_kind(const std::string& kind) {
  if (kind == "model") return ".lex3dm";
  if (kind == "alphabet") return ".lex3da";
  if (kind == "sequence") return ".lex3dq";
  if (kind == "database") return ".lex3dp";
  return "";
}

}  // namespace

int all_cores() {
  const unsigned n = std::thread::hardware_concurrency();  // 0 where unknown
  return static_cast<int>(std::clamp(n, 1U, 64U));
}

void add_threads_option(CLI::App& app, int& threads, const std::string& what) {
  threads = all_cores();
  app.add_option_function<int>(
         "--threads", [&threads](const int& n) { threads = n == 0 ? all_cores() : n; },
         what + " (0 = every core, the default; the output does not depend on it)")
      ->check(CLI::Range(0, 64));
}

std::string lower_extension(const std::string& path) {
  std::string ext = fs::path(path).extension().string();
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return ext;
}

std::shared_ptr<const codec::SequenceData> read_sequence(const std::string& path) {
  auto bytes = io::read_file(path);
  if (!bytes.ok()) throw CliError(3, bytes.status().to_string());
  auto seq = codec::decode_sequence(bytes.value());
  if (!seq.ok()) throw CliError(2, path + ": " + seq.status().to_string());
  return std::make_shared<const codec::SequenceData>(std::move(seq).value());
}

void check_output_kind(const std::string& path, const std::string& option, const std::string& kind) {
  if (path.empty()) return;
  const std::string ext = lower_extension(path);
  const bool lex3d_ext = ext == ".lex3dm" || ext == ".lex3da" || ext == ".lex3dq" || ext == ".lex3dp";
  if (kind == "cloud") {
    if (lex3d_ext)
      throw CliError(1, option + " " + path + ": a point cloud is written here, but " + ext +
                            " is a lex3d file extension (give .pcd, .ply, .bin, .xyz, .las or .bag)");
    return;
  }
  if (is_cloud_extension(ext) || ext == ".bt" || ext == ".png" || (lex3d_ext && ext != extension_of_kind(kind)))
    throw CliError(1, option + " " + path + ": a lex3d " + kind + " file is written here, but " + ext +
                          " names another kind of file (use " + extension_of_kind(kind) + ")");
}

std::string lex3d_file_kind(const std::vector<std::uint8_t>& bytes) {
  if (bytes.size() < 8) return "";
  const std::string magic(bytes.begin(), bytes.begin() + 8);
  if (magic == "LEX3DMDL") return "model";
  if (magic == "LEX3DALP") return "alphabet";
  if (magic == "LEX3DSEQ") return "sequence";
  if (magic == "LEX3DPDB") return "database";
  return "";
}

std::string ScanLoader::stem(std::size_t i) const {
  const Entry& e = entries_.at(i);
  if (!e.stem.empty()) return e.stem;
  std::string s = std::filesystem::path(e.path).stem().string();
  if (e.scans) s += "_turn" + std::to_string(e.turn);
  return s;
}

/// A file's scans (a raw log's turns, a bag topic's scans) for ScanLoader::load, read from
/// the file as they are asked for (the file is never held whole). Scans come in about their
/// order, two at once with two threads: a scan read on the way to another, up to two before
/// it, is held for its caller; one asked for behind the reader opens the file again.
class ScanLoader::Turns {
 public:
  /// The next scan of an open reader (std::nullopt after the last); throws CliError.
  using Next = std::function<std::optional<Cloud>()>;
  /// Opens the file again; throws CliError.
  using Open = std::function<Next()>;
  Turns(std::string path, Open open) : path_(std::move(path)), open_(std::move(open)) {}

  Cloud turn(std::size_t k) {
    const std::lock_guard<std::mutex> lock(mutex_);
    if (const auto it = held_.find(k); it != held_.end()) {
      Cloud c = std::move(it->second);
      held_.erase(it);
      return c;
    }
    if (!next_fn_ || k < next_) {
      next_fn_ = open_();
      next_ = 0;
    }
    for (;;) {
      std::optional<Cloud> c = next_fn_();
      if (!c) throw CliError(2, path_ + ": scan " + std::to_string(k) + " is no longer in the file");
      const std::size_t at = next_++;
      if (at == k) return std::move(*c);
      if (at + 2 >= k) held_[at] = std::move(*c);
    }
  }

 private:
  std::string path_;
  Open open_;
  std::mutex mutex_;
  Next next_fn_;
  std::size_t next_ = 0;  // the scan next_fn_ gives next
  std::map<std::size_t, Cloud> held_;
};

namespace {

[[noreturn]] void throw_read_error(const Status& s) {
  throw CliError(s.code() == ErrorCode::kOutOfMemory ? 4 : exit_code_for(s.code()) == 1 ? 1 : 2, s.to_string());
}

std::shared_ptr<io::SensorLogReader> open_log(const std::string& path, const io::ReadOptions& options) {
  auto r = io::SensorLogReader::open(path, options);
  if (!r.ok()) throw_read_error(r.status());
  return std::shared_ptr<io::SensorLogReader>(std::move(r).value());
}

std::shared_ptr<io::BagReader> open_bag_reader(const std::string& path, const io::ReadOptions& options) {
  auto r = io::BagReader::open(path, options.bag_topic, options);
  if (!r.ok()) throw_read_error(r.status());
  return std::shared_ptr<io::BagReader>(std::move(r).value());
}

}  // namespace

ScanLoader::ScanLoader(std::vector<std::string> paths, io::Format format, const std::string& poses_path,
                       bool points_in_world)
    : ScanLoader(paths, read_options(format, "", ""), poses_path, points_in_world) {}

ScanLoader::ScanLoader(const std::vector<std::string>& paths, const io::ReadOptions& options,
                       const std::string& poses_path, bool points_in_world)
    : options_(options), points_in_world_(points_in_world) {
  for (const auto& path : paths) {
    check_input_file(path);
    const bool log = options.format == io::Format::kPcap || (options.format == io::Format::kAuto && io::is_sensor_log(path));
    if (!log && options.format == io::Format::kAuto && io::is_rosbag(path)) {
      add_bag(path, options);
      continue;
    }
    if (!log && options.format == io::Format::kAuto && lower_extension(path) == ".lex3dq") {
      add_sequence(path);
      continue;
    }
    if (!log) {
      entries_.push_back({path, path, 0, "", nullptr, nullptr});
      continue;
    }
    // One pass for each turn's frame id and capture time (the turns' names) and every error
    // the capture holds, before any scan is coded; then turn by turn as they are loaded.
    std::vector<std::uint64_t> ids, captured;
    {
      const auto reader = open_log(path, options);
      for (;;) {
        auto t = reader->next();
        if (!t.ok()) throw_read_error(t.status());
        if (!t.value()) break;
        ids.push_back(t.value()->frame_id);
        captured.push_back(t.value()->captured_ns);
      }
    }
    const auto turns = std::make_shared<Turns>(path, [path, options]() -> Turns::Next {
      return [reader = open_log(path, options)]() -> std::optional<Cloud> {
        auto t = reader->next();
        if (!t.ok()) throw_read_error(t.status());
        if (!t.value()) return std::nullopt;
        return std::move(t.value()->cloud);
      };
    });
    const std::string stem = std::filesystem::path(path).stem().string();
    for (std::size_t k = 0; k < ids.size(); ++k) {
      // (a turn whose capture time is known is named with it, as a bag's message with its
      // stamp: a bag written from the scans is stamped with it)
      std::string name = path + " turn " + std::to_string(k) + " (frame " + std::to_string(ids[k]), scan_stem;
      if (k < captured.size() && captured[k] > 0) {
        const std::string stamp = stamp_text(captured[k]);
        name += ", captured " + stamp;
        scan_stem = stem + "_turn" + std::to_string(k) + "_" + stamp;
      }
      entries_.push_back({path, name + ")", k, scan_stem, turns, nullptr});
    }
  }
  if (points_in_world && poses_path.empty())
    throw CliError(1, "--input-frame world needs --poses: the sensor pose of each scan in that frame");
  if (poses_path.empty()) return;
  poses_ = read_scan_poses(poses_path, entries_.size());
}

void ScanLoader::add_sequence(const std::string& path) {
  set_current_file(path);
  const auto shared = read_sequence(path);
  const std::string stem = std::filesystem::path(path).stem().string();
  for (std::size_t k = 0; k < shared->model_files.size(); ++k) {
    // (its stored name, the scan's own: a bag written from the scans is stamped from it)
    char number[32];
    std::snprintf(number, sizeof number, "_%03zu", k);
    const bool named = k < shared->names.size() && !shared->names[k].empty();
    entries_.push_back({path, path + " " + (named ? shared->names[k] : "scan " + std::to_string(k)), k,
                        named ? shared->names[k] : stem + number, nullptr, shared});
  }
}

void ScanLoader::add_bag(const std::string& path, const io::ReadOptions& options) {
  set_current_file(path);
  // One pass for each scan's stamp (its name) and what the topic drops, before any scan is
  // coded; then scan by scan as they are loaded.
  std::vector<std::pair<std::uint32_t, std::uint32_t>> stamps;
  io::BagScans bag;
  {
    const auto reader = open_bag_reader(path, options);
    for (;;) {
      auto s = reader->next();
      if (!s.ok()) throw_read_error(s.status());
      if (!s.value()) break;
      stamps.emplace_back(s.value()->stamp_sec, s.value()->stamp_nsec);
    }
    bag = reader->summary();
  }
  // never drop silently: the fields not kept and what the reader noticed
  if (!bag.dropped_fields.empty()) {
    std::string list;
    for (const auto& f : bag.dropped_fields) list += (list.empty() ? "" : ", ") + f;
    std::fprintf(stderr, "note: %s: fields not kept (lex3d keeps x y z, intensity, ring, time, colour and single integer and float fields): %s\n",
                 path.c_str(), list.c_str());
  }
  for (const auto& n : bag.notes) std::fprintf(stderr, "note: %s: %s\n", path.c_str(), n.c_str());
  if (bag.non_finite_dropped > 0)
    std::fprintf(stderr, "note: %s: %zu points with a NaN or infinite coordinate dropped\n", path.c_str(), bag.non_finite_dropped);
  if (bag.incomplete_frames > 0)
    std::fprintf(stderr, "note: %s: %zu incomplete frame(s) dropped\n", path.c_str(), bag.incomplete_frames);
  const auto scans = std::make_shared<Turns>(path, [path, options]() -> Turns::Next {
    return [reader = open_bag_reader(path, options)]() -> std::optional<Cloud> {
      auto s = reader->next();
      if (!s.ok()) throw_read_error(s.status());
      if (!s.value()) return std::nullopt;
      return std::move(s.value()->cloud);
    };
  });
  const std::string stem = std::filesystem::path(path).stem().string();
  for (std::size_t k = 0; k < stamps.size(); ++k) {
    const std::string stamp = stamp_text(stamps[k].first, stamps[k].second);
    const char* what = bag.type == "sensor_msgs/PointCloud2" ? " message " : " frame ";
    entries_.push_back({path, path + " " + bag.topic + what + std::to_string(k) + " (stamp " + stamp + ")", k,
                        stem + "_" + stamp, scans, nullptr});
  }
}

std::vector<Pose> read_scan_poses(const std::string& path, std::size_t scans) {
  auto poses = io::read_pose_list(path);
  if (!poses.ok()) throw CliError(2, poses.status().to_string());
  if (poses.value().size() != scans)
    throw CliError(1, path + " has " + std::to_string(poses.value().size()) + " poses for " + std::to_string(scans) +
                          " scans (one pose a scan, in order)");
  return std::move(poses).value();
}

Cloud ScanLoader::load(std::size_t i) const {
  const Entry& e = entries_.at(i);
  Cloud cloud;
  if (e.sequence) {
    auto d = decompress(e.sequence->model_files[e.turn], &e.sequence->alphabet_file);
    if (!d.ok()) throw CliError(exit_code_for(d.status().code()), e.name + ": " + d.status().to_string());
    cloud = std::move(d.value().cloud);
  } else {
    cloud = e.scans ? e.scans->turn(e.turn) : load_cloud(e.path, options_).cloud;
  }
  set_current_file(e.name);
  if (!poses_.empty()) {
    if (points_in_world_) {
      cloud.T_cloud_sensor = poses_[i];
      cloud.T_world_cloud = Pose::Identity();
    } else {
      cloud.T_world_cloud = poses_[i];
    }
    cloud.has_world_pose = true;
  }
  return cloud;
}

std::array<std::uint8_t, 3> word_color(std::uint32_t word) {
  // Golden-angle hues at full saturation: neighbouring ids get distant colours.
  const double h = std::fmod(static_cast<double>(word) * 137.50776405, 360.0) / 60.0;
  const double x = 1.0 - std::abs(std::fmod(h, 2.0) - 1.0);
  double r = 0, g = 0, b = 0;
  switch (static_cast<int>(h)) {
    case 0: r = 1; g = x; break;
    case 1: r = x; g = 1; break;
    case 2: g = 1; b = x; break;
    case 3: g = x; b = 1; break;
    case 4: r = x; b = 1; break;
    default: r = 1; b = x; break;
  }
  const double v = (word % 3 == 0) ? 1.0 : (word % 3 == 1 ? 0.8 : 0.6);
  return {static_cast<std::uint8_t>(255 * r * v), static_cast<std::uint8_t>(255 * g * v),
          static_cast<std::uint8_t>(255 * b * v)};
}

std::string numbered_output(const std::string& output, std::size_t index, std::size_t count) {
  if (count <= 1) return output;
  namespace fs = std::filesystem;
  const fs::path p(output);
  char buf[16];
  std::snprintf(buf, sizeof buf, "_%03zu", index);
  return (p.parent_path() / (p.stem().string() + buf + p.extension().string())).string();
}

std::string named_output(const std::string& output, const std::string& name, std::size_t count) {
  if (count <= 1) return output;
  const std::filesystem::path p(output);
  return (p.parent_path() / (p.stem().string() + "_" + name + p.extension().string())).string();
}

Eigen::Vector3d parse_vector3(const std::string& text, const std::string& option) {
  Eigen::Vector3d v;
  std::string s = text;
  for (char& c : s)
    if (c == ',') c = ' ';
  std::istringstream in(s);
  if (!(in >> v.x() >> v.y() >> v.z()) || !v.allFinite())
    throw CliError(1, option + " expects three numbers x,y,z, got '" + text + "'");
  std::string rest;
  if (in >> rest) throw CliError(1, option + " expects three numbers x,y,z, got '" + text + "'");
  return v;
}

bool is_bag_output(const std::string& output) { return lower_extension(output) == ".bag"; }

std::string stamp_text(std::uint64_t sec, std::uint32_t nsec) {
  char text[40];
  std::snprintf(text, sizeof text, "%llu.%09u", static_cast<unsigned long long>(sec), nsec);
  return text;
}

bool stamp_from_name(const std::string& name, std::uint32_t& sec, std::uint32_t& nsec) {
  const std::size_t cut = name.find_last_of('_');
  const std::string s = cut == std::string::npos ? name : name.substr(cut + 1);
  const std::size_t dot = s.find('.');
  if (dot == std::string::npos || dot == 0 || dot > 10 || s.size() - dot - 1 != 9) return false;
  for (std::size_t i = 0; i < s.size(); ++i)
    if (i != dot && (s[i] < '0' || s[i] > '9')) return false;
  const unsigned long long a = std::stoull(s.substr(0, dot));
  if (a > 0xFFFFFFFFULL) return false;
  sec = static_cast<std::uint32_t>(a);
  nsec = static_cast<std::uint32_t>(std::stoul(s.substr(dot + 1)));
  return true;
}

void note_fields_not_written(const std::string& output, const Cloud& cloud, const io::WriteOptions& options) {
  // (a bag's message keeps the scan's stamp and frame; the point-cloud formats hold neither)
  if (cloud.stamp && !is_bag_output(output))
    std::fprintf(stderr, "note: %s: the scan's stamp (%s, %s)%s not written (the format holds none; a model file or a bag keeps %s)\n",
                 output.c_str(), stamp_source_name(*cloud.stamp), stamp_text(cloud.stamp->sec, cloud.stamp->nsec).c_str(),
                 cloud.stamp->frame_id.empty() ? "" : (" and frame " + cloud.stamp->frame_id).c_str(),
                 cloud.stamp->frame_id.empty() ? "it" : "them");
  const std::vector<std::string> missing = io::fields_not_written(output, cloud, options);
  if (missing.empty()) return;
  std::string list;
  for (const auto& f : missing) list += (list.empty() ? "" : ", ") + f;
  std::fprintf(stderr, "note: %s: %s not written (the format cannot hold %s; write .pcd or .ply to keep %s)\n",
               output.c_str(), list.c_str(), missing.size() == 1 ? "it" : "them", missing.size() == 1 ? "it" : "them");
}

}  // namespace lex3d::cli
