// OutFrame: one outbound frame as the segments a session writes in one
// scatter-gather write. A segment is either bytes the frame owns (the frame
// header and a message's tables, stream records' headers, varints, short
// payloads) or a span of immutable bytes shared with other frames (a chunk
// version's encoding, a horizon image, a frame built once for many
// clients) that the frame keeps alive through its owner. The segments in
// order are the frame's bytes: a chunk sent to N clients is one buffer
// referenced by N frames, not N copies of it.
//
//   [head][owned][shared][owned][shared] ... [owned]
//    head: bytes put before everything else (prepend), at least the frame
//          header and the Message table once the frame is complete: the
//          session reads the message type there (first_segment)
//
// A frame built whole (protocol/messages.h builders) is one owned segment.
// Ownership: move-only; the owners of shared spans are held until the
// frame is destroyed, so a session keeps a frame until its write ends.
// Thread-safety: a value used by one thread at a time; shared spans are
// immutable, so frames sharing them may be written on different threads.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

namespace terrane {

using Frame = std::vector<std::uint8_t>;

class OutFrame {
 public:
  // A span shorter than this is copied by append_shared: a segment of its
  // own costs an iovec, a reference count and (asio writes at most 64
  // buffers per system call) part of a system call, more than copying a
  // few hundred bytes.
  static constexpr std::size_t kMinSharedBytes = 512;

  OutFrame() = default;
  // A frame of owned bytes: one segment. Implicit: every builder's Frame
  // is an OutFrame.
  OutFrame(Frame bytes) : head_(std::move(bytes)) {}  // NOLINT(google-explicit-constructor)
  // A frame built once and sent to many sessions: one shared segment.
  explicit OutFrame(std::shared_ptr<const Frame> bytes);
  OutFrame(OutFrame&&) = default;
  OutFrame& operator=(OutFrame&&) = default;
  OutFrame(const OutFrame&) = delete;
  OutFrame& operator=(const OutFrame&) = delete;

  std::size_t size() const { return head_.size() + owned_.size() + shared_bytes_; }
  // The bytes in shared spans (the rest are the frame's own copies).
  std::size_t shared_bytes() const { return shared_bytes_; }
  bool empty() const { return size() == 0; }

  // Puts bytes before every byte of the frame.
  void prepend(Frame bytes);
  // Appends a copy of bytes.
  void append(std::span<const std::uint8_t> bytes) { owned_.insert(owned_.end(), bytes.begin(), bytes.end()); }
  // The owned bytes at the frame's end: what is pushed here follows every
  // byte before it (for put_varint and the codecs, which append to a vector).
  std::vector<std::uint8_t>& owned_tail() { return owned_; }
  // Appends bytes without copying them (shorter than kMinSharedBytes, or
  // without an owner: a copy). Precondition: they stay unchanged while
  // owner lives; the frame holds owner (a reference taken only when shared).
  template <class T>
  void append_shared(std::span<const std::uint8_t> bytes, const std::shared_ptr<T>& owner) {
    if (bytes.size() < kMinSharedBytes || !owner) return append(bytes);
    add_shared(bytes, owner);
  }

  // Calls fn(std::span<const std::uint8_t>) for each non-empty segment, in
  // order. The spans are valid while the frame lives and is not changed.
  template <class Fn>
  void for_each_segment(Fn&& fn) const;
  // The first non-empty segment (empty for an empty frame).
  std::span<const std::uint8_t> first_segment() const;
  std::size_t segment_count() const;
  // The frame's bytes in one buffer (tests, and a peer that needs them whole).
  Frame flatten() const;

 private:
  void add_shared(std::span<const std::uint8_t> bytes, std::shared_ptr<const void> owner);

  struct Shared {
    std::size_t owned_before = 0;  // the bytes of owned_ that come before it
    std::span<const std::uint8_t> bytes;
    std::shared_ptr<const void> owner;
  };

  Frame head_;
  std::vector<std::uint8_t> owned_;
  std::vector<Shared> shared_;
  std::size_t shared_bytes_ = 0;
};

template <class Fn>
void OutFrame::for_each_segment(Fn&& fn) const {
  auto emit = [&](std::span<const std::uint8_t> s) {
    if (!s.empty()) fn(s);
  };
  emit(head_);
  std::size_t from = 0;
  for (const Shared& s : shared_) {
    emit(std::span<const std::uint8_t>(owned_).subspan(from, s.owned_before - from));
    emit(s.bytes);
    from = s.owned_before;
  }
  emit(std::span<const std::uint8_t>(owned_).subspan(from));
}

}  // namespace terrane
