#include "client/redirects.h"

#include <gtest/gtest.h>

namespace terrane {
namespace {

using namespace std::chrono_literals;
using Clock = Redirects::Clock;

RedirectMsg to(std::uint16_t port, std::string token = "tok") { return RedirectMsg{2, "127.0.0.1", port, std::move(token)}; }

TEST(Redirects, FollowsOneAtATimeAndItsTokenGoesWithTheNextHelloOnce) {
  Redirects r(true);
  const auto now = Clock::now();
  EXPECT_TRUE(r.offer(to(7000, "abc"), now));
  EXPECT_FALSE(r.offer(to(7001), now));  // one pending already
  EXPECT_TRUE(r.pending());
  const RedirectMsg m = r.follow();
  EXPECT_EQ(m.port, 7000);
  EXPECT_FALSE(r.pending());
  EXPECT_EQ(r.take_token(), "abc");
  EXPECT_EQ(r.take_token(), "");
}

TEST(Redirects, NeverFollowedWhenFollowingIsOff) {
  Redirects r(false);
  EXPECT_FALSE(r.offer(to(7000), Clock::now()));
  EXPECT_FALSE(r.pending());
}

TEST(Redirects, AnUnreachableTargetIsNotFollowedForAWhile) {
  Redirects r(true);
  const auto now = Clock::now();
  ASSERT_TRUE(r.offer(to(7000), now));
  const RedirectMsg m = r.follow();
  r.unreachable(Redirects::target_of(m), now);
  EXPECT_EQ(r.take_token(), "");  // back to the old server: a fresh Hello
  EXPECT_FALSE(r.offer(to(7000), now + 1s));
  EXPECT_TRUE(r.offer(to(7001), now + 1s));  // another target is
  r.cancel();
  EXPECT_FALSE(r.pending());
  EXPECT_TRUE(r.offer(to(7000), now + Redirects::kUnreachableFor));
}

}  // namespace
}  // namespace terrane
