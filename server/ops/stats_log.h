// StatsLog: the server's periodic line in its log (clients, edits per
// second, bytes per second out and in, chunks loaded), every period: its
// timer and the figures of the last line, which the next one's rates are
// counted from.
//
// Threading: its timer runs on a strand of its own on the io threads (the
// lines are logged there, one at a time); start() and stop() may be called
// from any thread. No lock: the figures are the strand's (next_line() is
// for tests, on a log that is not started).
#pragma once

#include <asio.hpp>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <string>

#include "server/base/counters.h"

namespace terrane {

class StatsLog {
 public:
  using Clock = std::chrono::steady_clock;
  // Often enough to follow a load test, seldom enough not to flood the log.
  static constexpr std::chrono::seconds kPeriod{10};

  // counters outlive the log; the first line's rates count from since.
  StatsLog(asio::io_context& io, const ServerCounters& counters, Clock::duration period = kPeriod,
           Clock::time_point since = Clock::now());
  StatsLog(const StatsLog&) = delete;
  StatsLog& operator=(const StatsLog&) = delete;

  // The first line one period from now, then every period until stop().
  void start();
  // No period starts after it; the timer's wait is cancelled (so the io
  // threads can end).
  void stop();

  // The line for the counters at now, its rates since the last line (or
  // since); now's figures become the last.
  std::string next_line(Clock::time_point now);

 private:
  void arm();

  const ServerCounters& counters_;
  const Clock::duration period_;
  asio::strand<asio::io_context::executor_type> strand_;
  asio::steady_timer timer_;
  std::atomic<bool> stopping_{false};
  // The last line's time and figures.
  Clock::time_point at_;
  std::uint64_t edits_ = 0, sent_ = 0, received_ = 0;
};

}  // namespace terrane
