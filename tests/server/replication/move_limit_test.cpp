// MoveLimit: the first position is accepted wherever it is; after it a
// client moves at most max_speed voxels a second plus the slack; a move
// refused does not count as the last one; max_speed 0 accepts any move.
#include "server/replication/move_limit.h"

#include <gtest/gtest.h>

namespace terrane {
namespace {

using namespace std::chrono_literals;

TEST(MoveLimit, AClientMovesAtMostItsSpeedPlusTheSlackSinceItsLastAcceptedMove) {
  MoveLimit limit(100);  // voxels per second
  const auto t = MoveLimit::Clock::now();
  EXPECT_EQ(limit.too_far({0, 0, 0}, {1e6f, 0, 0}, t), std::nullopt);  // the first: where it joins
  const Vec3f at{1e6f, 0, 0};
  // One second later: 100 voxels plus the slack.
  EXPECT_EQ(limit.too_far(at, {1e6f + 100 + static_cast<float>(kSpeedSlackVoxels), 0, 0}, t + 1s), std::nullopt);
  const Vec3f there{1e6f + 100 + static_cast<float>(kSpeedSlackVoxels), 0, 0};
  // At once: only the slack.
  const auto refused = limit.too_far(there, {there.x, there.y + 60, there.z}, t + 1s);
  ASSERT_TRUE(refused);
  EXPECT_DOUBLE_EQ(*refused, 60);
  // What it was allowed then (the budget the server's reason names).
  EXPECT_DOUBLE_EQ(limit.allowed(t + 1s), kSpeedSlackVoxels);
  EXPECT_DOUBLE_EQ(limit.allowed(t + 1500ms), 50 + kSpeedSlackVoxels);
  // The refused move did not count: half a second after the last accepted one.
  EXPECT_EQ(limit.too_far(there, {there.x, there.y + 90, there.z}, t + 1500ms), std::nullopt);
}

TEST(MoveLimit, SpeedZeroAcceptsAnyMove) {
  MoveLimit limit(0);
  const auto t = MoveLimit::Clock::now();
  EXPECT_EQ(limit.too_far({0, 0, 0}, {0, 0, 0}, t), std::nullopt);
  EXPECT_EQ(limit.too_far({0, 0, 0}, {1e6f, 1e6f, 0}, t), std::nullopt);
}

}  // namespace
}  // namespace terrane
