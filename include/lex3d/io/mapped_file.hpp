#pragma once
/// \file
/// Files read by mapping them into memory (pages are read when first touched) and files
/// written at chosen offsets (for formats that append and then commit, e.g. the place
/// database, formats/place_db.md).

#include <cstdint>
#include <memory>
#include <string>

#include "lex3d/core/status.hpp"

// The public API: exported by liblex3d.so, which hides everything else.
#pragma GCC visibility push(default)

namespace lex3d::io {

/// A file mapped read-only. The bytes stay valid while the object lives; share it with
/// std::shared_ptr to keep views into it alive.
class MappedFile {
 public:
  /// Maps `path` (an empty file gives size 0 and no mapping). kIoError when it cannot be
  /// opened or mapped.
  [[nodiscard]] static StatusOr<std::shared_ptr<const MappedFile>> open(const std::string& path);
  ~MappedFile();
  MappedFile(const MappedFile&) = delete;
  MappedFile& operator=(const MappedFile&) = delete;
  [[nodiscard]] const std::uint8_t* data() const noexcept { return data_; }
  [[nodiscard]] std::size_t size() const noexcept { return size_; }
  [[nodiscard]] const std::string& path() const noexcept { return path_; }

 private:
  MappedFile() = default;
  const std::uint8_t* data_ = nullptr;
  std::size_t size_ = 0;
  std::string path_;
};

/// A file written at chosen offsets: write_at, truncate, sync (fsync), close. Errors are
/// kIoError naming the file.
class PositionalFile {
 public:
  /// Opens an existing file for reading and writing (never creates it), holding an
  /// exclusive advisory lock (flock) until closed: a second writer gets kIoError.
  [[nodiscard]] static StatusOr<std::unique_ptr<PositionalFile>> open_existing(const std::string& path);
  /// Creates a new file (fails when `path` exists).
  [[nodiscard]] static StatusOr<std::unique_ptr<PositionalFile>> create_new(const std::string& path);
  ~PositionalFile();
  PositionalFile(const PositionalFile&) = delete;
  PositionalFile& operator=(const PositionalFile&) = delete;
  [[nodiscard]] Status write_at(std::uint64_t offset, const std::uint8_t* data, std::size_t size);
  [[nodiscard]] Status truncate(std::uint64_t size);
  [[nodiscard]] Status sync();
  [[nodiscard]] Status close();

 private:
  PositionalFile() = default;
  int fd_ = -1;
  std::string path_;
};

/// A name next to `path` that no other writer of this process uses ("PATH.tmp-PID-N"),
/// for write-then-rename.
[[nodiscard]] std::string temporary_path_for(const std::string& path);
/// rename(2) of `from` to `to` (atomic on one file system); kIoError naming `to`.
[[nodiscard]] Status rename_file(const std::string& from, const std::string& to);
/// Removes a file, ignoring errors (for cleaning up a temporary file).
void remove_file_quietly(const std::string& path) noexcept;

}  // namespace lex3d::io

#pragma GCC visibility pop
