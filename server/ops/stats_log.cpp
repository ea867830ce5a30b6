#include "server/ops/stats_log.h"

#include <algorithm>

#include "server/base/log.h"

namespace terrane {

StatsLog::StatsLog(asio::io_context& io, const ServerCounters& counters, Clock::duration period,
                   Clock::time_point since)
    : counters_(counters), period_(period), strand_(asio::make_strand(io)), timer_(strand_), at_(since) {}

void StatsLog::start() {
  asio::dispatch(strand_, [this] { arm(); });
}

void StatsLog::stop() {
  stopping_ = true;
  asio::dispatch(strand_, [this] { timer_.cancel(); });
}

void StatsLog::arm() {
  if (stopping_) return;
  timer_.expires_after(period_);
  timer_.async_wait([this](const asio::error_code& ec) {
    if (ec || stopping_) return;
    server_log().info("{}", next_line(Clock::now()));
    arm();
  });
}

std::string StatsLog::next_line(Clock::time_point now) {
  const double dt = std::max(1e-3, std::chrono::duration<double>(now - at_).count());
  std::uint64_t sent = 0, received = 0;
  for (std::size_t t = 0; t < NetCounters::kTypes; ++t) {
    sent += counters_.net.sent_bytes[t].load(std::memory_order_relaxed);
    received += counters_.net.received_bytes[t].load(std::memory_order_relaxed);
  }
  const std::uint64_t edits = counters_.edits_applied.load(std::memory_order_relaxed);
  std::string line = fmt::format("{} clients; {:.1f} edits/s; out {:.2f} MB/s, in {:.3f} MB/s; {} chunks loaded",
                                 counters_.clients.load(), static_cast<double>(edits - edits_) / dt,
                                 static_cast<double>(sent - sent_) / dt / 1e6,
                                 static_cast<double>(received - received_) / dt / 1e6, counters_.chunks_loaded.load());
  at_ = now;
  edits_ = edits;
  sent_ = sent;
  received_ = received;
  return line;
}

}  // namespace terrane
