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

/// Parses a --format value; throws a usage CliError for an unknown name.
io::Format parse_format_option(const std::string& name);

/// Reads a point cloud or throws CliError (2 bad data, 3 I/O).
io::ReadResult load_cloud(const std::string& path, io::Format format);
io::ReadResult load_cloud(const std::string& path, const io::ReadOptions& options);

/// Options of raw lidar logs (--metadata, --sensor-model) on top of `format`.
io::ReadOptions read_options(io::Format format, const std::string& metadata, const std::string& sensor_model);

/// Refuses an output path that names one of the inputs (never overwrite an input).
void check_output_path(const std::string& output, const std::vector<std::string>& inputs);

/// Parses "x,y,z" into a vector; throws a usage CliError naming `option`.
Eigen::Vector3d parse_vector3(const std::string& text, const std::string& option);

/// Reads scans in order; with `poses_path` (one KITTI-style pose a scan, world <- sensor)
/// each cloud gets its world pose, so features stay upright for tilted sensors. With
/// `points_in_world` (which needs the poses) the points are already in the world frame:
/// each pose becomes the cloud's T_cloud_sensor (where its sensor was) and its world pose
/// the identity.
std::vector<Cloud> load_scans(const std::vector<std::string>& paths, io::Format format,
                              const std::string& poses_path, bool points_in_world = false);

/// The scans of load_scans one at a time, for commands that need only one in memory: the
/// poses are read (and their count checked) when it is made, a scan when it is asked for.
/// A raw lidar log (pcap) counts as one scan a complete turn: it is decoded when the loader
/// is made and its turns are kept in memory.
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

 private:
  struct Entry {
    std::string path;
    std::string name;
    std::shared_ptr<const std::vector<Cloud>> turns;  // raw log: its turns
    std::size_t turn = 0;
  };
  std::vector<Entry> entries_;
  io::ReadOptions options_;
  std::vector<Pose> poses_;  // empty: no poses file
  bool points_in_world_;
};

/// A distinct, stable colour for a word id.
std::array<std::uint8_t, 3> word_color(std::uint32_t word);

/// OUT for one scan; OUT's stem + "_<index>" + extension for several.
std::string numbered_output(const std::string& output, std::size_t index, std::size_t count);

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
