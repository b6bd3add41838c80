// lex3d convert IN OUT: any readable input (a raw log: every complete turn) to PCD, PLY,
// KITTI .bin or text, with the existing writer.

#include <CLI/CLI.hpp>

#include <cstdio>

#include "cli_common.hpp"

namespace lex3d::cli {

namespace {

struct ConvertOptions {
  std::string input;
  std::string output;
  std::string format = "auto";
  std::string metadata;
  std::string sensor_model;
};

void run_convert(const ConvertOptions& o) {
  const ScanLoader loader({o.input}, read_options(parse_format_option(o.format), o.metadata, o.sensor_model), "", false);
  std::vector<std::string> outputs;
  for (std::size_t i = 0; i < loader.size(); ++i) outputs.push_back(numbered_output(o.output, i, loader.size()));
  OutputSet files;
  files.input(o.input, "input");
  files.input(o.metadata, "--metadata");
  for (const auto& out : outputs) {
    files.output(out, "output");
    check_output_kind(out, "output", "cloud");
  }
  for (std::size_t i = 0; i < loader.size(); ++i) {
    const Cloud cloud = loader.load(i);
    throw_if_error(io::write_cloud(files.staged(outputs[i]), cloud));
    note_fields_not_written(outputs[i], cloud);
    std::printf("%s -> %s: %zu points%s\n", loader.name(i).c_str(), outputs[i].c_str(), cloud.size(),
                cloud.rows > 0 ? (" (" + std::to_string(cloud.rows) + " x " + std::to_string(cloud.columns) + " organised)").c_str() : "");
  }
  files.commit();
}

}  // namespace

void register_convert(CLI::App& app) {
  auto o = std::make_shared<ConvertOptions>();
  CLI::App* sub = app.add_subcommand("convert", "Convert a point cloud or raw lidar log (one file a turn) to PCD, PLY, .bin or text");
  sub->footer("Examples:\n  lex3d convert capture.pcap turns.pcd                  (one organised PCD a turn)\n  lex3d convert scan.bin scan.ply");
  sub->add_option("input", o->input, "Point cloud or raw lidar log (.pcap)")->required();
  sub->add_option("output", o->output, "Output (.pcd, .ply, .bin, .xyz/.txt); numbered _000, _001... for several turns")->required();
  sub->add_option("--format", o->format, "Input format: auto, kitti, binxyz, pcd, ply, xyz, uos, pcap");
  sub->add_option("--metadata", o->metadata, "Metadata JSON of an Ouster pcap (default: the .json beside it, same stem)");
  sub->add_option("--sensor-model", o->sensor_model, "Read a Velodyne pcap as this model: vlp16 or hdl32e");
  sub->callback([o] { run_convert(*o); });
}

}  // namespace lex3d::cli
