#include "protocol/out_frame.h"

namespace terrane {

OutFrame::OutFrame(std::shared_ptr<const Frame> bytes) {
  if (!bytes || bytes->empty()) return;
  const std::span<const std::uint8_t> span(*bytes);
  shared_bytes_ = span.size();
  shared_.push_back(Shared{0, span, std::move(bytes)});
}

void OutFrame::prepend(Frame bytes) {
  if (head_.empty()) {
    head_ = std::move(bytes);
  } else {
    head_.insert(head_.begin(), bytes.begin(), bytes.end());
  }
}

void OutFrame::add_shared(std::span<const std::uint8_t> bytes, std::shared_ptr<const void> owner) {
  shared_bytes_ += bytes.size();
  shared_.push_back(Shared{owned_.size(), bytes, std::move(owner)});
}

std::span<const std::uint8_t> OutFrame::first_segment() const {
  if (!head_.empty()) return head_;
  if (shared_.empty()) return owned_;
  if (shared_.front().owned_before > 0) return std::span<const std::uint8_t>(owned_).first(shared_.front().owned_before);
  return shared_.front().bytes;  // never empty
}

std::size_t OutFrame::segment_count() const {
  std::size_t n = 0;
  for_each_segment([&](std::span<const std::uint8_t>) { ++n; });
  return n;
}

Frame OutFrame::flatten() const {
  Frame out;
  out.reserve(size());
  for_each_segment([&](std::span<const std::uint8_t> s) { out.insert(out.end(), s.begin(), s.end()); });
  return out;
}

}  // namespace terrane
