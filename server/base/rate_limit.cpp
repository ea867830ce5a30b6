#include "server/base/rate_limit.h"

#include <algorithm>

#include "server/base/log.h"

namespace terrane {

void TokenBucket::refill(Clock::time_point now) {
  const double dt = std::chrono::duration<double>(now - last_).count();
  last_ = now;
  if (dt > 0) tokens_ = std::min(burst_, tokens_ + dt * rate_);
}

bool TokenBucket::take(double n, Clock::time_point now) {
  if (unlimited()) return true;
  refill(now);
  if (tokens_ < n) return false;
  tokens_ -= n;
  return true;
}

void TokenBucket::spend(double n, Clock::time_point now) {
  if (unlimited()) return;
  refill(now);
  tokens_ -= n;
}

double TokenBucket::available(Clock::time_point now) {
  if (unlimited()) return 1e300;
  refill(now);
  return tokens_;
}

void RateLimitedLog::warn(const std::string& line) {
  std::lock_guard lock(mutex_);
  const auto now = std::chrono::steady_clock::now();
  if (now - window_ >= std::chrono::seconds(1)) {
    window_ = now;
    used_ = 0;
  }
  if (used_ >= per_second_) {
    ++suppressed_;
    return;
  }
  ++used_;
  if (suppressed_ > 0) {
    server_log().warn("{} ({} similar lines suppressed)", line, suppressed_);
    suppressed_ = 0;
  } else {
    server_log().warn("{}", line);
  }
}

RateLimitedLog& violations() {
  static RateLimitedLog log(20);
  return log;
}

}  // namespace terrane
