#include "lex3d/core/status.hpp"

namespace lex3d {

int exit_code_for(ErrorCode code) noexcept {
  switch (code) {
    case ErrorCode::kOk: return 0;
    case ErrorCode::kInvalidArgument: return 1;
    case ErrorCode::kBadData: return 2;
    case ErrorCode::kIoError: return 3;
    case ErrorCode::kOutOfMemory: return 4;
  }
  return 2;
}

std::string Status::to_string() const {
  std::string s = message_;
  if (offset_) s += " (at byte " + std::to_string(*offset_) + ")";
  return s;
}

}  // namespace lex3d
