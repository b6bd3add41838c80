// Velodyne data packets (1206-byte UDP payloads: 12 blocks of a 0xEEFF flag, an azimuth in
// 0.01° and 32 × (distance, reflectivity), then a µs timestamp and the return-mode and
// product bytes) of the VLP-16, Puck Hi-Res, HDL-32E and VLP-32C, decoded into one
// organised Cloud a turn with the published per-model tables (elevation and, for the
// VLP-32C, azimuth offset of each laser) and firing timing.
//
// Coordinates (Velodyne's convention, azimuth α clockwise from +y, elevation ω):
//   x = d cos ω sin α,  y = d cos ω cos α,  z = d sin ω
// with α interpolated for each laser's firing time between the block azimuths, plus the
// laser's azimuth offset.
//
// Dual-return packets (return mode 0x39) hold each firing twice, in a pair of blocks with
// the same azimuth: the first of the pair the last return, the second the strongest (the
// second strongest where the last is the strongest). Both are kept: the other block's
// returns that differ from the last are points of their own at the same pixel, with a
// `return` field (0 the last return, 1 the other).

#include <algorithm>
#include <array>
#include <deque>
#include <cmath>
#include <cstring>
#include <map>
#include <numeric>
#include <optional>
#include <string_view>

#include <Eigen/Core>

#include "core/xml_elements.hpp"
#include "io/internal.hpp"
#include "io/sensor_log_internal.hpp"

namespace lex3d::io::detail {

namespace {

constexpr std::size_t kPacketBytes = 1206;
constexpr std::size_t kMaxTurnFirings = 65536;  // firings a turn may take (27 MB of them)
constexpr std::size_t kBlocks = 12;

struct Model {
  const char* name;       // "VLP-16"
  const char* key;        // "vlp16" (--sensor-model)
  std::uint8_t product;   // factory byte
  unsigned lasers;        // lasers a firing
  unsigned firings_per_block;
  double firing_us;       // a firing sequence's duration (the column period)
  double slot_us;         // time between two firing slots of a sequence
  unsigned lasers_per_slot;  // lasers fired together (the VLP-32C fires them in pairs)
  double packet_us;       // nominal packet period (single return)
  double range_unit_m;    // distance unit
  std::array<double, 32> elevation_deg;
  std::array<double, 32> azimuth_deg;  // added to the firing's azimuth (clockwise), degrees
};

// Tables by laser id: VLP-16 manual (63-9243) table 9-1; Puck Hi-Res manual (63-9318),
// vertical angles; HDL-32E manual (63-9113) appendix; VLP-32C manual (63-9325) table 9-1
// (vertical angle and azimuth offset). Timing: the manuals' firing sequences (VLP-16 and
// Puck Hi-Res: 16 slots of 2.304 µs, two sequences a block; HDL-32E: 32 slots of
// 1.152 µs; VLP-32C: 16 pairs of lasers, 2.304 µs apart, in 55.296 µs, one a block).
const Model kVlp16{"VLP-16", "vlp16", 0x22, 16, 2, 55.296, 2.304, 1, 24 * 55.296, 0.002,
                   {-15, 1, -13, 3, -11, 5, -9, 7, -7, 9, -5, 11, -3, 13, -1, 15}, {}};
const Model kPuckHiRes{"Puck Hi-Res", "puck-hires", 0x24, 16, 2, 55.296, 2.304, 1, 24 * 55.296, 0.002,
                       {-10, 0.667, -8.667, 2, -7.333, 3.333, -6, 4.667, -4.667, 6, -3.333, 7.333, -2, 8.667, -0.667,
                        10},
                       {}};
const Model kHdl32{"HDL-32E", "hdl32e", 0x21, 32, 1, 46.08, 1.152, 1, 12 * 46.08, 0.002,
                   {-30.67, -9.33, -29.33, -8.00, -28.00, -6.67, -26.67, -5.33, -25.33, -4.00, -24.00,
                    -2.67,  -22.67, -1.33, -21.33, 0.00, -20.00, 1.33, -18.67, 2.67, -17.33, 4.00,
                    -16.00, 5.33,  -14.67, 6.67, -13.33, 8.00, -12.00, 9.33, -10.67, 10.67},
                   {}};
const Model kVlp32c{"VLP-32C", "vlp32c", 0x28, 32, 1, 55.296, 2.304, 2, 12 * 55.296, 0.004,
                    {-25,    -1,    -1.667, -15.639, -11.31, 0,      -0.667, -8.843, -7.254, 0.333, -0.333,
                     -6.148, -5.333, 1.333, 0.667,   -4,     -4.667, 1.667,  1,      -3.667, -3.333, 3.333,
                     2.333,  -2.667, -3,    7,       4.667,  -2.333, -2,     15,     10.333, -1.333},
                    {1.4, -4.2, 1.4, -1.4, 1.4, -1.4, 4.2, -1.4, 1.4, -4.2, 1.4, -1.4, 4.2, -1.4, 4.2, -1.4,
                     1.4, -4.2, 1.4, -4.2, 4.2, -1.4, 1.4, -1.4, 1.4, -1.4, 1.4, -4.2, 4.2, -1.4, 1.4, -1.4}};
const Model* const kModels[] = {&kVlp16, &kPuckHiRes, &kHdl32, &kVlp32c};
// The HDL-64E (S2, S3 single return): upper (lasers 0-31) and lower (32-63) blocks of one
// azimuth, no factory byte, its angles from the unit's calibration only; points at their
// block's azimuth (as the calibration's rotation corrections assume).
const Model kHdl64{"HDL-64E", "hdl64e", 0x00, 64, 1, 0.0, 0.0, 1, 0.0, 0.002, {}, {}};

const Model* by_product(std::uint8_t b) {
  for (const Model* m : kModels)
    if (m->product == b) return m;
  return nullptr;
}

std::string hex(unsigned v) {
  char buf[8];
  std::snprintf(buf, sizeof buf, "0x%02X", v);
  return buf;
}

std::string product_name(std::uint8_t b) {
  if (const Model* m = by_product(b)) return m->name;
  switch (b) {
    case 0x31: return "Velarray";
    case 0xA1: return "VLS-128";
    default: return "unknown product " + hex(b);
  }
}

std::uint16_t le16(const std::uint8_t* p) { return static_cast<std::uint16_t>(p[0] | (p[1] << 8)); }
std::uint32_t le32(const std::uint8_t* p) {
  return static_cast<std::uint32_t>(p[0]) | (static_cast<std::uint32_t>(p[1]) << 8) |
         (static_cast<std::uint32_t>(p[2]) << 16) | (static_cast<std::uint32_t>(p[3]) << 24);
}

/// One firing of every laser: its start azimuth (degrees, unwrapped) and its returns.
struct Firing {
  double azimuth_deg = 0.0;  // start of the firing, unwrapped across turns
  double step_deg = 0.0;     // azimuth advance over one firing period
  std::int64_t time_ns = 0;  // start of the firing: the packet's timestamp (unwrapped across hours) plus its place in the packet
  std::uint64_t captured_ns = 0;  // when the capture recorded its packet (0: not known)
  std::array<std::uint16_t, 64> dist{};
  std::array<std::uint8_t, 64> refl{};
  std::array<std::uint16_t, 64> dist2{};  // dual return: the pair's other block's return, where it differs
  std::array<std::uint8_t, 64> refl2{};
};

/// One laser as its points are placed: at the firing's azimuth advanced by `share` of the
/// firing step and by `azimuth_deg` (clockwise), elevation `elevation_deg`, the distance
/// plus `dist_m`, from a beam origin `vert_offset_m` along the beam's upward normal and
/// `horiz_offset_m` to its side (Velodyne's calibration model); with `two_point`, the
/// HDL-64E S2 manual's near-range corrections (dist_x_m, dist_y_m) of x and y.
struct Laser {
  double elevation_deg = 0.0, azimuth_deg = 0.0, share = 0.0;
  double dist_m = 0.0, vert_offset_m = 0.0, horiz_offset_m = 0.0;
  bool two_point = false;
  double dist_x_m = 0.0, dist_y_m = 0.0;
};

/// A calibration file's lasers (by laser id) and distance unit (0: not given).
struct Calibration {
  std::vector<Laser> lasers;
  double range_unit_m = 0.0;
};

Status calibration_error(const std::string& origin, const std::string& what) { return bad_data(msg(origin, what)); }

/// Checks a laser's values; an error names the laser and the field.
std::optional<std::string> check_laser(const Laser& l, std::size_t id) {
  const auto outside = [&](const char* name, double v, double limit) -> std::optional<std::string> {
    if (std::isfinite(v) && std::abs(v) <= limit) return std::nullopt;
    char buf[64];
    std::snprintf(buf, sizeof buf, "%g", v);
    return "laser " + std::to_string(id) + ": " + name + " " + buf + " is not a number within +-" +
           std::to_string(static_cast<int>(limit));
  };
  for (auto e : {outside("elevation (degrees)", l.elevation_deg, 90), outside("rotation (degrees)", l.azimuth_deg, 180),
                 outside("distance correction (m)", l.dist_m, 10), outside("x distance correction (m)", l.dist_x_m, 10),
                 outside("y distance correction (m)", l.dist_y_m, 10), outside("vertical offset (m)", l.vert_offset_m, 10),
                 outside("horizontal offset (m)", l.horiz_offset_m, 10)})
    if (e) return e;
  return std::nullopt;
}

/// Lasers by id, which must be 0..n-1, each once.
StatusOr<Calibration> by_ids(const std::string& origin, std::vector<std::pair<long, Laser>> found, double unit) {
  if (found.empty()) return calibration_error(origin, "no laser found in the calibration");
  if (found.size() > 64) return calibration_error(origin, std::to_string(found.size()) + " lasers, more than 64");
  std::sort(found.begin(), found.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  Calibration c;
  c.range_unit_m = unit;
  for (std::size_t k = 0; k < found.size(); ++k) {
    if (found[k].first != static_cast<long>(k))
      return calibration_error(origin, "laser ids are not 0.." + std::to_string(found.size() - 1) + " each once (" +
                                           std::to_string(k) + ")");
    if (auto e = check_laser(found[k].second, k)) return calibration_error(origin, *e);
    c.lasers.push_back(found[k].second);
  }
  if (!(unit == 0.0 || (std::isfinite(unit) && unit > 0.0 && unit <= 0.1)))
    return calibration_error(origin, "distance resolution is not within (0, 0.1] m");
  return c;
}

/// Velodyne's db.xml or VeloView's calibration XML: distLSB_ (cm) and one <px> a laser with
/// id_, vertCorrection_ and rotCorrection_ (degrees; the rotation is subtracted from the
/// firing's azimuth), distCorrection_, distCorrectionX_, distCorrectionY_,
/// vertOffsetCorrection_ and horizOffsetCorrection_ (cm).
StatusOr<Calibration> parse_calibration_xml(std::string_view text, const std::string& origin) {
  double unit = 0.0;
  if (const auto lsb = ::lex3d::detail::xml_element(text, "distLSB_")) {
    const auto v = ::lex3d::detail::text_number(lsb->first);
    if (!v) return calibration_error(origin, "distLSB_ is not a number");
    unit = *v / 100.0;
  }
  std::vector<std::pair<long, Laser>> found;
  std::size_t at = 0;
  while (const auto px = ::lex3d::detail::xml_element(text, "px", at)) {
    at = px->second;
    const std::string where = "laser entry " + std::to_string(found.size()) + ": ";
    const auto number = [&](const char* name, std::optional<double>& out) -> std::optional<std::string> {
      const auto e = ::lex3d::detail::xml_element(px->first, name);
      if (!e) return std::nullopt;
      out = ::lex3d::detail::text_number(e->first);
      if (!out) return where + name + " is not a number";
      return std::nullopt;
    };
    std::optional<double> id, vert, rot, dist, dist_x, dist_y, vert_off, horiz_off;
    for (auto e : {number("id_", id), number("vertCorrection_", vert), number("rotCorrection_", rot),
                   number("distCorrection_", dist), number("distCorrectionX_", dist_x),
                   number("distCorrectionY_", dist_y), number("vertOffsetCorrection_", vert_off),
                   number("horizOffsetCorrection_", horiz_off)})
      if (e) return calibration_error(origin, *e);
    if (!id || *id != std::floor(*id) || *id < 0 || *id > 1023)
      return calibration_error(origin, where + "id_ is missing or not a laser number");
    if (!vert) return calibration_error(origin, where + "vertCorrection_ is missing");
    Laser l;
    l.elevation_deg = *vert;
    l.azimuth_deg = rot ? -*rot : 0.0;
    l.dist_m = dist ? *dist / 100.0 : 0.0;
    l.vert_offset_m = vert_off ? *vert_off / 100.0 : 0.0;
    l.horiz_offset_m = horiz_off ? *horiz_off / 100.0 : 0.0;
    l.two_point = dist_x.has_value() && dist_y.has_value();
    l.dist_x_m = dist_x ? *dist_x / 100.0 : l.dist_m;
    l.dist_y_m = dist_y ? *dist_y / 100.0 : l.dist_m;
    found.emplace_back(static_cast<long>(*id), l);
  }
  return by_ids(origin, std::move(found), unit);
}

/// The YAML of the ROS velodyne driver: distance_resolution (m) and a list `lasers` of
/// laser_id, vert_correction and rot_correction (radians; the rotation is subtracted from
/// the firing's azimuth), dist_correction, dist_correction_x, dist_correction_y,
/// vert_offset_correction, horiz_offset_correction (m), two_pt_correction_available; each
/// item in block style (`- key: value`, then `  key: value` lines) or flow style
/// (`- {key: value, ...}`).
StatusOr<Calibration> parse_calibration_yaml(std::string_view text, const std::string& origin) {
  double unit = 0.0;
  std::vector<std::map<std::string, std::string>> items;
  std::size_t line_no = 0;
  const auto add_pairs = [&](std::string_view t, std::map<std::string, std::string>& into) -> bool {
    // "k: v" or "k: v, k: v" (inside braces)
    while (!t.empty()) {
      const std::size_t comma = t.find(',');
      const std::string_view pair = trim(t.substr(0, comma));
      t = comma == std::string_view::npos ? std::string_view() : t.substr(comma + 1);
      if (pair.empty()) continue;
      const std::size_t colon = pair.find(':');
      if (colon == std::string_view::npos) return false;
      into[std::string(trim(pair.substr(0, colon)))] = std::string(trim(pair.substr(colon + 1)));
    }
    return true;
  };
  bool in_lasers = false;
  while (!text.empty()) {
    const std::size_t nl = text.find('\n');
    std::string_view line = text.substr(0, nl);
    text = nl == std::string_view::npos ? std::string_view() : text.substr(nl + 1);
    ++line_no;
    if (const std::size_t hash = line.find('#'); hash != std::string_view::npos) line = line.substr(0, hash);
    const bool indented = !line.empty() && is_space(line.front());
    line = trim(line);
    if (line.empty()) continue;
    const std::string where = "line " + std::to_string(line_no) + ": ";
    if (line.front() == '-') {
      if (!in_lasers) return calibration_error(origin, where + "a list item outside `lasers:`");
      std::string_view rest = trim(line.substr(1));
      items.emplace_back();
      if (!rest.empty() && rest.front() == '{') {
        if (rest.back() != '}') return calibration_error(origin, where + "a flow mapping without its closing brace");
        rest = rest.substr(1, rest.size() - 2);
      }
      if (!add_pairs(rest, items.back())) return calibration_error(origin, where + "not `key: value`");
      continue;
    }
    if (indented && in_lasers && !items.empty()) {
      if (!add_pairs(line, items.back())) return calibration_error(origin, where + "not `key: value`");
      continue;
    }
    std::map<std::string, std::string> top;
    if (!add_pairs(line, top) || top.size() != 1) return calibration_error(origin, where + "not `key: value`");
    const auto& [key, value] = *top.begin();
    in_lasers = key == "lasers";
    if (key == "distance_resolution") {
      const auto v = ::lex3d::detail::text_number(value);
      if (!v) return calibration_error(origin, where + "distance_resolution is not a number");
      unit = *v;
    }
  }
  std::vector<std::pair<long, Laser>> found;
  for (std::size_t k = 0; k < items.size(); ++k) {
    const auto& m = items[k];
    const std::string where = "laser entry " + std::to_string(k) + ": ";
    const auto number = [&](const char* name, double& out, bool required) -> std::optional<std::string> {
      const auto it = m.find(name);
      if (it == m.end()) return required ? std::optional<std::string>(where + name + " is missing") : std::nullopt;
      const auto v = ::lex3d::detail::text_number(it->second);
      if (!v) return where + name + " is not a number";
      out = *v;
      return std::nullopt;
    };
    double id = -1, vert = 0, rot = 0;
    Laser l;
    for (auto e : {number("laser_id", id, true), number("vert_correction", vert, true),
                   number("rot_correction", rot, false), number("dist_correction", l.dist_m, false),
                   number("vert_offset_correction", l.vert_offset_m, false),
                   number("horiz_offset_correction", l.horiz_offset_m, false)})
      if (e) return calibration_error(origin, *e);
    l.dist_x_m = l.dist_y_m = l.dist_m;
    for (auto e : {number("dist_correction_x", l.dist_x_m, false), number("dist_correction_y", l.dist_y_m, false)})
      if (e) return calibration_error(origin, *e);
    if (id != std::floor(id) || id < 0 || id > 1023) return calibration_error(origin, where + "laser_id is not a laser number");
    const auto two = m.find("two_pt_correction_available");
    l.two_point = two != m.end() && (to_lower(two->second) == "true" || two->second == "1");
    l.elevation_deg = vert * 180.0 / M_PI;
    l.azimuth_deg = -rot * 180.0 / M_PI;
    found.emplace_back(static_cast<long>(id), l);
  }
  return by_ids(origin, std::move(found), unit);
}

StatusOr<Calibration> read_calibration(const std::string& path) {
  auto bytes = read_file(path, 16U << 20);
  if (!bytes.ok()) return bytes.status();
  const std::string_view text(reinterpret_cast<const char*>(bytes.value().data()), bytes.value().size());
  std::size_t first = text.substr(0, 3) == "\xEF\xBB\xBF" ? 3 : 0;
  while (first < text.size() && std::isspace(static_cast<unsigned char>(text[first]))) ++first;
  if (first == text.size()) return calibration_error(path, "the calibration file is empty");
  if (text[first] == '<') return parse_calibration_xml(text, path);
  return parse_calibration_yaml(text, path);
}

/// A point of laser `l` at distance `d` (metres, the laser's correction added) and azimuth
/// `alpha` (radians, clockwise from +y).
Eigen::Vector3f place(const Laser& l, double cw, double sw, double d, double alpha) {
  const double sa = std::sin(alpha), ca = std::cos(alpha);
  double xy = d * cw - l.vert_offset_m * sw;
  double x = xy * sa - l.horiz_offset_m * ca;
  double y = xy * ca + l.horiz_offset_m * sa;
  double z = d * sw + l.vert_offset_m * cw;
  if (l.two_point) {
    // The HDL-64E S2 manual's two-point calibration: the distance correction of x moves
    // linearly from dist_x_m at |x| = 2.4 m to dist_m at 25.04 m, that of y (and z) from
    // dist_y_m at |y| = 1.93 m.
    const double cx = (l.dist_m - l.dist_x_m) * (std::abs(x) - 2.4) / (25.04 - 2.4) + l.dist_x_m - l.dist_m;
    const double cy = (l.dist_m - l.dist_y_m) * (std::abs(y) - 1.93) / (25.04 - 1.93) + l.dist_y_m - l.dist_m;
    x = ((d + cx) * cw - l.vert_offset_m * sw) * sa - l.horiz_offset_m * ca;
    xy = (d + cy) * cw - l.vert_offset_m * sw;
    y = xy * ca + l.horiz_offset_m * sa;
    z = (d + cy) * sw + l.vert_offset_m * cw;
  }
  return {static_cast<float>(x), static_cast<float>(y), static_cast<float>(z)};
}

double median(std::vector<double> v) {
  if (v.empty()) return std::nan("");
  const auto k = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

}  // namespace

bool is_velodyne_packet(const std::vector<std::uint8_t>& payload) {
  return payload.size() == kPacketBytes && payload[0] == 0xFF && (payload[1] == 0xEE || payload[1] == 0xDD);
}

namespace {

/// The Velodyne decoder, fed one datagram at a time. The first kVelodyneWindow data packets
/// (or all, in a shorter capture) are held until the model, return mode and packet period
/// are read from them; then every packet's firings are queued and each turn handed on
/// (SensorTurn) as soon as a firing past its 360° comes.
class VelodyneDecoder final : public LogDecoder {
 public:
  VelodyneDecoder(std::string path, std::string model_key, std::string calibration_path, SensorLogInfo& info)
      : path_(std::move(path)), model_key_(std::move(model_key)), calibration_path_(std::move(calibration_path)),
        info_(info) {
    info.vendor = "velodyne";
  }

  Status push(const Datagram& d) override {
    if (d.truncated && (d.dst_port == 2368 || d.claimed == kPacketBytes ||
                        (d.payload.size() >= 2 && d.payload[0] == 0xFF && (d.payload[1] == 0xEE || d.payload[1] == 0xDD))))
      return bad_data(msg(path_, "capture record " + std::to_string(d.record) + ": Velodyne data packet truncated: " +
                                     std::to_string(d.payload.size()) + " of " + std::to_string(d.claimed) +
                                     " bytes captured"));
    if (!is_velodyne_packet(d.payload) || d.truncated) {
      ++info_.other_packets;
      return {};
    }
    ++info_.lidar_packets;
    if (!started_) {
      window_.push_back(d);
      return window_.size() >= kVelodyneWindow ? start() : Status{};
    }
    return packet(d);
  }

  Status finish() override {
    if (!started_) {
      if (window_.empty()) return bad_data(msg(path_, "no Velodyne data packets"));
      Status s = start();
      if (!s.ok()) return s;
    }
    close_turns(true);
    if (!turn_columns_.empty()) {
      std::vector<double> c(turn_columns_.begin(), turn_columns_.end());
      info_.columns = static_cast<std::uint32_t>(median(c));
    }
    return {};
  }

 private:
  /// The model and everything read from the first packets; then those packets' firings.
  Status start() {
    started_ = true;
    // A calibration file (db.xml, VeloView's XML or the ROS driver's YAML) gives the lasers'
    // angles and offsets; an HDL-64E (upper 0xEEFF and lower 0xDDFF blocks) needs one.
    std::optional<Calibration> calibration;
    if (!calibration_path_.empty()) {
      auto c = read_calibration(calibration_path_);
      if (!c.ok()) return c.status();
      calibration = std::move(c).value();
      info_.metadata_path = calibration_path_;
    }
    const std::vector<std::uint8_t>& front = window_.front().payload;
    bool lower_blocks = false;
    for (std::size_t k = 0; k < kBlocks; ++k) lower_blocks = lower_blocks || front[k * 100 + 1] == 0xDD;
    hdl64_ = lower_blocks || to_lower(model_key_) == kHdl64.key;

    // The model: the factory byte, checked against the packet period (the firing timing is
    // fixed per model, the azimuth step is not: it follows the motor speed). An HDL-64E has
    // no factory byte (its last two bytes are status): its blocks tell it.
    product_ = front[1205];
    mode_ = front[1204];
    for (const Datagram& d : window_) {
      Status s = check_factory_bytes(d);
      if (!s.ok()) return s;
    }
    std::vector<double> dt;
    for (std::size_t i = 1; i < window_.size(); ++i) {
      const double a = le32(window_[i - 1].payload.data() + 1200);
      const double b = le32(window_[i].payload.data() + 1200);
      if (b > a) dt.push_back(b - a);
    }
    const double period_us = median(dt);
    // Dual-return packets hold half the firings of single-return ones: twice as many.
    dual_ = !hdl64_ && mode_ == 0x39;
    const double packet_share = dual_ ? 0.5 : 1.0;
    const auto timing_fits = [&](const Model* m) {
      return std::isfinite(period_us) && std::abs(period_us - m->packet_us * packet_share) < 0.1 * m->packet_us * packet_share;
    };
    const Model* timing = nullptr;  // the first model (in kModels' order) whose packet period fits
    for (const Model* m : kModels)
      if (timing == nullptr && timing_fits(m)) timing = m;
    const Model* by_byte = by_product(product_);
    const Model* model = nullptr;
    char period_text[64];
    std::snprintf(period_text, sizeof period_text, "%.0f", period_us);
    std::string keys;
    for (const std::string& k : velodyne_models()) keys += (keys.empty() ? "" : ", ") + k;
    if (hdl64_) {
      if (!model_key_.empty() && to_lower(model_key_) != kHdl64.key)
        return {ErrorCode::kInvalidArgument, "sensor model '" + printable(model_key_, 32) +
                                                 "' does not fit the capture: its upper and lower blocks are an HDL-64E's"};
      if (!calibration)
        return bad_data(msg(path_, "an HDL-64E capture needs the sensor's calibration (db.xml or the ROS driver's YAML, "
                                   "beside the capture with its stem or given with --metadata)"));
      model = &kHdl64;
      info_.model_note = lower_blocks ? "upper and lower blocks (HDL-64E); calibration " + calibration_path_
                                      : "given: HDL-64E; calibration " + calibration_path_;
    } else if (!model_key_.empty()) {
      const std::string k = to_lower(model_key_);
      for (const Model* m : kModels)
        if (k == m->key) model = m;
      if (model == nullptr)
        return {ErrorCode::kInvalidArgument, "sensor model '" + printable(model_key_, 32) + "' is not known (" + keys + ")"};
      info_.model_note = std::string("given: ") + model->name + "; factory byte " + hex(product_) + " (" +
                         product_name(product_) + "), packets every " + period_text + " us";
    } else if (by_byte != nullptr && timing != nullptr && !timing_fits(by_byte)) {
      model = timing;
      info_.model_note = std::string("read as ") + timing->name + ": the factory byte " + hex(product_) + " says " +
                         by_byte->name + " but packets arrive every " + period_text + " us, the " + timing->name + "'s period";
    } else if (by_byte != nullptr) {
      model = by_byte;
      info_.model_note = std::string("factory byte ") + hex(product_) + ", packets every " + period_text + " us" +
                         (timing_fits(by_byte) ? " (agrees)" : " (timing not conclusive)");
    } else if (timing != nullptr) {
      model = timing;
      info_.model_note = std::string("read as ") + timing->name + " from the packet period (" + period_text +
                         " us); factory byte " + hex(product_) + " (" + product_name(product_) + ")";
    } else {
      std::string names;
      for (const Model* m : kModels) names += std::string(names.empty() ? "" : ", ") + m->name;
      return bad_data(msg(path_, "Velodyne " + product_name(product_) + " (factory byte " + hex(product_) +
                                     ") is not supported (" + names + "; HDL-64E with its calibration; give --sensor-model to read it as one)"));
    }
    if (!hdl64_ && mode_ != 0x37 && mode_ != 0x38 && mode_ != 0x39)
      return bad_data(msg(path_, "Velodyne return mode byte " + hex(mode_) + " is not one of 0x37 (strongest), 0x38 (last), 0x39 (dual)"));
    model_ = model;
    info_.sensor = model->name;
    info_.profile = hdl64_ ? "single return" : mode_ == 0x37 ? "strongest" : mode_ == 0x38 ? "last" : "dual (both returns kept)";
    info_.lasers = model->lasers;

    // The lasers: the model's published table, or the calibration's (its laser count must be
    // the model's); the range unit the calibration's where it gives one.
    lasers_.assign(model->lasers, Laser{});
    range_unit_ = model->range_unit_m;
    // (laser l fires slot_us · its slot after the sequence starts: that share of the firing step)
    for (unsigned l = 0; l < model->lasers; ++l) {
      lasers_[l].share = model->firing_us > 0.0 ? (l / model->lasers_per_slot) * model->slot_us / model->firing_us : 0.0;
      if (l < 32) {
        lasers_[l].elevation_deg = model->elevation_deg[l];
        lasers_[l].azimuth_deg = model->azimuth_deg[l];
      }
    }
    if (calibration) {
      if (calibration->lasers.size() != model->lasers)
        return bad_data(msg(path_, "the calibration " + calibration_path_ + " has " +
                                       std::to_string(calibration->lasers.size()) + " lasers, the " + model->name +
                                       " capture " + std::to_string(model->lasers)));
      for (unsigned l = 0; l < model->lasers; ++l) {
        const double share = lasers_[l].share;
        lasers_[l] = calibration->lasers[l];
        lasers_[l].share = share;
      }
      if (calibration->range_unit_m > 0.0) range_unit_ = calibration->range_unit_m;
    }
    geometry_source_ = calibration ? "calibration " + calibration_path_ : "model table";

    // Firings in capture order, the azimuth unwrapped. A dual-return packet's block pairs
    // share an azimuth: the first block of each pair is the firing kept. An HDL-64E's upper
    // and lower blocks of one azimuth make one firing of its 64 lasers.
    block_stride_ = dual_ || hdl64_ ? 2 : 1;
    // Firing times: the packet's timestamp (µs past the hour, its first firing's) plus the
    // firing periods before it in the packet; an HDL-64E's period is the packet period over
    // its firings (its manual gives no sequence timing).
    const auto firings_per_packet = static_cast<double>(kBlocks / block_stride_ * model->firings_per_block);
    firing_ns_ = model->firing_us > 0.0       ? 1000.0 * model->firing_us
                 : std::isfinite(period_us) ? 1000.0 * period_us / firings_per_packet
                                            : 0.0;
    slot_ns_ = static_cast<std::int64_t>(std::llround(1000.0 * model->slot_us));

    // Rings: lasers ordered by elevation, lowest first.
    laser_of_ring_.resize(model->lasers);
    std::iota(laser_of_ring_.begin(), laser_of_ring_.end(), 0U);
    std::stable_sort(laser_of_ring_.begin(), laser_of_ring_.end(),
                     [&](unsigned a, unsigned b) { return lasers_[a].elevation_deg < lasers_[b].elevation_deg; });

    for (const Datagram& d : window_) {
      Status s = firings_of(d);
      if (!s.ok()) return s;
    }
    window_.clear();
    window_.shrink_to_fit();
    // The firing step a turn's holes are measured in: the median over the first packets.
    std::vector<double> steps;
    for (const auto& f : firings_) steps.push_back(f.step_deg);
    step_ = median(steps);
    if (!firings_.empty()) a0_ = firings_.front().azimuth_deg;
    close_turns(false);
    return {};
  }

  [[nodiscard]] Status check_factory_bytes(const Datagram& d) const {
    if (!hdl64_ && (d.payload[1205] != product_ || d.payload[1204] != mode_))
      return bad_data(msg(path_, "capture record " + std::to_string(d.record) +
                                     ": the factory bytes change within the capture (two sensors on one port?)"));
    return {};
  }

  Status packet(const Datagram& d) {
    Status s = check_factory_bytes(d);
    if (!s.ok()) return s;
    s = firings_of(d);
    if (!s.ok()) return s;
    close_turns(false);
    return {};
  }

  /// The packet's firings, queued.
  Status firings_of(const Datagram& d) {
    constexpr std::int64_t kHourUs = 3600LL * 1000000LL;
    const Model* model = model_;
    const std::uint8_t* b = d.payload.data();
    auto stamp = static_cast<std::int64_t>(le32(b + 1200));
    if (prev_stamp_ >= 0 && stamp + hours_us_ < prev_stamp_ - kHourUs / 2) hours_us_ += kHourUs;
    stamp += hours_us_;
    prev_stamp_ = stamp;
    std::size_t fired = 0;  // firings of this packet so far
    std::array<double, kBlocks> az{};
    for (std::size_t k = 0; k < kBlocks; ++k) {
      const std::uint8_t* blk = b + k * 100;
      const std::uint8_t want = hdl64_ && k % 2 == 1 ? 0xDD : 0xEE;
      if (blk[0] != 0xFF || blk[1] != want)
        return bad_data(msg(path_, "capture record " + std::to_string(d.record) + ": block " + std::to_string(k) +
                                       " has flag " + hex(blk[0]) + hex(blk[1]).substr(2) +
                                       (hdl64_ ? " (an HDL-64E's blocks alternate upper 0xFFEE and lower 0xFFDD)"
                                               : blk[1] == 0xDD ? " (an HDL-64E lower block in another model's packet)"
                                                                : " (not a data block)")));
      const std::uint16_t a = le16(blk + 2);
      if (a >= 36000)
        return bad_data(msg(path_, "capture record " + std::to_string(d.record) + ": block " + std::to_string(k) +
                                       " azimuth " + std::to_string(a) + " is not below 36000 (0.01 degree units)"));
      az[k] = a / 100.0;
      if (block_stride_ == 2 && k % 2 == 1 && le16(blk + 2) != le16(blk - 100 + 2))
        return bad_data(msg(path_, "capture record " + std::to_string(d.record) + ": " +
                                       (hdl64_ ? "upper and lower blocks " : "dual-return blocks ") + std::to_string(k - 1) +
                                       " and " + std::to_string(k) + " differ in azimuth" +
                                       (hdl64_ ? " (a dual-return HDL-64E S3 capture is not supported)" : "")));
    }
    for (std::size_t k = 0; k < kBlocks; k += block_stride_) {
      const std::size_t next = k + block_stride_;
      double gap = next < kBlocks ? az[next] - az[k] : last_gap_;
      if (next < kBlocks && gap < 0) gap += 360.0;
      if (!std::isfinite(gap)) gap = 0.0;
      if (next < kBlocks) last_gap_ = gap;
      const double a = az[k];
      if (prev_ >= 0.0 && a + unwrap_ < prev_ - 180.0) unwrap_ += 360.0;
      const double a_unwrapped = a + unwrap_;
      prev_ = a_unwrapped;
      const std::uint8_t* blk = b + k * 100 + 4;
      const double block_step = gap / model->firings_per_block;
      for (unsigned s = 0; s < model->firings_per_block; ++s) {
        Firing f;
        f.azimuth_deg = a_unwrapped + block_step * s;
        f.step_deg = block_step;
        f.time_ns = 1000 * stamp + std::llround(firing_ns_ * static_cast<double>(fired++));
        f.captured_ns = d.captured_ns;
        for (unsigned l = 0; l < model->lasers; ++l) {
          // (an HDL-64E's lasers 32-63 in the lower block, 100 bytes on)
          const std::uint8_t* ch = hdl64_ ? blk + (l / 32) * 100 + (l % 32) * 3 : blk + (s * model->lasers + l) * 3;
          f.dist[l] = le16(ch);
          f.refl[l] = ch[2];
          if (dual_) {
            const std::uint16_t other = le16(ch + 100);
            if (other != 0 && other != f.dist[l]) {
              f.dist2[l] = other;
              f.refl2[l] = ch[102];
            }
          }
        }
        firings_.push_back(f);
      }
    }
    return {};
  }

  /// Turns: 360° of azimuth from the capture's first firing on, each handed on once a
  /// firing past it is queued (`at_end`: the capture's end, where the turn it cuts is
  /// counted incomplete). A turn with a hole (an azimuth jump of more than 5 firing steps:
  /// lost packets) is dropped and counted. So is one that has not come round in
  /// kMaxTurnFirings firings (a head not spinning, or spinning up: 18 times a 300 rpm
  /// VLP-16's turn); the next starts at the newest firing.
  void close_turns(bool at_end) {
    while (!firings_.empty()) {
      const double end_az = a0_ + 360.0 * static_cast<double>(turn_ + 1);
      std::size_t end = 0;
      while (end < firings_.size() && firings_[end].azimuth_deg < end_az) ++end;
      if (end >= firings_.size()) {  // the capture ends inside this turn, or its packets are still to come
        if (at_end) {
          ++info_.incomplete_frames;
          firings_.clear();
        } else if (firings_.size() > kMaxTurnFirings) {
          ++info_.incomplete_frames;
          const Firing last = firings_.back();
          firings_.clear();
          firings_.push_back(last);
          ++turn_;
          a0_ = last.azimuth_deg - 360.0 * static_cast<double>(turn_);
        }
        return;
      }
      bool hole = false;
      for (std::size_t i = 1; i < end; ++i) hole = hole || firings_[i].azimuth_deg - firings_[i - 1].azimuth_deg > 5.0 * step_;
      if (hole || end < 2) ++info_.incomplete_frames;
      else emit(end);
      firings_.erase(firings_.begin(), firings_.begin() + static_cast<std::ptrdiff_t>(end));
      ++turn_;
    }
  }

  /// The turn of the queue's first `end` firings.
  void emit(std::size_t end) {
    const Model* model = model_;
    const auto columns = static_cast<std::uint32_t>(end);
    Cloud cloud;
    cloud.rows = model->lasers;
    cloud.columns = columns;
    IntegerField* which = nullptr;  // dual return: each point's return (0 last, 1 the other)
    if (dual_) {
      cloud.fields.push_back({kReturnField, {}, FieldType::kUint8});
      which = &cloud.fields.back();
    }
    SensorGeometry g;
    g.columns = columns;
    g.direction = -1;
    // The grid's column 0: the first firing's azimuth moved by the mean offset of all the
    // firings of the turn from a grid of 360°/columns steps (least squares for that step).
    double start = firings_[0].azimuth_deg, mean_offset = 0.0;
    for (std::size_t i = 0; i < end; ++i) mean_offset += firings_[i].azimuth_deg - (start + 360.0 * static_cast<double>(i) / columns);
    start += mean_offset / static_cast<double>(columns);
    g.azimuth0 = std::remainder(M_PI / 2 - start * M_PI / 180.0, 2.0 * M_PI);
    g.source = geometry_source_;
    g.sensor = model->name;
    for (unsigned r = 0; r < model->lasers; ++r) {
      const Laser& l = lasers_[laser_of_ring_[r]];
      const double w = l.elevation_deg * M_PI / 180.0;
      g.elevation.push_back(w);
      // The beam points azimuth_deg clockwise of its firing's column, fired `share` of a
      // step after it; its origin lies vert_offset along the beam's upward normal (height
      // vert_offset·cos w, vert_offset·sin w behind it) and horiz_offset to its side:
      // radially at angle psi from the beam's azimuth (counter-clockwise).
      // (an origin on the axis has no angle: psi is then the beam's own offset, which
      // keeps that offset in beam_azimuth)
      const double fired = -(2.0 * M_PI / columns) * l.share, offset = l.azimuth_deg * M_PI / 180.0;
      const double along = -l.vert_offset_m * std::sin(w), side = l.horiz_offset_m;
      const double radial = std::hypot(along, side);
      const double psi = radial > 0.0 ? std::atan2(side, along) : offset;
      g.column_azimuth.push_back(radial > 0.0 ? fired - offset + psi : fired);
      g.beam_azimuth.push_back(-psi);
      g.z_offset.push_back(l.vert_offset_m * std::cos(w));
      g.radial_offset.push_back(radial);
    }
    // Each point's time from the turn's first firing, as the ROS driver's `time` (float32
    // seconds): its firing's start plus its laser's slot. Not given where the packets'
    // timestamps run backwards within the turn or span more than a second.
    const std::int64_t t0 = firings_[0].time_ns;
    bool timed = true;
    for (std::size_t i = 0; i < end && timed; ++i) timed = firings_[i].time_ns >= t0 && firings_[i].time_ns - t0 <= 1000000000LL;
    if (timed) {
      cloud.time_source = {"time", FieldType::kFloat32};
      cloud.time.reserve(end * model->lasers);
    }
    std::size_t no_returns = 0;
    for (unsigned r = 0; r < model->lasers; ++r) {
      const unsigned id = laser_of_ring_[r];
      const std::int64_t slot = static_cast<std::int64_t>(id / model->lasers_per_slot) * slot_ns_;
      const Laser& l = lasers_[id];
      const double w = g.elevation[r];
      const double cw = std::cos(w), sw = std::sin(w);
      for (std::size_t i = 0; i < end; ++i) {
        const Firing& f = firings_[i];
        info_.second_returns += f.dist2[id] != 0 ? 1 : 0;
        if (f.dist[id] == 0 && f.dist2[id] == 0) {
          ++no_returns;
          continue;
        }
        const double a = (f.azimuth_deg + f.step_deg * l.share + l.azimuth_deg) * M_PI / 180.0;
        for (int ret = 0; ret < 2; ++ret) {
          const std::uint16_t dist = ret == 0 ? f.dist[id] : f.dist2[id];
          if (dist == 0) continue;
          const double d = dist * range_unit_ + l.dist_m;
          cloud.points.push_back(place(l, cw, sw, d, a));
          cloud.intensity.push_back(static_cast<float>(ret == 0 ? f.refl[id] : f.refl2[id]));
          if (which != nullptr) which->values.push_back(ret);
          cloud.ring.push_back(static_cast<std::uint16_t>(r));
          cloud.column.push_back(static_cast<std::uint32_t>(i));
          if (timed) cloud.time.push_back(static_cast<double>(f.time_ns + slot - t0) * 1e-9);
        }
      }
    }
    cloud.geometry = std::move(g);
    turn_columns_.push_back(columns);
    info_.no_returns += no_returns;
    info_.points += cloud.size();
    ++info_.frames;
    SensorTurn t;
    t.no_returns = no_returns;
    t.frame_id = turn_;
    t.captured_ns = firings_[0].captured_ns;
    cloud.stamp = capture_stamp(firings_[0].captured_ns);
    t.cloud = std::move(cloud);
    turns.push_back(std::move(t));
  }

  std::string path_, model_key_, calibration_path_;
  SensorLogInfo& info_;
  bool started_ = false;
  std::vector<Datagram> window_;  // the first packets, until the model is known
  // read from the first packets
  const Model* model_ = nullptr;
  bool hdl64_ = false, dual_ = false;
  std::uint8_t product_ = 0, mode_ = 0;
  std::vector<Laser> lasers_;
  std::vector<unsigned> laser_of_ring_;
  double range_unit_ = 0.0;
  std::string geometry_source_;
  std::size_t block_stride_ = 1;
  double firing_ns_ = 0.0;
  std::int64_t slot_ns_ = 0;
  double step_ = 0.0;  // the median firing step
  // the firings, from the turn being assembled on
  std::deque<Firing> firings_;
  double a0_ = 0.0;  // the capture's first firing's azimuth
  std::uint64_t turn_ = 0;
  double unwrap_ = 0.0, prev_ = -1.0, last_gap_ = std::nan("");
  std::int64_t hours_us_ = 0, prev_stamp_ = -1;
  std::vector<std::size_t> turn_columns_;
};

}  // namespace

std::unique_ptr<LogDecoder> velodyne_decoder(const std::string& path, const std::string& model,
                                             const std::string& calibration, SensorLogInfo& info) {
  return std::make_unique<VelodyneDecoder>(path, model, calibration, info);
}

}  // namespace lex3d::io::detail

namespace lex3d::io {

std::vector<std::string> velodyne_models() {
  std::vector<std::string> keys;
  for (const auto* m : detail::kModels) keys.emplace_back(m->key);
  keys.emplace_back(detail::kHdl64.key);
  return keys;
}

}  // namespace lex3d::io
