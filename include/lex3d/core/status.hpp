#pragma once
/// \file
/// Error values for data that is wrong (files, bitstreams). Caller mistakes
/// throw std::invalid_argument instead (see docs/errors.md).

#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>
#include <variant>

// The public API: exported by liblex3d.so, which hides everything else.
#pragma GCC visibility push(default)

namespace lex3d {

/// What kind of failure a Status reports; maps onto the CLI exit codes.
enum class ErrorCode : std::uint8_t {
  kOk = 0,
  kInvalidArgument,  ///< a parameter out of range (exit 1)
  kBadData,          ///< malformed, truncated or corrupt input (exit 2)
  kIoError,          ///< the file system failed us: missing file, no permission, disk full (exit 3)
  kOutOfMemory,      ///< an allocation the input asked for failed (exit 4)
};

/// Exit code of the `lex3d` command for an error code (0 ok, 1 usage, 2 bad data, 3 I/O,
/// 4 out of memory).
[[nodiscard]] int exit_code_for(ErrorCode code) noexcept;

/// An error with a message and, for bitstreams, the byte offset where it was found.
class Status {
 public:
  Status() = default;
  Status(ErrorCode code, std::string message, std::optional<std::uint64_t> offset = std::nullopt)
      : code_(code), message_(std::move(message)), offset_(offset) {}

  [[nodiscard]] bool ok() const noexcept { return code_ == ErrorCode::kOk; }
  [[nodiscard]] ErrorCode code() const noexcept { return code_; }
  [[nodiscard]] const std::string& message() const noexcept { return message_; }
  [[nodiscard]] std::optional<std::uint64_t> offset() const noexcept { return offset_; }
  /// One line: the message, plus " (at byte N)" when an offset is known.
  [[nodiscard]] std::string to_string() const;

 private:
  ErrorCode code_ = ErrorCode::kOk;
  std::string message_;
  std::optional<std::uint64_t> offset_;
};

[[nodiscard]] inline Status bad_data(std::string message,
                                     std::optional<std::uint64_t> offset = std::nullopt) {
  return {ErrorCode::kBadData, std::move(message), offset};
}
[[nodiscard]] inline Status io_error(std::string message) {
  return {ErrorCode::kIoError, std::move(message)};
}
[[nodiscard]] inline Status out_of_memory(std::string message) {
  return {ErrorCode::kOutOfMemory, std::move(message)};
}

/// Either a value or a non-ok Status (after Draco's StatusOr).
template <typename T>
class StatusOr {
 public:
  StatusOr(T value) : v_(std::move(value)) {}                                // NOLINT
  StatusOr(Status status) : v_(std::move(status)) {                          // NOLINT
    if (std::get<Status>(v_).ok()) throw std::logic_error("StatusOr built from an ok Status");
  }
  [[nodiscard]] bool ok() const noexcept { return std::holds_alternative<T>(v_); }
  [[nodiscard]] const Status& status() const {
    static const Status kOkStatus;
    return ok() ? kOkStatus : std::get<Status>(v_);
  }
  [[nodiscard]] T& value() & { return std::get<T>(v_); }
  [[nodiscard]] const T& value() const& { return std::get<T>(v_); }
  [[nodiscard]] T&& value() && { return std::get<T>(std::move(v_)); }

 private:
  std::variant<T, Status> v_;
};

}  // namespace lex3d

#pragma GCC visibility pop
