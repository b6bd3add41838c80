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
