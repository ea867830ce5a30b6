#include "server/world/request_queue.h"

namespace terrane {

RequestQueue::RequestQueue(Strand& strand, std::function<void(WorldRequest&)> handle)
    : strand_(strand), handle_(std::move(handle)) {}

void RequestQueue::push(WorldRequest r) {
  r.queued = std::chrono::steady_clock::now();
  std::lock_guard lock(m_);
  queue_.push_back(std::move(r));
  if (drain_posted_) return;
  drain_posted_ = true;
  asio::post(strand_, [this] { drain(); });
}

void RequestQueue::drain() {
  const auto until = std::chrono::steady_clock::now() + kSlice;
  for (;;) {
    WorldRequest r;
    {
      std::lock_guard lock(m_);
      if (queue_.empty()) {
        drain_posted_ = false;
        break;
      }
      r = std::move(queue_.front());
      queue_.pop_front();
    }
    const auto now = std::chrono::steady_clock::now();
    if (wait_) wait_(now - r.queued);
    handle_(r);
    if (std::chrono::steady_clock::now() >= until) {
      // The slice is spent: whatever was posted meanwhile goes first.
      asio::post(strand_, [this] { drain(); });
      return;
    }
  }
  if (wait_) wait_(std::chrono::nanoseconds{0});  // nothing waits now
}

}  // namespace terrane
