// A small PNG encoder (8-bit RGB, zlib via IDAT, no interlace).
//
// PCL has pcl::io::saveRgbPNGFile, but it returns void and reports failures
// only on the console, so it cannot give a Status nor write atomically; this
// encoder builds the bytes in memory (deterministically) and hands them to
// write_file_atomic.

#include <zlib.h>

#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "io/internal.hpp"
#include "lex3d/io/io.hpp"

namespace lex3d::io {

namespace {

void put_be32(std::vector<std::uint8_t>& out, std::uint32_t v) {
  out.push_back(static_cast<std::uint8_t>(v >> 24));
  out.push_back(static_cast<std::uint8_t>(v >> 16));
  out.push_back(static_cast<std::uint8_t>(v >> 8));
  out.push_back(static_cast<std::uint8_t>(v));
}

void put_chunk(std::vector<std::uint8_t>& out, const char type[4], const std::uint8_t* data,
               std::size_t size) {
  put_be32(out, static_cast<std::uint32_t>(size));
  const std::size_t start = out.size();
  out.insert(out.end(), type, type + 4);
  if (size > 0) out.insert(out.end(), data, data + size);
  const uLong crc = crc32(0L, out.data() + start, static_cast<uInt>(size + 4));
  put_be32(out, static_cast<std::uint32_t>(crc));
}

}  // namespace

Status write_png_rgb(const std::string& path, int width, int height, const std::vector<std::uint8_t>& rgb) {
  auto invalid = [&](const std::string& what) {
    return Status(ErrorCode::kInvalidArgument, detail::msg(path, what));
  };
  if (width <= 0 || height <= 0) {
    return invalid("bad image size " + std::to_string(width) + " x " + std::to_string(height));
  }
  const auto w = static_cast<std::uint64_t>(width);
  const auto h = static_cast<std::uint64_t>(height);
  const std::uint64_t row = w * 3 + 1;
  // IDAT is one chunk here: keep the filtered data below 2^31 bytes
  if (row * h > (1ULL << 31) - 1) {
    return invalid("image " + std::to_string(width) + " x " + std::to_string(height) + " is too large");
  }
  if (rgb.size() != w * h * 3) {
    return invalid("got " + std::to_string(rgb.size()) + " bytes for a " + std::to_string(width) + " x " +
                   std::to_string(height) + " RGB image (expected " + std::to_string(w * h * 3) + ")");
  }
  try {
    // scanlines, each with filter type 0 (None)
    std::vector<std::uint8_t> raw(static_cast<std::size_t>(row * h));
    for (std::uint64_t y = 0; y < h; ++y) {
      raw[static_cast<std::size_t>(y * row)] = 0;
      std::memcpy(raw.data() + y * row + 1, rgb.data() + y * w * 3, static_cast<std::size_t>(w * 3));
    }
    uLongf zsize = compressBound(static_cast<uLong>(raw.size()));
    std::vector<std::uint8_t> z(zsize);
    if (compress2(z.data(), &zsize, raw.data(), static_cast<uLong>(raw.size()), 6) != Z_OK) {
      return io_error(detail::msg(path, "zlib compression failed"));
    }
    if (zsize > (1ULL << 31) - 1) return invalid("compressed image too large for one IDAT chunk");

    std::vector<std::uint8_t> png;
    png.reserve(zsize + 64);
    static const std::uint8_t kSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n'};
    png.insert(png.end(), kSignature, kSignature + 8);
    std::vector<std::uint8_t> ihdr;
    put_be32(ihdr, static_cast<std::uint32_t>(width));
    put_be32(ihdr, static_cast<std::uint32_t>(height));
    ihdr.push_back(8);  // bit depth
    ihdr.push_back(2);  // colour type: RGB
    ihdr.push_back(0);  // compression: deflate
    ihdr.push_back(0);  // filter method 0
    ihdr.push_back(0);  // no interlace
    put_chunk(png, "IHDR", ihdr.data(), ihdr.size());
    put_chunk(png, "IDAT", z.data(), static_cast<std::size_t>(zsize));
    put_chunk(png, "IEND", nullptr, 0);
    return write_file_atomic(path, png);
  } catch (const std::bad_alloc&) {
    return out_of_memory(detail::msg(path, "out of memory encoding the PNG"));
  }
}

}  // namespace lex3d::io
