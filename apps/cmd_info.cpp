// lex3d info FILE: what a point cloud file holds.

#include <CLI/CLI.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <optional>
#include <string>

#include "cli_common.hpp"
#include "json.hpp"
#include "lex3d/codec/codec.hpp"
#include "lex3d/io/mapped_file.hpp"
#include "lex3d/io/rosbag.hpp"
#include "lex3d/io/sensor_log.hpp"
#include "lex3d/place/place.hpp"
#include "lex3d/place/vocabulary.hpp"
#include "lex3d/residual/attributes.hpp"
#include "lex3d/residual/residual.hpp"
#include "lex3d/range/range_image.hpp"

namespace lex3d::cli {

namespace {

/// The voxel coding's context model (formats/model.md §2.7).
const char* octree_contexts_name(std::uint32_t contexts) {
  return contexts == 1 ? "mixed (§2.7.4, format 1.8)" : "face (§2.7.1, format 1.3)";
}

/// The sensor-geometry coding's range predictor (formats/model.md §2.8.2, §2.8.4).
const char* range_predictor_name(std::uint32_t predictor) {
  switch (predictor) {
    case 0: return "left neighbour";
    case 1: return "median edge detector";
    case 2: return "median edge detector with edge flags";
    case 3: return "left neighbour with edge flags";
    case 4: return "median edge detector with edge flags and mixed contexts";
    case 5: return "left neighbour with edge flags and mixed contexts";
    default: return "unknown predictor";
  }
}

const char* layer_coding_name(std::uint32_t coding) {
  return coding == 1 ? "sweep" : coding == 2 ? "voxel" : coding == 3 ? "sensor-geometry" : coding == 4 ? "acquisition-order" : coding == 5 ? "lattice" : "previous-point";
}

struct InfoOptions {
  std::string path;
  std::string alphabet;  // the alphabet file a model references
  std::string format = "auto";
  std::string metadata;      // an Ouster capture's metadata JSON
  std::string sensor_model;  // a Velodyne capture's model
  std::string sensor;        // a sensor profile to fit the scan to
  bool json = false;
};

double quantile(std::vector<float> v, double q) {
  if (v.empty()) return std::nan("");
  const auto k = static_cast<std::size_t>(q * static_cast<double>(v.size() - 1));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return static_cast<double>(v[k]);
}

// lex3d's own files: header, chunk table with checksum status, counts, sizes.
/// The georeference of a cloud or model file: CRS, units, origin, LAS container.
void print_georef(const Georeference& g, bool measured) {
  std::printf("CRS            %s%s\n", g.crs_name.empty() ? "(not named)" : g.crs_name.c_str(),
              g.epsg ? (" (EPSG:" + std::to_string(g.epsg) + ")").c_str() : "");
  std::printf("units          %s (%.10g m)", g.unit_name.c_str(), g.unit_m);
  if (g.vertical_unit_m != g.unit_m) std::printf(", vertical %.10g m", g.vertical_unit_m);
  std::printf("; points read into metres\n");
  const Eigen::Vector3d o_crs = g.origin.cwiseQuotient(g.units());
  std::printf("origin         %.6f %.6f %.6f m = %.6f %.6f %.6f CRS units (true = origin + point)\n", g.origin.x(),
              g.origin.y(), g.origin.z(), o_crs.x(), o_crs.y(), o_crs.z());
  if (g.is_las())
    std::printf("LAS            1.%d, point format %d, scale %.10g %.10g %.10g, offset %.10g %.10g %.10g, %zu CRS records, "
                "system '%s', software '%s'\n",
                g.las_version_minor, g.las_point_format, g.las_scale.x(), g.las_scale.y(), g.las_scale.z(),
                g.las_offset.x(), g.las_offset.y(), g.las_offset.z(), g.crs_records.size(), g.las_system_id.c_str(),
                g.las_software.c_str());
  if (measured) std::printf("float32 error  %.3g m at most (positions relative to the origin)\n", g.representation_error_m);
}

void georef_json(Json& j, const Georeference& g) {
  j.begin_object("georeference")
      .value("crs_name", g.crs_name)
      .value("epsg", static_cast<std::uint64_t>(g.epsg))
      .value("unit", g.unit_name)
      .value("unit_m", g.unit_m)
      .value("vertical_unit_m", g.vertical_unit_m);
  j.numbers("origin_m", {g.origin.x(), g.origin.y(), g.origin.z()});
  if (g.is_las()) {
    j.numbers("las_scale", {g.las_scale.x(), g.las_scale.y(), g.las_scale.z()});
    j.numbers("las_offset", {g.las_offset.x(), g.las_offset.y(), g.las_offset.z()});
    j.value("las_version", "1." + std::to_string(g.las_version_minor))
        .value("las_point_format", static_cast<std::uint64_t>(g.las_point_format))
        .value("crs_records", g.crs_records.size());
  }
  j.value("representation_error_m", g.representation_error_m);
  j.end_object();
}

bool info_lex3d_file(const InfoOptions& o) {
  check_input_file(o.path);
  auto bytes = io::read_file(o.path);
  if (!bytes.ok()) return false;  // load_cloud reports the error
  const auto& b = bytes.value();
  static constexpr char kModel[] = "LEX3DMDL";
  static constexpr char kAlphabet[] = "LEX3DALP";
  if (b.size() < 8 || (std::memcmp(b.data(), kModel, 8) != 0 && std::memcmp(b.data(), kAlphabet, 8) != 0 &&
                       !codec::is_sequence_file(b)))
    return false;
  auto info = codec::inspect(b);
  if (!info.ok()) throw CliError(2, o.path + ": " + info.status().to_string());
  const codec::FileInfo& fi = info.value();
  std::optional<Georeference> georef;
  std::optional<ScanStamp> stamp;
  bool all_crc_ok = true;
  for (const auto& c : fi.chunks) all_crc_ok = all_crc_ok && c.crc_ok;
  std::size_t words = 0, word_points = 0, instances = 0;
  std::uint64_t input_points = 0;
  std::string decode_error;
  bool referenced = false;
  std::size_t scans = 0;
  if (fi.kind == "sequence") {
    auto q = codec::decode_sequence(b);
    if (q.ok()) {
      scans = q.value().model_files.size();
      auto a = codec::decode_alphabet(q.value().alphabet_file);
      if (a.ok()) {
        words = a.value().size();
        word_points = a.value().total_points();
      }
      for (const auto& mf : q.value().model_files) {
        auto m = codec::decode_model(mf, &q.value().alphabet_file);
        if (!m.ok()) {
          decode_error = m.status().to_string();
          break;
        }
        instances += m.value().model.instances.size();
        input_points += m.value().input_points;
      }
    } else {
      decode_error = q.status().to_string();
    }
  } else if (fi.kind == "alphabet") {
    auto a = codec::decode_alphabet(b);
    if (a.ok()) {
      words = a.value().size();
      word_points = a.value().total_points();
    } else {
      decode_error = a.status().to_string();
    }
  } else {
    std::vector<std::uint8_t> alphabet_file;
    if (!o.alphabet.empty()) {
      auto a = io::read_file(o.alphabet);
      if (!a.ok()) throw CliError(3, a.status().to_string());
      alphabet_file = std::move(a).value();
    }
    auto m = codec::decode_model(b, o.alphabet.empty() ? nullptr : &alphabet_file);
    if (m.ok()) georef = m.value().georef;
    if (m.ok()) stamp = m.value().stamp;
    if (m.ok()) {
      instances = m.value().model.instances.size();
      input_points = m.value().input_points;
      if (m.value().alphabet) {
        words = m.value().alphabet->size();
        word_points = m.value().alphabet->total_points();
      }
    } else if (o.alphabet.empty() && m.status().message().find("alphabet") != std::string::npos && (fi.flags & 2U) != 0) {
      referenced = true;  // counts of the model itself need no alphabet: report the chunks only
    } else {
      decode_error = m.status().to_string();
    }
  }
  // The residual layer's header, read from its (CRC-checked) chunk.
  std::optional<residual::LayerHeader> layer;
  std::uint64_t layer_bytes = 0;
  if (fi.kind == "model")
    for (const auto& c : fi.chunks)
      if ((c.type == "RESD" || c.type == "RESW" || c.type == "RESV" || c.type == "RESL" || c.type == "RESA" || c.type == "RESG") && c.crc_ok) {
        auto h = residual::read_layer_header(b.data() + c.offset + 12, static_cast<std::size_t>(c.length));
        if (h.ok()) layer = h.value();
        layer_bytes = c.length;
      }
  // The point attributes (an ATTR chunk): their fields, read from the descriptors.
  std::vector<residual::AttributeField> attributes;
  if (fi.kind == "model")
    for (const auto& c : fi.chunks)
      if (c.type == "ATTR" && c.crc_ok) {
        const auto* at = b.data() + c.offset + 12;
        auto f = residual::inspect_attributes(std::vector<std::uint8_t>(at, at + c.length));
        if (f.ok()) attributes = f.value();
      }
  const auto& translation_step = fi.translation_step_m;
  const auto& rotation_step = fi.rotation_step_rad;
  const auto& word_radius = fi.word_radius_m;
  const auto& point_spacing = fi.point_spacing_m;
  const auto& word_point_step = fi.word_point_step_m;

  const double bpp = input_points ? 8.0 * static_cast<double>(b.size()) / static_cast<double>(input_points) : 0.0;
  if (o.json) {
    Json j;
    j.begin_object();
    j.value("file", o.path).value("kind", fi.kind).value("format_version", std::to_string(fi.major) + "." + std::to_string(fi.minor));
    j.value("flags", static_cast<std::uint64_t>(fi.flags)).value("file_bytes", fi.file_bytes);
    j.begin_array("chunks");
    for (const auto& c : fi.chunks)
      j.begin_object().value("type", c.type).value("offset", c.offset).value("length", c.length).value("crc_ok", c.crc_ok).end_object();
    j.end_array();
    j.value("checksums_ok", all_crc_ok);
    if (fi.kind == "sequence") j.value("scans", scans);
    if (fi.kind != "alphabet" && !referenced && decode_error.empty())
      j.value("instances", instances).value("input_points", input_points).value("bits_per_point", bpp);
    j.value("words", words).value("word_points", word_points);
    if (translation_step) j.value("translation_step_m", *translation_step).value("rotation_step_rad", *rotation_step);
    if (word_radius)
      j.value("word_radius_m", *word_radius).value("point_spacing_m", *point_spacing).value("word_point_step_m", *word_point_step);
    if (referenced) j.value("alphabet", "referenced");
    if (layer)
      (void)j.begin_object("residual")
          .value("max_error_m", layer->max_error)
          .value("step_m", layer->step)
          .value("coding", layer_coding_name(layer->coding))
          .value("word_points", layer->word_points)
          .value("coded_points", layer->coded_points)
          .value("bytes", layer_bytes);
    if (layer && layer->coding == 3)
      j.value("tangential_step_m", layer->tangential_step).value("lasers", static_cast<std::uint64_t>(layer->lasers))
          .value("columns", static_cast<std::uint64_t>(layer->columns))
          .value("range_predictor", range_predictor_name(layer->predictor))
          .value("quick_models", layer->quick_models)
          .value("laser_table", "stored in the layer (its source is reported by compress --json, not stored)");
    if (layer && layer->coding == 2) {
      j.value("octree_depth", static_cast<std::uint64_t>(layer->depth)).value("octree_contexts", octree_contexts_name(layer->octree_contexts));
      j.begin_array("octree_origin_m");
      for (double c : layer->origin) j.value({}, c);
      j.end_array();
    }
    if (layer && layer->coding == 1) j.value("direction_cell_rad", layer->cell);
    if (layer && layer->coding == 5) {
      j.value("lattice_pitch_m", layer->pitch).value("lattice_columns", static_cast<std::uint64_t>(layer->columns))
          .value("lattice_rows", static_cast<std::uint64_t>(layer->rows))
          .value("lattice_stacked", layer->voxel_reserved != 0);
      j.begin_array("lattice_origin_m");
      for (double c : layer->origin) j.value({}, c);
      j.end_array();
    }
    if (layer && layer->coding == 4) {
      j.begin_array("grid_origin_m");
      for (double c : layer->origin) j.value({}, c);
      j.end_array();
      j.value("fit_pulses", static_cast<std::uint64_t>(layer->fit_pulses));
      j.value("cell_height_m", layer->step_z == 0.0 ? layer->step : layer->step_z);
    }
    if (layer) j.end_object();
    if (georef) georef_json(j, *georef);
    if (stamp)
      j.begin_object("stamp").value("sec", stamp->sec).value("nsec", static_cast<std::uint64_t>(stamp->nsec))
          .value("text", stamp_text(stamp->sec, stamp->nsec))
          .value("source", stamp->source == ScanStamp::Source::kCapture ? "capture" : "message")
          .value("frame_id", stamp->frame_id).end_object();
    if (fi.kind == "model") {
      j.begin_array("attributes");
      for (const auto& a : attributes)
        j.begin_object().value("name", a.name).value("representation", a.representation)
            .value("lossless", a.max_error == 0.0).value("bytes", static_cast<std::uint64_t>(a.bytes)).end_object();
      j.end_array();
    }
    if (!decode_error.empty()) j.value("error", decode_error);
    j.end_object();
    std::cout << j.str() << "\n";
  } else {
    std::printf("file           %s\n", o.path.c_str());
    std::printf("kind           lex3d %s, format %d.%d, flags 0x%x\n", fi.kind.c_str(), fi.major, fi.minor, fi.flags);
    std::printf("size           %llu bytes\n", static_cast<unsigned long long>(fi.file_bytes));
    std::printf("chunks         %-6s %10s %12s  crc\n", "type", "offset", "length");
    for (const auto& c : fi.chunks)
      std::printf("               %-6s %10llu %12llu  %s\n", c.type.c_str(), static_cast<unsigned long long>(c.offset),
                  static_cast<unsigned long long>(c.length), c.crc_ok ? "ok" : "MISMATCH");
    if (fi.kind == "sequence") std::printf("scans          %zu\n", scans);
    if (fi.kind != "alphabet") {
      if (referenced) {
        std::printf("alphabet       referenced by hash (external file; give --alphabet for the counts)\n");
      } else if (decode_error.empty()) {
        std::printf("instances      %zu\n", instances);
        std::printf("input points   %llu (%.3f bits per point)\n", static_cast<unsigned long long>(input_points), bpp);
      }
      if (layer)
        std::printf("residual layer max error %.4g m (%s %.4g m, %s coding), %llu coded %s, a keep mask over %llu word points, %llu bytes\n",
                    layer->max_error, layer->coding == 2 ? "cell" : "step", layer->step, layer_coding_name(layer->coding),
                    static_cast<unsigned long long>(layer->coded_points), layer->coding == 2 ? "voxels" : "points",
                    static_cast<unsigned long long>(layer->word_points), static_cast<unsigned long long>(layer_bytes));
      if (layer && layer->coding == 3)
        std::printf("laser table    %u lasers, %u columns a turn, stored in the layer (its source is reported by "
                    "compress --json, not stored); step across the beams %.4g m; ranges predicted by the %s%s%s\n",
                    layer->lasers, layer->columns, layer->tangential_step, range_predictor_name(layer->predictor),
                    layer->quick_models ? " (quick-learning models)" : "",
                    layer->motion ? "; beams moving over the turn (a motion-compensated scan)" : "");
      if (layer && layer->coding == 2)
        std::printf("octree         %u levels of %.4g m cells from (%.4g, %.4g, %.4g) m, %s contexts\n", layer->depth,
                    layer->step, layer->origin[0], layer->origin[1], layer->origin[2],
                    octree_contexts_name(layer->octree_contexts));
      if (layer && layer->coding == 1) std::printf("sweep          direction cell %.4g rad\n", layer->cell);
      if (layer && layer->coding == 5)
        std::printf("lattice        %u x %u cells of %.4g m from (%.4g, %.4g) m, %s\n", layer->columns, layer->rows,
                    layer->pitch, layer->origin[0], layer->origin[1],
                    layer->voxel_reserved != 0 ? "a cell's points stacked" : "a cell's points in input order");
      if (layer && layer->coding == 4)
        std::printf("grid           cells %.4g m wide, %.4g m tall, from (%.4g, %.4g, %.4g) m, points in the order they were fired, %s\n",
                    layer->step, layer->step_z == 0.0 ? layer->step : layer->step_z, layer->origin[0], layer->origin[1], layer->origin[2],
                    layer->fit_pulses == 0 ? "x and y stepped from the last pulse"
                                           : ("x and y fitted over " + std::to_string(layer->fit_pulses) + " pulses").c_str());
    }
    if (translation_step)
      std::printf("instance steps %.4g m, %.4g rad\n", *translation_step, *rotation_step);
    if (words) std::printf("words          %zu (%zu points)\n", words, word_points);
    if (georef) print_georef(*georef, false);
    if (stamp)
      std::printf("scan stamp     %s (%s)%s\n", stamp_text(stamp->sec, stamp->nsec).c_str(), stamp_source_name(*stamp),
                  stamp->frame_id.empty() ? "" : (", frame " + stamp->frame_id).c_str());
    if (fi.kind == "model") {
      std::printf("fields         x y z");
      for (const auto& a : attributes) std::printf(" %s", a.name.c_str());
      std::printf("\n");
      for (const auto& a : attributes)
        std::printf("  %-12s %s, %zu bytes\n", a.name.c_str(), a.representation.c_str(), a.bytes);
    }
    if (word_radius)
      std::printf("word radius    %.4g m (points %.4g m apart, stored in steps of %.4g m)\n", *word_radius, *point_spacing,
                  *word_point_step);
    if (!decode_error.empty()) std::printf("error          %s\n", decode_error.c_str());
  }
  if (!all_crc_ok || !decode_error.empty())
    throw CliError(2, o.path + ": " + (decode_error.empty() ? std::string("checksum mismatch") : decode_error));
  return true;
}

// A raw lidar log: the sensor, its lasers and columns, and the turns found.
/// A ROS bag: its topics, their message types and counts.
// A place database, read as a query reads it (header, alphabet and index, no entry decoded):
// its format, scans, alphabet, descriptors and vocabulary. False when the file is not one.
bool info_place_db(const InfoOptions& o) {
  check_input_file(o.path);
  auto file = io::MappedFile::open(o.path);
  if (!file.ok()) return false;  // load_cloud reports the error
  static constexpr char kPlaceDb[] = "LEX3DPDB";
  if (file.value()->size() < 8 || std::memcmp(file.value()->data(), kPlaceDb, 8) != 0) return false;
  SharedBytes bytes;
  bytes.data = file.value()->data();
  bytes.size = file.value()->size();
  bytes.owner = file.value();
  auto opened = PlaceDatabase::open(bytes);
  if (!opened.ok()) throw CliError(2, o.path + ": " + opened.status().to_string());
  const PlaceDatabase& db = opened.value();
  const PlaceFileInfo& fi = db.file_info();
  const PlaceStorageParams& st = db.storage();
  const std::string version = std::to_string(fi.major) + "." + std::to_string(fi.minor);
  const auto file_bytes = static_cast<std::uint64_t>(bytes.size);
  const auto scans = static_cast<std::uint64_t>(db.size());
  const auto words = static_cast<std::uint64_t>(db.has_alphabet() ? db.alphabet().size() : 0);
  const auto leaves = static_cast<std::uint64_t>(db.has_vocabulary() ? db.vocabulary()->leaves() : 0);
  if (o.json) {
    Json j;
    j.begin_object();
    j.value("file", o.path).value("kind", "place database").value("format_version", version);
    j.value("file_bytes", file_bytes).value("scans", scans).value("alphabet_words", words);
    j.value("descriptor", to_string(st.descriptor)).value("descriptor_bits", static_cast<std::uint64_t>(st.descriptor_bits));
    j.value("max_features", static_cast<std::uint64_t>(st.max_features));
    j.value("vocabulary_words", leaves).value("index_bytes", fi.index_bytes).value("dead_bytes", fi.dead_bytes);
    j.value("ignored_tail_bytes", fi.ignored_tail_bytes);
    j.end_object();
    std::printf("%s\n", j.str().c_str());
    return true;
  }
  std::printf("file           %s\n", o.path.c_str());
  std::printf("kind           lex3d place database, format %s, %llu bytes\n", version.c_str(),
              static_cast<unsigned long long>(file_bytes));
  std::printf("scans          %llu (%.1f KB a scan)\n", static_cast<unsigned long long>(scans),
              scans ? static_cast<double>(file_bytes) / 1024.0 / static_cast<double>(scans) : 0.0);
  std::printf("alphabet       %llu words\n", static_cast<unsigned long long>(words));
  std::printf("features       up to %d a scan, %s descriptors of %d bits a value\n", st.max_features,
              to_string(st.descriptor), st.descriptor_bits);
  if (leaves) std::printf("vocabulary     %llu words\n", static_cast<unsigned long long>(leaves));
  else std::printf("vocabulary     none\n");
  std::printf("index          %llu bytes", static_cast<unsigned long long>(fi.index_bytes));
  if (fi.dead_bytes) std::printf(", %llu bytes of earlier indexes", static_cast<unsigned long long>(fi.dead_bytes));
  if (fi.ignored_tail_bytes)
    std::printf(", %llu bytes after the committed state ignored", static_cast<unsigned long long>(fi.ignored_tail_bytes));
  std::printf("\n");
  return true;
}

void info_bag(const InfoOptions& o) {
  auto r = io::read_bag_info(o.path);
  if (!r.ok()) throw CliError(exit_code_for(r.status().code()), r.status().to_string());
  const io::BagInfo& b = r.value();
  if (o.json) {
    Json j;
    j.begin_object().value("file", o.path).value("format", "rosbag").value("bytes", b.file_bytes);
    j.value("messages", b.messages).value("start_s", b.start_s).value("end_s", b.end_s).begin_array("topics");
    for (const auto& t : b.topics) j.begin_object().value("topic", t.name).value("type", t.type).value("messages", t.messages).end_object();
    j.end_array().end_object();
    std::cout << j.str() << "\n";
    return;
  }
  std::printf("file           %s\nformat         ROS bag 2.0, %llu bytes\n", o.path.c_str(), static_cast<unsigned long long>(b.file_bytes));
  std::printf("messages       %llu over %.3f s\n", static_cast<unsigned long long>(b.messages), b.end_s - b.start_s);
  for (const auto& t : b.topics)
    std::printf("topic          %-32s %-28s %8llu messages\n", t.name.c_str(), t.type.c_str(), static_cast<unsigned long long>(t.messages));
}

void info_sensor_log(const InfoOptions& o, const io::ReadOptions& ro) {
  // (turn by turn: what each turn shows, not its points, is kept)
  struct Turn {
    std::uint64_t frame_id = 0, captured_ns = 0;
    std::size_t points = 0, no_returns = 0;
    std::uint32_t rows = 0, columns = 0;
    bool timed = false;
    double time_lo = 0.0, time_hi = 0.0;
    std::string time_name;
    FieldType time_type = FieldType::kFloat64;
  };
  std::vector<Turn> turns;
  auto reader = io::SensorLogReader::open(o.path, ro);
  if (!reader.ok()) throw CliError(exit_code_for(reader.status().code()), reader.status().to_string());
  for (;;) {
    auto next = reader.value()->next();
    if (!next.ok()) throw CliError(exit_code_for(next.status().code()), next.status().to_string());
    if (!next.value()) break;
    const io::SensorTurn& t = *next.value();
    const Cloud& c = t.cloud;
    Turn u;
    u.frame_id = t.frame_id;
    u.captured_ns = t.captured_ns;
    u.points = c.size();
    u.no_returns = t.no_returns;
    u.rows = c.rows;
    u.columns = c.columns;
    if (c.has_time()) {
      const auto [lo, hi] = std::minmax_element(c.time.begin(), c.time.end());
      u.timed = true;
      u.time_lo = *lo;
      u.time_hi = *hi;
      u.time_name = c.time_source.name;
      u.time_type = c.time_source.type;
    }
    turns.push_back(std::move(u));
  }
  const io::SensorLogInfo& i = reader.value()->info();
  if (o.json) {
    Json j;
    j.begin_object();
    j.value("file", o.path).value("format", "pcap").value("vendor", i.vendor).value("sensor", i.sensor);
    j.value("profile", i.profile);
    if (!i.metadata_path.empty()) j.value("metadata", i.metadata_path);
    if (!i.model_note.empty()) j.value("model", i.model_note);
    j.value("lasers", i.lasers).value("columns", i.columns).value("frames", i.frames);
    j.value("incomplete_frames_dropped", i.incomplete_frames).value("points", i.points).value("no_returns", i.no_returns);
    j.value("second_returns", i.second_returns);
    j.value("pcap_records", i.pcap_packets).value("udp_datagrams", i.udp_datagrams);
    j.value("fragmented_datagrams", i.fragmented_datagrams).value("incomplete_datagrams_dropped", i.incomplete_datagrams);
    j.value("lidar_packets", i.lidar_packets).value("other_packets", i.other_packets);
    j.begin_array("scans");
    for (const Turn& t : turns) {
      j.begin_object()
          .value("frame_id", t.frame_id)
          .value("points", t.points)
          .value("no_returns", t.no_returns)
          .value("rows", t.rows)
          .value("columns", t.columns);
      if (t.captured_ns > 0) j.value("captured_ns", t.captured_ns);
      if (t.timed) {
        j.begin_object("time_s").value("min", t.time_lo).value("max", t.time_hi);
        j.value("source_name", t.time_name).value("source_type", std::string(field_type_name(t.time_type)));
        j.end_object();
      }
      j.end_object();
    }
    j.end_array();
    j.end_object();
    std::cout << j.str() << "\n";
    return;
  }
  std::printf("file           %s\n", o.path.c_str());
  std::printf("format         pcap / %s %s\n", i.vendor.c_str(), i.profile.c_str());
  std::printf("sensor         %s, %u lasers, %u columns a turn\n", i.sensor.c_str(), i.lasers, i.columns);
  if (!i.metadata_path.empty()) std::printf("metadata       %s\n", i.metadata_path.c_str());
  if (!i.model_note.empty()) std::printf("model          %s\n", i.model_note.c_str());
  std::printf("frames         %zu complete (%zu incomplete dropped)\n", i.frames, i.incomplete_frames);
  std::printf("points         %zu (%zu no-returns not counted)\n", i.points, i.no_returns);
  if (i.second_returns) std::printf("second returns %zu (kept, each a point of its own: return 1)\n", i.second_returns);
  std::printf("packets        %zu lidar, %zu other; %zu capture records, %zu UDP datagrams (%zu reassembled from fragments, %zu cut by the capture dropped)\n",
              i.lidar_packets, i.other_packets, i.pcap_packets, i.udp_datagrams, i.fragmented_datagrams,
              i.incomplete_datagrams);
  for (std::size_t k = 0; k < turns.size(); ++k) {
    const Turn& t = turns[k];
    // (each point's time from the turn's first measurement, as the source gives it)
    std::string times;
    if (t.timed) {
      char buf[160];
      std::snprintf(buf, sizeof buf, ", times %.3f .. %.3f ms (%s %s)", t.time_lo * 1e3, t.time_hi * 1e3, t.time_name.c_str(),
                    field_type_name(t.time_type));
      times = buf;
    }
    if (t.captured_ns > 0) times += ", captured " + stamp_text(t.captured_ns);
    std::printf("  turn %-4zu    frame %llu: %zu points, %zu no-returns, %u x %u%s\n", k,
                static_cast<unsigned long long>(t.frame_id), t.points, t.no_returns, t.rows, t.columns, times.c_str());
  }
}

void run_info(const InfoOptions& o) {
  if (o.format == "auto" && (info_lex3d_file(o) || info_place_db(o))) return;
  const io::ReadOptions ro = read_options(parse_format_option(o.format), o.metadata, o.sensor_model);
  if (ro.format == io::Format::kAuto && io::is_rosbag(o.path)) {
    check_input_file(o.path);
    info_bag(o);
    return;
  }
  if (ro.format == io::Format::kPcap || (ro.format == io::Format::kAuto && io::is_sensor_log(o.path))) {
    info_sensor_log(o, ro);
    return;
  }
  const io::ReadResult r = load_cloud(o.path, ro);
  const Cloud& c = r.cloud;
  // How the scan fits a sensor profile (its lasers hit, the points' distance from the beams).
  std::optional<residual::ProfileFit> fit;
  if (!o.sensor.empty()) {
    Cloud fitted = c;
    auto f = residual::apply_sensor_profile(fitted, read_sensor_profile(o.sensor), o.path);
    if (!f.ok()) throw CliError(2, f.status().to_string());
    fit = f.value();
  }
  const Bounds b = compute_bounds(c);
  std::vector<float> ranges;
  ranges.reserve(c.size());
  const Eigen::Isometry3f T_sensor_cloud = c.T_cloud_sensor.inverse().cast<float>();
  for (const auto& p : c.points) ranges.push_back((T_sensor_cloud * p).norm());
  float imin = 0.0F, imax = 0.0F;
  if (c.has_intensity()) {
    const auto [lo, hi] = std::minmax_element(c.intensity.begin(), c.intensity.end());
    imin = *lo;
    imax = *hi;
  }
  // (the ring and time spans, and how the source stored ring, intensity and time)
  std::uint16_t ring_min = 0, ring_max = 0;
  if (c.has_rings()) {
    const auto [lo, hi] = std::minmax_element(c.ring.begin(), c.ring.end());
    ring_min = *lo;
    ring_max = *hi;
  }
  double time_min = 0.0, time_max = 0.0;
  if (c.has_time()) {
    const auto [lo, hi] = std::minmax_element(c.time.begin(), c.time.end());
    time_min = *lo;
    time_max = *hi;
  }
  const auto source_text = [](const SourceField& s, bool time) {
    if (!s.given()) return std::string();
    return " (" + s.name + " " + field_type_name(s.type) + (time && !is_float_type(s.type) ? " nanoseconds" : "") + ")";
  };
  const auto res = estimate_angular_resolution(c);
  const double rad2deg = 180.0 / M_PI;
  const double r_min = quantile(ranges, 0.0), r_med = quantile(ranges, 0.5), r_max = quantile(ranges, 1.0);

  if (o.json) {
    Json j;
    j.begin_object();
    j.value("file", o.path).value("format", io::format_name(r.format)).value("encoding", r.encoding);
    j.value("file_bytes", r.file_bytes).value("points", c.size());
    j.value("non_finite_dropped", r.non_finite_dropped).value("no_return_dropped", r.no_return_dropped);
    j.value("far_dropped", r.far_dropped);
    j.value("has_intensity", c.has_intensity());
    j.value("rows", c.rows).value("columns", c.columns).value("has_rings", c.has_rings());
    if (b.valid) {
      j.numbers("bounds_min", {b.min.x(), b.min.y(), b.min.z()});
      j.numbers("bounds_max", {b.max.x(), b.max.y(), b.max.z()});
    }
    j.begin_object("range_m").value("min", r_min).value("median", r_med).value("max", r_max).end_object();
    // (each with the name and type its source stored it in, where the reader recorded them)
    const auto source_json = [&j](const SourceField& src) {
      if (src.given()) j.value("source_name", src.name).value("source_type", std::string(field_type_name(src.type)));
    };
    if (c.has_intensity()) {
      j.begin_object("intensity").value("min", imin).value("max", imax);
      source_json(c.intensity_source);
      j.end_object();
    }
    if (c.has_rings()) {
      j.begin_object("ring").value("min", static_cast<std::uint64_t>(ring_min)).value("max", static_cast<std::uint64_t>(ring_max));
      source_json(c.ring_source);
      j.end_object();
    }
    if (c.has_time()) {
      j.begin_object("time_s").value("min", time_min).value("max", time_max);
      source_json(c.time_source);
      j.end_object();
    }
    if (res)
      j.begin_object("angular_resolution_deg")
          .value("azimuth", res->azimuth_rad * rad2deg)
          .value("elevation", res->elevation_rad * rad2deg)
          .end_object();
    j.value("has_world_pose", c.has_world_pose);
    if (fit)
      j.begin_object("sensor_profile")
          .value("file", o.sensor)
          .value("lasers", static_cast<std::uint64_t>(fit->lasers))
          .value("lasers_hit", static_cast<std::uint64_t>(fit->lasers_hit))
          .value("median_off_beam_m", fit->median_off_beam_m)
          .value("direction", static_cast<std::int64_t>(fit->direction))
          .value("firing_times", fit->firing_times)
          .end_object();
    if (c.georef) georef_json(j, *c.georef);
    if (!c.fields.empty()) {
      j.begin_array("fields");
      for (const IntegerField& f : c.fields) {
        // (a float field's keys order as its values: its least and greatest values)
        const auto mm = std::minmax_element(f.values.begin(), f.values.end());
        j.begin_object().value("name", f.name).value("type", std::string(field_type_name(f.type)));
        if (!f.values.empty() && is_float_type(f.type))
          j.value("min", static_cast<double>(key_float(*mm.first))).value("max", static_cast<double>(key_float(*mm.second)));
        else if (!f.values.empty())
          j.value("min", static_cast<std::int64_t>(*mm.first)).value("max", static_cast<std::int64_t>(*mm.second));
        j.end_object();
      }
      j.end_array();
    }
    if (!r.dropped_fields.empty()) {
      j.begin_array("fields_not_kept");
      for (const auto& f : r.dropped_fields) j.value({}, f);
      j.end_array();
    }
    j.end_object();
    std::cout << j.str() << "\n";
    return;
  }
  std::printf("file           %s\n", o.path.c_str());
  std::printf("format         %s%s%s\n", std::string(io::format_name(r.format)).c_str(),
              r.encoding.empty() ? "" : " / ", r.encoding.c_str());
  std::printf("file size      %llu bytes\n", static_cast<unsigned long long>(r.file_bytes));
  std::printf("points         %zu\n", c.size());
  std::printf("NaN/Inf dropped %zu\n", r.non_finite_dropped);
  if (r.far_dropped) std::printf("far dropped    %zu (beyond %.0f m)\n", r.far_dropped, r.far_limit_m);
  if (r.no_return_dropped)
    std::printf("no-return      %zu (%s)\n", r.no_return_dropped,
                c.no_return_directions.empty() ? "not points" : "kept as max-range directions");
  if (c.rows > 0) std::printf("organised      %u rows x %u columns\n", c.rows, c.columns);
  if (fit)
    std::printf("sensor profile %s: %zu of %zu lasers hit, points a median %.2f mm from the beams (azimuths %s with "
                "the column%s)\n",
                o.sensor.c_str(), fit->lasers_hit, fit->lasers, fit->median_off_beam_m * 1e3,
                fit->direction > 0 ? "grow" : "fall", fit->firing_times ? ", firing times included" : "");
  if (b.valid)
    std::printf("bounds         [%.3f %.3f %.3f] .. [%.3f %.3f %.3f] m\n", static_cast<double>(b.min.x()),
                static_cast<double>(b.min.y()), static_cast<double>(b.min.z()), static_cast<double>(b.max.x()),
                static_cast<double>(b.max.y()), static_cast<double>(b.max.z()));
  if (!ranges.empty()) std::printf("range          min %.3f  median %.3f  max %.3f m\n", r_min, r_med, r_max);
  if (c.has_intensity())
    std::printf("intensity      %.4g .. %.4g%s\n", static_cast<double>(imin), static_cast<double>(imax),
                source_text(c.intensity_source, false).c_str());
  if (c.has_rings())
    std::printf("ring           %u .. %u%s\n", unsigned{ring_min}, unsigned{ring_max}, source_text(c.ring_source, false).c_str());
  if (c.has_time())
    std::printf("time           %.9g .. %.9g s%s\n", time_min, time_max, source_text(c.time_source, true).c_str());
  if (res)
    std::printf("beam spacing   %.4f deg horizontal, %.4f deg vertical (estimated)\n", res->azimuth_rad * rad2deg,
                res->elevation_rad * rad2deg);
  if (c.has_world_pose) std::printf("world pose     yes\n");
  if (c.georef) print_georef(*c.georef, true);
  for (const IntegerField& f : c.fields) {
    if (f.values.empty()) continue;
    const auto mm = std::minmax_element(f.values.begin(), f.values.end());
    if (is_float_type(f.type))
      std::printf("field          %s (%s) %.9g .. %.9g\n", f.name.c_str(), field_type_name(f.type),
                  static_cast<double>(key_float(*mm.first)), static_cast<double>(key_float(*mm.second)));
    else
      std::printf("field          %s (%s) %d .. %d\n", f.name.c_str(), field_type_name(f.type), *mm.first, *mm.second);
  }
  for (const auto& f : r.dropped_fields) std::printf("not kept       %s\n", f.c_str());
}

}  // namespace

void register_info(CLI::App& app) {
  auto o = std::make_shared<InfoOptions>();
  CLI::App* sub = app.add_subcommand("info", "Describe a point cloud, model or alphabet file");
  sub->footer("Examples:\n  lex3d info scan.las\n  lex3d info model.lex3dm --json");
  sub->add_option("file", o->path, "Point cloud (.bin, .pcd, .ply, .xyz/.txt, .3d), or a lex3d model, alphabet or sequence file")->required();
  sub->add_option("--format", o->format, "Input format: auto, kitti, binxyz, pcd, ply, xyz, uos, pcap");
  sub->add_option("--metadata", o->metadata, "Metadata of a pcap: an Ouster metadata JSON, or a Velodyne calibration (db.xml, VeloView XML or the ROS driver's YAML; needed for an HDL-64E) (default: the .json, .xml, .yaml or .yml beside it, same stem)");
  sub->add_option("--sensor-model", o->sensor_model, "Read a Velodyne pcap as this model: vlp16, puck-hires, hdl32e, vlp32c or hdl64e (default: detected from the packets)");
  sub->add_option("--sensor", o->sensor,
                  "A point cloud: how it fits this sensor profile (formats/sensor_profile.md); exit 2 if it does not");
  sub->add_option("--alphabet", o->alphabet, "The alphabet file a model references (for its counts)");
  sub->add_flag("--json", o->json, "Print one JSON object");
  sub->callback([o] { run_info(*o); });
}

}  // namespace lex3d::cli
