// StreamYield: while the stream gate is closed a client's streaming waits,
// kYieldAtMost at most (then one pump goes through and it waits again),
// and for as long as the gate is held closed by hand; each yield that
// begins is counted once. Refreshes of mips wait while the gate is closed,
// kYieldAtMost past their due time at most. Retries are jittered by client.
#include "server/replication/stream_yield.h"

#include <gtest/gtest.h>

namespace terrane {
namespace {

using namespace std::chrono_literals;
using Clock = StreamYield::Clock;

// Closes gate by a late probe (not held).
void close_by_probe(StreamGate& gate) { gate.observe(StreamGate::Probe::kIo, 200ms); }
void open_by_probes(StreamGate& gate) {
  for (auto p : {StreamGate::Probe::kIo, StreamGate::Probe::kWorld, StreamGate::Probe::kRequests}) gate.observe(p, 0ms);
}

TEST(StreamYield, AClosedGateHoldsStreamingBackForAtMostTheLimitThenLetsOnePumpThrough) {
  StreamGate gate(100ms);
  ServerCounters counters;
  StreamYield y(gate, 1, counters);
  const auto t = Clock::now();
  EXPECT_FALSE(y.streaming_waits(t));
  EXPECT_FALSE(y.yielding());
  close_by_probe(gate);
  ASSERT_FALSE(gate.open());
  EXPECT_TRUE(y.streaming_waits(t));
  EXPECT_TRUE(y.yielding());
  EXPECT_TRUE(y.streaming_waits(t + 1s));
  EXPECT_EQ(counters.stream_yields.load(), 1u);
  EXPECT_FALSE(y.streaming_waits(t + StreamYield::kYieldAtMost));  // one pump through
  EXPECT_TRUE(y.streaming_waits(t + StreamYield::kYieldAtMost + 1ms));  // and waits again
  EXPECT_EQ(counters.stream_yields.load(), 1u);
  open_by_probes(gate);
  EXPECT_FALSE(y.streaming_waits(t + 3s));
  EXPECT_FALSE(y.yielding());
  close_by_probe(gate);
  EXPECT_TRUE(y.streaming_waits(t + 4s));
  EXPECT_EQ(counters.stream_yields.load(), 2u);
}

TEST(StreamYield, AGateHeldClosedHoldsStreamingAndMipsBackForAsLongAsItIsHeld) {
  StreamGate gate(100ms);
  ServerCounters counters;
  StreamYield y(gate, 1, counters);
  const auto t = Clock::now();
  gate.hold_closed(true);
  EXPECT_TRUE(y.streaming_waits(t));
  EXPECT_TRUE(y.streaming_waits(t + 1min));
  EXPECT_TRUE(y.mips_wait(t + 1min, t));
  gate.hold_closed(false);
  EXPECT_FALSE(y.streaming_waits(t + 1min));
  EXPECT_FALSE(y.mips_wait(t + 1min, t));
  EXPECT_EQ(counters.mip_refresh_yields.load(), 1u);
}

TEST(StreamYield, MipsWaitWhileTheGateIsClosedAtMostTheLimitPastTheirDueTime) {
  StreamGate gate(100ms);
  ServerCounters counters;
  StreamYield y(gate, 1, counters);
  const auto due = Clock::now();
  EXPECT_FALSE(y.mips_wait(due, due));
  close_by_probe(gate);
  EXPECT_TRUE(y.mips_wait(due + 1s, due));
  EXPECT_FALSE(y.mips_wait(due + StreamYield::kYieldAtMost, due));
  EXPECT_EQ(counters.mip_refresh_yields.load(), 1u);
}

TEST(StreamYield, RetriesAreJitteredByClient) {
  StreamGate gate(100ms);
  ServerCounters counters;
  const auto t = Clock::now();
  EXPECT_EQ(StreamYield(gate, 7, counters).retry_at(t), t + StreamYield::kYieldRetry + 7ms);
  EXPECT_EQ(StreamYield(gate, 57, counters).retry_at(t), t + StreamYield::kYieldRetry + 7ms);
  EXPECT_EQ(StreamYield(gate, 50, counters).retry_at(t), t + StreamYield::kYieldRetry);
}

}  // namespace
}  // namespace terrane
