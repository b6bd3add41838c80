// Raw lidar logs: every shared Ouster and Velodyne capture decodes into plausible turns
// whose points the SensorGeometry model of cloud.hpp reproduces; IPv4 fragments are
// reassembled; damaged captures and metadata give one-line errors naming the file.

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <string>
#include <tuple>
#include <vector>

#include <gtest/gtest.h>

#include "lex3d/io/io.hpp"
#include "lex3d/io/sensor_log.hpp"
#include "support/test_support.hpp"

namespace lex3d::io {
namespace {

using test::write_bytes;

namespace fs = std::filesystem;
using test::shared_data;
using test::temp_dir;

std::string slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}
// ------------------------------------------------------------ a classic pcap, edited in memory

struct Record {
  std::uint32_t sec = 0, usec = 0, len = 0;
  std::string data;  // the captured bytes (caplen = data.size())
};
struct Capture {
  std::string header;  // 24-byte global header
  std::vector<Record> records;
};

std::uint32_t u32(const std::string& s, std::size_t at) {
  std::uint32_t v = 0;
  std::memcpy(&v, s.data() + at, 4);
  return v;
}
void put32(std::string& s, std::uint32_t v) { s.append(reinterpret_cast<const char*>(&v), 4); }

Capture parse_capture(const std::string& bytes) {
  Capture c;
  c.header = bytes.substr(0, 24);
  std::size_t at = 24;
  while (at + 16 <= bytes.size()) {
    Record r;
    r.sec = u32(bytes, at);
    r.usec = u32(bytes, at + 4);
    const std::uint32_t cap = u32(bytes, at + 8);
    r.len = u32(bytes, at + 12);
    r.data = bytes.substr(at + 16, cap);
    at += 16 + cap;
    c.records.push_back(std::move(r));
  }
  return c;
}
std::string serialise(const Capture& c) {
  std::string out = c.header;
  for (const auto& r : c.records) {
    put32(out, r.sec);
    put32(out, r.usec);
    put32(out, static_cast<std::uint32_t>(r.data.size()));
    put32(out, r.len);
    out += r.data;
  }
  return out;
}

/// Splits every Ethernet/IPv4 record larger than `mtu` into IPv4 fragments of the same
/// datagram (payload chunks a multiple of 8 bytes); returns how many datagrams were split.
std::size_t fragment(Capture& c, std::size_t mtu) {
  std::vector<Record> out;
  std::size_t split = 0;
  std::uint16_t id = 1000;
  for (const auto& r : c.records) {
    const std::string& d = r.data;
    const bool ipv4 = d.size() > 34 && static_cast<unsigned char>(d[12]) == 0x08 && d[13] == 0 &&
                      (static_cast<unsigned char>(d[14]) == 0x45);
    const std::size_t total = ipv4 ? (static_cast<unsigned char>(d[16]) << 8 | static_cast<unsigned char>(d[17])) : 0;
    if (!ipv4 || total <= mtu) {
      out.push_back(r);
      continue;
    }
    ++split;
    const std::string eth = d.substr(0, 14), body = d.substr(34, total - 20);
    std::string ip = d.substr(14, 20);
    ++id;  // each fragmented datagram its own IPv4 identification
    ip[4] = static_cast<char>(id >> 8);
    ip[5] = static_cast<char>(id & 255);
    const std::size_t chunk = (mtu - 20) / 8 * 8;
    for (std::size_t off = 0; off < body.size(); off += chunk) {
      const std::size_t n = std::min(chunk, body.size() - off);
      std::string h = ip;
      const std::size_t t = 20 + n;
      h[2] = static_cast<char>(t >> 8);
      h[3] = static_cast<char>(t & 255);
      const std::size_t fo = (off / 8) | (off + n < body.size() ? 0x2000 : 0);
      h[6] = static_cast<char>(fo >> 8);
      h[7] = static_cast<char>(fo & 255);
      Record f = r;
      f.data = eth + h + body.substr(off, n);
      f.len = static_cast<std::uint32_t>(f.data.size());
      out.push_back(std::move(f));
    }
  }
  c.records = std::move(out);
  return split;
}

// ------------------------------------------------------------ the geometry model of cloud.hpp

/// Largest distance between a point and the ray the geometry gives its (ring, column), the
/// range along the ray solved from the point (so this is the point recomputed from ring,
/// column, range and the geometry). Also the largest angle off the ray, radians.
struct Residual {
  double max_m = 0.0;
  double max_angle = 0.0;
  double median_angle = 0.0;
};
Residual geometry_residual(const Cloud& c) {
  Residual res;
  const SensorGeometry& g = *c.geometry;
  const Pose T_head_sensor = g.T_sensor_head.inverse();
  std::vector<double> angles;
  for (std::size_t i = 0; i < c.size(); ++i) {
    const std::size_t l = c.ring[i];
    const double a = g.azimuth0 + g.direction * 2.0 * M_PI * c.column[i] / g.columns + g.column_azimuth[l];
    const Eigen::Vector3d o(g.radial_offset[l] * std::cos(a), g.radial_offset[l] * std::sin(a), g.z_offset[l]);
    const double phi = g.elevation[l];
    const double b = a + g.beam_azimuth[l];
    const Eigen::Vector3d u(std::cos(b) * std::cos(phi), std::sin(b) * std::cos(phi), std::sin(phi));
    const Eigen::Vector3d p = T_head_sensor * c.points[i].cast<double>();
    const double r = (p - o).dot(u);
    const Eigen::Vector3d q = o + r * u;
    res.max_m = std::max(res.max_m, (q - p).norm());
    const double ang = std::atan2((q - p).norm(), std::max(std::abs(r), 1e-9));
    angles.push_back(ang);
    res.max_angle = std::max(res.max_angle, ang);
  }
  if (!angles.empty()) {
    std::nth_element(angles.begin(), angles.begin() + static_cast<std::ptrdiff_t>(angles.size() / 2), angles.end());
    res.median_angle = angles[angles.size() / 2];
  }
  return res;
}

/// The pixels a turn's points take (one point a pixel and return: a dual-return turn's
/// `return` field tells a pixel's two apart).
std::size_t expect_organised(const Cloud& c) {
  EXPECT_TRUE(c.has_rings() && c.has_columns() && c.has_intensity() && c.geometry.has_value());
  if (!c.has_rings() || !c.has_columns() || !c.geometry) return 0;
  EXPECT_EQ(c.geometry->lasers(), c.rows);
  const IntegerField* ret = c.field("return");
  std::set<std::uint64_t> seen, pixels;
  for (std::size_t i = 0; i < c.size(); ++i) {
    EXPECT_LT(c.ring[i], c.rows);
    EXPECT_LT(c.column[i], c.columns);
    const std::uint64_t px = static_cast<std::uint64_t>(c.ring[i]) * c.columns + c.column[i];
    pixels.insert(px);
    EXPECT_TRUE(seen.insert(2 * px + (ret != nullptr ? static_cast<std::uint64_t>(ret->values[i]) : 0U)).second)
        << "two points in one pixel";
    EXPECT_TRUE(c.points[i].allFinite());
    EXPECT_GT(c.points[i].norm(), 0.0F);
  }
  return pixels.size();
}

// ------------------------------------------------------------ Ouster

/// An Ouster turn's times (`t`, uint32 ns, as the ROS driver's): every point of one
/// measurement column (the destaggered column less its row's pixel shift) has that column's
/// timestamp, the first column's is 0, and they rise with the measurement column evenly
/// (within the timestamps' jitter of a few µs) over a turn (10 or 20 Hz).
void expect_ouster_times(const Cloud& c) {
  ASSERT_EQ(c.time.size(), c.size());
  EXPECT_EQ(c.time_source.name, "t");
  EXPECT_EQ(c.time_source.type, FieldType::kUint32);
  std::map<std::uint32_t, double> of_column;
  for (std::size_t i = 0; i < c.size(); ++i) {
    const auto shift = static_cast<std::int64_t>(std::llround(c.geometry->column_azimuth[c.ring[i]] * c.columns / (2.0 * M_PI)));
    const auto mc = static_cast<std::uint32_t>(((static_cast<std::int64_t>(c.column[i]) - shift) % c.columns + c.columns) % c.columns);
    const auto [at, fresh] = of_column.emplace(mc, c.time[i]);
    ASSERT_TRUE(fresh || at->second == c.time[i]) << "two times in measurement column " << mc;
    ASSERT_NEAR(c.time[i] * 1e9, std::round(c.time[i] * 1e9), 1e-6) << "whole nanoseconds";
  }
  ASSERT_GT(of_column.size(), 2U);
  const auto& [first_mc, low] = *of_column.begin();
  const auto& [last_mc, high] = *of_column.rbegin();
  EXPECT_EQ(low, 0.0);
  EXPECT_GT(high, 0.045);
  EXPECT_LT(high, 0.1);
  const double step = (high - low) / (last_mc - first_mc);
  for (auto a = of_column.begin(), b = std::next(a); b != of_column.end(); ++a, ++b) {
    const double s = (b->second - a->second) / (b->first - a->first);
    ASSERT_GT(s, 0.7 * step) << "measurement column " << b->first;
    ASSERT_LT(s, 1.3 * step) << "measurement column " << b->first;
  }
}

struct OusterCase {
  const char* pcap;
  const char* json;  // nullptr: found beside the capture
  std::uint32_t beams;
  std::size_t frames;
  const char* profile;
};

const OusterCase kOuster[] = {
    {"OS-0-128-U1_v2.3.0_1024x10.pcap", nullptr, 128, 1, "RNG15_RFL8_NIR8"},
    {"OS-0-32-U1_v2.2.0_1024x10.pcap", nullptr, 32, 1, "RNG19_RFL8_SIG16_NIR16_DUAL"},
    {"OS-1-128_v2.3.0_1024x10_lb_n3.pcap", "OS-1-128_v2.3.0_1024x10.json", 128, 3, "RNG15_RFL8_NIR8"},
    {"OS-1-32-G_v2.1.1_1024x10.pcap", nullptr, 32, 1, "LEGACY"},
    {"OS-2-128-U1_v2.3.0_1024x10.pcap", nullptr, 128, 1, "RNG19_RFL8_SIG16_NIR16"},
    {"OS-2-32-U0_v2.0.0_1024x10.pcap", nullptr, 32, 1, "LEGACY"},
};

TEST(SensorLog, EveryOusterCaptureDecodesAndTheGeometryReproducesEveryPoint) {
  LEX3D_REQUIRE_SHARED("ouster/OS-1-32-G_v2.1.1_1024x10.pcap");
  for (const OusterCase& k : kOuster) {
    SCOPED_TRACE(k.pcap);
    ReadOptions o;
    if (k.json != nullptr) o.metadata_path = shared_data(std::string("ouster/") + k.json);
    auto r = read_sensor_log(shared_data(std::string("ouster/") + k.pcap), o);
    ASSERT_TRUE(r.ok()) << r.status().to_string();
    const SensorLog& log = r.value();
    EXPECT_EQ(log.info.vendor, "ouster");
    EXPECT_EQ(log.info.profile, k.profile);
    EXPECT_EQ(log.info.lasers, k.beams);
    EXPECT_EQ(log.info.columns, 1024U);
    ASSERT_EQ(log.scans.size(), k.frames);
    EXPECT_EQ(log.info.incomplete_frames, 0U);
    std::size_t points = 0;
    for (std::size_t s = 0; s < log.scans.size(); ++s) {
      const Cloud& c = log.scans[s];
      EXPECT_EQ(c.rows, k.beams);
      EXPECT_EQ(c.columns, 1024U);
      const std::size_t pixels = expect_organised(c);
      // every pixel of the full column window holds points or is a counted no-return
      EXPECT_EQ(pixels + log.no_returns[s], static_cast<std::size_t>(k.beams) * 1024U);
      EXPECT_GT(c.size(), c.rows * c.columns / 2);
      const Residual res = geometry_residual(c);
      std::printf("[ geometry ] %s turn %zu: %zu points, %zu no-returns, max residual %.3g m\n", k.pcap, s, c.size(),
                  log.no_returns[s], res.max_m);
      EXPECT_LT(res.max_m, 1e-4);
      expect_ouster_times(c);
      // the packets' signal (not in the low-data profile) and near-infrared channels, kept as
      // named fields in their types: the signal follows the reflectivity, and the
      // near-infrared (an ambient-light image) changes little along a laser's row
      const bool low_data = std::string(k.profile) == "RNG15_RFL8_NIR8";
      const bool dual = std::string(k.profile).find("DUAL") != std::string::npos;
      ASSERT_EQ(c.fields.size(), (low_data ? 1U : 2U) + (dual ? 1U : 0U));
      const IntegerField& nir = c.fields[low_data ? 0 : 1];
      EXPECT_EQ(nir.name, "near_ir");
      EXPECT_EQ(nir.type, low_data ? FieldType::kUint8 : FieldType::kUint16);
      ASSERT_EQ(nir.values.size(), c.size());
      double along = 0.0, across = 0.0;
      for (std::size_t i = 1; i < c.size(); ++i) {
        along += std::abs(nir.values[i] - nir.values[i - 1]);
        across += std::abs(nir.values[i] - nir.values[(i * 7919) % c.size()]);
      }
      EXPECT_LT(along, 0.7 * across);
      if (!low_data) {
        const IntegerField& signal = c.fields.front();
        EXPECT_EQ(signal.name, "signal");
        EXPECT_EQ(signal.type, FieldType::kUint16);
        double sx = 0, sy = 0, sxx = 0, syy = 0, sxy = 0;
        const auto n = static_cast<double>(c.size());
        for (std::size_t i = 0; i < c.size(); ++i) {
          const double x = signal.values[i], y = c.intensity[i];
          sx += x;
          sy += y;
          sxx += x * x;
          syy += y * y;
          sxy += x * y;
        }
        const double corr = (n * sxy - sx * sy) / std::sqrt((n * sxx - sx * sx) * (n * syy - sy * sy));
        EXPECT_GT(corr, 0.1);
      }
      points += c.size();
      if (s > 0) EXPECT_EQ(log.frame_ids[s], log.frame_ids[s - 1] + 1);
      // each frame stamped with its first packet's capture time, a frame period apart
      // (10 or 20 Hz, within a few ms of the capturing host's scheduling)
      ASSERT_EQ(log.captured_ns.size(), log.scans.size());
      EXPECT_GT(log.captured_ns[s], 1400000000ULL * 1000000000ULL);  // after 2014
      if (s > 0) {
        const double apart = static_cast<double>(log.captured_ns[s] - log.captured_ns[s - 1]) * 1e-9;
        EXPECT_NEAR(apart, *std::max_element(c.time.begin(), c.time.end()) > 0.06 ? 0.1 : 0.05, 0.01);
      }
    }
    EXPECT_EQ(points, log.info.points);
    if (std::string(k.profile).find("DUAL") != std::string::npos) {
      // the second returns are points of their own: `return` 1, after the pixel's first
      // return where it has one, further along the same beam
      EXPECT_GT(log.info.second_returns, 0U);
      std::size_t seconds = 0, behind = 0;
      for (const Cloud& c : log.scans) {
        const IntegerField& ret = c.fields.back();
        ASSERT_EQ(ret.name, "return");
        ASSERT_EQ(ret.type, FieldType::kUint8);
        ASSERT_EQ(ret.values.size(), c.size());
        for (std::size_t i = 0; i < c.size(); ++i) {
          ASSERT_TRUE(ret.values[i] == 0 || ret.values[i] == 1);
          if (ret.values[i] == 0) continue;
          ++seconds;
          if (i == 0 || ret.values[i - 1] != 0 || c.ring[i - 1] != c.ring[i] || c.column[i - 1] != c.column[i]) continue;
          ++behind;
          EXPECT_EQ(c.time[i - 1], c.time[i]);
          EXPECT_NEAR(c.points[i].normalized().dot(c.points[i - 1].normalized()), 1.0, 1e-3);  // one beam
        }
      }
      EXPECT_EQ(seconds, log.info.second_returns);
      EXPECT_GT(behind, 0U);
      // read with single_return: the strongest returns alone, one a pixel
      ReadOptions first = o;
      first.single_return = true;
      auto single = read_sensor_log(shared_data(std::string("ouster/") + k.pcap), first);
      ASSERT_TRUE(single.ok()) << single.status().to_string();
      std::size_t firsts = 0;
      for (const Cloud& c : log.scans) firsts += c.size();
      for (const Cloud& c : single.value().scans) {
        EXPECT_EQ(c.field("return"), nullptr);
        EXPECT_FALSE(pixel_points(c).empty());
        firsts -= c.size();
      }
      EXPECT_EQ(firsts, seconds);
    } else {
      EXPECT_EQ(log.info.second_returns, 0U);
    }
  }
}

TEST(SensorLog, ReadCloudGivesTheFirstTurnOfACapture) {
  LEX3D_REQUIRE_SHARED("ouster/OS-1-128_v2.3.0_1024x10_lb_n3.pcap");
  const std::string pcap = shared_data("ouster/OS-1-128_v2.3.0_1024x10_lb_n3.pcap");
  // the metadata is found beside it by its stem cut at '_' (OS-1-128_v2.3.0_1024x10.json)
  auto log = read_sensor_log(pcap);
  ASSERT_TRUE(log.ok()) << log.status().to_string();
  auto r = read_cloud(pcap);
  ASSERT_TRUE(r.ok()) << r.status().to_string();
  EXPECT_EQ(r.value().format, Format::kPcap);
  EXPECT_EQ(r.value().sensor, "OS-1-128");
  EXPECT_EQ(r.value().scans_in_file, 3U);
  EXPECT_EQ(r.value().no_return_dropped, log.value().no_returns[0]);
  ASSERT_EQ(r.value().cloud.size(), log.value().scans[0].size());
  EXPECT_EQ(r.value().cloud.points[100], log.value().scans[0].points[100]);
  auto f = detect_format(pcap);
  ASSERT_TRUE(f.ok());
  EXPECT_EQ(f.value(), Format::kPcap);
}

TEST(SensorLog, FragmentedDatagramsAreReassembled) {
  LEX3D_REQUIRE_SHARED("ouster/OS-2-32-U0_v2.0.0_1024x10.pcap");
  const std::string src = shared_data("ouster/OS-2-32-U0_v2.0.0_1024x10.pcap");
  const fs::path dir = temp_dir("sensor_log_fragments");
  Capture c = parse_capture(slurp(src));
  const std::size_t split = fragment(c, 1500);
  ASSERT_GT(split, 0U);
  const std::string pcap = (dir / "frag.pcap").string();
  write_bytes(pcap, serialise(c));
  ReadOptions o;
  o.metadata_path = shared_data("ouster/OS-2-32-U0_v2.0.0_1024x10.json");
  auto a = read_sensor_log(src, o);
  auto b = read_sensor_log(pcap, o);
  ASSERT_TRUE(a.ok()) << a.status().to_string();
  ASSERT_TRUE(b.ok()) << b.status().to_string();
  EXPECT_EQ(b.value().info.fragmented_datagrams, split);
  EXPECT_GT(b.value().info.pcap_packets, a.value().info.pcap_packets);
  ASSERT_EQ(a.value().scans.size(), b.value().scans.size());
  EXPECT_EQ(a.value().scans[0].points, b.value().scans[0].points);
  EXPECT_EQ(a.value().scans[0].column, b.value().scans[0].column);
}

TEST(SensorLog, NestedMetadataLayoutGivesTheSamePoints) {
  LEX3D_REQUIRE_SHARED("ouster/OS-1-32-G_v2.1.1_1024x10.pcap");
  const std::string pcap = shared_data("ouster/OS-1-32-G_v2.1.1_1024x10.pcap");
  auto flat = read_sensor_log(pcap);
  ReadOptions o;
  o.metadata_path = std::string(LEX3D_TEST_DATA_DIR) + "/io/ouster_fw3_layout_OS-1-32-G.json";
  auto nested = read_sensor_log(pcap, o);
  ASSERT_TRUE(flat.ok()) << flat.status().to_string();
  ASSERT_TRUE(nested.ok()) << nested.status().to_string();
  EXPECT_EQ(nested.value().info.sensor, "OS-1-32-G");
  ASSERT_EQ(nested.value().scans.size(), 1U);
  EXPECT_EQ(nested.value().scans[0].points, flat.value().scans[0].points);
}

// ------------------------------------------------------------ Velodyne

/// A Velodyne turn's times (`time`, float32 seconds from the turn's first firing, as the
/// ROS driver's): a laser's rise with its column, one firing's lie within a firing period
/// `firing_us`, and the turn spans its columns' firings.
void expect_velodyne_times(const Cloud& c, double firing_us) {
  ASSERT_EQ(c.time.size(), c.size());
  EXPECT_EQ(c.time_source.name, "time");
  EXPECT_EQ(c.time_source.type, FieldType::kFloat32);
  std::map<std::uint32_t, std::pair<double, double>> firing;  // column: (earliest, latest)
  std::map<std::uint16_t, std::pair<std::uint32_t, double>> laser;  // ring: (last column, its time)
  for (std::size_t i = 0; i < c.size(); ++i) {
    const double t = c.time[i];
    ASSERT_GE(t, 0.0);
    auto [f, fresh] = firing.emplace(c.column[i], std::make_pair(t, t));
    f->second = {std::min(f->second.first, t), std::max(f->second.second, t)};
    auto [l, first] = laser.emplace(c.ring[i], std::make_pair(c.column[i], t));
    if (!first) {
      ASSERT_GT(c.column[i], l->second.first);
      ASSERT_GT(t, l->second.second) << "ring " << c.ring[i] << " column " << c.column[i];
      l->second = {c.column[i], t};
    }
  }
  for (const auto& [column, span] : firing) ASSERT_LT(span.second - span.first, firing_us * 1e-6) << column;
  const double last = firing.rbegin()->second.second;
  EXPECT_NEAR(last, c.columns * firing_us * 1e-6, 0.02 * c.columns * firing_us * 1e-6);
}

void expect_velodyne_turn(const Cloud& c, std::uint32_t lasers) {
  expect_organised(c);
  EXPECT_EQ(c.rows, lasers);
  for (std::size_t l = 1; l < c.geometry->elevation.size(); ++l)
    EXPECT_LT(c.geometry->elevation[l - 1], c.geometry->elevation[l]) << "rings ordered by elevation";
  const Residual res = geometry_residual(c);
  const double step = 2.0 * M_PI / c.columns;
  std::printf("[ geometry ] %s turn: %zu points, %u columns, grid residual median %.3g step, max %.3g steps\n",
              c.geometry->sensor.c_str(), c.size(), c.columns, res.median_angle / step, res.max_angle / step);
  // the firing azimuths come from the packets: the regular grid is close, not exact
  EXPECT_LT(res.median_angle, 0.3 * step);
  EXPECT_LT(res.max_angle, 1.0 * step);
}

TEST(SensorLog, Hdl32eCaptureGivesFiveTurns) {
  LEX3D_REQUIRE_SHARED("velodyne/hdl32e_hdl32_example.pcap");
  auto r = read_sensor_log(shared_data("velodyne/hdl32e_hdl32_example.pcap"));
  ASSERT_TRUE(r.ok()) << r.status().to_string();
  const SensorLog& log = r.value();
  EXPECT_EQ(log.info.sensor, "HDL-32E");
  EXPECT_EQ(log.info.lasers, 32U);
  ASSERT_EQ(log.scans.size(), 5U);
  for (std::size_t s = 0; s < log.scans.size(); ++s) {
    const Cloud& c = log.scans[s];
    // ~1,850 firings a turn at ~11.7 Hz, about three quarters of the slots with a return
    EXPECT_GT(c.columns, 1700U);
    EXPECT_LT(c.columns, 2000U);
    EXPECT_EQ(c.size() + log.no_returns[s], static_cast<std::size_t>(c.rows) * c.columns);
    EXPECT_GT(c.size(), 30000U);
    expect_velodyne_turn(c, 32);
    expect_velodyne_times(c, 46.08);
  }
  EXPECT_NEAR(log.scans[0].geometry->elevation.front() * 180 / M_PI, -30.67, 1e-9);
  // each turn stamped with its first packet's capture time, a turn (85 ms) after the one before
  ASSERT_EQ(log.captured_ns.size(), 5U);
  for (std::size_t s = 1; s < 5; ++s) {
    const double apart = static_cast<double>(log.captured_ns[s] - log.captured_ns[s - 1]) * 1e-9;
    const auto& t = log.scans[s - 1].time;
    EXPECT_NEAR(apart, *std::max_element(t.begin(), t.end()), 0.002) << s;
  }
  EXPECT_NEAR(log.scans[0].geometry->elevation.back() * 180 / M_PI, 10.67, 1e-9);
}

TEST(SensorLog, Vlp16CapturesGiveOneTurnAndTheWrongModelByteIsCaught) {
  LEX3D_REQUIRE_SHARED("velodyne/vlp16_velodyne_vlp16.pcap");
  for (const char* name : {"velodyne/vlp16_velodyne_example.pcap", "velodyne/vlp16_velodyne_vlp16.pcap"}) {
    SCOPED_TRACE(name);
    auto r = read_sensor_log(shared_data(name));
    ASSERT_TRUE(r.ok()) << r.status().to_string();
    const SensorLog& log = r.value();
    EXPECT_EQ(log.info.sensor, "VLP-16");
    ASSERT_EQ(log.scans.size(), 1U);  // 1.12 turns: one complete
    EXPECT_EQ(log.info.incomplete_frames, 1U);
    const Cloud& c = log.scans[0];
    EXPECT_GT(c.columns, 1700U);  // 0.2° a firing at 10 Hz
    EXPECT_LT(c.columns, 1900U);
    EXPECT_EQ(c.size() + log.no_returns[0], static_cast<std::size_t>(c.rows) * c.columns);
    expect_velodyne_turn(c, 16);
    expect_velodyne_times(c, 55.296);
    EXPECT_NEAR(c.geometry->elevation.front() * 180 / M_PI, -15.0, 1e-9);
  }
  auto r = read_sensor_log(shared_data("velodyne/vlp16_velodyne_vlp16.pcap"));
  EXPECT_NE(r.value().info.model_note.find("factory byte 0x21 says HDL-32E"), std::string::npos) << r.value().info.model_note;
  ReadOptions o;
  o.sensor_model = "hdl32e";  // the override wins over the timing check
  auto forced = read_sensor_log(shared_data("velodyne/vlp16_velodyne_vlp16.pcap"), o);
  ASSERT_TRUE(forced.ok()) << forced.status().to_string();
  EXPECT_EQ(forced.value().info.sensor, "HDL-32E");
  EXPECT_EQ(forced.value().info.lasers, 32U);
}

::testing::AssertionResult bad(const StatusOr<SensorLog>& r, const std::string& path, const std::string& what) {
  if (r.ok()) return ::testing::AssertionFailure() << "expected an error";
  const Status& s = r.status();
  if (s.code() != ErrorCode::kBadData) return ::testing::AssertionFailure() << "not kBadData: " << s.message();
  if (s.message().find(path) == std::string::npos)
    return ::testing::AssertionFailure() << "does not name " << path << ": " << s.message();
  if (s.message().find('\n') != std::string::npos) return ::testing::AssertionFailure() << "several lines";
  if (s.message().find(what) == std::string::npos)
    return ::testing::AssertionFailure() << "does not say '" << what << "': " << s.message();
  return ::testing::AssertionSuccess() << s.message();
}

// Velodyne packets edited in memory: the UDP payload of an Ethernet/IPv4 record.
constexpr std::size_t kUdpPayload = 42, kVelodynePacket = 1206;
bool velodyne_record(const Record& r) { return r.data.size() == kUdpPayload + kVelodynePacket; }
std::uint8_t* velodyne_payload(Record& r) { return reinterpret_cast<std::uint8_t*>(r.data.data()) + kUdpPayload; }
std::uint32_t payload_time(Record& r) {
  std::uint32_t t = 0;
  std::memcpy(&t, velodyne_payload(r) + 1200, 4);
  return t;
}
void set_payload_time(Record& r, std::uint32_t t) { std::memcpy(velodyne_payload(r) + 1200, &t, 4); }

/// Decodes `capture` (written under `name`) and returns its log; fails the test otherwise.
SensorLog decode_edited(const Capture& capture, const std::string& name, const ReadOptions& o = {}) {
  const std::string p = (temp_dir("sensor_log_edited") / name).string();
  write_bytes(p, serialise(capture));
  auto r = read_sensor_log(p, o);
  EXPECT_TRUE(r.ok()) << r.status().to_string();
  return r.ok() ? r.value() : SensorLog{};
}

/// The sample VLP-16 capture's first whole turn of packets (its first packet's azimuth
/// reached again), repeated `turns` times, each repetition's record times and packet
/// timestamps a turn's span on: a capture as long as wanted whose turns, but the first,
/// are all alike (each the end of one repetition and the start of the next).
Capture repeated_vlp16(std::size_t turns) {
  const Capture one = parse_capture(slurp(test::sample("vlp16_velodyne_example.pcap")));
  std::vector<Record> packets;
  for (const Record& r : one.records)
    if (velodyne_record(r)) packets.push_back(r);
  const auto azimuth = [](Record& r) {
    std::uint16_t a = 0;
    std::memcpy(&a, velodyne_payload(r) + 2, 2);
    return a / 100.0;
  };
  std::size_t end = 0;
  double turned = 0.0;
  for (std::size_t i = 1; i < packets.size() && end == 0; ++i) {
    turned += std::fmod(azimuth(packets[i]) - azimuth(packets[i - 1]) + 360.0, 360.0);
    if (turned >= 360.0) end = i;
  }
  EXPECT_GT(end, 60U);
  const std::uint64_t span_us = (static_cast<std::uint64_t>(packets[end].sec) * 1000000 + packets[end].usec) -
                                (static_cast<std::uint64_t>(packets[0].sec) * 1000000 + packets[0].usec);
  const std::uint32_t stamp_span = payload_time(packets[end]) - payload_time(packets[0]);
  Capture c;
  c.header = one.header;
  for (std::size_t k = 0; k < turns; ++k)
    for (std::size_t i = 0; i < end; ++i) {
      Record r = packets[i];
      const std::uint64_t t = static_cast<std::uint64_t>(r.sec) * 1000000 + r.usec + k * span_us;
      r.sec = static_cast<std::uint32_t>(t / 1000000);
      r.usec = static_cast<std::uint32_t>(t % 1000000);
      set_payload_time(r, static_cast<std::uint32_t>((payload_time(r) + k * stamp_span) % 3600000000U));
      c.records.push_back(std::move(r));
    }
  return c;
}

bool same_points(const Cloud& a, const Cloud& b) {
  return a.points == b.points && a.intensity == b.intensity && a.ring == b.ring && a.column == b.column &&
         a.rows == b.rows && a.columns == b.columns;
}

// A capture is read turn by turn (SensorLogReader): the first kVelodyneWindow packets tell
// the model, then each turn is handed on as it closes. 60 repetitions of a whole turn
// (4,560 packets, past that window; each a little over 360°): 60 complete turns and the
// rest cut, the turns after the first all alike, the same as read_sensor_log gives, the
// counters the whole capture's.
TEST(SensorLogReader, ALongCaptureGivesEveryTurnOneAtATime) {
  const Capture c = repeated_vlp16(60);
  const std::string p = (temp_dir("sensor_log_reader") / "long.pcap").string();
  write_bytes(p, serialise(c));
  auto reader = SensorLogReader::open(p);
  ASSERT_TRUE(reader.ok()) << reader.status().to_string();
  std::vector<SensorTurn> turns;
  for (;;) {
    auto t = reader.value()->next();
    ASSERT_TRUE(t.ok()) << t.status().to_string();
    if (!t.value()) break;
    turns.push_back(std::move(*t.value()));
  }
  const SensorLogInfo& info = reader.value()->info();
  ASSERT_EQ(turns.size(), 60U);
  EXPECT_EQ(info.frames, 60U);
  EXPECT_EQ(info.lidar_packets, c.records.size());
  EXPECT_EQ(info.incomplete_frames, 1U);
  EXPECT_EQ(info.sensor, "VLP-16");
  std::size_t points = 0;
  for (std::size_t k = 0; k < turns.size(); ++k) {
    SCOPED_TRACE(k);
    points += turns[k].cloud.size();
    EXPECT_EQ(turns[k].frame_id, k);
    EXPECT_EQ(turns[k].cloud.stamp.has_value(), true);
    if (k >= 2) {
      EXPECT_TRUE(same_points(turns[k].cloud, turns[1].cloud));
      EXPECT_EQ(turns[k].cloud.time, turns[1].cloud.time);
      EXPECT_GT(turns[k].captured_ns, turns[k - 1].captured_ns);
    }
  }
  EXPECT_EQ(info.points, points);
  auto whole = read_sensor_log(p);
  ASSERT_TRUE(whole.ok()) << whole.status().to_string();
  ASSERT_EQ(whole.value().scans.size(), turns.size());
  for (std::size_t k = 0; k < turns.size(); ++k) EXPECT_TRUE(same_points(whole.value().scans[k], turns[k].cloud)) << k;
  EXPECT_EQ(whole.value().info.points, info.points);
}

// A packet damaged late in a long capture: the turns before it come first, then its error
// (one line naming the file and the record); read_sensor_log gives the error alone.
TEST(SensorLogReader, TurnsBeforeALateErrorComeFirst) {
  Capture c = repeated_vlp16(60);
  const std::size_t bad_record = c.records.size() - 200;
  velodyne_payload(c.records[bad_record])[2] = 0xFF;  // block 0's azimuth: 65,535 hundredths of a degree
  velodyne_payload(c.records[bad_record])[3] = 0xFF;
  const std::string p = (temp_dir("sensor_log_reader") / "late_error.pcap").string();
  write_bytes(p, serialise(c));
  auto reader = SensorLogReader::open(p);
  ASSERT_TRUE(reader.ok()) << reader.status().to_string();
  std::size_t good = 0;
  Status error;
  for (;;) {
    auto t = reader.value()->next();
    if (!t.ok()) {
      error = t.status();
      break;
    }
    ASSERT_TRUE(t.value().has_value()) << "the capture ended without its error";
    EXPECT_GT(t.value()->cloud.size(), 20000U);
    ++good;
  }
  EXPECT_GE(good, 55U);
  EXPECT_EQ(error.code(), ErrorCode::kBadData);
  auto after = reader.value()->next();  // the error ended the reading
  ASSERT_FALSE(after.ok());
  EXPECT_EQ(after.status().message(), error.message());
  EXPECT_NE(error.message().find("capture record " + std::to_string(bad_record + 1)), std::string::npos) << error.message();
  EXPECT_NE(error.message().find(p), std::string::npos);
  EXPECT_TRUE(bad(read_sensor_log(p), p, "block 0 azimuth 65535 is not below 36000"));
}

// A head that does not spin (every packet at one azimuth): no turn ever closes; the firings
// held are bounded (past kMaxTurnFirings, 65,536, the open turn is counted incomplete and
// dropped: here once the first 4,096 packets are read, and at the end) and the capture ends
// in "no complete turn".
TEST(SensorLogReader, AHeadThatDoesNotSpinGivesNoTurnAndHoldsNoMore) {
  Capture c = repeated_vlp16(1);
  const Record still = c.records.front();
  c.records.assign(6000, still);  // 144,000 firings at one azimuth
  for (std::size_t i = 0; i < c.records.size(); ++i) {
    c.records[i].usec = static_cast<std::uint32_t>(i % 1000000);
    set_payload_time(c.records[i], static_cast<std::uint32_t>(1327 * i));
    for (std::size_t k = 0; k < 12; ++k) {  // every block at the same azimuth
      velodyne_payload(c.records[i])[k * 100 + 2] = 0x10;
      velodyne_payload(c.records[i])[k * 100 + 3] = 0x27;
    }
  }
  const std::string p = (temp_dir("sensor_log_reader") / "still.pcap").string();
  write_bytes(p, serialise(c));
  auto r = read_sensor_log(p);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("no complete turn: 6000 VLP-16 packets, 2 incomplete"), std::string::npos)
      << r.status().message();
}

TEST(SensorLog, PuckHiResPacketsUseItsElevations) {
  // The VLP-16 sample with the Puck Hi-Res factory byte (same packets and timing, the
  // lasers 4/3° apart within ±10°): every point keeps its range and column, at the Hi-Res
  // elevation of its laser.
  const std::string bytes = slurp(test::sample("vlp16_velodyne_example.pcap"));
  const SensorLog vlp = decode_edited(parse_capture(bytes), "vlp16.pcap");
  Capture c = parse_capture(bytes);
  for (Record& r : c.records)
    if (velodyne_record(r)) velodyne_payload(r)[1205] = 0x24;
  const SensorLog hires = decode_edited(c, "hires.pcap");
  ASSERT_EQ(vlp.scans.size(), 1U);
  ASSERT_EQ(hires.scans.size(), 1U);
  EXPECT_EQ(hires.info.sensor, "Puck Hi-Res");
  EXPECT_NE(hires.info.model_note.find("(agrees)"), std::string::npos) << hires.info.model_note;
  const Cloud& a = vlp.scans[0];
  const Cloud& b = hires.scans[0];
  expect_velodyne_turn(b, 16);
  ASSERT_EQ(a.size(), b.size());
  EXPECT_NEAR(b.geometry->elevation.front() * 180 / M_PI, -10.0, 1e-9);
  EXPECT_NEAR(b.geometry->elevation.back() * 180 / M_PI, 10.0, 1e-9);
  for (std::size_t i = 0; i < a.size(); i += 97) {
    ASSERT_EQ(a.ring[i], b.ring[i]);  // both tables interleave low and high lasers alike
    ASSERT_EQ(a.column[i], b.column[i]);
    EXPECT_NEAR(a.points[i].norm(), b.points[i].norm(), 1e-4);
    EXPECT_NEAR(std::asin(b.points[i].z() / b.points[i].norm()), b.geometry->elevation[b.ring[i]], 1e-5);
  }
}

TEST(SensorLog, Vlp32cPacketsUseItsTableAzimuthOffsetsAndRangeUnit) {
  // The HDL-32E capture's packets (12 blocks of one 32-laser firing each, as a VLP-32C's)
  // with the VLP-32C factory byte and packet period: read with the VLP-32C's elevations,
  // azimuth offsets (±1.4°, ±4.2°), paired firing times and 4 mm range unit.
  LEX3D_REQUIRE_SHARED("velodyne/hdl32e_hdl32_example.pcap");
  const std::string bytes = slurp(shared_data("velodyne/hdl32e_hdl32_example.pcap"));
  const SensorLog hdl = decode_edited(parse_capture(bytes), "hdl32e.pcap");
  Capture c = parse_capture(bytes);
  std::size_t k = 0;
  std::uint32_t t0 = 0;
  for (Record& r : c.records) {
    if (!velodyne_record(r)) continue;
    if (k == 0) t0 = payload_time(r);
    velodyne_payload(r)[1205] = 0x28;
    set_payload_time(r, t0 + static_cast<std::uint32_t>(std::lround(static_cast<double>(k++) * 12 * 55.296)));
  }
  const SensorLog v = decode_edited(c, "vlp32c.pcap");
  EXPECT_EQ(v.info.sensor, "VLP-32C");
  EXPECT_EQ(v.info.lasers, 32U);
  EXPECT_NE(v.info.model_note.find("(agrees)"), std::string::npos) << v.info.model_note;
  ASSERT_EQ(v.scans.size(), hdl.scans.size());
  ASSERT_FALSE(v.scans.empty());
  const Cloud& a = hdl.scans[0];
  const Cloud& b = v.scans[0];
  expect_velodyne_turn(b, 32);
  ASSERT_EQ(a.size(), b.size());
  EXPECT_NEAR(b.geometry->elevation.front() * 180 / M_PI, -25.0, 1e-9);
  EXPECT_NEAR(b.geometry->elevation.back() * 180 / M_PI, 15.0, 1e-9);
  // the lowest beam (laser 0) points 1.4° clockwise of its firing: beam_azimuth -1.4°
  EXPECT_NEAR(b.geometry->beam_azimuth.front() * 180 / M_PI, -1.4, 1e-9);
  double max_offset = 0.0;
  for (double x : b.geometry->beam_azimuth) max_offset = std::max(max_offset, std::abs(x) * 180 / M_PI);
  EXPECT_NEAR(max_offset, 4.2, 1e-9);
  // Each point from its own firing: the HDL-32E reading's point of the same laser id and
  // column at azimuth α_h (laser l fires l·1.152 µs into 46.08 µs there, floor(l/2)·2.304 µs
  // into 55.296 µs here), twice the range (4 mm units), at the VLP-32C laser's elevation and
  // offset. Rings are lasers by elevation: each table, sorted, gives a ring's laser id.
  const double hdl_el[32] = {-30.67, -9.33, -29.33, -8.00, -28.00, -6.67, -26.67, -5.33, -25.33, -4.00, -24.00,
                             -2.67,  -22.67, -1.33, -21.33, 0.00, -20.00, 1.33, -18.67, 2.67, -17.33, 4.00,
                             -16.00, 5.33,  -14.67, 6.67, -13.33, 8.00, -12.00, 9.33, -10.67, 10.67};
  const double vlp_el[32] = {-25,    -1,     -1.667, -15.639, -11.31, 0,      -0.667, -8.843, -7.254, 0.333, -0.333,
                             -6.148, -5.333, 1.333,  0.667,   -4,     -4.667, 1.667,  1,      -3.667, -3.333, 3.333,
                             2.333,  -2.667, -3,     7,       4.667,  -2.333, -2,     15,     10.333, -1.333};
  const auto ids_by_ring = [](const double* el) {
    std::vector<int> id(32);
    for (int l = 0; l < 32; ++l) id[l] = l;
    std::sort(id.begin(), id.end(), [&](int x, int y) { return el[x] < el[y]; });
    return id;
  };
  const std::vector<int> hdl_id = ids_by_ring(hdl_el), vlp_id = ids_by_ring(vlp_el);
  std::map<std::pair<int, std::uint32_t>, std::size_t> in_a;
  for (std::size_t i = 0; i < a.size(); ++i) in_a[{hdl_id[a.ring[i]], a.column[i]}] = i;
  const double step = 360.0 / a.columns;
  std::size_t checked = 0;
  for (std::size_t j = 0; j < b.size(); j += 101) {
    const int id = vlp_id[b.ring[j]];
    EXPECT_NEAR(b.geometry->elevation[b.ring[j]] * 180 / M_PI, vlp_el[id], 1e-9);
    const auto it = in_a.find({id, b.column[j]});
    ASSERT_NE(it, in_a.end());
    const std::size_t i = it->second;
    EXPECT_NEAR(b.points[j].norm(), 2.0 * a.points[i].norm(), 2e-4 * a.points[i].norm() + 1e-4);
    EXPECT_NEAR(std::asin(b.points[j].z() / b.points[j].norm()), vlp_el[id] * M_PI / 180, 1e-5);
    // azimuth: clockwise from +y (Velodyne's), the firing's start + the time share + the offset
    const double alpha_a = std::atan2(a.points[i].x(), a.points[i].y()) * 180 / M_PI;
    const double alpha_b = std::atan2(b.points[j].x(), b.points[j].y()) * 180 / M_PI;
    const double share_a = id * 1.152 / 46.08, share_b = (id / 2) * 2.304 / 55.296;
    const double offset = -b.geometry->beam_azimuth[b.ring[j]] * 180 / M_PI;
    EXPECT_TRUE(std::abs(std::abs(offset) - 1.4) < 1e-9 || std::abs(std::abs(offset) - 4.2) < 1e-9) << offset;
    const double expected = alpha_a + step * (share_b - share_a) + offset;
    EXPECT_NEAR(std::remainder(alpha_b - expected, 360.0), 0.0, 0.05 * step) << "point " << j << " laser " << id;
    ++checked;
  }
  EXPECT_GT(checked, 100U);
}

TEST(SensorLog, DualReturnPacketsKeepBothReturns) {
  // The VLP-16 sample turned into dual-return packets: each packet's 12 blocks go into two
  // packets of 6 block pairs (the block, then a copy with every third return moved 20 cm
  // as a distinct strongest return), mode byte 0x39, packets twice as often.
  const std::string bytes = slurp(test::sample("vlp16_velodyne_example.pcap"));
  const SensorLog single = decode_edited(parse_capture(bytes), "single.pcap");
  Capture c = parse_capture(bytes);
  std::vector<Record> out;
  std::size_t moved = 0;
  for (Record& r : c.records) {
    if (!velodyne_record(r)) {
      out.push_back(r);
      continue;
    }
    const std::uint32_t t = payload_time(r);
    for (int half = 0; half < 2; ++half) {
      Record d = r;
      std::uint8_t* p = velodyne_payload(d);
      const std::uint8_t* src = velodyne_payload(r);
      for (int k = 0; k < 6; ++k) {
        const std::uint8_t* blk = src + (half * 6 + k) * 100;
        std::memcpy(p + (2 * k) * 100, blk, 100);
        std::memcpy(p + (2 * k + 1) * 100, blk, 100);
        for (int ch = 0; ch < 32; ch += 3) {
          std::uint8_t* x = p + (2 * k + 1) * 100 + 4 + ch * 3;
          const int dist = x[0] | (x[1] << 8);
          if (dist == 0 || dist > 60000) continue;
          x[0] = static_cast<std::uint8_t>((dist + 100) & 255);
          x[1] = static_cast<std::uint8_t>((dist + 100) >> 8);
          ++moved;
        }
      }
      p[1204] = 0x39;
      set_payload_time(d, t + static_cast<std::uint32_t>(half * 664));
      out.push_back(std::move(d));
    }
  }
  c.records = std::move(out);
  const SensorLog dual = decode_edited(c, "dual.pcap");
  EXPECT_EQ(dual.info.sensor, "VLP-16");
  EXPECT_EQ(dual.info.profile, "dual (both returns kept)");
  EXPECT_NE(dual.info.model_note.find("(agrees)"), std::string::npos) << dual.info.model_note;
  ASSERT_EQ(dual.scans.size(), single.scans.size());
  ASSERT_EQ(dual.scans.size(), 1U);
  const Cloud& a = single.scans[0];
  const Cloud& all = dual.scans[0];
  EXPECT_EQ(a.columns, all.columns);
  // the last returns (`return` 0) are the single-return turn's points; the others (`return`
  // 1) follow them at the same pixel and time, 100 range units (0.2 m) further along the beam
  ASSERT_EQ(all.fields.size(), 1U);
  const IntegerField& ret = all.fields[0];
  EXPECT_EQ(ret.name, "return");
  Cloud b;
  std::size_t others = 0;
  for (std::size_t i = 0; i < all.size(); ++i) {
    if (ret.values[i] == 1) {
      ++others;
      ASSERT_GT(i, 0U);
      ASSERT_EQ(ret.values[i - 1], 0);
      ASSERT_EQ(all.ring[i], all.ring[i - 1]);
      ASSERT_EQ(all.column[i], all.column[i - 1]);
      ASSERT_EQ(all.time[i], all.time[i - 1]);
      ASSERT_NEAR(all.points[i].norm() - all.points[i - 1].norm(), 0.2, 0.01) << i;
      continue;
    }
    b.points.push_back(all.points[i]);
    b.ring.push_back(all.ring[i]);
    b.column.push_back(all.column[i]);
    b.time.push_back(all.time[i]);
  }
  EXPECT_EQ(others, dual.info.second_returns);
  b.columns = all.columns;
  b.rows = all.rows;
  b.time_source = all.time_source;
  ASSERT_EQ(a.size(), b.size());
  // the same ranges, lasers and columns; azimuths within 0.3 of a firing step (a packet's
  // last block pair places its second firing and its lasers' firing times by the gap from
  // the pair before, whose block azimuths, in 0.01° units, jitter by a unit or two)
  for (std::size_t i = 0; i < a.size(); ++i) {
    ASSERT_EQ(a.ring[i], b.ring[i]);
    ASSERT_EQ(a.column[i], b.column[i]);
    ASSERT_NEAR(a.points[i].norm(), b.points[i].norm(), 1e-5) << i;
    ASSERT_EQ(a.points[i].z(), b.points[i].z()) << i;
    const double da = std::remainder(std::atan2(a.points[i].y(), a.points[i].x()) - std::atan2(b.points[i].y(), b.points[i].x()), 2 * M_PI);
    ASSERT_LT(std::abs(da), 0.3 * 2 * M_PI / a.columns) << i;
    // the same firing times (the second packet of each pair stamped 664 us, 12 firings, on)
    ASSERT_NEAR(a.time[i], b.time[i], 0.5e-6) << i;
  }
  expect_velodyne_times(b, 55.296);
  // read with single_return: the last returns alone, as the single-return turn, organised
  ReadOptions one;
  one.single_return = true;
  const SensorLog lasts = decode_edited(c, "dual_single.pcap", one);
  ASSERT_EQ(lasts.scans.size(), 1U);
  const Cloud& l = lasts.scans[0];
  EXPECT_EQ(lasts.info.second_returns, dual.info.second_returns);  // still counted
  EXPECT_TRUE(l.fields.empty());
  ASSERT_EQ(l.size(), b.size());
  for (std::size_t i = 0; i < l.size(); ++i) {
    ASSERT_EQ(l.points[i], b.points[i]);
    ASSERT_EQ(l.column[i], b.column[i]);
    ASSERT_EQ(l.time[i], b.time[i]);
  }
  EXPECT_FALSE(io::pixel_points(l).empty());
  EXPECT_TRUE(io::pixel_points(all).empty());
  // the moved returns of the kept turn (a share of all moved ones: 1.12 turns captured)
  EXPECT_GT(dual.info.second_returns, a.size() / 20);
  EXPECT_LT(dual.info.second_returns, moved);
  EXPECT_EQ(single.info.second_returns, 0U);
  // a pair whose blocks disagree in azimuth is not a dual-return packet
  for (Record& r : c.records)
    if (velodyne_record(r)) {
      velodyne_payload(r)[100 + 2] ^= 1;
      break;
    }
  const std::string p = (temp_dir("sensor_log_edited") / "dual_bad.pcap").string();
  write_bytes(p, serialise(c));
  EXPECT_TRUE(bad(read_sensor_log(p), p, "differ in azimuth"));
}

// ------------------------------------------------------------ HDL-64E with its calibration

/// An HDL-64E-like calibration: 64 lasers from -24.8° to +2° (upper block above), rotation
/// corrections within ±8°, distance corrections near 1.3 m, beam origins 15-22 cm up their
/// normals and 2.6 cm to alternate sides (the ranges of real S2 calibrations).
struct Calib64 {
  double vert_deg[64], rot_deg[64], dist[64], vert_off[64], horiz_off[64];
  Calib64() {
    for (int l = 0; l < 64; ++l) {
      const bool upper = l < 32;
      const int k = upper ? l : l - 32;
      vert_deg[l] = upper ? 2.0 - 0.34 * (k * 7 % 32) : -8.8 - 0.5 * (k * 5 % 32);
      rot_deg[l] = 8.0 * std::sin(1.7 * l + 0.3);
      dist[l] = 1.2 + 0.005 * ((l * 13) % 40);
      vert_off[l] = upper ? 0.215 - 0.0004 * k : 0.160 - 0.0005 * k;
      horiz_off[l] = l % 2 == 0 ? 0.026 : -0.026;
    }
  }
  [[nodiscard]] std::string yaml() const {
    std::string y = "distance_resolution: 0.002\nlasers:\n";
    char buf[512];
    for (int l = 0; l < 64; ++l) {
      std::snprintf(buf, sizeof buf,
                    "- dist_correction: %.17g\n  dist_correction_x: %.17g\n  dist_correction_y: %.17g\n"
                    "  laser_id: %d\n  rot_correction: %.17g\n  two_pt_correction_available: false\n"
                    "  vert_correction: %.17g\n  vert_offset_correction: %.17g\n  horiz_offset_correction: %.17g\n",
                    dist[l], dist[l], dist[l], l, rot_deg[l] * M_PI / 180, vert_deg[l] * M_PI / 180, vert_off[l],
                    horiz_off[l]);
      y += buf;
    }
    return y + "num_lasers: 64\n";
  }
  [[nodiscard]] std::string xml() const {  // db.xml: degrees and centimetres
    std::string x = "<?xml version=\"1.0\"?>\n<boost_serialization>\n<DB>\n<distLSB_>0.2</distLSB_>\n<points_>\n";
    char buf[512];
    for (int l = 0; l < 64; ++l) {
      std::snprintf(buf, sizeof buf,
                    "<item><px><id_>%d</id_><rotCorrection_>%.17g</rotCorrection_><vertCorrection_>%.17g</vertCorrection_>"
                    "<distCorrection_>%.17g</distCorrection_><vertOffsetCorrection_>%.17g</vertOffsetCorrection_>"
                    "<horizOffsetCorrection_>%.17g</horizOffsetCorrection_></px></item>\n",
                    l, rot_deg[l], vert_deg[l], dist[l] * 100, vert_off[l] * 100, horiz_off[l] * 100);
      x += buf;
    }
    return x + "</points_>\n</DB>\n</boost_serialization>\n";
  }
};

/// Distance along laser l's beam fired at Velodyne azimuth `alpha_deg` (clockwise from +y)
/// to a scene of a floor 1.73 m below the sensor and a round wall 18 m from its axis;
/// 0 where it hits neither within 120 m.
double scene_distance(const Calib64& c, int l, double alpha_deg) {
  const double w = c.vert_deg[l] * M_PI / 180, th = (alpha_deg - c.rot_deg[l]) * M_PI / 180;
  const double v = c.vert_off[l], h = c.horiz_off[l];
  const Eigen::Vector3d o(-v * std::sin(w) * std::sin(th) - h * std::cos(th), -v * std::sin(w) * std::cos(th) + h * std::sin(th),
                          v * std::cos(w));
  const Eigen::Vector3d u(std::cos(w) * std::sin(th), std::cos(w) * std::cos(th), std::sin(w));
  double t = 1e9;
  if (u.z() < 0) t = (-1.73 - o.z()) / u.z();
  const double a = u.x() * u.x() + u.y() * u.y(), b = 2 * (o.x() * u.x() + o.y() * u.y()),
               cc = o.x() * o.x() + o.y() * o.y() - 18.0 * 18.0;
  const double disc = b * b - 4 * a * cc;
  if (a > 0 && disc >= 0) t = std::min(t, (-b + std::sqrt(disc)) / (2 * a));
  return t > 0 && t < 120 ? t : 0.0;
}

/// An HDL-64E capture of that scene: 1.2 turns of firings 0.18° apart, each packet six
/// upper/lower block pairs, the distances in 2 mm units less the laser's correction.
Capture hdl64_capture(const Calib64& c, const Record& frame_template) {
  Capture cap = parse_capture(slurp(test::sample("vlp16_velodyne_example.pcap")));
  cap.records.clear();
  int az = 17000;  // 0.01° units
  for (int packet = 0; packet < 400; ++packet) {
    Record r = frame_template;
    std::uint8_t* p = velodyne_payload(r);
    for (int pair = 0; pair < 6; ++pair) {
      for (int bank = 0; bank < 2; ++bank) {
        std::uint8_t* blk = p + (2 * pair + bank) * 100;
        blk[0] = 0xFF;
        blk[1] = bank == 0 ? 0xEE : 0xDD;
        blk[2] = static_cast<std::uint8_t>((az % 36000) & 255);
        blk[3] = static_cast<std::uint8_t>((az % 36000) >> 8);
        for (int k = 0; k < 32; ++k) {
          const int l = bank * 32 + k;
          const double d = scene_distance(c, l, az / 100.0);
          const long raw = d > 0 ? std::lround((d - c.dist[l]) / 0.002) : 0;
          blk[4 + 3 * k] = static_cast<std::uint8_t>(raw & 255);
          blk[5 + 3 * k] = static_cast<std::uint8_t>(raw >> 8);
          blk[6 + 3 * k] = static_cast<std::uint8_t>(l * 3);
        }
      }
      az += 18;
    }
    set_payload_time(r, static_cast<std::uint32_t>(packet * 288));
    p[1204] = 0xA5;  // status bytes, not a return mode
    p[1205] = static_cast<std::uint8_t>(packet);
    cap.records.push_back(std::move(r));
  }
  return cap;
}

Record velodyne_frame_template() {
  Capture c = parse_capture(slurp(test::sample("vlp16_velodyne_example.pcap")));
  for (const Record& r : c.records)
    if (velodyne_record(r)) return r;
  ADD_FAILURE() << "no Velodyne packet in the sample";
  return {};
}

TEST(SensorLog, Hdl64eCaptureWithItsCalibrationPlacesEveryPointOnTheScene) {
  const Calib64 calib;
  const fs::path dir = temp_dir("sensor_log_hdl64");
  const Capture cap = hdl64_capture(calib, velodyne_frame_template());
  const std::string pcap = (dir / "hdl64e_run.pcap").string();
  write_bytes(pcap, serialise(cap));
  // the ROS driver's YAML beside the capture (found by the stem cut at '_'), then db.xml given
  write_bytes((dir / "hdl64e.yaml").string(), calib.yaml());
  auto from_yaml = read_sensor_log(pcap);
  ASSERT_TRUE(from_yaml.ok()) << from_yaml.status().to_string();
  ReadOptions o;
  o.metadata_path = (dir / "db.xml").string();
  write_bytes(o.metadata_path, calib.xml());
  auto from_xml = read_sensor_log(pcap, o);
  ASSERT_TRUE(from_xml.ok()) << from_xml.status().to_string();
  const SensorLog& log = from_yaml.value();
  EXPECT_EQ(log.info.sensor, "HDL-64E");
  EXPECT_EQ(log.info.lasers, 64U);
  EXPECT_EQ(log.info.metadata_path, (dir / "hdl64e.yaml").string());
  ASSERT_EQ(log.scans.size(), 1U);
  const Cloud& c = log.scans[0];
  EXPECT_EQ(c.columns, 2000U);
  expect_organised(c);
  // (a packet every 288 us holds 6 firings: 48 us apart, the upper and lower lasers at once)
  expect_velodyne_times(c, 48.0);
  EXPECT_EQ(c.geometry->source, "calibration " + (dir / "hdl64e.yaml").string());
  // both calibration files give the same points (to float rounding of their units)
  const Cloud& x = from_xml.value().scans[0];
  ASSERT_EQ(x.size(), c.size());
  for (std::size_t i = 0; i < c.size(); ++i) ASSERT_LT((x.points[i] - c.points[i]).norm(), 1e-5F) << i;
  // every point on the floor or the wall, within the 2 mm range unit
  std::size_t floor = 0, wall = 0;
  for (const Eigen::Vector3f& q : c.points) {
    const double to_floor = std::abs(q.z() + 1.73), to_wall = std::abs(std::hypot(q.x(), q.y()) - 18.0);
    ASSERT_LT(std::min(to_floor, to_wall), 1.5e-3) << q.transpose();
    (to_floor < to_wall ? floor : wall) += 1;
  }
  EXPECT_GT(floor, c.size() / 4);
  EXPECT_GT(wall, c.size() / 10);
  // the geometry (beam origins off the axis and up the beams' normals) reproduces each point
  const Residual res = geometry_residual(c);
  std::printf("[ geometry ] HDL-64E turn: %zu points, %u columns, max residual %.3g m\n", c.size(), c.columns, res.max_m);
  EXPECT_LT(res.max_m, 1e-4);
  for (std::size_t r = 1; r < 64; ++r) EXPECT_LT(c.geometry->elevation[r - 1], c.geometry->elevation[r]);
}

TEST(SensorLogErrors, Hdl64eWithoutOrWithAWrongCalibration) {
  const Calib64 calib;
  const fs::path dir = temp_dir("sensor_log_hdl64_bad");
  Capture cap = hdl64_capture(calib, velodyne_frame_template());
  const std::string pcap = (dir / "capture.pcap").string();
  write_bytes(pcap, serialise(cap));
  EXPECT_TRUE(bad(read_sensor_log(pcap), pcap, "needs the sensor's calibration"));
  ReadOptions o;
  o.metadata_path = (dir / "c.yaml").string();
  // 32 lasers
  std::string y = calib.yaml();
  write_bytes(o.metadata_path, y.substr(0, y.find("- dist_correction", y.find("laser_id: 31"))));
  EXPECT_TRUE(bad(read_sensor_log(pcap, o), pcap, "32 lasers"));
  EXPECT_TRUE(bad(read_sensor_log(pcap, o), o.metadata_path, "32 lasers"));  // (both named)
  // a NaN angle, a missing angle, a repeated id
  for (const auto& [from, to, what] : std::vector<std::tuple<std::string, std::string, std::string>>{
           {"laser_id: 5\n  rot_correction: ", "laser_id: 5\n  rot_correction: nan #", "laser 5: rotation"},
           {"laser_id: 7\n", "laser_id: 6\n", "laser ids are not 0..63"},
           {"  vert_correction", "  vert_corr", "vert_correction is missing"}}) {
    std::string t = y;
    t.replace(t.find(from), from.size(), to);
    write_bytes(o.metadata_path, t);
    EXPECT_TRUE(bad(read_sensor_log(pcap, o), o.metadata_path, what)) << what;
  }
  // every cut of either calibration file: read, or one line naming it (never a crash)
  for (const std::string& text : {y, calib.xml()})
    for (std::size_t cut = 0; cut < text.size(); cut += 331) {
      write_bytes(o.metadata_path, text.substr(0, cut));
      auto r = read_sensor_log(pcap, o);
      if (r.ok()) continue;
      EXPECT_EQ(r.status().message().find('\n'), std::string::npos) << r.status().message();
      EXPECT_NE(r.status().message().find(o.metadata_path), std::string::npos) << r.status().message();
    }
  // the capture's upper and lower blocks at two azimuths (a dual-return S3 layout)
  write_bytes(o.metadata_path, y);
  velodyne_payload(cap.records[3])[100 + 2] ^= 1;
  write_bytes(pcap, serialise(cap));
  EXPECT_TRUE(bad(read_sensor_log(pcap, o), pcap, "differ in azimuth"));
}

// ------------------------------------------------------------ bad input


TEST(SensorLogErrors, NoLidarPackets) {
  LEX3D_REQUIRE_SHARED("velodyne/hdl32e_hdl32_example.pcap");
  Capture c = parse_capture(slurp(shared_data("velodyne/hdl32e_hdl32_example.pcap")));
  std::vector<Record> gps;
  for (const auto& r : c.records)
    if (r.data.size() < 1000) gps.push_back(r);  // the 512-byte position packets only
  ASSERT_FALSE(gps.empty());
  c.records = gps;
  const std::string p = (temp_dir("sensor_log_nolidar") / "gps_only.pcap").string();
  write_bytes(p, serialise(c));
  EXPECT_TRUE(bad(read_sensor_log(p), p, "no lidar packets"));
  c.records.clear();
  write_bytes(p, serialise(c));
  EXPECT_TRUE(bad(read_sensor_log(p), p, "no lidar packets"));
  write_bytes(p, "not a capture at all");
  EXPECT_TRUE(bad(read_sensor_log(p), p, "not a readable pcap"));
}

TEST(SensorLogErrors, TruncatedPackets) {
  LEX3D_REQUIRE_SHARED("velodyne/hdl32e_hdl32_example.pcap");
  const std::string bytes = slurp(shared_data("velodyne/hdl32e_hdl32_example.pcap"));
  const fs::path dir = temp_dir("sensor_log_truncated");
  // the capture file ends inside a record
  const std::string cut = (dir / "cut.pcap").string();
  write_bytes(cut, bytes.substr(0, bytes.size() / 2 + 7));
  EXPECT_TRUE(bad(read_sensor_log(cut), cut, "truncated"));
  // a data packet captured short (snap length)
  Capture c = parse_capture(bytes);
  for (auto& r : c.records)
    if (r.data.size() > 1200) {
      r.data.resize(r.data.size() - 300);
      break;
    }
  const std::string snap = (dir / "snap.pcap").string();
  write_bytes(snap, serialise(c));
  EXPECT_TRUE(bad(read_sensor_log(snap), snap, "truncated"));
  // an Ouster lidar packet captured short
  LEX3D_REQUIRE_SHARED("ouster/OS-1-32-G_v2.1.1_1024x10.pcap");
  Capture o = parse_capture(slurp(shared_data("ouster/OS-1-32-G_v2.1.1_1024x10.pcap")));
  o.records[10].data.resize(o.records[10].data.size() / 2);
  const std::string os = (dir / "ouster.pcap").string();
  write_bytes(os, serialise(o));
  ReadOptions opt;
  opt.metadata_path = shared_data("ouster/OS-1-32-G_v2.1.1_1024x10.json");
  EXPECT_TRUE(bad(read_sensor_log(os, opt), os, "truncated"));
}

TEST(SensorLogErrors, MetadataThatDoesNotMatchThePackets) {
  LEX3D_REQUIRE_SHARED("ouster/OS-0-32-U1_v2.2.0_1024x10.pcap");
  const std::string pcap = shared_data("ouster/OS-0-32-U1_v2.2.0_1024x10.pcap");
  ReadOptions o;
  // beam count and profile: 128-beam RNG15 metadata for a 32-beam dual-return capture
  o.metadata_path = shared_data("ouster/OS-0-128-U1_v2.3.0_1024x10.json");
  EXPECT_TRUE(bad(read_sensor_log(pcap, o), pcap, "does not match"));
  // same size, another sensor: OS-1-128 metadata for the OS-0-128 capture (serial numbers)
  const std::string os0 = shared_data("ouster/OS-0-128-U1_v2.3.0_1024x10.pcap");
  o.metadata_path = shared_data("ouster/OS-1-128_v2.3.0_1024x10.json");
  EXPECT_TRUE(bad(read_sensor_log(os0, o), os0, "does not match"));
  // columns: a frame of 512 columns cannot hold measurement ids up to 1023
  const fs::path dir = temp_dir("sensor_log_mismatch");
  std::string js = slurp(shared_data("ouster/OS-1-32-G_v2.1.1_1024x10.json"));
  const std::size_t at = js.find("\"columns_per_frame\": 1024");
  ASSERT_NE(at, std::string::npos);
  js.replace(at, std::strlen("\"columns_per_frame\": 1024"), "\"columns_per_frame\": 512");
  const std::size_t win = js.find("1023");
  ASSERT_NE(win, std::string::npos);
  js.replace(win, 4, "511");
  const std::string meta = (dir / "512.json").string();
  write_bytes(meta, js);
  o.metadata_path = meta;
  const std::string legacy = shared_data("ouster/OS-1-32-G_v2.1.1_1024x10.pcap");
  EXPECT_TRUE(bad(read_sensor_log(legacy, o), legacy, "does not match"));
  // no metadata at all
  const std::string lone = (dir / "lone.pcap").string();
  fs::copy_file(legacy, lone);
  EXPECT_TRUE(bad(read_sensor_log(lone), lone, "metadata"));
}

TEST(SensorLogErrors, LaserTableWithNaN) {
  LEX3D_REQUIRE_SHARED("ouster/OS-1-32-G_v2.1.1_1024x10.pcap");
  const std::string pcap = shared_data("ouster/OS-1-32-G_v2.1.1_1024x10.pcap");
  const fs::path dir = temp_dir("sensor_log_nan");
  const std::string orig = slurp(shared_data("ouster/OS-1-32-G_v2.1.1_1024x10.json"));
  const std::size_t at = orig.find("10.03");  // beam_altitude_angles[1]
  ASSERT_NE(at, std::string::npos);
  ReadOptions o;
  for (const char* token : {"NaN", "null", "\"x\""}) {
    std::string js = orig;
    js.replace(at, 5, token);
    o.metadata_path = (dir / "nan.json").string();
    write_bytes(o.metadata_path, js);
    auto r = read_sensor_log(pcap, o);
    EXPECT_TRUE(bad(r, o.metadata_path, std::string(token) == "NaN" ? "NaN" : "beam_altitude_angles[1]")) << token;
  }
}

TEST(SensorLogErrors, FragmentThatNeverCompletes) {
  LEX3D_REQUIRE_SHARED("ouster/OS-2-32-U0_v2.0.0_1024x10.pcap");
  Capture c = parse_capture(slurp(shared_data("ouster/OS-2-32-U0_v2.0.0_1024x10.pcap")));
  ASSERT_GT(fragment(c, 1500), 10U);
  const std::size_t n = c.records.size();
  ReadOptions o;
  o.metadata_path = shared_data("ouster/OS-2-32-U0_v2.0.0_1024x10.json");
  const fs::path dir = temp_dir("sensor_log_fragment");
  {  // a fragment lost in the middle of the capture: an error
    Capture m = c;
    m.records.erase(m.records.begin() + static_cast<std::ptrdiff_t>(n / 2));
    const std::string p = (dir / "middle.pcap").string();
    write_bytes(p, serialise(m));
    EXPECT_TRUE(bad(read_sensor_log(p, o), p, "never completes"));
  }
  {  // the capture ends inside a datagram: that datagram is dropped and counted, and the
     // frame it belonged to is incomplete
    Capture e = c;
    e.records.pop_back();
    const std::string p = (dir / "end.pcap").string();
    write_bytes(p, serialise(e));
    auto r = read_sensor_log(p, o);
    EXPECT_FALSE(r.ok());  // the only frame lost its last packet: no complete turn
    if (!r.ok()) {
      EXPECT_NE(r.status().message().find("no complete turn"), std::string::npos) << r.status().message();
    }
  }
}

// ------------------------------------------------------------ organised inputs

TEST(OrganisedInput, PcdRoundTripKeepsRowsColumnsAndCountsNoReturns) {
  LEX3D_REQUIRE_SHARED("ouster/OS-1-32-G_v2.1.1_1024x10.pcap");
  auto log = read_sensor_log(shared_data("ouster/OS-1-32-G_v2.1.1_1024x10.pcap"));
  ASSERT_TRUE(log.ok()) << log.status().to_string();
  const Cloud& c = log.value().scans[0];
  const fs::path dir = temp_dir("organised_pcd");
  for (const PcdEncoding enc : {PcdEncoding::kAscii, PcdEncoding::kBinary, PcdEncoding::kBinaryCompressed}) {
    SCOPED_TRACE(static_cast<int>(enc));
    const std::string p = (dir / "scan.pcd").string();
    WriteOptions w;
    w.pcd_encoding = enc;
    ASSERT_TRUE(write_cloud(p, c, w).ok());
    EXPECT_NE(slurp(p).find("HEIGHT 32"), std::string::npos);
    auto r = read_cloud(p);
    ASSERT_TRUE(r.ok()) << r.status().to_string();
    const Cloud& b = r.value().cloud;
    EXPECT_EQ(b.rows, c.rows);
    EXPECT_EQ(b.columns, c.columns);
    EXPECT_EQ(r.value().no_return_dropped, log.value().no_returns[0]);
    EXPECT_EQ(r.value().non_finite_dropped, 0U);
    ASSERT_EQ(b.size(), c.size());
    // written row by row: the same points in the same (ring, column) order
    EXPECT_EQ(b.ring, c.ring);
    EXPECT_EQ(b.column, c.column);
    if (enc != PcdEncoding::kAscii) EXPECT_EQ(b.points, c.points);
  }
}

TEST(OrganisedInput, RingFieldAndZeroRecords) {
  const fs::path dir = temp_dir("ring_field");
  const std::string pcd = (dir / "ring.pcd").string();
  write_bytes(pcd,
              "VERSION 0.7\nFIELDS x y z ring\nSIZE 4 4 4 2\nTYPE F F F U\nCOUNT 1 1 1 1\nWIDTH 3\nHEIGHT 1\n"
              "POINTS 3\nDATA ascii\n1 2 3 7\n4 5 6 0\nnan 1 1 2\n");
  auto r = read_cloud(pcd);
  ASSERT_TRUE(r.ok()) << r.status().to_string();
  EXPECT_EQ(r.value().cloud.ring, (std::vector<std::uint16_t>{7, 0}));
  EXPECT_EQ(r.value().non_finite_dropped, 1U);  // not organised: a NaN is a non-finite drop
  EXPECT_EQ(r.value().cloud.rows, 0U);
  write_bytes(pcd,
              "VERSION 0.7\nFIELDS x y z ring\nSIZE 4 4 4 2\nTYPE F F F U\nCOUNT 1 1 1 1\nWIDTH 1\nHEIGHT 1\n"
              "POINTS 1\nDATA ascii\n1 2 3 -1\n");
  EXPECT_FALSE(read_cloud(pcd).ok());
  // a PLY ring property, ascii and binary (with and without a list property)
  const std::string ply = (dir / "ring.ply").string();
  write_bytes(ply,
              "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
              "property ushort ring\nend_header\n1 2 3 7\n4 5 6 0\nnan 1 1 2\n");
  auto pa = read_cloud(ply);
  ASSERT_TRUE(pa.ok()) << pa.status().to_string();
  EXPECT_EQ(pa.value().cloud.ring, (std::vector<std::uint16_t>{7, 0}));
  std::string bply = "ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
                     "property float z\nproperty uchar laser_id\nend_header\n";
  for (const float v : {1.0F, 2.0F, 3.0F}) bply.append(reinterpret_cast<const char*>(&v), 4);
  bply.push_back(static_cast<char>(5));
  for (const float v : {4.0F, 5.0F, 6.0F}) bply.append(reinterpret_cast<const char*>(&v), 4);
  bply.push_back(static_cast<char>(9));
  write_bytes(ply, bply);
  auto pb = read_cloud(ply);
  ASSERT_TRUE(pb.ok()) << pb.status().to_string();
  EXPECT_EQ(pb.value().cloud.ring, (std::vector<std::uint16_t>{5, 9}));
  std::string lply = "ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
                     "property float z\nproperty list uchar int idx\nproperty int ring\nend_header\n";
  for (const float v : {1.0F, 2.0F, 3.0F}) lply.append(reinterpret_cast<const char*>(&v), 4);
  lply.push_back(static_cast<char>(0));
  const std::int32_t bad_ring = -3;
  lply.append(reinterpret_cast<const char*>(&bad_ring), 4);
  write_bytes(ply, lply);
  EXPECT_FALSE(read_cloud(ply).ok()) << "a negative ring";
  // a KITTI .bin with exact (0, 0, 0) records: no-returns, dropped and counted
  std::string bin;
  for (const float v : {1.0F, 2.0F, 3.0F, 0.5F, 0.0F, 0.0F, 0.0F, 0.0F, 4.0F, 0.0F, 0.0F, 0.25F})
    bin.append(reinterpret_cast<const char*>(&v), 4);
  const std::string b = (dir / "zeros.bin").string();
  write_bytes(b, bin);
  auto k = read_cloud(b);
  ASSERT_TRUE(k.ok()) << k.status().to_string();
  EXPECT_EQ(k.value().cloud.size(), 2U);
  EXPECT_EQ(k.value().no_return_dropped, 1U);
}

TEST(SensorLogErrors, CorruptAndTruncatedCapturesNeverCrash) {
  LEX3D_REQUIRE_SHARED("velodyne/vlp16_velodyne_example.pcap");
  const fs::path dir = temp_dir("sensor_log_sweep");
  std::uint32_t seed = 12345;
  auto next = [&seed]() { return seed = seed * 1664525U + 1013904223U; };
  for (const char* name : {"velodyne/vlp16_velodyne_example.pcap", "ouster/OS-1-32-G_v2.1.1_1024x10.pcap"}) {
    if (!test::has_shared_data(name)) continue;
    const std::string orig = slurp(shared_data(name));
    const std::string p = (dir / "x.pcap").string();
    ReadOptions o;
    if (std::string(name).find("ouster") != std::string::npos)
      o.metadata_path = shared_data("ouster/OS-1-32-G_v2.1.1_1024x10.json");
    for (int k = 0; k < 60; ++k) {
      std::string b = orig;
      if (k % 2 == 0) {
        b.resize(next() % b.size());
      } else {
        for (int j = 0; j < 8; ++j) b[next() % b.size()] = static_cast<char>(next() & 255);
      }
      write_bytes(p, b);
      auto r = read_sensor_log(p, o);  // ok or a one-line error, never a crash
      if (!r.ok()) {
        EXPECT_EQ(r.status().message().find('\n'), std::string::npos);
      }
    }
  }
}

}  // namespace
}  // namespace lex3d::io
