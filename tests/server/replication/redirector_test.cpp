// Redirector: a client well inside regions one other server writes (every
// region within the margin, each lease seen for kRedirectStable, a fresh
// map, the client settled) is redirected once; still here after the grace
// it is served again, not redirected during the back-off, and redirected
// after it. By a border, with a young lease, a stale map, just joined, or
// in a world of one server, it stays.
#include "server/replication/redirector.h"

#include <gtest/gtest.h>

#include <memory>

namespace terrane {
namespace {

using Clock = Redirector::Clock;
using namespace std::chrono_literals;

constexpr float kRegionVoxels = 256;  // 8 chunks of 32

class RedirectorTest : public ::testing::Test {
 protected:
  RedirectorTest() {
    options_.server_id = 1;
    options_.redirect_margin = 32;
    options_.lease = 5000ms;
  }
  // Server `writer` writes regions x in [x0, x1] (y = z = 0), first seen at
  // first_seen, read again at read_at.
  void publish(std::uint32_t writer, int x0, int x1, Clock::time_point first_seen, Clock::time_point read_at) {
    std::vector<RegionWriter> writers;
    for (int x = x0; x <= x1; ++x) writers.push_back(RegionWriter{{x, 0, 0}, writer, 7});
    const std::vector<ServerAddress> servers{{1, "10.0.0.1", 7001}, {2, "10.0.0.2", 7002}};
    auto first = std::make_shared<const ClusterMap>(writers, servers, first_seen);
    cluster_.publish(std::make_shared<const ClusterMap>(writers, servers, read_at, first.get()));
  }
  static Vec3f in_region(float x) { return {x * kRegionVoxels + 128, 128, 128}; }

  ClusterOptions options_;
  ClusterDirectory cluster_;
  const Clock::time_point t0_ = Clock::now();
};

TEST_F(RedirectorTest, AClientWellInsideAnotherServersRegionsIsRedirectedOnceThenServedAgainAfterTheGrace) {
  Redirector r(&cluster_, options_);
  r.joined(t0_);
  const auto now = t0_ + 20s;
  publish(2, 0, 2, t0_, now);
  auto move = r.check(in_region(1), now);
  ASSERT_TRUE(move);
  EXPECT_EQ(move->to.id, 2u);
  EXPECT_EQ(move->to.port, 7002);
  EXPECT_EQ(move->region, (Vec3i{1, 0, 0}));
  EXPECT_EQ(r.target(), "server 2 at 10.0.0.2:7002");
  EXPECT_TRUE(r.redirected());
  EXPECT_FALSE(r.check(in_region(1), now));  // once
  EXPECT_EQ(r.next_wake(now, true), now + Redirector::kRedirectGrace);

  EXPECT_FALSE(r.expire(now + Redirector::kRedirectGrace - 1ms));
  const auto back = now + Redirector::kRedirectGrace;
  EXPECT_TRUE(r.expire(back));
  EXPECT_FALSE(r.expire(back));
  EXPECT_FALSE(r.redirected());
  EXPECT_EQ(r.next_wake(back, true), back + Redirector::kRedirectCheck);
  publish(2, 0, 2, t0_, back + 1s);
  EXPECT_FALSE(r.check(in_region(1), back + 1s));  // backing off
  const auto later = back + Redirector::kRedirectBackoff;
  publish(2, 0, 2, t0_, later);
  EXPECT_TRUE(r.check(in_region(1), later));
}

TEST_F(RedirectorTest, AClientStaysByABorderWithAYoungLeaseAStaleMapOrJustJoined) {
  Redirector r(&cluster_, options_);
  r.joined(t0_);
  const auto now = t0_ + 20s;
  // Regions 0 and 1 written by server 2, region 2 by nobody: a client
  // within the margin of region 2's border stays.
  publish(2, 0, 1, t0_, now);
  EXPECT_FALSE(r.check({2 * kRegionVoxels - 10, 128, 128}, now));
  // A lease seen for less than kRedirectStable.
  publish(2, 0, 1, now - 5s, now);
  EXPECT_FALSE(r.check(in_region(0), now));
  // A map older than a lease.
  publish(2, 0, 1, t0_, now - options_.lease - 1ms);
  EXPECT_FALSE(r.check(in_region(0), now));
  // Its own regions.
  publish(1, 0, 1, t0_, now);
  EXPECT_FALSE(r.check(in_region(0), now));
  EXPECT_FALSE(r.redirected());

  Redirector fresh(&cluster_, options_);
  fresh.joined(now - 1s);  // within kRedirectSettle
  publish(2, 0, 1, t0_, now);
  EXPECT_FALSE(fresh.check(in_region(0), now));
  EXPECT_TRUE(fresh.check(in_region(0), now + Redirector::kRedirectSettle));
}

TEST_F(RedirectorTest, NothingIsRedirectedInAWorldOfOneServerOrWithoutAMargin) {
  Redirector alone(nullptr, options_);
  alone.joined(t0_);
  EXPECT_FALSE(alone.check(in_region(0), t0_ + 20s));
  EXPECT_EQ(alone.next_wake(t0_, true), Clock::time_point::max());
  options_.redirect_margin = 0;
  Redirector off(&cluster_, options_);
  off.joined(t0_);
  publish(2, 0, 2, t0_, t0_ + 20s);
  EXPECT_FALSE(off.check(in_region(1), t0_ + 20s));
  EXPECT_EQ(off.next_wake(t0_, true), Clock::time_point::max());
  EXPECT_EQ(off.next_wake(t0_, false), Clock::time_point::max());
}

}  // namespace
}  // namespace terrane
