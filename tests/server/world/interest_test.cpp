// InterestIndex and PresenceGrid: the world strand's indexes.
#include "server/world/interest.h"

#include <gtest/gtest.h>

#include "server/world/presence.h"

namespace terrane {
namespace {

TEST(InterestIndex, HoldersAreExactlyThoseThatHoldAndNotReleased) {
  InterestIndex idx;
  const Vec3i a{1, 2, 3}, b{-4, 0, 9};
  idx.hold(a, 7, false);
  idx.hold(a, 8, true);
  idx.hold(b, 7, false);
  idx.hold(a, 7, false);  // again: still one entry
  EXPECT_EQ(idx.holders(a).size(), 2u);
  EXPECT_EQ(idx.entries(), 3u);
  EXPECT_TRUE(idx.held_full(a));
  EXPECT_FALSE(idx.held_full(b));
  idx.hold(b, 7, true);  // refined to full
  EXPECT_TRUE(idx.held_full(b));
  idx.release(a, 8);
  EXPECT_FALSE(idx.held_full(a));
  ASSERT_EQ(idx.holders(a).size(), 1u);
  EXPECT_EQ(idx.holders(a).front().id, 7u);
  idx.release(a, 7);
  idx.release(a, 7);  // twice: harmless
  EXPECT_FALSE(idx.watched(a));
  EXPECT_TRUE(idx.holders(a).empty());
  EXPECT_EQ(idx.chunks(), 1u);
  EXPECT_EQ(idx.entries(), 1u);
}

TEST(PresenceGrid, NearestFirstWithinTheRadiusAcrossCells) {
  PresenceGrid g;
  g.place(1, {0, 0, 0});
  g.place(2, {100, 0, 0});     // another cell
  g.place(3, {-30, 0, 40});    // 50 away
  g.place(4, {400, 0, 0});     // beyond 300
  g.place(5, {0, 200, 0});     // above: distance is 3D
  auto near = g.nearest(1, {0, 0, 0}, 300, 10);
  ASSERT_EQ(near.size(), 3u);
  EXPECT_EQ(near[0].client_id, 3u);
  EXPECT_EQ(near[1].client_id, 2u);
  EXPECT_EQ(near[2].client_id, 5u);
  EXPECT_EQ(g.nearest(1, {0, 0, 0}, 300, 2).size(), 2u);
  // Moving across cells and leaving.
  g.place(4, {10, 0, 0});
  near = g.nearest(1, {0, 0, 0}, 300, 10);
  ASSERT_EQ(near.size(), 4u);
  EXPECT_EQ(near[0].client_id, 4u);
  g.remove(4);
  g.remove(3);
  near = g.nearest(1, {0, 0, 0}, 300, 10);
  ASSERT_EQ(near.size(), 2u);
  EXPECT_EQ(near[0].client_id, 2u);
}

}  // namespace
}  // namespace terrane
