#include "client/emulated_link.h"

#include <gtest/gtest.h>

namespace terrane {
namespace {

using namespace std::chrono_literals;
using Clock = EmulatedLink::Clock;

TEST(EmulatedLink, LatencyDelaysEveryReadByTheSameTime) {
  EmulatedLink link(NetworkEmulation{50ms, 0});
  ASSERT_TRUE(link.active());
  const auto t0 = Clock::time_point{} + 1s;
  const std::vector<std::uint8_t> a{1, 2}, b{3};
  link.carry(a, t0);
  link.carry(b, t0 + 10ms);
  EXPECT_EQ(link.next_at(), t0 + 50ms);
  EXPECT_FALSE(link.take_due(t0 + 49ms).has_value());
  EXPECT_EQ(link.take_due(t0 + 50ms), a);
  EXPECT_FALSE(link.take_due(t0 + 55ms).has_value());
  EXPECT_EQ(link.take_due(t0 + 60ms), b);
  EXPECT_FALSE(link.next_at().has_value());
  EXPECT_EQ(link.waiting_bytes(), 0u);
}

TEST(EmulatedLink, BandwidthQueuesReadsBehindEachOther) {
  // 1000 bytes/s: 100 bytes take 100 ms on the wire.
  EmulatedLink link(NetworkEmulation{0ms, 1000});
  const auto t0 = Clock::time_point{} + 1s;
  const std::vector<std::uint8_t> hundred(100, 7);
  link.carry(hundred, t0);
  link.carry(hundred, t0);
  EXPECT_EQ(link.next_at(), t0 + 100ms);
  ASSERT_TRUE(link.take_due(t0 + 100ms).has_value());
  EXPECT_EQ(link.next_at(), t0 + 200ms);
}

TEST(EmulatedLink, ReadingPausesAtOneBandwidthDelayProductButAtLeastOneRead) {
  // 1 MB/s and 1 s: about 1 MB may wait.
  EmulatedLink slow(NetworkEmulation{1000ms, 1'000'000});
  const auto t0 = Clock::time_point{} + 1s;
  const std::vector<std::uint8_t> read(EmulatedLink::kReadChunkBytes, 1);
  for (int i = 0; i < 15; ++i) EXPECT_TRUE(slow.carry(read, t0));
  EXPECT_FALSE(slow.carry(read, t0));
  EXPECT_FALSE(slow.resume()) << "nothing delivered yet";
  ASSERT_TRUE(slow.take_due(t0 + 2s).has_value());
  EXPECT_TRUE(slow.resume());
  EXPECT_FALSE(slow.resume()) << "once";
  // A tiny product: one read fills it.
  EmulatedLink tiny(NetworkEmulation{1ms, 1000});
  EXPECT_FALSE(tiny.carry(read, t0));
  tiny.clear();
  EXPECT_FALSE(tiny.resume()) << "a new connection reads anyway";
  EXPECT_FALSE(tiny.next_at().has_value());
}

TEST(EmulatedLink, InactiveWithoutLatencyOrBandwidth) {
  EXPECT_FALSE(EmulatedLink(NetworkEmulation{}).active());
}

}  // namespace
}  // namespace terrane
