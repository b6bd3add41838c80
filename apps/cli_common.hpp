#pragma once
// Shared pieces of the lex3d subcommands: errors with exit codes, loading inputs,
// output-path safety.

#include <array>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "lex3d/core/status.hpp"
#include "lex3d/io/io.hpp"
#include "lex3d/residual/sensor_profile.hpp"

namespace lex3d::codec {
struct SequenceData;
}

namespace CLI {
class App;
}

namespace lex3d::cli {

/// An error the command reports as one line on stderr with its exit code
/// (1 usage, 2 bad data, 3 I/O).
class CliError : public std::runtime_error {
 public:
  CliError(int exit_code, const std::string& message) : std::runtime_error(message), code_(exit_code) {}
  [[nodiscard]] int exit_code() const noexcept { return code_; }

 private:
  int code_;
};

/// Throws CliError for a non-ok status.
void throw_if_error(const Status& status);

/// Says on stderr which of the cloud's attributes the format of `output` cannot hold (and so
/// were not written there), e.g. "note: out.bin: ring, time not written (a KITTI .bin keeps x
/// y z intensity; write .pcd or .ply to keep them)"; nothing when every one is written.
void note_fields_not_written(const std::string& output, const Cloud& cloud, const io::WriteOptions& options = {});

/// Parses a --format value; throws a usage CliError for an unknown name.
io::Format parse_format_option(const std::string& name);

/// Reads a point cloud or throws CliError (2 bad data, 3 I/O).
io::ReadResult load_cloud(const std::string& path, io::Format format);
io::ReadResult load_cloud(const std::string& path, const io::ReadOptions& options);

/// Options of raw lidar logs (--metadata, --sensor-model) on top of `format`.
io::ReadOptions read_options(io::Format format, const std::string& metadata, const std::string& sensor_model);

/// Reads a sensor profile (--sensor; formats/sensor_profile.md) or throws CliError (2 bad
/// or missing data, naming the file).
residual::SensorProfile read_sensor_profile(const std::string& path);

/// Refuses (exit 2) an input that is not a regular file or a directory: a pipe, FIFO, device
/// or socket is never opened (a FIFO without a writer would block, /dev/zero never ends).
void check_input_file(const std::string& path);

/// Refuses an output path that names one of the inputs (never overwrite an input).
void check_output_path(const std::string& output, const std::vector<std::string>& inputs);

/// The files one command reads and writes, checked before any work is done and written all
/// or nothing. Every output is compared with every input and every other output by file
/// identity (device and inode when it exists, else its canonical directory and name, so
/// hard links, symbolic links and `./x` against `x` are caught): a clash is a usage error
/// (exit 1) naming both options; an output whose directory is missing or that is a directory
/// is an I/O error (exit 3). Outputs are written to temporary files beside their final names
/// (`staged(path)`) and renamed by `commit()`; destroyed without a commit, the temporary
/// files are removed, so a command that fails leaves no output behind.
class OutputSet {
 public:
  OutputSet() = default;
  OutputSet(const OutputSet&) = delete;
  OutputSet& operator=(const OutputSet&) = delete;
  ~OutputSet();
  /// Records a file the command reads; `option` names it in messages ("--poses", "input").
  void input(const std::string& path, const std::string& option);
  void inputs(const std::vector<std::string>& paths, const std::string& option);
  /// Records a file the command writes and checks it against every file recorded so far
  /// (inputs and outputs alike, so record the inputs first).
  void output(const std::string& path, const std::string& option);
  /// Where to write output `path` (recorded with output()): a temporary name in its
  /// directory that keeps its extension, so writers that pick a format by extension agree.
  [[nodiscard]] std::string staged(const std::string& path);
  /// Renames every staged file onto its output, in the order they were staged.
  void commit();
  /// The outputs renamed by commit().
  [[nodiscard]] const std::vector<std::string>& written() const { return written_; }

 private:
  struct Entry {
    std::string path, option;
    bool is_output = false;
  };
  std::vector<Entry> files_;
  std::vector<std::pair<std::string, std::string>> staged_;  // temporary, final
  std::vector<std::string> written_;
};

/// Checks that the extension of `path` (option `option`) suits a file of kind `kind`
/// ("model", "alphabet", "sequence", "database" or "cloud"); throws a usage CliError naming
/// the option when it names another kind (a point-cloud extension for a model, say). Any
/// other extension is accepted.
void check_output_kind(const std::string& path, const std::string& option, const std::string& kind);

/// The kind of lex3d file `bytes` hold from its magic ("model", "alphabet", "sequence",
/// "database"), or "" when it is none of them.
std::string lex3d_file_kind(const std::vector<std::uint8_t>& bytes);

/// The file being read or worked on, for the message of an out-of-memory error.
void set_current_file(const std::string& path);
const std::string& current_file();

/// The pose list `path` (formats: io::read_pose_list), one pose for each of `scans` scans in
/// order; throws CliError 2 for an unreadable list, 1 for a count that does not match.
std::vector<Pose> read_scan_poses(const std::string& path, std::size_t scans);

/// Parses "x,y,z" into a vector; throws a usage CliError naming `option`.
Eigen::Vector3d parse_vector3(const std::string& text, const std::string& option);

/// The scans of the inputs in order, one at a time: the poses are read (and their count
/// checked) when it is made, a scan when it is asked for. With `poses_path` (one KITTI-style
/// pose a scan, world <- sensor) each cloud gets its world pose, so features stay upright
/// for tilted sensors; with `points_in_world` (which needs the poses) the points are already
/// in the world frame: each pose becomes the cloud's T_cloud_sensor (where its sensor was)
/// and its world pose the identity. A raw lidar log (pcap) counts as one scan a complete
/// turn, a ROS bag as one a message of its topic (options.bag_topic), both read through once
/// when the loader is made (names, errors) and again as scans are asked for; a sequence file
/// (.lex3dq) as one a model, decoded when asked for.
class ScanLoader {
 public:
  ScanLoader(std::vector<std::string> paths, io::Format format, const std::string& poses_path, bool points_in_world);
  ScanLoader(const std::vector<std::string>& paths, const io::ReadOptions& options, const std::string& poses_path,
             bool points_in_world);
  [[nodiscard]] std::size_t size() const { return entries_.size(); }
  /// Scan i with its poses (load_scans's clouds[i]); throws CliError as load_scans does.
  [[nodiscard]] Cloud load(std::size_t i) const;
  /// What scan i is: its file, or "<file> turn <k>" for a raw log's turn.
  [[nodiscard]] const std::string& name(std::size_t i) const { return entries_.at(i).name; }
  /// A short name of scan i for a file: its file's stem, "<stem>_turn<k>" for a raw log's turn,
  /// "<stem>_<sec>.<nsec>" (its stamp) for a ROS bag's message.
  [[nodiscard]] std::string stem(std::size_t i) const;

 private:
  class Turns;
  struct Entry {
    std::string path;
    std::string name;
    std::size_t turn = 0;  // raw log or ROS bag: the scan's place in its file
    std::string stem;  // raw log: "<stem>_turn<k>_<sec>.<nsec>"; ROS bag: "<stem>_<sec>.<nsec>", the message's stamp
    std::shared_ptr<Turns> scans;  // raw log or ROS bag: read scan by scan as they are loaded
    std::shared_ptr<const codec::SequenceData> sequence;  // sequence file: its model `turn`
  };
  void add_bag(const std::string& path, const io::ReadOptions& options);
  void add_sequence(const std::string& path);
  std::vector<Entry> entries_;
  io::ReadOptions options_;
  std::vector<Pose> poses_;  // empty: no poses file
  bool points_in_world_;
};

/// A distinct, stable colour for a word id.
std::array<std::uint8_t, 3> word_color(std::uint32_t word);

/// OUT for one scan; OUT's stem + "_<index>" + extension for several.
std::string numbered_output(const std::string& output, std::size_t index, std::size_t count);
/// OUT for one scan; OUT's stem + "_<name>" + extension for several (a scan's stored name).
std::string named_output(const std::string& output, const std::string& name, std::size_t count);

/// The machine's cores, in [1, 64]: what `--threads 0` means.
int all_cores();
/// `--threads N` on a command, the same on every one: worker threads, 0 = every core (the
/// default); `threads` is set to the resolved count, never 0. The outputs do not depend on it.
void add_threads_option(CLI::App& app, int& threads, const std::string& what);

/// The extension of `path` in lower case (".lex3dq", ".pcd"; empty when it has none).
std::string lower_extension(const std::string& path);

/// A sequence file (formats/sequence.md) read and decoded (its models not yet); throws
/// CliError: 3 where it cannot be read, 2 where it is not a sequence file.
std::shared_ptr<const codec::SequenceData> read_sequence(const std::string& path);

/// True when `output` names a ROS bag (`.bag`): every scan goes into it, one message each.
bool is_bag_output(const std::string& output);

/// A scan's stamp from its stored name ("<stem>_<sec>.<nsec>", as ScanLoader::stem gives a
/// bag's message); false when the name holds none.
bool stamp_from_name(const std::string& name, std::uint32_t& sec, std::uint32_t& nsec);

/// A stamp as names and messages show it: "<sec>.<nsec>", nine digits of nanoseconds.
std::string stamp_text(std::uint64_t sec, std::uint32_t nsec);
/// What a scan's stamp is: "message stamp" or "capture time of its first packet".
inline const char* stamp_source_name(const ScanStamp& s) {
  return s.source == ScanStamp::Source::kCapture ? "capture time of its first packet" : "message stamp";
}
/// The same of a time in nanoseconds.
inline std::string stamp_text(std::uint64_t ns) {
  return stamp_text(ns / 1000000000ULL, static_cast<std::uint32_t>(ns % 1000000000ULL));
}

/// Registration of each subcommand (one file each).
void register_info(CLI::App& app);
void register_features(CLI::App& app);
void register_learn(CLI::App& app);
void register_reconstruct(CLI::App& app);
void register_place(CLI::App& app);
void register_compress(CLI::App& app);
void register_decompress(CLI::App& app);
void register_convert(CLI::App& app);

}  // namespace lex3d::cli
