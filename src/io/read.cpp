// read_cloud: reads the file, picks the format and hands the bytes to its
// reader; read_file; helpers the readers share.
//
// The readers, one a source: read_bin.cpp (KITTI / x y z float binaries),
// read_pcd.cpp (PCD ascii, binary, binary_compressed), read_ply.cpp (PLY ascii,
// binary little/big endian), read_text.cpp (x y z text and 3DTK `.3d`).
// Every reader works on the whole file in memory and checks each length read
// from the file against the bytes left before it allocates or reads; errors
// are one-line messages "<path>: <what is wrong>" with a byte offset where one
// is meaningful.

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cstring>
#include <new>
#include <stdexcept>

#include "io/internal.hpp"
#include "lex3d/io/io.hpp"
#include "lex3d/io/sensor_log.hpp"

namespace lex3d::io {

using detail::msg;

namespace detail {

std::vector<std::string_view> split_ws(std::string_view line) {
  std::vector<std::string_view> out;
  for_each_token(line, false, [&](const char* b, const char* e) {
    out.emplace_back(b, static_cast<std::size_t>(e - b));
    return true;
  });
  return out;
}

}  // namespace detail

namespace {

/// `<dir>/<stem>.pose` for `<dir>/<stem>.3d`.
std::string pose_path_for(const std::string& path) {
  const std::size_t slash = path.find_last_of('/');
  const std::size_t dot = path.find_last_of('.');
  if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return path + ".pose";
  return path.substr(0, dot) + ".pose";
}

/// A raw log's first complete turn.
StatusOr<ReadResult> read_log_first_turn(const std::string& path, const ReadOptions& options) {
  auto log = read_sensor_log(path, options);
  if (!log.ok()) return log.status();
  SensorLog& l = log.value();
  ReadResult r;
  r.format = Format::kPcap;
  r.encoding = l.info.vendor + " " + l.info.profile;
  r.sensor = l.info.sensor;
  r.scans_in_file = l.scans.size();
  r.no_return_dropped = l.no_returns.front();
  r.cloud = std::move(l.scans.front());
  struct stat st {};
  if (::stat(path.c_str(), &st) == 0) r.file_bytes = static_cast<std::uint64_t>(st.st_size);
  return r;
}

StatusOr<ReadResult> read_cloud_impl(const std::string& path, const ReadOptions& options) {
  if (options.format == Format::kPcap || (options.format == Format::kAuto && is_sensor_log(path)))
    return read_log_first_turn(path, options);
  auto file = read_file(path);
  if (!file.ok()) return file.status();
  const std::vector<std::uint8_t>& bytes = file.value();
  ReadResult r;
  r.file_bytes = bytes.size();
  if (bytes.empty()) return bad_data(msg(path, "file is empty"), 0);
  Format f = options.format;
  const bool detected = f == Format::kAuto;
  if (detected) {
    auto d = detail::detect_from_bytes(path, bytes.data(), std::min<std::size_t>(bytes.size(), 4096),
                                       bytes.size());
    if (!d.ok()) return d.status();
    f = d.value();
  }
  r.format = f;
  Status s;
  switch (f) {
    case Format::kKitti:
    case Format::kBinXyz:
      s = detail::read_float_binary(path, bytes.data(), bytes.size(), f, detected, r);
      break;
    case Format::kPcd: s = detail::read_pcd(path, bytes.data(), bytes.size(), r); break;
    case Format::kPly: s = detail::read_ply(path, bytes.data(), bytes.size(), r); break;
    case Format::kXyz: s = detail::read_text(path, bytes.data(), bytes.size(), false, options, r); break;
    case Format::kUos3d: s = detail::read_text(path, bytes.data(), bytes.size(), true, options, r); break;
    case Format::kPcap:  // handled above; reached only when detection disagrees with is_sensor_log
    case Format::kAuto: s = bad_data(msg(path, "cannot tell the format")); break;
  }
  if (!s.ok()) return s;
  if (f == Format::kUos3d && options.load_pose) {
    const std::string pose_path = pose_path_for(path);
    struct stat st {};
    if (::stat(pose_path.c_str(), &st) == 0) {
      auto pose = detail::read_uos_pose(pose_path);
      if (!pose.ok()) return pose.status();
      r.cloud.T_world_cloud = pose.value();
      r.cloud.has_world_pose = true;
    }
  }
  return r;
}

}  // namespace

StatusOr<std::vector<std::uint8_t>> read_file(const std::string& path, std::uint64_t max_bytes) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return io_error(msg(path, std::string("cannot open: ") + std::strerror(errno)));
  struct Closer {
    int fd;
    ~Closer() { ::close(fd); }
  } closer{fd};
  struct stat st {};
  if (::fstat(fd, &st) != 0) return io_error(msg(path, std::string("cannot stat: ") + std::strerror(errno)));
  if (S_ISDIR(st.st_mode)) return io_error(msg(path, "is a directory"));
  auto too_big = [&]() {
    return bad_data(msg(path, "file is larger than the limit of " + std::to_string(max_bytes) + " bytes"));
  };
  std::vector<std::uint8_t> buf;
  try {
    std::size_t want = 0;
    if (S_ISREG(st.st_mode)) {
      const auto sz = static_cast<std::uint64_t>(st.st_size);
      if (sz > max_bytes) return too_big();
      want = static_cast<std::size_t>(sz);
    }
    buf.resize(want);
    std::size_t got = 0;
    while (got < buf.size()) {
      const ssize_t r = ::read(fd, buf.data() + got, buf.size() - got);
      if (r < 0 && errno == EINTR) continue;
      if (r < 0) return io_error(msg(path, std::string("cannot read: ") + std::strerror(errno)));
      if (r == 0) break;  // the file shrank
      got += static_cast<std::size_t>(r);
    }
    if (got == buf.size()) {
      // the file grew, or it is a pipe: read the rest in chunks
      std::array<std::uint8_t, 1U << 14> chunk{};
      for (;;) {
        const ssize_t r = ::read(fd, chunk.data(), chunk.size());
        if (r < 0 && errno == EINTR) continue;
        if (r < 0) return io_error(msg(path, std::string("cannot read: ") + std::strerror(errno)));
        if (r == 0) break;
        const auto n = static_cast<std::size_t>(r);
        if (got + n > max_bytes) return too_big();
        buf.insert(buf.end(), chunk.begin(), chunk.begin() + r);
        got += n;
      }
    }
    buf.resize(got);
  } catch (const std::bad_alloc&) {
    return io_error(msg(path, "out of memory reading the file"));
  }
  return buf;
}

StatusOr<ReadResult> read_cloud(const std::string& path, const ReadOptions& options) {
  try {
    return read_cloud_impl(path, options);
  } catch (const std::bad_alloc&) {
    return io_error(msg(path, "out of memory reading the point cloud"));
  } catch (const std::length_error&) {
    return io_error(msg(path, "out of memory reading the point cloud"));
  }
}

}  // namespace lex3d::io
