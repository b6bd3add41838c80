#pragma once
// The place database loader under fuzzing (fuzz_place_db.cpp, and reader_replay.cpp in
// CTest): open the bytes, read every entry a query could read, retrieve with them, save
// and open again; abort when a documented property fails
// (formats/place_db.md, place.hpp):
// - open() fails with kBadData, one line, an offset inside the bytes; a newer major
//   version is refused the same way;
// - a corrupt entry is a kBadData Status from read_scan() or a PlaceDataError from save(),
//   never another exception;
// - an entry that reads is consistent (features, codes and words as the format bounds them);
// - a database that saves opens again with the same scans.
//
// And a structure-aware mutator for the 2.0 layout (header, two commit records, chunks;
// fuzz_mutate.hpp's container mutator handles 1.0): it mutates one part, then rebuilds the
// file with correct CRCs, chunk offsets in the index and a commit record that points at
// the index, so that mutations reach the checks behind the CRCs.

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

[[noreturn]] inline void db_fail(const char* what, const std::string& detail) {
  std::fprintf(stderr, "fuzz property violated: %s: %s\n", what, detail.c_str());
  std::abort();
}

inline void check_db_status(const Status& s, std::size_t size) {
  if (s.code() != ErrorCode::kBadData) db_fail("unexpected error code", s.to_string());
  if (s.message().empty() || s.to_string().find('\n') != std::string::npos) db_fail("message not one line", s.to_string());
  if (s.offset() && *s.offset() > size) db_fail("offset past the input", s.to_string());
}

inline void check_place_scan(const PlaceScan& s, int descriptor_dim) {
  if (s.descriptor_dim != descriptor_dim && descriptor_dim != 0) db_fail("descriptor size differs from the database's", "");
  if (s.descriptor_codes.size() != s.features.size() * static_cast<std::size_t>(s.descriptor_dim))
    db_fail("descriptor codes not one set a feature", "");
  for (const auto& f : s.features)
    if (!f.position.allFinite() || !f.rotation.coeffs().allFinite()) db_fail("non-finite feature", "");
  for (std::size_t i = 1; i < s.words.size(); ++i)
    if (s.words[i].first <= s.words[i - 1].first) db_fail("word ids not increasing", "");
  for (const auto& p : s.dense_points)
    if (!p.allFinite()) db_fail("non-finite dense point", "");
  if (!s.T_world_cloud.matrix().allFinite()) db_fail("non-finite pose", "");
}

/// Everything the place-DB fuzzer does with one input.
inline void check_place_db(const std::uint8_t* data, std::size_t size) {
  const std::vector<std::uint8_t> bytes(data, data + size);
  auto opened = PlaceDatabase::load(bytes);
  if (!opened.ok()) return check_db_status(opened.status(), size);
  PlaceDatabase& db = opened.value();
  const std::size_t n = db.size();
  if (n > (1U << 24)) db_fail("more scans than the format allows", std::to_string(n));
  std::vector<PlaceScan> readable;
  for (std::size_t i = 0; i < n && i < 16; ++i) {
    (void)db.name(i);
    auto s = db.read_scan(i);
    if (!s.ok()) {
      check_db_status(s.status(), size);
      continue;
    }
    check_place_scan(s.value(), db.descriptor_dim());
    if (readable.size() < 2) readable.push_back(std::move(s).value());
  }
  try {
    // Retrieval over the index for each readable entry. (A whole query, verification
    // included, takes seconds under the sanitizers: it runs in the CLI tests on damaged
    // databases, tests/cli/patch_place_db.py, not here.)
    for (const auto& q : readable) (void)db.retrieve(q, 8);
    const auto saved = db.save();
    auto again = PlaceDatabase::load(saved);
    if (!again.ok()) db_fail("a saved database does not open", again.status().to_string());
    if (again.value().size() != n) db_fail("a saved database opens with another scan count", "");
  } catch (const PlaceDataError& e) {
    check_db_status(e.status(), size);
  } catch (const std::exception& e) {
    db_fail("unexpected exception", e.what());
  }
}

/// The 2.0 layout split into its parts.
struct PlaceFile {
  Bytes head;     // 20 bytes
  Bytes commits;  // 56 bytes: two records
  Container chunks;
};

inline bool parse_place_2(const Bytes& b, PlaceFile& f) {
  if (b.size() < 76 || std::memcmp(b.data(), "LEX3DPDB", 8) != 0 || b[8] != 2 || b[9] != 0) return false;
  f.head.assign(b.begin(), b.begin() + 20);
  f.commits.assign(b.begin() + 20, b.begin() + 76);
  Bytes rest(20, 0);  // parse() wants a 20-byte head before the chunks
  rest.insert(rest.end(), b.begin() + 76, b.end());
  return parse(rest, f.chunks);
}

/// Reassembles: header CRC, chunk CRCs, the index entries' chunk offsets and lengths (the
/// SCAN chunks in order), and the commit record in force pointing at the last PIDX chunk.
inline Bytes build_place_2(PlaceFile& f) {
  Bytes b = f.head;
  b.resize(20, 0);
  store_u32(&b[16], crc_of(b.data(), 16));
  b.insert(b.end(), f.commits.begin(), f.commits.end());
  b.resize(76, 0);
  std::vector<std::pair<std::uint64_t, std::uint64_t>> scans;  // offset, payload length
  std::size_t last_index = 0;
  // Offsets first (payload sizes are final), then patch the index, then serialise.
  std::uint64_t at = 76;
  std::uint64_t index_offset = 0;
  for (std::size_t i = 0; i < f.chunks.chunks.size(); ++i) {
    const auto& k = f.chunks.chunks[i];
    if (is_type(k, "SCAN")) scans.emplace_back(at, k.payload.size());
    if (is_type(k, "PIDX")) {
      index_offset = at;
      last_index = i;
    }
    at += 16 + k.payload.size();
  }
  if (index_offset != 0) {
    Bytes& idx = f.chunks.chunks[last_index].payload;
    if (idx.size() >= 24) {
      const std::uint32_t count = static_cast<std::uint32_t>(load_u64(idx.data()) & 0xFFFFFFFFU);
      for (std::size_t s = 0; s < count && s < scans.size() && 24 + 36 * (s + 1) <= idx.size(); ++s) {
        store_u64(&idx[24 + 36 * s], scans[s].first);
        store_u64(&idx[24 + 36 * s + 8], scans[s].second);
      }
    }
  }
  for (const auto& k : f.chunks.chunks) append_chunk(b, k);
  // The record in force: the valid one with the higher sequence (slot = sequence mod 2).
  int slot = -1;
  std::uint64_t best = 0;
  for (int r = 0; r < 2; ++r) {
    const std::uint8_t* rec = &b[20 + 28 * r];
    const std::uint64_t seq = load_u64(rec);
    if (seq >= 1 && seq % 2 == static_cast<std::uint64_t>(r) && seq >= best) {
      best = seq;
      slot = r;
    }
  }
  if (slot < 0) slot = 1;  // sequence 1 in slot 1
  std::uint8_t* rec = &b[20 + 28 * slot];
  if (load_u64(rec) == 0 || load_u64(rec) % 2 != static_cast<std::uint64_t>(slot)) store_u64(rec, slot == 1 ? 1 : 2);
  store_u64(rec + 8, b.size());
  store_u64(rec + 16, index_offset);
  store_u32(rec + 24, crc_of(rec, 24));
  return b;
}

/// One structure-aware mutation of a 2.0 place database; false when `file` is not one.
template <typename Rng, typename Mutate>
bool mutate_place_db(Bytes& file, Rng& rng, Mutate&& mutate) {
  PlaceFile f;
  if (!parse_place_2(file, f)) return mutate_structure(file, rng, mutate);  // 1.0: the generic container
  auto& chunks = f.chunks.chunks;
  switch (rng() % 6) {
    case 0: {  // version and flags
      Bytes fields(f.head.begin() + 8, f.head.begin() + 16);
      mutate(fields);
      fields.resize(8, 0);
      std::copy(fields.begin(), fields.end(), f.head.begin() + 8);
      break;
    }
    case 1:
    case 2: {  // a chunk's payload, often the index or a scan
      if (chunks.empty()) break;
      auto& k = chunks[rng() % chunks.size()];
      if (rng() % 2 == 0) {  // same length: offsets stay meaningful
        const std::size_t n = k.payload.size();
        mutate(k.payload);
        k.payload.resize(n, 0);
      } else {
        mutate(k.payload);
      }
      break;
    }
    case 3: {  // a few bytes of the index changed in place (counts, starts, postings)
      for (auto& k : chunks)
        if (is_type(k, "PIDX") && !k.payload.empty()) {
          const std::size_t at = rng() % k.payload.size();
          k.payload[at] = static_cast<std::uint8_t>(rng());
        }
      break;
    }
    case 4: {  // a chunk dropped or duplicated
      if (chunks.empty()) break;
      const std::size_t i = rng() % chunks.size();
      if (rng() % 2 == 0)
        chunks.erase(chunks.begin() + static_cast<std::ptrdiff_t>(i));
      else
        chunks.insert(chunks.begin() + static_cast<std::ptrdiff_t>(i), chunks[i]);
      break;
    }
    default: {  // the commit records (their CRC is fixed only for the record in force)
      mutate(f.commits);
      f.commits.resize(56, 0);
      break;
    }
  }
  file = build_place_2(f);
  return true;
}

}  // namespace lex3d::fuzz
