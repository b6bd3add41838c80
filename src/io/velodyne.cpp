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
// second strongest where the last is the strongest). The last return is kept; the other
// block's returns that differ from it are counted as second returns, not kept.

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <numeric>

#include "io/internal.hpp"
#include "io/sensor_log_internal.hpp"

namespace lex3d::io::detail {

namespace {

constexpr std::size_t kPacketBytes = 1206;
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
  std::array<std::uint16_t, 32> dist{};
  std::array<std::uint8_t, 32> refl{};
  std::array<bool, 32> second{};  // dual return: the pair's other block holds another return
};

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

Status decode_velodyne(const std::string& path, const std::string& model_key, const std::vector<Datagram>& datagrams,
                       SensorLog& log) {
  SensorLogInfo& info = log.info;
  info.vendor = "velodyne";
  std::vector<const Datagram*> packets;
  for (const auto& d : datagrams) {
    if (d.truncated && (d.dst_port == 2368 || d.claimed == kPacketBytes ||
                        (d.payload.size() >= 2 && d.payload[0] == 0xFF && d.payload[1] == 0xEE)))
      return bad_data(msg(path, "capture record " + std::to_string(d.record) + ": Velodyne data packet truncated: " +
                                    std::to_string(d.payload.size()) + " of " + std::to_string(d.claimed) +
                                    " bytes captured"));
    if (is_velodyne_packet(d.payload) && !d.truncated) packets.push_back(&d);
    else ++info.other_packets;
  }
  if (packets.empty()) return bad_data(msg(path, "no Velodyne data packets"));
  info.lidar_packets = packets.size();

  // The model: the factory byte, checked against the packet period (the firing timing is
  // fixed per model, the azimuth step is not: it follows the motor speed).
  const std::uint8_t product = packets.front()->payload[1205];
  const std::uint8_t mode = packets.front()->payload[1204];
  for (const Datagram* d : packets) {
    if (d->payload[1205] != product || d->payload[1204] != mode)
      return bad_data(msg(path, "capture record " + std::to_string(d->record) +
                                    ": the factory bytes change within the capture (two sensors on one port?)"));
  }
  std::vector<double> dt;
  for (std::size_t i = 1; i < packets.size(); ++i) {
    const double a = le32(packets[i - 1]->payload.data() + 1200);
    const double b = le32(packets[i]->payload.data() + 1200);
    if (b > a) dt.push_back(b - a);
  }
  const double period_us = median(dt);
  // Dual-return packets hold half the firings of single-return ones: twice as many.
  const bool dual = mode == 0x39;
  const double packet_share = dual ? 0.5 : 1.0;
  const auto timing_fits = [&](const Model* m) {
    return std::isfinite(period_us) && std::abs(period_us - m->packet_us * packet_share) < 0.1 * m->packet_us * packet_share;
  };
  const Model* timing = nullptr;  // the first model (in kModels' order) whose packet period fits
  for (const Model* m : kModels)
    if (timing == nullptr && timing_fits(m)) timing = m;
  const Model* by_byte = by_product(product);
  const Model* model = nullptr;
  char period_text[64];
  std::snprintf(period_text, sizeof period_text, "%.0f", period_us);
  std::string keys;
  for (const Model* m : kModels) keys += std::string(keys.empty() ? "" : ", ") + m->key;
  if (!model_key.empty()) {
    const std::string k = to_lower(model_key);
    for (const Model* m : kModels)
      if (k == m->key) model = m;
    if (model == nullptr)
      return {ErrorCode::kInvalidArgument, "sensor model '" + printable(model_key, 32) + "' is not known (" + keys + ")"};
    info.model_note = std::string("given: ") + model->name + "; factory byte " + hex(product) + " (" + product_name(product) +
                      "), packets every " + period_text + " us";
  } else if (by_byte != nullptr && timing != nullptr && !timing_fits(by_byte)) {
    model = timing;
    info.model_note = std::string("read as ") + timing->name + ": the factory byte " + hex(product) + " says " + by_byte->name +
                      " but packets arrive every " + period_text + " us, the " + timing->name + "'s period";
  } else if (by_byte != nullptr) {
    model = by_byte;
    info.model_note = std::string("factory byte ") + hex(product) + ", packets every " + period_text + " us" +
                      (timing_fits(by_byte) ? " (agrees)" : " (timing not conclusive)");
  } else if (timing != nullptr) {
    model = timing;
    info.model_note = std::string("read as ") + timing->name + " from the packet period (" + period_text +
                      " us); factory byte " + hex(product) + " (" + product_name(product) + ")";
  } else {
    std::string names;
    for (const Model* m : kModels) names += std::string(names.empty() ? "" : ", ") + m->name;
    return bad_data(msg(path, "Velodyne " + product_name(product) + " (factory byte " + hex(product) +
                                  ") is not supported (" + names + "; give --sensor-model to read it as one)"));
  }
  if (mode != 0x37 && mode != 0x38 && mode != 0x39)
    return bad_data(msg(path, "Velodyne return mode byte " + hex(mode) + " is not one of 0x37 (strongest), 0x38 (last), 0x39 (dual)"));
  info.sensor = model->name;
  info.profile = mode == 0x37 ? "strongest" : mode == 0x38 ? "last" : "dual (last return kept)";
  info.lasers = model->lasers;

  // Firings in capture order, the azimuth unwrapped. A dual-return packet's block pairs
  // share an azimuth: the first block of each pair is the firing kept.
  const std::size_t block_stride = dual ? 2 : 1, kept_blocks = kBlocks / block_stride;
  std::vector<Firing> firings;
  firings.reserve(packets.size() * kept_blocks * model->firings_per_block);
  double unwrap = 0.0, prev = -1.0, last_gap = std::nan("");
  for (const Datagram* d : packets) {
    const std::uint8_t* b = d->payload.data();
    std::array<double, kBlocks> az{};
    for (std::size_t k = 0; k < kBlocks; ++k) {
      const std::uint8_t* blk = b + k * 100;
      if (blk[0] != 0xFF || blk[1] != 0xEE)
        return bad_data(msg(path, "capture record " + std::to_string(d->record) + ": block " + std::to_string(k) +
                                      " has flag " + hex(blk[0]) + hex(blk[1]).substr(2) +
                                      (blk[1] == 0xDD ? " (an HDL-64E upper/lower block: not supported)" : " (not a data block)")));
      const std::uint16_t a = le16(blk + 2);
      if (a >= 36000)
        return bad_data(msg(path, "capture record " + std::to_string(d->record) + ": block " + std::to_string(k) +
                                      " azimuth " + std::to_string(a) + " is not below 36000 (0.01 degree units)"));
      az[k] = a / 100.0;
      if (dual && k % 2 == 1 && le16(blk + 2) != le16(blk - 100 + 2))
        return bad_data(msg(path, "capture record " + std::to_string(d->record) + ": dual-return blocks " +
                                      std::to_string(k - 1) + " and " + std::to_string(k) + " differ in azimuth"));
    }
    for (std::size_t k = 0; k < kBlocks; k += block_stride) {
      const std::size_t next = k + block_stride;
      double gap = next < kBlocks ? az[next] - az[k] : last_gap;
      if (next < kBlocks && gap < 0) gap += 360.0;
      if (!std::isfinite(gap)) gap = 0.0;
      if (next < kBlocks) last_gap = gap;
      double a = az[k];
      if (prev >= 0.0 && a + unwrap < prev - 180.0) unwrap += 360.0;
      const double a_unwrapped = a + unwrap;
      prev = a_unwrapped;
      const std::uint8_t* blk = b + k * 100 + 4;
      const double block_step = gap / model->firings_per_block;
      for (unsigned s = 0; s < model->firings_per_block; ++s) {
        Firing f;
        f.azimuth_deg = a_unwrapped + block_step * s;
        f.step_deg = block_step;
        for (unsigned l = 0; l < model->lasers; ++l) {
          const std::uint8_t* ch = blk + (s * model->lasers + l) * 3;
          f.dist[l] = le16(ch);
          f.refl[l] = ch[2];
          if (dual) {
            const std::uint16_t other = le16(ch + 100);
            f.second[l] = other != 0 && other != f.dist[l];
          }
        }
        firings.push_back(f);
      }
    }
  }

  // Rings: lasers ordered by elevation, lowest first.
  std::vector<unsigned> laser_of_ring(model->lasers);
  std::iota(laser_of_ring.begin(), laser_of_ring.end(), 0U);
  std::stable_sort(laser_of_ring.begin(), laser_of_ring.end(),
                   [&](unsigned a, unsigned b) { return model->elevation_deg[a] < model->elevation_deg[b]; });

  // Turns: 360° of azimuth from the first firing on. A turn with a hole (an azimuth jump of
  // more than 5 firing steps: lost packets) is dropped and counted.
  std::vector<double> steps;
  for (const auto& f : firings) steps.push_back(f.step_deg);
  const double step = median(steps);
  const double a0 = firings.front().azimuth_deg;
  std::size_t begin = 0;
  std::vector<std::size_t> turn_columns;
  for (std::uint64_t turn = 0;; ++turn) {
    const double end_az = a0 + 360.0 * static_cast<double>(turn + 1);
    std::size_t end = begin;
    while (end < firings.size() && firings[end].azimuth_deg < end_az) ++end;
    if (end >= firings.size()) {  // the capture ends inside this turn
      if (end > begin) ++info.incomplete_frames;
      break;
    }
    bool hole = false;
    for (std::size_t i = begin + 1; i < end; ++i)
      hole = hole || firings[i].azimuth_deg - firings[i - 1].azimuth_deg > 5.0 * step;
    if (hole || end - begin < 2) {
      ++info.incomplete_frames;
      begin = end;
      continue;
    }
    const auto columns = static_cast<std::uint32_t>(end - begin);
    Cloud cloud;
    cloud.rows = model->lasers;
    cloud.columns = columns;
    SensorGeometry g;
    g.columns = columns;
    g.direction = -1;
    // The grid's column 0: the first firing's azimuth moved by the mean offset of all the
    // firings of the turn from a grid of 360°/columns steps (least squares for that step).
    double start = firings[begin].azimuth_deg, mean_offset = 0.0;
    for (std::size_t i = begin; i < end; ++i)
      mean_offset += firings[i].azimuth_deg - (start + 360.0 * static_cast<double>(i - begin) / columns);
    start += mean_offset / static_cast<double>(columns);
    g.azimuth0 = std::remainder(M_PI / 2 - start * M_PI / 180.0, 2.0 * M_PI);
    g.source = "model table";
    g.sensor = model->name;
    // (laser l fires slot_us · its slot after the sequence starts: a share `frac` of the
    // column's azimuth step; its beam points azimuth_deg further, clockwise)
    const auto frac = [&](unsigned l) { return (l / model->lasers_per_slot) * model->slot_us / model->firing_us; };
    for (unsigned r = 0; r < model->lasers; ++r) {
      const unsigned l = laser_of_ring[r];
      g.elevation.push_back(model->elevation_deg[l] * M_PI / 180.0);
      g.beam_azimuth.push_back(-model->azimuth_deg[l] * M_PI / 180.0);
      g.column_azimuth.push_back(-(2.0 * M_PI / columns) * frac(l));
      g.z_offset.push_back(0.0);
      g.radial_offset.push_back(0.0);
    }
    std::size_t no_returns = 0;
    for (unsigned r = 0; r < model->lasers; ++r) {
      const unsigned l = laser_of_ring[r];
      const double w = g.elevation[r];
      const double cw = std::cos(w), sw = std::sin(w);
      const double share = frac(l);
      for (std::size_t i = begin; i < end; ++i) {
        const Firing& f = firings[i];
        info.second_returns += f.second[l] ? 1 : 0;
        if (f.dist[l] == 0) {
          ++no_returns;
          continue;
        }
        const double d = f.dist[l] * model->range_unit_m;
        const double a = (f.azimuth_deg + f.step_deg * share + model->azimuth_deg[l]) * M_PI / 180.0;
        cloud.points.emplace_back(static_cast<float>(d * cw * std::sin(a)), static_cast<float>(d * cw * std::cos(a)),
                                  static_cast<float>(d * sw));
        cloud.intensity.push_back(static_cast<float>(f.refl[l]));
        cloud.ring.push_back(static_cast<std::uint16_t>(r));
        cloud.column.push_back(static_cast<std::uint32_t>(i - begin));
      }
    }
    cloud.geometry = std::move(g);
    turn_columns.push_back(columns);
    info.no_returns += no_returns;
    info.points += cloud.size();
    log.no_returns.push_back(no_returns);
    log.frame_ids.push_back(turn);
    log.scans.push_back(std::move(cloud));
    begin = end;
  }
  if (!turn_columns.empty()) {
    std::vector<double> c(turn_columns.begin(), turn_columns.end());
    info.columns = static_cast<std::uint32_t>(median(c));
  }
  info.frames = log.scans.size();
  return {};
}

}  // namespace lex3d::io::detail

namespace lex3d::io {

std::vector<std::string> velodyne_models() {
  std::vector<std::string> keys;
  for (const auto* m : detail::kModels) keys.emplace_back(m->key);
  return keys;
}

}  // namespace lex3d::io
