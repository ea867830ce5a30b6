// ClusterMap and ServerAddress (server/storage/cluster_map.h): who writes
// each region and since when, and the addresses servers advertise.
#include "server/storage/cluster_map.h"

#include <gtest/gtest.h>

#include <chrono>
#include <string>
#include <vector>

namespace terrane {
namespace {

using namespace std::chrono_literals;

TEST(ClusterMapTest, ALeaseKeepsTheTimeItWasFirstSeenUntilItChangesHands) {
  using Clock = ClusterMap::Clock;
  const Clock::time_point t0{}, t1 = t0 + 1s, t2 = t0 + 2s;
  const std::vector<ServerAddress> servers{{1, "a", 1}, {2, "b", 2}};
  const ClusterMap first({{{0, 0, 0}, 1, 5}, {{1, 0, 0}, 1, 3}}, servers, t0);
  // (1,0,0) is handed to server 2, (0,0,0) claimed again by its writer (a
  // new epoch: a restart), (2,0,0) new.
  const ClusterMap second({{{0, 0, 0}, 1, 5}, {{1, 0, 0}, 2, 4}, {{2, 0, 0}, 2, 1}}, servers, t1, &first);
  EXPECT_EQ(second.written_since({0, 0, 0}), t0);
  EXPECT_EQ(second.written_since({1, 0, 0}), t1);
  EXPECT_EQ(second.written_since({2, 0, 0}), t1);
  EXPECT_EQ(second.writer_of({1, 0, 0})->id, 2u);
  const ClusterMap third({{{0, 0, 0}, 1, 6}, {{1, 0, 0}, 2, 4}}, servers, t2, &second);
  EXPECT_EQ(third.written_since({0, 0, 0}), t2);
  EXPECT_EQ(third.written_since({1, 0, 0}), t1);
  EXPECT_EQ(third.written_since({2, 0, 0}), std::nullopt);
  EXPECT_EQ(third.writer_of({2, 0, 0}), nullptr);
}

TEST(ServerAddressTest, ParsesHostAndPortAndSaysWhatIsWrong) {
  std::string why;
  auto a = parse_server_address("game.example:7777", &why);
  ASSERT_TRUE(a) << why;
  EXPECT_EQ(a->host, "game.example");
  EXPECT_EQ(a->port, 7777);
  auto v6 = parse_server_address("[::1]:7778", &why);
  ASSERT_TRUE(v6) << why;
  EXPECT_EQ(v6->host, "::1");
  EXPECT_EQ(v6->text(), "[::1]:7778");
  for (const char* bad : {"7777", "host:", "host:0", "host:65536", "host:x", "bad host:1", ":7777"}) {
    why.clear();
    EXPECT_FALSE(parse_server_address(bad, &why)) << bad;
    EXPECT_NE(why.find(bad), std::string::npos) << why;
  }
}

}  // namespace
}  // namespace terrane
