#include "cli_common.hpp"

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
    throw CliError(1, "unknown --format '" + name + "' (expected auto, kitti, binxyz, pcd, ply, xyz or uos)");
  return *f;
}

io::ReadResult load_cloud(const std::string& path, io::Format format) {
  io::ReadOptions opt;
  opt.format = format;
  auto r = io::read_cloud(path, opt);
  // Any input that cannot be read (missing, unreadable, malformed) is bad input: exit 2.
  if (!r.ok()) throw CliError(2, r.status().to_string());
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
