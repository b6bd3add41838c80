// Memory-mapped reading and positional writing of whole files (POSIX).

#include "lex3d/io/mapped_file.hpp"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>

namespace lex3d::io {

namespace {

Status fail(const std::string& path, const char* what, int err) {
  return io_error(path + ": " + what + ": " + std::strerror(err));
}

std::atomic<unsigned> g_counter{0};

}  // namespace

StatusOr<std::shared_ptr<const MappedFile>> MappedFile::open(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return fail(path, "cannot open", errno);
  struct stat st {};
  if (::fstat(fd, &st) != 0) {
    const int err = errno;
    ::close(fd);
    return fail(path, "cannot stat", err);
  }
  if (!S_ISREG(st.st_mode)) {
    ::close(fd);
    return io_error(path + ": not a regular file");
  }
  std::shared_ptr<MappedFile> m(new MappedFile());
  m->path_ = path;
  m->size_ = static_cast<std::size_t>(st.st_size);
  if (m->size_ > 0) {
    void* p = ::mmap(nullptr, m->size_, PROT_READ, MAP_PRIVATE, fd, 0);
    if (p == MAP_FAILED) {
      const int err = errno;
      ::close(fd);
      return fail(path, "cannot map", err);
    }
    m->data_ = static_cast<const std::uint8_t*>(p);
  }
  ::close(fd);  // the mapping keeps the file
  return std::shared_ptr<const MappedFile>(std::move(m));
}

MappedFile::~MappedFile() {
  if (data_ != nullptr) ::munmap(const_cast<std::uint8_t*>(data_), size_);
}

StatusOr<std::unique_ptr<PositionalFile>> PositionalFile::open_existing(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDWR | O_CLOEXEC);
  if (fd < 0) return fail(path, "cannot open for writing", errno);
  if (::flock(fd, LOCK_EX | LOCK_NB) != 0) {
    const int err = errno;
    ::close(fd);
    if (err == EWOULDBLOCK) return io_error(path + ": another process is writing it");
    return fail(path, "cannot lock", err);
  }
  std::unique_ptr<PositionalFile> f(new PositionalFile());
  f->fd_ = fd;
  f->path_ = path;
  return f;
}

StatusOr<std::unique_ptr<PositionalFile>> PositionalFile::create_new(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
  if (fd < 0) return fail(path, "cannot create", errno);
  std::unique_ptr<PositionalFile> f(new PositionalFile());
  f->fd_ = fd;
  f->path_ = path;
  return f;
}

PositionalFile::~PositionalFile() {
  if (fd_ >= 0) ::close(fd_);
}

Status PositionalFile::write_at(std::uint64_t offset, const std::uint8_t* data, std::size_t size) {
  std::size_t done = 0;
  while (done < size) {
    const ssize_t w = ::pwrite(fd_, data + done, std::min<std::size_t>(size - done, 1U << 30),
                               static_cast<off_t>(offset + done));
    if (w < 0) {
      if (errno == EINTR) continue;
      return fail(path_, "cannot write", errno);
    }
    done += static_cast<std::size_t>(w);
  }
  return {};
}

Status PositionalFile::truncate(std::uint64_t size) {
  if (::ftruncate(fd_, static_cast<off_t>(size)) != 0) return fail(path_, "cannot truncate", errno);
  return {};
}

Status PositionalFile::sync() {
  if (::fsync(fd_) != 0) return fail(path_, "cannot sync", errno);
  return {};
}

Status PositionalFile::close() {
  if (fd_ < 0) return {};
  const int fd = fd_;
  fd_ = -1;
  if (::close(fd) != 0) return fail(path_, "cannot write (close)", errno);
  return {};
}

std::string temporary_path_for(const std::string& path) {
  return path + ".tmp-" + std::to_string(::getpid()) + "-p" + std::to_string(g_counter.fetch_add(1));
}

Status rename_file(const std::string& from, const std::string& to) {
  if (::rename(from.c_str(), to.c_str()) != 0) return fail(to, "cannot rename the temporary file", errno);
  return {};
}

void remove_file_quietly(const std::string& path) noexcept { ::unlink(path.c_str()); }

}  // namespace lex3d::io
