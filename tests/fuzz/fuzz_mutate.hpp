#pragma once
// Structure-aware mutation of model and alphabet files, shared by the libFuzzer targets'
// custom mutator and the corpus replay driver. Plain byte mutations rarely get past the
// CRCs and never past deflate; these parse the container (formats/alphabet.md §2),
// mutate one part (a header field, a chunk's payload, the inflated data of an INST or
// WORD chunk, the chunk list) and rebuild the file with correct CRCs, so the decoders'
// deeper checks (counts, raw sizes, word ids, rotations, values) are exercised.

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include <zlib.h>

namespace lex3d::fuzz {

using Bytes = std::vector<std::uint8_t>;

struct Container {
  Bytes head;  // 20 bytes
  struct Chunk {
    Bytes type;  // 4 bytes
    Bytes payload;
  };
  std::vector<Chunk> chunks;
};

inline std::uint64_t load_u64(const std::uint8_t* p) {
  std::uint64_t v = 0;
  for (int i = 7; i >= 0; --i) v = (v << 8) | p[i];
  return v;
}
inline void store_u64(std::uint8_t* p, std::uint64_t v) {
  for (int i = 0; i < 8; ++i) p[i] = static_cast<std::uint8_t>(v >> (8 * i));
}
inline void store_u32(std::uint8_t* p, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) p[i] = static_cast<std::uint8_t>(v >> (8 * i));
}
inline std::uint32_t crc_of(const std::uint8_t* p, std::size_t n) {
  return static_cast<std::uint32_t>(crc32(0, p, static_cast<uInt>(n)));
}

/// Splits a file whose framing is intact (header present, every chunk inside the file).
inline bool parse(const Bytes& b, Container& c) {
  if (b.size() < 20) return false;
  c.head.assign(b.begin(), b.begin() + 20);
  c.chunks.clear();
  std::size_t pos = 20;
  while (pos < b.size()) {
    if (b.size() - pos < 16) return false;
    const std::uint64_t len = load_u64(&b[pos + 4]);
    if (len > b.size() - pos - 16) return false;
    Container::Chunk k;
    k.type.assign(b.begin() + static_cast<std::ptrdiff_t>(pos), b.begin() + static_cast<std::ptrdiff_t>(pos + 4));
    k.payload.assign(b.begin() + static_cast<std::ptrdiff_t>(pos + 12),
                     b.begin() + static_cast<std::ptrdiff_t>(pos + 12 + len));
    c.chunks.push_back(std::move(k));
    pos += 16 + static_cast<std::size_t>(len);
  }
  return true;
}

/// Reassembles with a correct header CRC and chunk CRCs.
/// Appends one chunk (type, length, payload, CRC over the three) to `b`.
inline void append_chunk(Bytes& b, const Container::Chunk& k) {
  const std::size_t start = b.size();
  b.insert(b.end(), k.type.begin(), k.type.end());
  b.resize(b.size() + 8);
  store_u64(&b[b.size() - 8], k.payload.size());
  b.insert(b.end(), k.payload.begin(), k.payload.end());
  b.resize(b.size() + 4);
  store_u32(&b[b.size() - 4], crc_of(b.data() + start, b.size() - 4 - start));
}

inline Bytes build(const Container& c) {
  Bytes b = c.head;
  b.resize(20, 0);
  store_u32(&b[16], crc_of(b.data(), 16));
  for (const auto& k : c.chunks) append_chunk(b, k);
  return b;
}

inline bool is_type(const Container::Chunk& k, const char* t) {
  return k.type.size() == 4 && std::memcmp(k.type.data(), t, 4) == 0;
}

/// The inflated data of an INST or WORD payload (count u64, raw_size u64, zlib stream).
inline bool inflate_raw(const Bytes& payload, Bytes& raw) {
  if (payload.size() < 16) return false;
  const std::uint64_t n = load_u64(&payload[8]);
  if (n > (1U << 22)) return false;
  uLongf got = static_cast<uLongf>(n);
  raw.assign(static_cast<std::size_t>(n) + 1, 0);
  if (uncompress(raw.data(), &got, payload.data() + 16, static_cast<uLong>(payload.size() - 16)) != Z_OK) return false;
  raw.resize(got);
  return true;
}

inline Bytes deflated(std::uint64_t count, std::uint64_t raw_size, const Bytes& raw) {
  Bytes p(16);
  store_u64(&p[0], count);
  store_u64(&p[8], raw_size);
  uLongf n = compressBound(static_cast<uLong>(raw.size()));
  Bytes z(n);
  if (compress2(z.data(), &n, raw.data(), static_cast<uLong>(raw.size()), 9) != Z_OK) return p;
  p.insert(p.end(), z.begin(), z.begin() + static_cast<std::ptrdiff_t>(n));
  return p;
}

/// One structure-aware mutation of `file`; `mutate(Bytes&)` changes a byte string (the
/// fuzzer's own mutator, or a simple random one). Returns false when `file` has no
/// intact framing to work on.
template <typename Rng, typename Mutate>
bool mutate_structure(Bytes& file, Rng& rng, Mutate&& mutate) {
  Container c;
  if (!parse(file, c)) return false;
  // Work inside an embedded alphabet half of the time.
  Container inner;
  Container::Chunk* alph = nullptr;
  for (auto& k : c.chunks) {
    Container candidate;
    if (alph == nullptr && is_type(k, "ALPH") && parse(k.payload, candidate) && rng() % 2 == 0) {
      alph = &k;
      inner = std::move(candidate);
    }
  }
  Container& target = alph ? inner : c;
  const auto pick = [&]() -> Container::Chunk* {
    if (target.chunks.empty()) return nullptr;
    return &target.chunks[rng() % target.chunks.size()];
  };
  switch (rng() % 6) {
    case 0: {  // header fields (version, flags)
      Bytes fields(target.head.begin() + 8, target.head.begin() + 16);
      mutate(fields);
      fields.resize(8, 0);
      std::copy(fields.begin(), fields.end(), target.head.begin() + 8);
      break;
    }
    case 1: {  // a chunk's payload
      if (auto* k = pick()) mutate(k->payload);
      break;
    }
    case 2:
    case 3: {  // the inflated data of INST / WORD, re-deflated
      for (auto& k : target.chunks) {
        Bytes raw;
        if ((is_type(k, "INST") || is_type(k, "WORD")) && inflate_raw(k.payload, raw)) {
          const std::uint64_t count = load_u64(&k.payload[0]);
          const std::uint64_t raw_size = load_u64(&k.payload[8]);
          mutate(raw);
          k.payload = deflated(count, rng() % 4 == 0 ? raw.size() : raw_size, raw);
          break;
        }
      }
      break;
    }
    case 4: {  // counts and raw sizes of INST / WORD
      for (auto& k : target.chunks)
        if ((is_type(k, "INST") || is_type(k, "WORD")) && k.payload.size() >= 16) {
          Bytes head(k.payload.begin(), k.payload.begin() + 16);
          mutate(head);
          head.resize(16, 0);
          std::copy(head.begin(), head.end(), k.payload.begin());
          break;
        }
      break;
    }
    default: {  // the chunk list: drop, duplicate, swap, retype, or add an unknown chunk
      const std::size_t n = target.chunks.size();
      const auto op = rng() % 5;
      if (op == 0 && n > 0) {
        target.chunks.erase(target.chunks.begin() + static_cast<std::ptrdiff_t>(rng() % n));
      } else if (op == 1 && n > 0) {
        const auto i = rng() % n;
        target.chunks.insert(target.chunks.begin() + static_cast<std::ptrdiff_t>(i), target.chunks[i]);
      } else if (op == 2 && n > 1) {
        std::swap(target.chunks[rng() % n], target.chunks[rng() % n]);
      } else if (op == 3 && n > 0) {
        mutate(target.chunks[rng() % n].type);  // resized to 4 below
      } else {
        Container::Chunk k;
        const char* types[] = {"note", "XTRA", "AREF", "ALPH", "INST", "MHDR", "AHDR", "WORD"};
        const char* t = types[rng() % 8];
        k.type.assign(t, t + 4);
        mutate(k.payload);
        target.chunks.insert(target.chunks.begin() + static_cast<std::ptrdiff_t>(rng() % (n + 1)), std::move(k));
      }
      for (auto& k : target.chunks) k.type.resize(4, 'a');
      break;
    }
  }
  if (alph) alph->payload = build(inner);
  file = build(c);
  return true;
}

/// A simple byte mutator for the replay driver: bit flips, interesting values, inserted,
/// erased and duplicated ranges, truncation.
template <typename Rng>
void mutate_bytes(Bytes& b, Rng& rng) {
  const int edits = 1 + static_cast<int>(rng() % 4);
  for (int e = 0; e < edits; ++e) {
    const std::size_t n = b.size();
    switch (rng() % 7) {
      case 0:
        if (n) b[rng() % n] ^= static_cast<std::uint8_t>(1U << (rng() % 8));
        break;
      case 1:
        if (n) b[rng() % n] = static_cast<std::uint8_t>(rng());
        break;
      case 2: {
        static const std::uint64_t values[] = {0, 1, 0x7F, 0x80, 0xFF, 0xFFFF, 0x7FFFFFFF, 0x80000000, 0xFFFFFFFF,
                                               std::uint64_t{1} << 32, std::uint64_t{1} << 63, ~std::uint64_t{0}};
        if (n >= 8) store_u64(&b[rng() % (n - 7)], values[rng() % 12]);
        break;
      }
      case 3:
        b.insert(b.begin() + static_cast<std::ptrdiff_t>(n ? rng() % (n + 1) : 0), static_cast<std::uint8_t>(rng()));
        break;
      case 4:
        if (n) b.erase(b.begin() + static_cast<std::ptrdiff_t>(rng() % n));
        break;
      case 5:
        if (n) {
          const std::size_t at = rng() % n;
          const std::size_t len = std::min<std::size_t>(n - at, 1 + rng() % 32);
          const Bytes piece(b.begin() + static_cast<std::ptrdiff_t>(at),
                            b.begin() + static_cast<std::ptrdiff_t>(at + len));
          b.insert(b.begin() + static_cast<std::ptrdiff_t>(rng() % (n + 1)), piece.begin(), piece.end());
        }
        break;
      default:
        if (n) b.resize(rng() % n);
        break;
    }
  }
}

}  // namespace lex3d::fuzz
