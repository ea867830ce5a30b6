#include "client/emulated_link.h"

#include <algorithm>

namespace terrane {

std::size_t EmulatedLink::cap() const {
  if (e_.bandwidth_bytes_per_s == 0) return std::size_t{64} << 20;  // latency only: never the bottleneck
  const double bdp = static_cast<double>(e_.bandwidth_bytes_per_s) * static_cast<double>(e_.latency.count()) / 1000.0;
  return std::max<std::size_t>(kReadChunkBytes, static_cast<std::size_t>(bdp));
}

bool EmulatedLink::carry(std::span<const std::uint8_t> bytes, Clock::time_point now) {
  auto sent_at = now;
  if (e_.bandwidth_bytes_per_s > 0) {
    const auto on_wire = std::chrono::nanoseconds(static_cast<std::int64_t>(
        static_cast<double>(bytes.size()) * 1e9 / static_cast<double>(e_.bandwidth_bytes_per_s)));
    link_free_ = std::max(link_free_, now) + on_wire;
    sent_at = link_free_;
  }
  delayed_.push_back(Delayed{sent_at + e_.latency, std::vector<std::uint8_t>(bytes.begin(), bytes.end())});
  waiting_bytes_ += bytes.size();
  paused_ = full();
  return !paused_;
}

bool EmulatedLink::resume() {
  if (!paused_ || full()) return false;
  paused_ = false;
  return true;
}

std::optional<EmulatedLink::Clock::time_point> EmulatedLink::next_at() const {
  if (delayed_.empty()) return std::nullopt;
  return delayed_.front().deliver_at;
}

std::optional<std::vector<std::uint8_t>> EmulatedLink::take_due(Clock::time_point now) {
  if (delayed_.empty() || delayed_.front().deliver_at > now) return std::nullopt;
  std::vector<std::uint8_t> bytes = std::move(delayed_.front().bytes);
  delayed_.pop_front();
  waiting_bytes_ -= bytes.size();
  return bytes;
}

void EmulatedLink::clear() {
  delayed_.clear();
  waiting_bytes_ = 0;
  paused_ = false;
}

}  // namespace terrane
