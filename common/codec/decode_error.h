// Result type for every decoder of untrusted bytes (network, disk, files).
// Decoders never throw across that edge and never assert on input: they
// return a value or a DecodeError saying what was wrong and where.
#pragma once

#include <cstddef>
#include <optional>
#include <string>
#include <utility>
#include <variant>

namespace terrane {

enum class DecodeErrorCode {
  kTruncated,      // input ended before the format said it would
  kBadMagic,       // not this format at all
  kBadVersion,     // this format, a version we do not speak
  kOverLimit,      // a size or count beyond what the format or caller allows
  kTrailingBytes,  // valid data followed by bytes that belong to nothing
  kInvalidValue,   // a field with a value the format forbids
};

const char* to_string(DecodeErrorCode code);

struct DecodeError {
  DecodeErrorCode code;
  std::size_t offset = 0;     // byte offset in the input where it was noticed
  const char* detail = "";    // static text: what exactly was wrong

  std::string describe() const;  // "truncated at byte 12: run past end of box"
};

// A value or an error E. Small, move-only where T is.
template <class T, class E>
class [[nodiscard]] BasicResult {
 public:
  BasicResult(T value) : v_(std::move(value)) {}   // NOLINT: implicit by design
  BasicResult(E error) : v_(std::move(error)) {}   // NOLINT: implicit by design

  bool ok() const { return v_.index() == 0; }
  explicit operator bool() const { return ok(); }
  T& value() & { return std::get<0>(v_); }
  const T& value() const& { return std::get<0>(v_); }
  T&& value() && { return std::get<0>(std::move(v_)); }
  T& operator*() & { return value(); }
  const T& operator*() const& { return value(); }
  T* operator->() { return &value(); }
  const T* operator->() const { return &value(); }
  const E& error() const { return std::get<1>(v_); }

 private:
  std::variant<T, E> v_;
};

// A value or a DecodeError: what every decoder of untrusted bytes returns.
template <class T>
using Result = BasicResult<T, DecodeError>;

// A failed file or store operation: a message for people, naming the file
// (and, for chunk data, the chunk), plus the DecodeError when the content
// rather than the file system was at fault.
struct FileError {
  std::string message;
  std::optional<DecodeError> decode;
  // A write whose commit was sent and never answered, and that could not be
  // asked about since (a lost connection): it may have been stored. Its
  // edits are neither acknowledged nor refused, their outcome is unknown.
  bool outcome_unknown = false;
};
template <class T>
using FileResult = BasicResult<T, FileError>;

// For decoders that write into a caller's buffer and return nothing else.
struct Ok {};
using Status = Result<Ok>;
using FileStatus = FileResult<Ok>;

}  // namespace terrane
