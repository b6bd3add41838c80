// Format names and format detection (extension, magic bytes, file size).

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>

#include "io/internal.hpp"
#include "lex3d/io/io.hpp"

namespace lex3d::io {

namespace detail {

std::string printable(std::string_view s, std::size_t max_len) {
  std::string out;
  const std::size_t n = std::min(s.size(), max_len);
  out.reserve(n + 3);
  for (std::size_t i = 0; i < n; ++i) {
    const auto c = static_cast<unsigned char>(s[i]);
    out.push_back(c >= 0x20 && c < 0x7F ? static_cast<char>(c) : '?');
  }
  if (s.size() > max_len) out += "...";
  return out;
}

std::string to_lower(std::string_view s) {
  std::string out(s);
  for (char& c : out) {
    if (c >= 'A' && c <= 'Z') c = static_cast<char>(c - 'A' + 'a');
  }
  return out;
}

std::string extension_lower(const std::string& path) {
  const std::size_t slash = path.find_last_of('/');
  const std::size_t dot = path.find_last_of('.');
  if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return {};
  if (dot == 0 || (slash != std::string::npos && dot == slash + 1)) return {};  // ".hidden"
  return to_lower(std::string_view(path).substr(dot));
}

namespace {

bool starts_with(const std::uint8_t* p, std::size_t n, std::string_view prefix) {
  return n >= prefix.size() && std::memcmp(p, prefix.data(), prefix.size()) == 0;
}

bool looks_like_ply(const std::uint8_t* p, std::size_t n) {
  return starts_with(p, n, "ply\n") || starts_with(p, n, "ply\r\n");
}

/// PCD: "# .PCD" first, or the first line that is not a comment starts with VERSION.
bool looks_like_pcd(const std::uint8_t* p, std::size_t n) {
  if (starts_with(p, n, "# .PCD")) return true;
  const char* b = reinterpret_cast<const char*>(p);
  LineCursor lines(b, b + n);
  std::string_view line;
  int seen = 0;
  while (lines.next(line) && seen < 16) {
    line = trim(line);
    if (line.empty() || line.front() == '#') {
      ++seen;
      continue;
    }
    return line.substr(0, 7) == "VERSION" || line.substr(0, 6) == "FIELDS";
  }
  return false;
}

/// libpcap (microsecond or nanosecond, either byte order) or pcapng magic.
bool looks_like_pcap(const std::uint8_t* p, std::size_t n) {
  if (n < 4) return false;
  std::uint32_t m = 0;
  std::memcpy(&m, p, 4);
  return m == 0xA1B2C3D4U || m == 0xD4C3B2A1U || m == 0xA1B23C4DU || m == 0x4D3CB2A1U || m == 0x0A0D0D0AU;
}

/// Text with at least three numbers on its first data line.
bool looks_like_numbers(const std::uint8_t* p, std::size_t n) {
  if (n == 0 || std::memchr(p, '\0', n) != nullptr) return false;
  const char* b = reinterpret_cast<const char*>(p);
  LineCursor lines(b, b + n);
  std::string_view line;
  while (lines.next(line)) {
    const std::string_view t = trim(line);
    if (t.empty() || t.front() == '#') continue;
    int count = 0;
    bool ok = true;
    for_each_token(t, true, [&](const char* tb, const char* te) {
      double v = 0.0;
      if (!parse_number(tb, te, v)) {
        ok = false;
        return false;
      }
      ++count;
      return true;
    });
    return ok && count >= 3;
  }
  return false;
}

Format detect_bin(const std::uint8_t* head, std::size_t head_size, std::uint64_t file_size) {
  const bool m16 = file_size % 16 == 0;
  const bool m12 = file_size % 12 == 0;
  if (m12 && !m16) return Format::kBinXyz;
  if (!m12) return Format::kKitti;  // multiple of 16 only, or neither (the reader reports it)
  // Both: KITTI unless a fourth float of the first records is negative or not finite.
  const std::size_t records = std::min<std::size_t>(head_size / 16, 64);
  for (std::size_t i = 0; i < records; ++i) {
    float v = 0.0F;
    std::memcpy(&v, head + i * 16 + 12, 4);
    if (!std::isfinite(v) || v < 0.0F) return Format::kBinXyz;
  }
  return Format::kKitti;
}

}  // namespace

StatusOr<Format> detect_from_bytes(const std::string& path, const std::uint8_t* head,
                                   std::size_t head_size, std::uint64_t file_size) {
  if (file_size == 0) return bad_data(msg(path, "file is empty"));
  const std::string ext = extension_lower(path);
  if (looks_like_pcap(head, head_size)) return Format::kPcap;
  if (ext == ".laz" || (starts_with(head, head_size, "LASF") && head_size > 104 && (head[104] & 0xC0U) != 0))
    return bad_data(msg(path, "compressed LAS (LAZ) is not supported: decompress it to .las first (e.g. with laszip)"));
  if (starts_with(head, head_size, "LASF")) return Format::kLas;
  if (ext == ".las") return bad_data(msg(path, "not a LAS file (no \"LASF\" signature)"), 0);
  if (looks_like_ply(head, head_size)) return Format::kPly;
  if (looks_like_pcd(head, head_size)) return Format::kPcd;
  if (ext == ".bin") return detect_bin(head, head_size, file_size);
  if (ext == ".pcd") return Format::kPcd;
  if (ext == ".ply") return Format::kPly;
  if (ext == ".3d") return Format::kUos3d;
  if (ext == ".pcap" || ext == ".pcapng") return Format::kPcap;
  if (ext == ".xyz" || ext == ".txt" || ext == ".asc" || ext == ".csv") return Format::kXyz;
  if (looks_like_numbers(head, head_size)) return Format::kXyz;
  return bad_data(msg(path, "cannot tell the format: unknown extension '" + printable(ext, 16) +
                                "' and the content is neither PCD, PLY nor numeric text"));
}

}  // namespace detail

std::string_view format_name(Format f) noexcept {
  switch (f) {
    case Format::kAuto: return "auto";
    case Format::kKitti: return "kitti";
    case Format::kBinXyz: return "binxyz";
    case Format::kPcd: return "pcd";
    case Format::kPly: return "ply";
    case Format::kXyz: return "xyz";
    case Format::kUos3d: return "uos";
    case Format::kPcap: return "pcap";
    case Format::kLas: return "las";
  }
  return "unknown";
}

std::optional<Format> parse_format(std::string_view name) noexcept {
  std::string lower;
  try {
    lower = detail::to_lower(name);
  } catch (...) {
    return std::nullopt;
  }
  for (Format f : {Format::kAuto, Format::kKitti, Format::kBinXyz, Format::kPcd, Format::kPly,
                   Format::kXyz, Format::kUos3d, Format::kPcap, Format::kLas}) {
    if (lower == format_name(f)) return f;
  }
  if (lower == "3d") return Format::kUos3d;
  return std::nullopt;
}

StatusOr<Format> detect_format(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) {
    return io_error(detail::msg(path, std::string("cannot open: ") + std::strerror(errno)));
  }
  struct stat st {};
  if (::fstat(fd, &st) != 0) {
    const int err = errno;
    ::close(fd);
    return io_error(detail::msg(path, std::string("cannot stat: ") + std::strerror(err)));
  }
  if (S_ISDIR(st.st_mode)) {
    ::close(fd);
    return io_error(detail::msg(path, "is a directory"));
  }
  std::uint8_t head[4096];
  std::size_t got = 0;
  while (got < sizeof(head)) {
    const ssize_t r = ::read(fd, head + got, sizeof(head) - got);
    if (r < 0) {
      if (errno == EINTR) continue;
      const int err = errno;
      ::close(fd);
      return io_error(detail::msg(path, std::string("cannot read: ") + std::strerror(err)));
    }
    if (r == 0) break;
    got += static_cast<std::size_t>(r);
  }
  ::close(fd);
  const std::uint64_t size =
      S_ISREG(st.st_mode) ? static_cast<std::uint64_t>(st.st_size) : static_cast<std::uint64_t>(got);
  return detail::detect_from_bytes(path, head, got, size);
}

}  // namespace lex3d::io
