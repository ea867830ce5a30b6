// WorldBounds: what a world border makes of a world's bounds.
#include "common/world/world_bounds.h"

#include <gtest/gtest.h>

namespace terrane {
namespace {

TEST(WorldBoundsTest, ABorderReplacesOnlyTheHorizontalLimits) {
  const WorldBounds world{-64, 192, false, 0, 0, 0, 0};
  const WorldBounds border{0, 1, true, -512, 512, -256, 256};
  const WorldBounds b = world.with_border(border);
  EXPECT_EQ(b.min_y, -64);
  EXPECT_EQ(b.max_y, 192);
  EXPECT_TRUE(b.bounded_xz);
  EXPECT_EQ(b.min_x, -512);
  EXPECT_EQ(b.max_z, 256);
  EXPECT_TRUE(b.same_border(border));
  EXPECT_FALSE(world.same_border(border));
  // No border is the same as no border, whatever stale limits it carries.
  EXPECT_TRUE(world.same_border(WorldBounds{0, 1, false, 7, 9, 7, 9}));
  EXPECT_FALSE(b.same_border(WorldBounds{0, 1, true, -512, 511, -256, 256}));
  EXPECT_FALSE(b.with_border(WorldBounds{}).bounded_xz);
}

}  // namespace
}  // namespace terrane
