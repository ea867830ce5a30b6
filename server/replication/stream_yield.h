// StreamYield: one client's side of the stream gate (stream_gate.h). While
// the gate is closed, the client's streaming (chunks sent and asked for,
// the refreshes of the mips it holds) waits, and is tried again after
// kYieldRetry plus up to kYieldJitterMs by client (a thousand clients do
// not all wake at once, and each costs a timer wake, not 50 a second). It
// waits kYieldAtMost at most: then it goes on once and yields again, so
// under a load that never lets up a view still fills, slowly; unless the
// gate is held closed by hand, when it waits for as long as it is held.
//
// Threading: the client's session strand (one replicator's); the gate is
// read from any thread.
#pragma once

#include <chrono>
#include <cstdint>

#include "server/base/counters.h"
#include "server/replication/stream_gate.h"

namespace terrane {

class StreamYield {
 public:
  using Clock = std::chrono::steady_clock;
  static constexpr auto kYieldRetry = std::chrono::milliseconds(100);
  static constexpr std::uint64_t kYieldJitterMs = 50;
  static constexpr auto kYieldAtMost = std::chrono::seconds(2);

  // id: the client's (its jitter). gate and counters outlive this.
  StreamYield(const StreamGate& gate, std::uint64_t id, ServerCounters& counters)
      : gate_(gate), id_(id), counters_(counters) {}

  // Whether streaming waits now (at a pump). A yield that begins is
  // counted (stream_yields); one that has lasted kYieldAtMost lets this
  // pump through and begins again.
  bool streaming_waits(Clock::time_point now);
  // Whether the client's streaming is yielding (since the last pump).
  bool yielding() const { return yielding_; }
  // Whether the refreshes of mips, due since due, wait now (counted:
  // mip_refresh_yields).
  bool mips_wait(Clock::time_point now, Clock::time_point due);
  // When to try again after a wait.
  Clock::time_point retry_at(Clock::time_point now) const {
    return now + kYieldRetry + std::chrono::milliseconds(id_ % kYieldJitterMs);
  }

 private:
  const StreamGate& gate_;
  const std::uint64_t id_;
  ServerCounters& counters_;
  // The gate was closed at the last pump: streaming waits for the timer
  // (since yielded_since_, or the last pump it let through).
  bool yielding_ = false;
  Clock::time_point yielded_since_;
};

}  // namespace terrane
