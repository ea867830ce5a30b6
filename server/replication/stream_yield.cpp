#include "server/replication/stream_yield.h"

namespace terrane {

bool StreamYield::streaming_waits(Clock::time_point now) {
  if (gate_.open()) {
    yielding_ = false;
    return false;
  }
  // The server is behind: live traffic first.
  if (!yielding_) {
    counters_.stream_yields.fetch_add(1, std::memory_order_relaxed);
    yielding_ = true;
    yielded_since_ = now;
  }
  if (gate_.held() || now - yielded_since_ < kYieldAtMost) return true;
  yielded_since_ = now;  // waited long enough: one pump, then yield again
  return false;
}

bool StreamYield::mips_wait(Clock::time_point now, Clock::time_point due) {
  if (gate_.open() || (!gate_.held() && now - due >= kYieldAtMost)) return false;
  counters_.mip_refresh_yields.fetch_add(1, std::memory_order_relaxed);
  return true;
}

}  // namespace terrane
