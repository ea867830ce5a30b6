#include "common/codec/decode_error.h"

namespace terrane {

const char* to_string(DecodeErrorCode code) {
  switch (code) {
    case DecodeErrorCode::kTruncated: return "truncated";
    case DecodeErrorCode::kBadMagic: return "bad magic";
    case DecodeErrorCode::kBadVersion: return "bad version";
    case DecodeErrorCode::kOverLimit: return "over limit";
    case DecodeErrorCode::kTrailingBytes: return "trailing bytes";
    case DecodeErrorCode::kInvalidValue: return "invalid value";
  }
  return "unknown";
}

std::string DecodeError::describe() const {
  std::string s = to_string(code);
  s += " at byte ";
  s += std::to_string(offset);
  if (detail != nullptr && *detail != '\0') {
    s += ": ";
    s += detail;
  }
  return s;
}

}  // namespace terrane
