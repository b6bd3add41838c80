#pragma once
// Private pieces of the LAS reader and writer (read_las.cpp, write_las.cpp): the point data
// record formats, the CRS records and their units. Field names and offsets follow the
// ASPRS LAS 1.4 R15 specification (header §2.4, VLRs §2.5, point records §2.6, EVLRs §2.7).
// Not installed.

#include <cstdint>
#include <string>
#include <vector>

#include "lex3d/core/cloud.hpp"

namespace lex3d::io::detail::las {

constexpr std::size_t kHeader12 = 227;  // LAS 1.0-1.2 header bytes
constexpr std::size_t kHeader13 = 235;  // + start of waveform data packet record
constexpr std::size_t kHeader14 = 375;  // + EVLRs, 64-bit point counts
constexpr std::size_t kVlrHeader = 54;
constexpr std::size_t kEvlrHeader = 60;
constexpr int kMaxFormat = 10;

/// Minimum record length of point data record formats 0..10.
constexpr std::uint16_t kMinRecord[kMaxFormat + 1] = {20, 28, 26, 34, 57, 63, 30, 36, 38, 59, 67};

/// Byte offset of the RGB triple in a record of `format`, or -1 when it has none.
inline int rgb_offset(int format) {
  switch (format) {
    case 2: return 20;
    case 3: case 5: return 28;
    case 7: case 8: case 10: return 30;
    default: return -1;
  }
}

/// A per-point field of a point record that Cloud keeps as an IntegerField (LAS 1.4 R15
/// §2.6): `size` 1 (bits `shift`.. of width given by `mask`) or 2 bytes (all of them),
/// signed or not. `plain` is the value the writer puts where a cloud lacks the field (the
/// return number and count: 1 of 1; the rest 0); a field whose every value is plain is
/// not kept (the writer gives it back as it was).
struct PointField {
  const char* name;
  std::uint16_t offset;
  std::uint8_t size;
  std::uint8_t shift;
  std::uint16_t mask;
  bool is_signed;
  std::int32_t plain;
  /// The field's value in record `p`.
  [[nodiscard]] std::int32_t get(const std::uint8_t* p) const {
    if (size == 1) return is_signed ? static_cast<std::int32_t>(static_cast<std::int8_t>(p[offset]))
                                    : static_cast<std::int32_t>((p[offset] >> shift) & mask);
    const auto u = static_cast<std::uint16_t>(p[offset] | (p[offset + 1] << 8));
    return is_signed ? static_cast<std::int32_t>(static_cast<std::int16_t>(u)) : static_cast<std::int32_t>(u);
  }
  /// Whether `v` fits the field.
  [[nodiscard]] bool fits(std::int32_t v) const {
    if (size == 1) return is_signed ? v >= -128 && v <= 127 : v >= 0 && v <= static_cast<std::int32_t>(mask);
    return is_signed ? v >= -32768 && v <= 32767 : v >= 0 && v <= 65535;
  }
  /// Stores `v` (which fits) into record `p`, whose other bits it leaves alone.
  void put(std::uint8_t* p, std::int32_t v) const {
    if (size == 1) {
      if (is_signed) p[offset] = static_cast<std::uint8_t>(static_cast<std::int8_t>(v));
      else p[offset] = static_cast<std::uint8_t>((p[offset] & ~(mask << shift)) | ((static_cast<unsigned>(v) & mask) << shift));
      return;
    }
    const auto u = static_cast<std::uint16_t>(v);
    p[offset] = static_cast<std::uint8_t>(u & 0xFFU);
    p[offset + 1] = static_cast<std::uint8_t>(u >> 8);
  }
};

/// The fields of point format `format` (0-10) that Cloud keeps as IntegerFields, in the
/// order of the record.
std::vector<PointField> point_fields(int format);

/// The Extra Bytes record (LAS 1.4 R15 §2.5.2): "LASF_Spec" record 4, one 192-byte
/// descriptor for each extra value at the end of a point record, in record order.
constexpr char kExtraBytesUser[] = "LASF_Spec";
constexpr std::uint16_t kExtraBytesRecord = 4;
constexpr std::size_t kExtraBytesDescriptor = 192;

/// One extra value of a point record, as its descriptor gives it.
struct ExtraBytes {
  std::string name;          ///< the descriptor's (up to 32 characters)
  std::uint8_t data_type = 0;  ///< 1-10 the scalars (uchar, char, ushort, short, ulong, long, u64, i64, float, double); 0 undocumented bytes; 11-30 deprecated arrays
  std::uint8_t options = 0;    ///< bits: 0 no_data, 1 min, 2 max, 3 scale, 4 offset given
  std::size_t size = 0;        ///< bytes in the record
  std::size_t at = 0;          ///< offset in the record
  double scale = 1.0, offset = 0.0;  ///< applied where options says so: value = raw · scale + offset
  [[nodiscard]] bool scaled() const { return (options & 0x18U) != 0; }
};

/// The bytes a value of extra-bytes `data_type` takes (0 for 0, whose size is in options).
inline std::size_t extra_bytes_size(std::uint8_t data_type) {
  static constexpr std::uint8_t kSize[11] = {0, 1, 1, 2, 2, 4, 4, 8, 8, 4, 8};
  if (data_type <= 10) return kSize[data_type];
  if (data_type <= 30) return kSize[(data_type - 1) % 10 + 1] * ((data_type - 1) / 10 + 1);  // arrays of 2 and 3
  return 0;
}

/// Whether a VLR/EVLR describes the coordinate reference system (and is carried through).
inline bool is_crs_record(const std::string& user_id, std::uint16_t record_id) {
  if (user_id == "LASF_Projection") return record_id == 34735 || record_id == 34736 || record_id == 34737 ||
                                           record_id == 2111 || record_id == 2112;
  return user_id == "liblas" && record_id == 2112;
}

/// What the CRS records say about the coordinate system.
struct CrsInfo {
  std::string name;
  std::uint32_t epsg = 0;
  double unit_m = 0.0;            ///< 0: not stated
  std::string unit_name;
  double vertical_unit_m = 0.0;   ///< 0: not stated
  std::string vertical_unit_name;
  std::vector<std::string> notes;  ///< records that could not be read
};

/// Reads the GeoTIFF keys and/or the OGC WKT among `records`; `prefer_wkt` when the
/// header's global encoding says the WKT is the file's CRS.
CrsInfo describe_crs(const std::vector<CrsRecord>& records, bool prefer_wkt);

}  // namespace lex3d::io::detail::las
