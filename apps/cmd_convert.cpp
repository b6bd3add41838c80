// lex3d convert IN OUT: any readable input (a raw log: every complete turn) to PCD, PLY,
// KITTI .bin or text, with the existing writer.

#include <CLI/CLI.hpp>

#include <algorithm>
#include <cstdio>
#include <optional>

#include "cli_common.hpp"
#include "lex3d/io/rosbag.hpp"

namespace lex3d::cli {

namespace {

struct ConvertOptions {
  std::string input;
  std::string output;
  std::string format = "auto";
  std::string metadata;
  std::string sensor_model;
  std::string topic;
  std::string sensor;  ///< --sensor: a sensor profile whose lasers become the ring field
  bool single_return = false;
};

void run_convert(const ConvertOptions& o) {
  io::ReadOptions options = read_options(parse_format_option(o.format), o.metadata, o.sensor_model);
  options.bag_topic = o.topic;
  options.single_return = o.single_return;
  const ScanLoader loader({o.input}, options, "", false);
  std::vector<std::string> outputs;
  const bool bag = is_bag_output(o.output);  // one bag, a message a scan
  for (std::size_t i = 0; i < loader.size(); ++i) outputs.push_back(bag ? o.output : numbered_output(o.output, i, loader.size()));
  if (bag) outputs.resize(std::min<std::size_t>(outputs.size(), 1));
  OutputSet files;
  files.input(o.input, "input");
  files.input(o.metadata, "--metadata");
  files.input(o.sensor, "--sensor");
  std::optional<residual::SensorProfile> profile;
  if (!o.sensor.empty()) profile = read_sensor_profile(o.sensor);
  for (const auto& out : outputs) {
    files.output(out, "output");
    check_output_kind(out, "output", "cloud");
  }
  // (a bag written message by message as the scans come)
  std::unique_ptr<io::BagWriter> bag_out;
  if (bag) {
    auto w = io::BagWriter::open(files.staged(o.output));
    if (!w.ok()) throw CliError(exit_code_for(w.status().code()), w.status().to_string());
    bag_out = std::move(w).value();
  }
  for (std::size_t i = 0; i < loader.size(); ++i) {
    Cloud cloud = loader.load(i);
    if (profile) {
      const bool had_rings = cloud.has_rings();
      auto fit = residual::apply_sensor_profile(cloud, *profile, loader.name(i));
      if (!fit.ok()) throw CliError(2, fit.status().to_string());
      std::fprintf(stderr, "note: %s: ring field %s the lasers of %s (%zu of %zu hit, points a median %.2f mm from the beams)\n",
                   loader.name(i).c_str(), had_rings ? "replaced by" : "from", o.sensor.c_str(), fit.value().lasers_hit,
                   fit.value().lasers, fit.value().median_off_beam_m * 1e3);
    }
    const std::string& out = bag ? o.output : outputs[i];
    if (!bag) {
      throw_if_error(io::write_cloud(files.staged(out), cloud));
      note_fields_not_written(out, cloud);
    }
    std::printf("%s -> %s: %zu points%s\n", loader.name(i).c_str(), out.c_str(), cloud.size(),
                cloud.rows > 0 ? (" (" + std::to_string(cloud.rows) + " x " + std::to_string(cloud.columns) +
                                  (io::pixel_points(cloud).empty() ? ", written unorganised: pixels with two returns)" : " organised)")).c_str()
                               : "");
    if (bag) {
      io::BagScan scan;
      stamp_from_name(loader.stem(i), scan.stamp_sec, scan.stamp_nsec);
      scan.cloud = std::move(cloud);
      throw_if_error(bag_out->write(scan));
    }
  }
  if (bag) throw_if_error(bag_out->close());
  files.commit();
}

}  // namespace

void register_convert(CLI::App& app) {
  auto o = std::make_shared<ConvertOptions>();
  CLI::App* sub = app.add_subcommand("convert", "Convert a point cloud or raw lidar log (one file a turn) to PCD, PLY, .bin or text");
  sub->footer("Examples:\n  lex3d convert capture.pcap turns.pcd                  (one organised PCD a turn)\n  lex3d convert scan.bin scan.ply");
  sub->add_option("input", o->input, "Point cloud or raw lidar log (.pcap)")->required();
  sub->add_option("output", o->output, "Output (.pcd, .ply, .bin, .xyz/.txt; numbered _000, _001... for several turns), or .bag: one ROS bag, a PointCloud2 message a scan")->required();
  sub->add_option("--format", o->format, "Input format: auto, kitti, binxyz, pcd, ply, xyz, uos, pcap");
  sub->add_option("--metadata", o->metadata, "Metadata of a pcap: an Ouster metadata JSON, or a Velodyne calibration (db.xml, VeloView XML or the ROS driver's YAML; needed for an HDL-64E) (default: the .json, .xml, .yaml or .yml beside it, same stem)");
  sub->add_option("--sensor-model", o->sensor_model, "Read a Velodyne pcap as this model: vlp16, puck-hires, hdl32e, vlp32c or hdl64e (default: detected from the packets)");
  sub->add_option("--topic", o->topic, "The topic of a ROS bag to read (default: its only point cloud topic)");
  sub->add_option("--sensor", o->sensor,
                  "Sensor profile (formats/sensor_profile.md): write each point's laser by its table as the ring field");
  sub->add_flag("--single-return", o->single_return, "A dual-return capture: keep one return a pixel (Ouster's strongest, Velodyne's last), as a single-return capture gives it, organised; the second returns are counted, not kept (default: each a point of its own with a return field)");
  sub->callback([o] { run_convert(*o); });
}

}  // namespace lex3d::cli
