// Ouster lidar packets (LEGACY, RNG19_RFL8_SIG16_NIR16[_DUAL], RNG15_RFL8_NIR8) and the
// sensor metadata JSON (fw 2.x flat layout, fw 3 nested layout), decoded into one organised
// Cloud a complete frame, placed with Ouster's documented beam model:
//
//   θ_enc = 2π (1 − m / W)           m: measurement column, W: columns_per_frame
//   θ_az  = −2π beam_azimuth / 360,  φ = 2π beam_altitude / 360,  n: beam origin offset
//   p     = (r − n) (cos(θ_enc + θ_az) cos φ, sin(θ_enc + θ_az) cos φ, sin φ)
//           + (n cos θ_enc, n sin θ_enc, z_beam)
//   p_sensor = lidar_to_sensor_transform · p
//
// which is cloud.hpp's SensorGeometry model with r_model = r − n, radial_offset = n,
// direction = −1, azimuth0 = 0 and column_azimuth = 2π shift / W for the destaggered
// column c = (m + shift) mod W.

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <optional>

#include "io/internal.hpp"
#include "io/sensor_log_internal.hpp"

namespace lex3d::io::detail {

namespace {

using nlohmann::json;

enum class Profile { kLegacy, kSingle, kDual, kLowData };

struct Meta {
  std::string prod_line;
  std::uint64_t prod_sn = 0;  // 0: unknown
  std::string profile_name = "LEGACY";
  Profile profile = Profile::kLegacy;
  std::uint32_t H = 0, W = 0, cpp = 0;
  std::uint32_t window0 = 0, window1 = 0;
  std::vector<double> altitude_deg, azimuth_deg;
  std::vector<int> shift;
  double n_mm = 0.0;
  double z_mm = 0.0;
  Eigen::Matrix4d lidar_to_sensor = Eigen::Matrix4d::Identity();  // translation in mm
  int udp_port_lidar = 0;                                        // 0: not given
  [[nodiscard]] std::size_t pixel_bytes() const {
    switch (profile) {
      case Profile::kLegacy: return 12;
      case Profile::kSingle: return 12;
      case Profile::kDual: return 16;
      case Profile::kLowData: return 4;
    }
    return 12;
  }
  [[nodiscard]] bool legacy() const { return profile == Profile::kLegacy; }
  [[nodiscard]] std::size_t column_bytes() const { return (legacy() ? 20 : 12) + H * pixel_bytes(); }
  [[nodiscard]] std::size_t packet_bytes() const { return (legacy() ? 0 : 64) + cpp * column_bytes(); }
  [[nodiscard]] bool in_window(std::uint32_t m) const {
    return window0 <= window1 ? (m >= window0 && m <= window1) : (m >= window0 || m <= window1);
  }
};

/// Errors of the metadata reader: "<metadata path>: <what>".
struct MetaError {
  std::string what;
};

const json* find(const json& j, std::initializer_list<const char*> path) {
  const json* cur = &j;
  for (const char* k : path) {
    if (!cur->is_object()) return nullptr;
    auto it = cur->find(k);
    if (it == cur->end()) return nullptr;
    cur = &*it;
  }
  return cur;
}

/// The first of several locations that exists.
const json* find_any(const json& j, std::initializer_list<std::initializer_list<const char*>> paths) {
  for (const auto& p : paths)
    if (const json* v = find(j, p)) return v;
  return nullptr;
}

double number(const json* v, const std::string& name) {
  if (v == nullptr) throw MetaError{"no " + name};
  if (!v->is_number()) throw MetaError{name + " is not a number"};
  const double d = v->get<double>();
  if (!std::isfinite(d)) throw MetaError{name + " is not finite"};
  return d;
}

std::vector<double> numbers(const json* v, const std::string& name, std::size_t want) {
  if (v == nullptr) throw MetaError{"no " + name};
  if (!v->is_array()) throw MetaError{name + " is not an array"};
  if (want != 0 && v->size() != want)
    throw MetaError{name + " has " + std::to_string(v->size()) + " entries, expected " + std::to_string(want)};
  std::vector<double> out;
  out.reserve(v->size());
  for (std::size_t i = 0; i < v->size(); ++i) {
    const json& e = (*v)[i];
    if (!e.is_number() || !std::isfinite(e.get<double>()))
      throw MetaError{name + "[" + std::to_string(i) + "] is not a finite number"};
    out.push_back(e.get<double>());
  }
  return out;
}

std::uint32_t whole(const json* v, const std::string& name, std::uint32_t lo, std::uint32_t hi) {
  const double d = number(v, name);
  if (d != std::floor(d) || d < lo || d > hi)
    throw MetaError{name + " is " + json(d).dump() + ", expected a whole number in [" + std::to_string(lo) + ", " +
                    std::to_string(hi) + "]"};
  return static_cast<std::uint32_t>(d);
}

Meta parse_meta(const json& j) {
  Meta m;
  if (!j.is_object()) throw MetaError{"not a JSON object"};
  const bool nested = find(j, {"beam_intrinsics"}) != nullptr;
  const json* fmt = nested ? find(j, {"lidar_data_format"}) : find(j, {"data_format"});
  if (fmt == nullptr || !fmt->is_object())
    throw MetaError{nested ? "no lidar_data_format object" : "no data_format object (not Ouster metadata?)"};
  m.H = whole(find(*fmt, {"pixels_per_column"}), "pixels_per_column", 1, 512);
  m.W = whole(find(*fmt, {"columns_per_frame"}), "columns_per_frame", 1, 16384);
  m.cpp = whole(find(*fmt, {"columns_per_packet"}), "columns_per_packet", 1, m.W);
  const std::vector<double> win = numbers(find(*fmt, {"column_window"}), "column_window", 2);
  for (int k = 0; k < 2; ++k)
    if (win[k] != std::floor(win[k]) || win[k] < 0 || win[k] >= m.W)
      throw MetaError{"column_window[" + std::to_string(k) + "] is outside [0, columns_per_frame)"};
  m.window0 = static_cast<std::uint32_t>(win[0]);
  m.window1 = static_cast<std::uint32_t>(win[1]);
  const std::vector<double> shifts = numbers(find(*fmt, {"pixel_shift_by_row"}), "pixel_shift_by_row", m.H);
  for (std::size_t i = 0; i < shifts.size(); ++i) {
    if (shifts[i] != std::floor(shifts[i]) || std::abs(shifts[i]) >= m.W)
      throw MetaError{"pixel_shift_by_row[" + std::to_string(i) + "] is not a whole number of columns below columns_per_frame"};
    m.shift.push_back(static_cast<int>(shifts[i]));
  }
  const json* prof = find_any(j, {{nested ? "lidar_data_format" : "data_format", "udp_profile_lidar"},
                                  {"config_params", "udp_profile_lidar"}});
  if (prof != nullptr) {
    if (!prof->is_string()) throw MetaError{"udp_profile_lidar is not a string"};
    m.profile_name = prof->get<std::string>();
  }
  if (m.profile_name == "LEGACY") m.profile = Profile::kLegacy;
  else if (m.profile_name == "RNG19_RFL8_SIG16_NIR16") m.profile = Profile::kSingle;
  else if (m.profile_name == "RNG19_RFL8_SIG16_NIR16_DUAL") m.profile = Profile::kDual;
  else if (m.profile_name == "RNG15_RFL8_NIR8") m.profile = Profile::kLowData;
  else
    throw MetaError{"udp_profile_lidar '" + printable(m.profile_name, 40) +
                    "' is not supported (LEGACY, RNG19_RFL8_SIG16_NIR16, RNG19_RFL8_SIG16_NIR16_DUAL, RNG15_RFL8_NIR8)"};

  const json* bi = nested ? find(j, {"beam_intrinsics"}) : &j;
  m.altitude_deg = numbers(find(*bi, {"beam_altitude_angles"}), "beam_altitude_angles", m.H);
  m.azimuth_deg = numbers(find(*bi, {"beam_azimuth_angles"}), "beam_azimuth_angles", m.H);
  for (std::uint32_t i = 0; i < m.H; ++i) {
    if (std::abs(m.altitude_deg[i]) > 90.0)
      throw MetaError{"beam_altitude_angles[" + std::to_string(i) + "] is outside [-90, 90] degrees"};
    if (std::abs(m.azimuth_deg[i]) > 180.0)
      throw MetaError{"beam_azimuth_angles[" + std::to_string(i) + "] is outside [-180, 180] degrees"};
  }
  m.n_mm = number(find(*bi, {"lidar_origin_to_beam_origin_mm"}), "lidar_origin_to_beam_origin_mm");
  if (const json* b2l = find(*bi, {"beam_to_lidar_transform"})) {
    const std::vector<double> t = numbers(b2l, "beam_to_lidar_transform", 16);
    // The beam model has a radial offset (t[3]) and a height (t[11]); a rotation or a sideways
    // offset would need more than it describes.
    const Eigen::Matrix3d R = Eigen::Map<const Eigen::Matrix<double, 4, 4, Eigen::RowMajor>>(t.data()).topLeftCorner<3, 3>();
    if ((R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() > 1e-9 || std::abs(t[7]) > 1e-9)
      throw MetaError{"beam_to_lidar_transform has a rotation or a y offset, which the beam model does not describe"};
    m.n_mm = t[3];
    m.z_mm = t[11];
  }
  if (!(m.n_mm >= 0.0 && m.n_mm < 1000.0)) throw MetaError{"lidar_origin_to_beam_origin_mm is outside [0, 1000)"};
  const json* l2s = nested ? find(j, {"lidar_intrinsics", "lidar_to_sensor_transform"}) : find(j, {"lidar_to_sensor_transform"});
  const std::vector<double> t = numbers(l2s, "lidar_to_sensor_transform", 16);
  m.lidar_to_sensor = Eigen::Map<const Eigen::Matrix<double, 4, 4, Eigen::RowMajor>>(t.data());
  const Eigen::Matrix3d R = m.lidar_to_sensor.topLeftCorner<3, 3>();
  if ((R * R.transpose() - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() > 1e-3 ||
      m.lidar_to_sensor.row(3).transpose() != Eigen::Vector4d(0, 0, 0, 1))
    throw MetaError{"lidar_to_sensor_transform is not a rigid transform"};
  if (const json* pl = find_any(j, {{"prod_line"}, {"sensor_info", "prod_line"}}); pl != nullptr && pl->is_string())
    m.prod_line = pl->get<std::string>();
  if (const json* sn = find_any(j, {{"prod_sn"}, {"sensor_info", "prod_sn"}}); sn != nullptr) {
    if (sn->is_string()) {
      const std::string s = sn->get<std::string>();
      std::uint64_t v = 0;
      if (parse_u64(s, v)) m.prod_sn = v;
    } else if (sn->is_number_unsigned()) {
      m.prod_sn = sn->get<std::uint64_t>();
    }
  }
  if (const json* port = find_any(j, {{"udp_port_lidar"}, {"config_params", "udp_port_lidar"}});
      port != nullptr && port->is_number_integer()) {
    const auto v = port->get<std::int64_t>();
    if (v > 0 && v < 65536) m.udp_port_lidar = static_cast<int>(v);
  }
  return m;
}

template <typename T>
T le(const std::uint8_t* p) {
  T v;
  std::memcpy(&v, p, sizeof(T));
  return v;  // the host is little-endian (checked in read_sensor_log)
}

/// One frame being assembled: the staggered range and reflectivity images.
struct Frame {
  std::uint32_t id = 0;
  std::vector<std::uint32_t> range_mm;  // H × W, row-major by beam
  std::vector<std::uint16_t> refl;
  std::vector<std::uint16_t> signal;    // (not in the low-data profile)
  std::vector<std::uint16_t> near_ir;
  std::vector<std::uint32_t> range2_mm;  // dual profile: the second return's range,
  std::vector<std::uint16_t> refl2;      // reflectivity
  std::vector<std::uint16_t> signal2;    // and signal
  std::vector<std::uint8_t> have;       // per measurement column
  std::vector<std::uint64_t> stamp_ns;  // per measurement column: its timestamp
  std::uint64_t captured_ns = 0;        // the capture time of its first packet
  std::size_t columns_seen = 0;
};

/// The Ouster decoder, fed one datagram at a time: a frame is assembled until a packet of
/// another frame_id comes, then handed on (SensorTurn) when its columns cover the window.
class OusterDecoder final : public LogDecoder {
 public:
  OusterDecoder(std::string path, std::string metadata_path, Meta meta, bool by_size, std::string topic, SensorLogInfo& info)
      : path_(std::move(path)), metadata_path_(std::move(metadata_path)), topic_(std::move(topic)), m_(std::move(meta)),
        info_(info) {
    info.vendor = "ouster";
    info.sensor = m_.prod_line.empty() ? "Ouster" : m_.prod_line;
    info.profile = m_.profile_name;
    info.metadata_path = metadata_path_;
    info.lasers = m_.H;
    info.columns = m_.W;
    want_ = m_.packet_bytes();
    expect_ = m_.profile_name + ", " + std::to_string(m_.H) + " beams, " + std::to_string(m_.cpp) +
              " columns a packet: " + std::to_string(want_) + " bytes";
    port_ = by_size ? 0 : m_.udp_port_lidar;
    T_sensor_lidar_.linear() = m_.lidar_to_sensor.topLeftCorner<3, 3>();
    T_sensor_lidar_.translation() = m_.lidar_to_sensor.topRightCorner<3, 1>() / 1000.0;
    window_columns_ = m_.window0 <= m_.window1 ? m_.window1 - m_.window0 + 1 : m_.W - m_.window0 + m_.window1 + 1;
    g_.columns = m_.W;
    g_.azimuth0 = 0.0;
    g_.direction = -1;
    g_.T_sensor_head = T_sensor_lidar_;
    g_.source = "metadata";
    g_.sensor = info.sensor;
    const double two_pi = 2.0 * M_PI;
    for (std::uint32_t l = 0; l < m_.H; ++l) {
      g_.elevation.push_back(m_.altitude_deg[l] * M_PI / 180.0);
      g_.beam_azimuth.push_back(-m_.azimuth_deg[l] * M_PI / 180.0);
      g_.column_azimuth.push_back(two_pi * m_.shift[l] / m_.W);
      g_.z_offset.push_back(m_.z_mm / 1000.0);
      g_.radial_offset.push_back(m_.n_mm / 1000.0);
    }
  }

  // Which datagrams are lidar packets: those to the metadata's lidar port, else those of
  // the expected size, else those to Ouster's default port 7502 (to report a mismatch).
  // Lidar packets of another size than the metadata's: an error at the first such packet
  // where a packet of the right size comes before or after it (a truncated packet), the
  // metadata's mismatch where none does.
  Status push(const Datagram& d) override {
    ++datagrams_;
    const bool lidar_port = port_ != 0 ? d.dst_port == port_ : (d.dst_port == 7502 || d.claimed == want_);
    if (d.truncated && lidar_port)
      return bad_data(msg(path_, record(d) + ": lidar packet truncated: " + std::to_string(d.payload.size()) + " of " +
                                     std::to_string(d.claimed) + " bytes captured"));
    if (d.dst_port == 7502 && !d.truncated) {
      ++on_default_port_;
      default_port_size_ = d.payload.size();
    }
    const bool lidar = !d.truncated && (port_ != 0 ? d.dst_port == port_ : d.payload.size() == want_);
    if (!lidar) {
      ++info_.other_packets;
      return {};
    }
    ++packets_;
    if (d.payload.size() != want_) {
      if (right_size_) return wrong_size(d.record, d.payload.size());
      if (!first_wrong_) first_wrong_ = {d.record, d.payload.size()};
      return {};
    }
    right_size_ = true;
    if (first_wrong_) return wrong_size(first_wrong_->first, first_wrong_->second);
    return decode(d);
  }

  Status finish() override {
    if (packets_ == 0) {
      if (on_default_port_ > 0)
        return bad_data(msg(path_, "the metadata " + display_path(metadata_path_) + " does not match the packets: " +
                                       std::to_string(on_default_port_) + " packets on UDP port 7502 are " +
                                       std::to_string(default_port_size_) + " bytes, the metadata (" + expect_ +
                                       ") needs " + std::to_string(want_)));
      return bad_data(msg(path_, "no Ouster lidar packets (" + std::to_string(datagrams_) + " UDP datagrams, none " +
                                     (port_ != 0 ? "to port " + std::to_string(port_) : "of " + std::to_string(want_) + " bytes") +
                                     ")"));
    }
    if (!right_size_)
      return bad_data(msg(path_, "the metadata " + display_path(metadata_path_) + " does not match the packets: lidar packets are " +
                                     std::to_string(first_wrong_ ? first_wrong_->second : 0) + " bytes, the metadata (" +
                                     expect_ + ")"));
    if (cur_) finish_frame(*cur_);
    cur_.reset();
    return {};
  }

 private:
  /// Where a datagram came from, in error messages.
  [[nodiscard]] std::string record(std::size_t r) const {
    return topic_.empty() ? "capture record " + std::to_string(r) : "message " + std::to_string(r) + " on " + topic_;
  }
  [[nodiscard]] std::string record(const Datagram& d) const { return record(d.record); }

  [[nodiscard]] Status wrong_size(std::size_t r, std::size_t bytes) const {
    return bad_data(msg(path_, record(r) + ": lidar packet of " + std::to_string(bytes) + " bytes, expected " +
                                   std::to_string(want_) + " (" + expect_ +
                                   "; truncated packet or metadata of another mode)"));
  }

  void finish_frame(Frame& f) {
    const Meta& m = m_;
    const SensorGeometry& g = g_;
    const double two_pi = 2.0 * M_PI;
    const double n_m = m.n_mm / 1000.0;
    const double z_m = m.z_mm / 1000.0;
    std::size_t in_window = 0;
    for (std::uint32_t c = 0; c < m.W; ++c) in_window += (f.have[c] != 0 && m.in_window(c)) ? 1 : 0;
    if (in_window < window_columns_) {
      ++info_.incomplete_frames;
      return;
    }
    Cloud cloud;
    cloud.rows = m.H;
    cloud.columns = m.W;
    cloud.geometry = g;
    std::size_t no_returns = 0;
    const std::size_t pixels = static_cast<std::size_t>(m.H) * m.W;
    cloud.points.reserve(pixels);
    cloud.intensity.reserve(pixels);
    cloud.ring.reserve(pixels);
    cloud.column.reserve(pixels);
    // the packets' signal and near-infrared channels, in their types (the low-data profile
    // has no signal and an 8-bit near-infrared)
    const bool with_signal = m.profile != Profile::kLowData;
    if (with_signal) cloud.fields.push_back({"signal", {}, FieldType::kUint16});
    cloud.fields.push_back({"near_ir", {}, m.profile == Profile::kLowData ? FieldType::kUint8 : FieldType::kUint16});
    // The dual profile's second returns are points of their own, at their pixel, with their
    // reflectivity and signal (the near-infrared is the pixel's): `return` says which (0 the
    // strongest, 1 the second strongest).
    const bool dual = m.profile == Profile::kDual;
    if (dual) cloud.fields.push_back({kReturnField, {}, FieldType::kUint8});
    for (IntegerField& x : cloud.fields) x.values.reserve(pixels);
    // Each point's time: its measurement column's timestamp from the frame's first (as
    // Ouster's ROS driver gives `t`, uint32 nanoseconds). A frame whose timestamps run
    // backwards or over more than 2^32 ns (a clock jump) gives no time.
    std::uint64_t t0 = std::numeric_limits<std::uint64_t>::max(), t1 = 0;
    for (std::uint32_t mc = 0; mc < m.W; ++mc)
      if (f.have[mc] != 0 && m.in_window(mc)) {
        t0 = std::min(t0, f.stamp_ns[mc]);
        t1 = std::max(t1, f.stamp_ns[mc]);
      }
    const bool timed = t0 <= t1 && t1 - t0 <= std::numeric_limits<std::uint32_t>::max();
    if (timed) {
      cloud.time.reserve(pixels);
      cloud.time_source = {"t", FieldType::kUint32};
    }
    IntegerField* signal = with_signal ? &cloud.fields.front() : nullptr;
    IntegerField& near_ir = cloud.fields[with_signal ? 1 : 0];
    IntegerField* which = dual ? &cloud.fields.back() : nullptr;
    // each measurement column's encoder angle, and its cosine and sine (shared by the beams)
    std::vector<double> theta(m.W), cos_theta(m.W), sin_theta(m.W);
    for (std::uint32_t mc = 0; mc < m.W; ++mc) {
      theta[mc] = two_pi * (1.0 - static_cast<double>(mc) / m.W);
      cos_theta[mc] = std::cos(theta[mc]);
      sin_theta[mc] = std::sin(theta[mc]);
    }
    for (std::uint32_t l = 0; l < m.H; ++l) {
      const double phi = g.elevation[l];
      const double cphi = std::cos(phi), sphi = std::sin(phi);
      for (std::uint32_t c = 0; c < m.W; ++c) {
        const auto mc = static_cast<std::uint32_t>(((static_cast<std::int64_t>(c) - m.shift[l]) % m.W + m.W) % m.W);
        if (!m.in_window(mc)) continue;
        const std::size_t k = static_cast<std::size_t>(l) * m.W + mc;
        const std::uint32_t r2_mm = dual ? f.range2_mm[k] : 0;
        if (r2_mm != 0) ++info_.second_returns;
        if (f.range_mm[k] == 0 && r2_mm == 0) {
          ++no_returns;
          continue;
        }
        const double a = theta[mc] + g.beam_azimuth[l];
        const double ca = std::cos(a), sa = std::sin(a);
        for (int ret = 0; ret < 2; ++ret) {
          const std::uint32_t r_mm = ret == 0 ? f.range_mm[k] : r2_mm;
          if (r_mm == 0) continue;
          const double r = r_mm / 1000.0 - n_m;
          const Eigen::Vector3d p(r * ca * cphi + n_m * cos_theta[mc], r * sa * cphi + n_m * sin_theta[mc], r * sphi + z_m);
          cloud.points.push_back((T_sensor_lidar_ * p).cast<float>());
          cloud.intensity.push_back(static_cast<float>(ret == 0 ? f.refl[k] : f.refl2[k]));
          if (signal != nullptr) signal->values.push_back(ret == 0 ? f.signal[k] : f.signal2[k]);
          near_ir.values.push_back(f.near_ir[k]);
          if (which != nullptr) which->values.push_back(ret);
          cloud.ring.push_back(static_cast<std::uint16_t>(l));
          cloud.column.push_back(c);
          if (timed) cloud.time.push_back(static_cast<double>(f.stamp_ns[mc] - t0) * 1e-9);
        }
      }
    }
    info_.no_returns += no_returns;
    info_.points += cloud.size();
    ++info_.frames;
    SensorTurn t;
    t.no_returns = no_returns;
    t.frame_id = f.id;
    t.captured_ns = f.captured_ns;
    cloud.stamp = capture_stamp(f.captured_ns);
    t.cloud = std::move(cloud);
    turns.push_back(std::move(t));
  }

  Status decode(const Datagram& d) {
    const Meta& m = m_;
    const std::size_t HW = static_cast<std::size_t>(m.H) * m.W;
    const std::size_t col_bytes = m.column_bytes();
    const std::size_t head = m.legacy() ? 0 : 32;
    const std::size_t col_head = m.legacy() ? 16 : 12;
    const std::vector<std::uint8_t>& b = d.payload;
    ++info_.lidar_packets;
    std::uint32_t frame_id = 0;
    if (!m.legacy()) {
      const auto type = le<std::uint16_t>(b.data());
      if (type != 1)
        return bad_data(msg(path_, record(d) + ": packet type " + std::to_string(type) + " is not a lidar data packet"));
      frame_id = le<std::uint16_t>(b.data() + 2);
      std::uint64_t sn = 0;
      std::memcpy(&sn, b.data() + 7, 5);
      if (m.prod_sn != 0 && sn != 0 && sn != m.prod_sn)
        return bad_data(msg(path_, "the metadata " + display_path(metadata_path_) + " does not match the packets: they come from sensor " +
                                       std::to_string(sn) + ", the metadata is for " + std::to_string(m.prod_sn)));
    } else {
      frame_id = le<std::uint16_t>(b.data() + 10);
    }
    if (!cur_ || cur_->id != frame_id) {
      if (cur_) finish_frame(*cur_);
      cur_.emplace();
      cur_->id = frame_id;
      cur_->range_mm.assign(HW, 0);
      cur_->refl.assign(HW, 0);
      cur_->signal.assign(HW, 0);
      cur_->near_ir.assign(HW, 0);
      if (m.profile == Profile::kDual) {
        cur_->range2_mm.assign(HW, 0);
        cur_->refl2.assign(HW, 0);
        cur_->signal2.assign(HW, 0);
      }
      cur_->have.assign(m.W, 0);
      cur_->stamp_ns.assign(m.W, 0);
      cur_->captured_ns = d.captured_ns;
    }
    Frame& f = *cur_;
    for (std::uint32_t k = 0; k < m.cpp; ++k) {
      const std::uint8_t* col = b.data() + head + k * col_bytes;
      const auto mid = le<std::uint16_t>(col + 8);
      const bool valid = m.legacy() ? le<std::uint32_t>(col + col_bytes - 4) == 0xFFFFFFFFU
                                    : (le<std::uint16_t>(col + 10) & 1U) != 0;
      if (!valid) continue;
      if (mid >= m.W)
        return bad_data(msg(path_, "the metadata " + display_path(metadata_path_) + " does not match the packets: " +
                                       record(d) + " has measurement_id " + std::to_string(mid) +
                                       ", columns_per_frame is " + std::to_string(m.W)));
      if (m.legacy() && le<std::uint16_t>(col + 10) != frame_id)
        return bad_data(msg(path_, record(d) + ": columns of one packet carry different frame ids"));
      f.have[mid] = 1;
      f.stamp_ns[mid] = le<std::uint64_t>(col);
      for (std::uint32_t l = 0; l < m.H; ++l) {
        const std::uint8_t* px = col + col_head + static_cast<std::size_t>(l) * m.pixel_bytes();
        const std::size_t idx = static_cast<std::size_t>(l) * m.W + mid;
        switch (m.profile) {
          // (the pixel layouts of the Ouster sensor user manual: range, reflectivity,
          // signal and near-infrared; the dual profile's signal of the first return)
          case Profile::kLegacy:
            f.range_mm[idx] = le<std::uint32_t>(px) & 0xFFFFFU;
            f.refl[idx] = le<std::uint16_t>(px + 4);
            f.signal[idx] = le<std::uint16_t>(px + 6);
            f.near_ir[idx] = le<std::uint16_t>(px + 8);
            break;
          case Profile::kSingle:
            f.range_mm[idx] = le<std::uint32_t>(px) & 0x7FFFFU;
            f.refl[idx] = px[4];
            f.signal[idx] = le<std::uint16_t>(px + 6);
            f.near_ir[idx] = le<std::uint16_t>(px + 8);
            break;
          case Profile::kDual:
            f.range_mm[idx] = le<std::uint32_t>(px) & 0x7FFFFU;
            f.refl[idx] = px[3];
            f.range2_mm[idx] = le<std::uint32_t>(px + 4) & 0x7FFFFU;
            f.refl2[idx] = px[7];
            f.signal[idx] = le<std::uint16_t>(px + 8);
            f.signal2[idx] = le<std::uint16_t>(px + 10);
            f.near_ir[idx] = le<std::uint16_t>(px + 12);
            break;
          case Profile::kLowData:
            f.range_mm[idx] = (static_cast<std::uint32_t>(le<std::uint16_t>(px)) & 0x7FFFU) * 8U;
            f.refl[idx] = px[2];
            f.near_ir[idx] = px[3];
            break;
        }
      }
    }
    return {};
  }

  std::string path_, metadata_path_, topic_;
  Meta m_;
  SensorLogInfo& info_;
  std::size_t want_ = 0;
  std::string expect_;
  int port_ = 0;
  Eigen::Isometry3d T_sensor_lidar_ = Eigen::Isometry3d::Identity();
  std::uint32_t window_columns_ = 0;
  SensorGeometry g_;
  std::optional<Frame> cur_;
  std::size_t datagrams_ = 0, packets_ = 0, on_default_port_ = 0, default_port_size_ = 0;
  bool right_size_ = false;
  std::optional<std::pair<std::size_t, std::size_t>> first_wrong_;  // (record, bytes)
};

}  // namespace

StatusOr<std::unique_ptr<LogDecoder>> ouster_decoder(const std::string& path, const std::string& metadata_path,
                                                      const std::vector<std::uint8_t>& tb, bool by_size,
                                                      SensorLogInfo& info, const std::string& topic) {
  const json j = json::parse(tb.begin(), tb.end(), nullptr, false);
  if (j.is_discarded()) {
    const std::string s(tb.begin(), tb.end());
    const bool nan = s.find("NaN") != std::string::npos || s.find("Infinity") != std::string::npos;
    return bad_data(msg(metadata_path, nan ? "a number is NaN or Infinity (the laser table must be finite numbers)"
                                           : "not valid JSON"));
  }
  Meta m;
  try {
    m = parse_meta(j);
  } catch (const MetaError& e) {
    return bad_data(msg(metadata_path, e.what));
  } catch (const json::exception& e) {
    return bad_data(msg(metadata_path, std::string("unexpected value: ") + printable(e.what(), 120)));
  }
  return std::unique_ptr<LogDecoder>(std::make_unique<OusterDecoder>(path, metadata_path, std::move(m), by_size, topic, info));
}

}  // namespace lex3d::io::detail
