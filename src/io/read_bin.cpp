// Reader of KITTI (x y z intensity) and x y z float32 binaries.

#include <string>

#include "io/internal.hpp"
#include "lex3d/io/io.hpp"

namespace lex3d::io::detail {

Status read_float_binary(const std::string& path, const std::uint8_t* data, std::size_t size,
                         Format format, bool detected, ReadResult& r) {
  const std::size_t stride = format == Format::kKitti ? 16 : 12;
  if (size % stride != 0) {
    std::string what = "size " + std::to_string(size) + " is not a multiple of " +
                       std::to_string(stride) + " bytes";
    if (detected) {
      what += " (KITTI x y z intensity) nor of 12 bytes (x y z float32)";
    } else {
      what += format == Format::kKitti ? " (KITTI x y z intensity)" : " (x y z float32)";
    }
    return bad_data(msg(path, what), size - size % stride);
  }
  const std::size_t n = size / stride;
  // x y z asked for, but the bytes are KITTI records: every fourth float, at the same place
  // in each 16 bytes, is an intensity in [0, 1]. Read as x y z they would be garbage points
  // (a real x y z cloud is not inside a unit cube on every third coordinate).
  if (format == Format::kBinXyz && !detected && size % 16 == 0 && size / 16 >= 16) {
    bool kitti = true;
    for (std::size_t i = 0; i < size / 16 && kitti; ++i) {
      const float v = load<float>(data + i * 16 + 12, kHostBigEndian);
      kitti = v >= 0.0F && v <= 1.0F;
    }
    if (kitti)
      return bad_data(msg(path, "holds KITTI records (x y z intensity, 16 bytes a point: every fourth float is an "
                                "intensity in [0, 1]), not x y z float32; read it with --format kitti"),
                      0);
  }
  r.encoding = "binary_little_endian";
  Builder b(r, format == Format::kKitti, false);
  b.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint8_t* p = data + i * stride;
    const float x = load<float>(p, kHostBigEndian);
    const float y = load<float>(p + 4, kHostBigEndian);
    const float z = load<float>(p + 8, kHostBigEndian);
    const float in = stride == 16 ? load<float>(p + 12, kHostBigEndian) : 0.0F;
    if (x == 0.0F && y == 0.0F && z == 0.0F) {  // an organised sensor's no-return written out
      ++r.no_return_dropped;
      continue;
    }
    b.add(x, y, z, in);
  }
  return {};
}

}  // namespace lex3d::io::detail
