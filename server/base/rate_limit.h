// Rates for the server's rooms: a token bucket (edits, bytes, requests)
// and a rate-limited log for violations (a flood of bad clients must not
// become a flood of log lines).
//
// Thread-safety: TokenBucket is single-threaded (each lives on one strand);
// RateLimitedLog is thread-safe.
#pragma once

#include <chrono>
#include <cstdint>
#include <mutex>
#include <string>

namespace terrane {

class TokenBucket {
 public:
  using Clock = std::chrono::steady_clock;
  // rate per second; burst: the most that can be taken at once. rate 0
  // means unlimited.
  TokenBucket(double rate = 0, double burst = 0) : rate_(rate), burst_(burst), tokens_(burst) {}
  bool unlimited() const { return rate_ <= 0; }
  // Takes n if available; false (and nothing taken) otherwise.
  bool take(double n, Clock::time_point now = Clock::now());
  // Takes n even if that leaves a debt (used for bytes already sent).
  void spend(double n, Clock::time_point now = Clock::now());
  double available(Clock::time_point now = Clock::now());

 private:
  void refill(Clock::time_point now);
  double rate_, burst_, tokens_;
  Clock::time_point last_ = Clock::now();
};

// At most `per_second` lines a second; the rest are counted and reported
// with the next line that gets through.
class RateLimitedLog {
 public:
  explicit RateLimitedLog(int per_second = 10) : per_second_(per_second) {}
  // Logs a warning unless over the limit.
  void warn(const std::string& line);

 private:
  std::mutex mutex_;
  int per_second_;
  int used_ = 0;
  std::uint64_t suppressed_ = 0;
  std::chrono::steady_clock::time_point window_ = std::chrono::steady_clock::now();
};

// The server's shared log for client misbehaviour.
RateLimitedLog& violations();

}  // namespace terrane
