#include "client/send_queue.h"

#include <algorithm>

namespace terrane {

bool SendQueue::reserve(std::size_t n) {
  if (bytes_.load(std::memory_order_relaxed) + n > max_bytes_) return false;
  bytes_.fetch_add(n, std::memory_order_relaxed);
  return true;
}

void SendQueue::push_front(std::vector<Outbound> frames) {
  // Behind a write under way: its frame must stay the front until it ends.
  const auto at = writing_ ? std::next(frames_.begin()) : frames_.begin();
  for (const Outbound& o : frames) bytes_.fetch_add(o.frame.size(), std::memory_order_relaxed);
  frames_.insert(at, std::make_move_iterator(frames.begin()), std::make_move_iterator(frames.end()));
}

void SendQueue::drop(wire::Body type) {
  const auto from = writing_ ? std::next(frames_.begin()) : frames_.begin();
  const auto kept = std::remove_if(from, frames_.end(), [&](const Outbound& o) {
    if (o.type != type) return false;
    bytes_.fetch_sub(o.frame.size(), std::memory_order_relaxed);
    return true;
  });
  frames_.erase(kept, frames_.end());
}

const Outbound* SendQueue::start_write() {
  if (writing_) return nullptr;
  while (!frames_.empty() && frames_.front().skip) {
    bytes_.fetch_sub(frames_.front().frame.size(), std::memory_order_relaxed);
    frames_.pop_front();
  }
  if (frames_.empty()) return nullptr;
  writing_ = true;
  return &frames_.front();
}

void SendQueue::finish_write() {
  writing_ = false;
  bytes_.fetch_sub(frames_.front().frame.size(), std::memory_order_relaxed);
  frames_.pop_front();
}

std::uint32_t SendQueue::abandon_write() {
  if (!writing_) return 0;
  writing_ = false;
  frames_.front().skip = true;
  return frames_.front().edit_id;
}

void SendQueue::clear() {
  frames_.clear();
  writing_ = false;
  bytes_.store(0, std::memory_order_relaxed);
}

}  // namespace terrane
