#include "cli_common.hpp"

#include "lex3d/io/sensor_log.hpp"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <sstream>

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
  if (!sensor_model.empty() && sensor_model != "vlp16" && sensor_model != "hdl32e")
    throw CliError(1, "unknown --sensor-model '" + sensor_model + "' (expected vlp16 or hdl32e)");
  return opt;
}

io::ReadResult load_cloud(const std::string& path, const io::ReadOptions& opt) {
  auto r = io::read_cloud(path, opt);
  // Any input that cannot be read (missing, unreadable, malformed) is bad input: exit 2.
  if (!r.ok()) throw CliError(2, r.status().to_string());
  // never drop silently: what the file holds that lex3d does not keep, and what the reader noticed
  const io::ReadResult& res = r.value();
  if (!res.dropped_fields.empty()) {
    std::string list;
    for (const auto& f : res.dropped_fields) list += (list.empty() ? "" : ", ") + f;
    std::fprintf(stderr, "note: %s: fields not kept (lex3d keeps x y z, intensity, ring, time and colour): %s\n", path.c_str(), list.c_str());
  }
  for (const auto& n : res.notes) std::fprintf(stderr, "note: %s: %s\n", path.c_str(), n.c_str());
  return std::move(r).value();
}

void check_output_path(const std::string& output, const std::vector<std::string>& inputs) {
  namespace fs = std::filesystem;
  std::error_code ec;
  for (const auto& in : inputs) {
    if (fs::exists(output, ec) && fs::equivalent(output, in, ec))
      throw CliError(1, "refusing to overwrite input file " + in);
  }
}

ScanLoader::ScanLoader(std::vector<std::string> paths, io::Format format, const std::string& poses_path,
                       bool points_in_world)
    : ScanLoader(paths, read_options(format, "", ""), poses_path, points_in_world) {}

ScanLoader::ScanLoader(const std::vector<std::string>& paths, const io::ReadOptions& options,
                       const std::string& poses_path, bool points_in_world)
    : options_(options), points_in_world_(points_in_world) {
  for (const auto& path : paths) {
    const bool log = options.format == io::Format::kPcap || (options.format == io::Format::kAuto && io::is_sensor_log(path));
    if (!log) {
      entries_.push_back({path, path, nullptr, 0});
      continue;
    }
    auto r = io::read_sensor_log(path, options);
    if (!r.ok()) throw CliError(exit_code_for(r.status().code()) == 1 ? 1 : 2, r.status().to_string());
    auto turns = std::make_shared<const std::vector<Cloud>>(std::move(r.value().scans));
    const auto& ids = r.value().frame_ids;
    for (std::size_t k = 0; k < turns->size(); ++k)
      entries_.push_back({path, path + " turn " + std::to_string(k) + " (frame " + std::to_string(ids[k]) + ")", turns, k});
  }
  if (points_in_world && poses_path.empty())
    throw CliError(1, "--input-frame world needs --poses: the sensor pose of each scan in that frame");
  if (poses_path.empty()) return;
  auto poses = io::read_pose_list(poses_path);
  if (!poses.ok()) throw CliError(2, poses.status().to_string());
  if (poses.value().size() != entries_.size())
    throw CliError(1, poses_path + " has " + std::to_string(poses.value().size()) + " poses for " +
                          std::to_string(entries_.size()) + " scans (one pose a scan, in order)");
  poses_ = std::move(poses).value();
}

Cloud ScanLoader::load(std::size_t i) const {
  const Entry& e = entries_.at(i);
  Cloud cloud = e.turns ? (*e.turns)[e.turn] : load_cloud(e.path, options_).cloud;
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

std::vector<Cloud> load_scans(const std::vector<std::string>& paths, io::Format format,
                              const std::string& poses_path, bool points_in_world) {
  const ScanLoader loader(paths, format, poses_path, points_in_world);
  std::vector<Cloud> clouds;
  clouds.reserve(paths.size());
  for (std::size_t i = 0; i < paths.size(); ++i) clouds.push_back(loader.load(i));
  return clouds;
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

}  // namespace lex3d::cli
