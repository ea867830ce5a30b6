// Framing for Terrane's TCP stream: each frame is a 4-byte little-endian
// body length followed by the body, one FlatBuffers Message
// (protocol/terrane.fbs). The length is checked against a fixed maximum
// before anything is buffered, and every body is run through the
// FlatBuffers verifier with tight depth and table limits before it is read.
#pragma once

#include <cstddef>
#include <algorithm>
#include <cstdint>
#include <span>
#include <vector>

#include "common/codec/decode_error.h"

namespace terrane::wire {
struct Message;
}

namespace terrane {

inline constexpr std::uint32_t kProtocolVersion = 2;
inline constexpr std::size_t kFrameHeaderBytes = 4;
// Largest frame a peer may send unless the handshake agrees on less: a
// worst-case 16³ unit (NET_CODEC.md) plus message overhead fits many times.
inline constexpr std::size_t kDefaultMaxFrameBytes = 1 << 20;

// A socket is read at most this many bytes at a time.
inline constexpr std::size_t kSocketReadBytes = 64 * 1024;
// The calling thread's buffer for socket reads (kSocketReadBytes), one per
// thread, not per connection: a process of many connections (a server, or
// terrane-bots) waits for readiness on each socket and reads on a few io
// threads. The bytes read must be consumed (framed by a FrameReader, which
// keeps only a partial frame, or copied) before the reading handler returns.
std::span<std::uint8_t> thread_read_buffer();

// Appends header + body to out. Precondition: body.size() <= UINT32_MAX.
void append_frame(std::span<const std::uint8_t> body, std::vector<std::uint8_t>& out);

// Splits a byte stream into frame bodies. Memory held is bounded by
// max_frame_bytes + the header: an over-long length is an error as soon as
// its header arrives, before any body byte is stored.
class FrameReader {
 public:
  explicit FrameReader(std::size_t max_frame_bytes = kDefaultMaxFrameBytes) : max_(max_frame_bytes) {}

  // Consumes bytes; calls on_frame(std::span<const std::uint8_t> body) for
  // each complete frame (the span is valid during the call). Returns an
  // error (kOverLimit for an oversized length) and stops at the first bad
  // frame; the reader must not be fed again after an error.
  template <class OnFrame>
  Status feed(std::span<const std::uint8_t> bytes, OnFrame&& on_frame);

  std::size_t buffered() const { return header_size_ + buf_.size(); }

 private:
  std::size_t max_;
  std::uint8_t header_[kFrameHeaderBytes] = {};
  std::size_t header_size_ = 0;
  std::size_t want_ = 0;           // body length of the frame being read
  std::vector<std::uint8_t> buf_;  // body only, so it starts aligned
  std::size_t total_ = 0;  // stream offset of buf_[0], for error offsets
};

// Verifies a frame body as a Message and returns it (pointing into body).
// Rejects bodies that fail the verifier (kInvalidValue), have no body union
// member, or exceed the depth/table limits.
Result<const wire::Message*> verify_message(std::span<const std::uint8_t> body);

template <class OnFrame>
Status FrameReader::feed(std::span<const std::uint8_t> bytes, OnFrame&& on_frame) {
  while (!bytes.empty()) {
    if (header_size_ < kFrameHeaderBytes) {
      // Header bytes are kept apart from the body so that the body starts
      // at the beginning of buf_ (allocator-aligned): FlatBuffers structs
      // with 8-byte fields are read in place.
      header_[header_size_++] = bytes.front();
      bytes = bytes.subspan(1);
      if (header_size_ < kFrameHeaderBytes) continue;
      const std::size_t len = std::size_t{header_[0]} | std::size_t{header_[1]} << 8 |
                              std::size_t{header_[2]} << 16 | std::size_t{header_[3]} << 24;
      if (len > max_) return DecodeError{DecodeErrorCode::kOverLimit, total_, "frame length over the maximum"};
      if (len == 0) return DecodeError{DecodeErrorCode::kInvalidValue, total_, "empty frame"};
      want_ = len;
      buf_.clear();
      continue;
    }
    const std::size_t take = std::min(want_ - buf_.size(), bytes.size());
    buf_.insert(buf_.end(), bytes.begin(), bytes.begin() + static_cast<std::ptrdiff_t>(take));
    bytes = bytes.subspan(take);
    if (buf_.size() == want_) {
      on_frame(std::span<const std::uint8_t>(buf_.data(), buf_.size()));
      total_ += kFrameHeaderBytes + want_;
      header_size_ = 0;
      buf_.clear();
    }
  }
  return Ok{};
}

}  // namespace terrane
