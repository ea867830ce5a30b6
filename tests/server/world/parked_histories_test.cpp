#include "server/world/parked_histories.h"

#include <gtest/gtest.h>

namespace terrane {
namespace {

// A history of `steps` undo steps, each a box with some voxels.
History history_of(int steps) {
  History h(1u << 20);
  for (int i = 0; i < steps; ++i) {
    const Region box{{i, 0, 0}, {i + 1, 4, 4}};
    h.record(HistoryEntry{box, std::vector<std::uint8_t>(64, static_cast<std::uint8_t>(i)), {}});
  }
  return h;
}

TEST(ParkedHistories, APlayersHistoryIsTakenBackOnceWhole) {
  ParkedHistories parked(1u << 20);
  parked.park("alice", history_of(3));
  EXPECT_EQ(parked.count(), 1u);
  EXPECT_FALSE(parked.take("bob").has_value());
  auto h = parked.take("alice");
  ASSERT_TRUE(h.has_value());
  EXPECT_EQ(h->steps(false), 3u);
  EXPECT_EQ(h->top(false)->box, (Region{{2, 0, 0}, {3, 4, 4}}));
  EXPECT_FALSE(parked.take("alice").has_value());  // taken: gone
  EXPECT_EQ(parked.bytes(), 0u);
}

TEST(ParkedHistories, AnEmptyHistoryIsNotKeptAndALaterOneReplacesTheEarlier) {
  ParkedHistories parked(1u << 20);
  parked.park("alice", History(1u << 20));
  EXPECT_EQ(parked.count(), 0u);
  parked.park("alice", history_of(1));
  parked.park("alice", history_of(2));
  EXPECT_EQ(parked.count(), 1u);
  EXPECT_EQ(parked.bytes(), history_of(2).bytes());
  EXPECT_EQ(parked.take("alice")->steps(false), 2u);
}

TEST(ParkedHistories, TheLongestParkedGoFirstOverTheBound) {
  const std::size_t one = history_of(2).bytes();
  ParkedHistories parked(2 * one);  // room for two
  parked.park("a", history_of(2));
  parked.park("b", history_of(2));
  parked.park("c", history_of(2));
  EXPECT_EQ(parked.count(), 2u);
  EXPECT_LE(parked.bytes(), 2 * one);
  EXPECT_FALSE(parked.take("a").has_value());
  EXPECT_TRUE(parked.take("b").has_value());
  EXPECT_TRUE(parked.take("c").has_value());
}

}  // namespace
}  // namespace terrane
