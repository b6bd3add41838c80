#pragma once
// The prepared place query under fuzzing (fuzz_place_query.cpp, and reader_replay.cpp in
// CTest): decode_place_query (formats/place_db.md §7), the bytes a staged query sends to every
// shard of a sharded database. Properties (place.hpp):
// - a failure is kBadData with a one-line message and an offset inside the bytes;
// - a scan that decodes is consistent: one descriptor code set a feature, codes within the
//   descriptor bits, unit rotations, finite positions and poses, word ids increasing with
//   counts above zero, a coarse image whose states and ranges match its size;
// - it encodes again (encode_place_query) to bytes that decode to the same scan, and those
//   bytes are a fixed point: decoding and encoding them once more gives them back.
// The storage parameters are those of the input's descriptor bits (4 or 8; else the
// defaults, whose 4 bits the input then has to match).
//
// And a structure-aware mutator: it splits the bytes into the header fields, the SCAN payload
// and the rotations, mutates one of them (or the payload's coarse range image, inflated), and
// rebuilds the deflated image, the payload length and the CRC, so that mutations reach the
// checks behind them.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <string>
#include <vector>

#include "fuzz_mutate.hpp"
#include "lex3d/place/place.hpp"

namespace lex3d::fuzz {

[[noreturn]] inline void query_fail(const char* what, const std::string& detail) {
  std::fprintf(stderr, "fuzz property violated: %s: %s\n", what, detail.c_str());
  std::abort();
}

inline void check_query_value(const PlaceScan& s) {
  if (s.descriptor_bits != 4 && s.descriptor_bits != 8) query_fail("descriptor bits", std::to_string(s.descriptor_bits));
  if (s.descriptor_dim < 0 || s.descriptor_dim > 4096) query_fail("descriptor size", std::to_string(s.descriptor_dim));
  if (s.descriptor_codes.size() != s.features.size() * static_cast<std::size_t>(s.descriptor_dim))
    query_fail("descriptor codes not one set a feature", "");
  if (s.descriptors.size() != s.descriptor_codes.size()) query_fail("descriptor values not one a code", "");
  const int top = (1 << s.descriptor_bits) - 1;
  for (const auto c : s.descriptor_codes)
    if (c > top) query_fail("descriptor code past its bits", std::to_string(c));
  for (const float d : s.descriptors)
    if (!(d >= -1.0F && d <= 1.0F)) query_fail("descriptor value outside [-1, 1]", std::to_string(d));
  for (const auto& f : s.features) {
    if (!f.position.allFinite()) query_fail("non-finite feature position", "");
    if (!f.rotation.coeffs().allFinite() || std::abs(f.rotation.norm() - 1.0F) > 1e-3F)
      query_fail("feature rotation not a unit quaternion", "");
  }
  for (std::size_t i = 0; i < s.words.size(); ++i) {
    if (i > 0 && s.words[i].first <= s.words[i - 1].first) query_fail("word ids not increasing", "");
    if (s.words[i].second == 0) query_fail("word count zero", "");
  }
  if (!s.T_world_cloud.matrix().allFinite() || !s.coarse.T_cloud_sensor.matrix().allFinite())
    query_fail("non-finite pose", "");
  const auto pixels = static_cast<std::size_t>(s.coarse.width) * static_cast<std::size_t>(s.coarse.height);
  if (pixels > 0 && (s.coarse.state.size() != pixels || s.coarse.range.size() != pixels))
    query_fail("coarse image size", std::to_string(pixels));
  for (const auto& p : s.dense_points)
    if (!p.allFinite()) query_fail("non-finite dense point", "");
}

inline bool same_query(const PlaceScan& a, const PlaceScan& b) {
  if (a.name != b.name || a.has_world_pose != b.has_world_pose || a.words != b.words ||
      a.descriptor_dim != b.descriptor_dim || a.descriptor_codes != b.descriptor_codes ||
      a.features.size() != b.features.size() || a.coarse.width != b.coarse.width ||
      a.coarse.height != b.coarse.height || a.coarse.state != b.coarse.state)
    return false;
  for (std::size_t i = 0; i < a.features.size(); ++i)
    if (a.features[i].position != b.features[i].position ||
        a.features[i].rotation.coeffs() != b.features[i].rotation.coeffs())
      return false;
  return true;
}

/// Everything the place query fuzzer does with one input.
inline void check_place_query(const std::uint8_t* data, std::size_t size) {
  const std::vector<std::uint8_t> bytes(data, data + size);
  PlaceStorageParams storage;
  if (size > 6 && (bytes[6] == 4 || bytes[6] == 8)) storage.descriptor_bits = bytes[6];
  const auto r = decode_place_query(bytes.data(), bytes.size(), storage);
  if (!r.ok()) {
    const Status& s = r.status();
    if (s.code() != ErrorCode::kBadData) query_fail("unexpected error code", s.to_string());
    if (s.message().empty() || s.to_string().find('\n') != std::string::npos) query_fail("message not one line", s.to_string());
    if (!s.offset() || *s.offset() > size) query_fail("offset missing or past the input", s.to_string());
    return;
  }
  const PlaceScan& q = r.value();
  check_query_value(q);
  std::vector<std::uint8_t> again;
  try {
    again = encode_place_query(q, storage);
  } catch (const std::exception& e) {
    query_fail("a decoded query does not encode", e.what());
  }
  const auto r2 = decode_place_query(again.data(), again.size(), storage);
  if (!r2.ok()) query_fail("a re-encoded query does not decode", r2.status().to_string());
  if (!same_query(q, r2.value())) query_fail("a re-encoded query decodes to another scan", "");
  if (encode_place_query(r2.value(), storage) != again) query_fail("encoding is not a fixed point", "");
}

/// The coarse range image's codes inside a SCAN payload (formats/place_db.md §3.3), inflated:
/// where its deflated data starts and ends, or false when the payload's framing is not intact.
inline bool find_coarse_image(const Bytes& payload, std::size_t descriptor_dim, bool four_bits, std::size_t& at,
                              std::size_t& pixels) {
  const auto u16 = [&](std::size_t i) { return static_cast<std::size_t>(payload[i] | (payload[i + 1] << 8)); };
  const auto u32 = [&](std::size_t i) {
    return static_cast<std::size_t>(payload[i] | (payload[i + 1] << 8) | (payload[i + 2] << 16)) |
           (static_cast<std::size_t>(payload[i + 3]) << 24);
  };
  const std::size_t n = payload.size();
  std::size_t p = 0;
  if (n < 2) return false;
  p = 2 + u16(0) + 1 + 192;  // name, flags, two poses
  if (p + 4 > n) return false;
  p += 4 + 8 * u32(p);  // words
  if (p + 4 > n) return false;
  const std::size_t features = u32(p);
  const std::size_t codes = features * descriptor_dim;
  p += 4 + 20 * features + (four_bits ? (codes + 1) / 2 : codes);
  if (p + 29 > n) return false;
  pixels = u16(p) * u16(p + 2);
  const std::size_t height = u16(p + 2);
  p += 29 + (pixels > 0 ? (height + 1) * 8 : 0);
  if (p + 4 > n || pixels == 0 || p + 4 + u32(p) != n) return false;
  at = p;
  return true;
}

/// One structure-aware mutation of a prepared query; false when `file` has no intact framing
/// (magic, a payload length inside the bytes) to work on.
template <typename Rng, typename Mutate>
bool mutate_place_query(Bytes& file, Rng& rng, Mutate&& mutate) {
  constexpr std::size_t kHead = 4 + 2 + 1 + 8;
  if (file.size() < kHead + 4 + 4 || std::memcmp(file.data(), "L3PQ", 4) != 0) return false;
  const std::uint64_t length = load_u64(&file[7]);
  if (length > file.size() - kHead - 4 - 4) return false;
  Bytes head(file.begin(), file.begin() + 7);
  Bytes payload(file.begin() + kHead, file.begin() + static_cast<std::ptrdiff_t>(kHead + length));
  Bytes tail(file.begin() + static_cast<std::ptrdiff_t>(kHead + length), file.end() - 4);  // count, rotations
  bool keep_length = true;
  switch (rng() % 5) {
    case 0: {  // descriptor values and bits
      Bytes fields(head.begin() + 4, head.end());
      mutate(fields);
      fields.resize(3, 0);
      std::copy(fields.begin(), fields.end(), head.begin() + 4);
      break;
    }
    case 1: mutate(payload); break;
    case 2: mutate(tail); break;
    case 3: {  // the coarse image's range codes, deflated again (the payload's last part)
      std::size_t at = 0, pixels = 0;
      if (!find_coarse_image(payload, head[4] | (head[5] << 8), head[6] != 8, at, pixels)) {
        mutate(payload);
        break;
      }
      Bytes raw(2 * pixels);
      uLongf raw_len = static_cast<uLongf>(raw.size());
      if (uncompress(raw.data(), &raw_len, payload.data() + at + 4, static_cast<uLong>(payload.size() - at - 4)) != Z_OK)
        return false;
      raw.resize(raw_len);
      mutate(raw);
      if (rng() % 8 != 0) raw.resize(2 * pixels, 0);  // mostly the size the image says
      Bytes z(compressBound(static_cast<uLong>(raw.size())));
      uLongf z_len = static_cast<uLongf>(z.size());
      if (compress(z.data(), &z_len, raw.data(), static_cast<uLong>(raw.size())) != Z_OK) return false;
      z.resize(z_len);
      payload.resize(at + 4);
      store_u32(&payload[at], static_cast<std::uint32_t>(z.size()));
      payload.insert(payload.end(), z.begin(), z.end());
      break;
    }
    default:  // a payload length that does not match
      mutate(payload);
      keep_length = false;
      break;
  }
  Bytes out = head;
  out.resize(kHead, 0);
  store_u64(&out[7], keep_length ? payload.size() : length);
  out.insert(out.end(), payload.begin(), payload.end());
  out.insert(out.end(), tail.begin(), tail.end());
  out.resize(out.size() + 4);
  store_u32(&out[out.size() - 4], crc_of(out.data(), out.size() - 4));
  file = std::move(out);
  return true;
}

}  // namespace lex3d::fuzz
