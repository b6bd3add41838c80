#pragma once
// Little-endian field writing and reading shared by lex3d's file formats
// (formats/alphabet.md §1): the codec's containers and the residual layer's header.

#include <cstdint>
#include <cstring>
#include <vector>

namespace lex3d::codec::bytes {

inline void put_u16(std::vector<std::uint8_t>& b, std::uint16_t v) {
  b.push_back(static_cast<std::uint8_t>(v & 0xFFU));
  b.push_back(static_cast<std::uint8_t>(v >> 8));
}
inline void put_u32(std::vector<std::uint8_t>& b, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) b.push_back(static_cast<std::uint8_t>((v >> (8 * i)) & 0xFFU));
}
inline void put_u64(std::vector<std::uint8_t>& b, std::uint64_t v) {
  for (int i = 0; i < 8; ++i) b.push_back(static_cast<std::uint8_t>((v >> (8 * i)) & 0xFFU));
}
inline void put_f64(std::vector<std::uint8_t>& b, double d) {
  std::uint64_t v = 0;
  std::memcpy(&v, &d, sizeof v);
  put_u64(b, v);
}

inline std::uint16_t ld_u16(const std::uint8_t* p) { return static_cast<std::uint16_t>(p[0] | (p[1] << 8)); }
inline std::uint32_t ld_u32(const std::uint8_t* p) {
  return static_cast<std::uint32_t>(p[0]) | (static_cast<std::uint32_t>(p[1]) << 8) |
         (static_cast<std::uint32_t>(p[2]) << 16) | (static_cast<std::uint32_t>(p[3]) << 24);
}
inline std::uint64_t ld_u64(const std::uint8_t* p) {
  return static_cast<std::uint64_t>(ld_u32(p)) | (static_cast<std::uint64_t>(ld_u32(p + 4)) << 32);
}
inline double ld_f64(const std::uint8_t* p) {
  const std::uint64_t v = ld_u64(p);
  double d = 0.0;
  std::memcpy(&d, &v, sizeof d);
  return d;
}

}  // namespace lex3d::codec::bytes
