// The view rule (common/view.h): distances to a chunk's closed cube, ties
// inside, levels by distance, nearest-first order.
#include "common/view.h"

#include <gtest/gtest.h>

#include <algorithm>

namespace terrane {
namespace {

bool contains(const std::vector<Vec3i>& v, Vec3i c) { return std::find(v.begin(), v.end(), c) != v.end(); }

TEST(View, ChunksExactlyAtTheRadiusAreInsideAboveAndBelow) {
  // PROTOCOL.md's worked example: both chunks are exactly 64 voxels away
  // (one above, one below the client); ties are in.
  const Vec3f p{232.0f, 128.0f, -88.0f};
  EXPECT_EQ(chunk_dist2(p, {7, 6, -3}), 64.0 * 64.0);
  EXPECT_EQ(chunk_dist2(p, {7, 1, -3}), 64.0 * 64.0);
  EXPECT_TRUE(within(p, {7, 6, -3}, 64));
  EXPECT_TRUE(within(p, {7, 1, -3}, 64));
  EXPECT_FALSE(within(p, {7, 0, -3}, 64));
  EXPECT_FALSE(within(p, {7, 7, -3}, 64));
  const auto view = chunks_in_view(p, 64, -1000, 1000);
  EXPECT_TRUE(contains(view, {7, 6, -3}));
  EXPECT_TRUE(contains(view, {7, 1, -3}));
  EXPECT_FALSE(contains(view, {7, 0, -3}));
  EXPECT_EQ(desired_level(p, {7, 1, -3}, 64), 0);
  EXPECT_EQ(desired_level(p, {7, 0, -3}, 64), 1);
}

TEST(View, EveryChunkWithinTheRadiusAndNoOtherIsInView) {
  const Vec3f p{10.3f, -5.7f, 100.9f};
  for (const std::int32_t r : {0, 1, 31, 32, 33, 64, 100}) {
    const auto view = chunks_in_view(p, r, -10000, 10000);
    for (int y = -6; y <= 6; ++y)
      for (int z = -6; z <= 10; ++z)
        for (int x = -6; x <= 6; ++x) EXPECT_EQ(contains(view, {x, y, z}), within(p, {x, y, z}, r)) << r;
  }
}

TEST(View, NearestFirstWithTiesByYThenZThenX) {
  const Vec3f p{16.0f, 16.0f, 16.0f};  // the centre of chunk (0, 0, 0)
  const auto view = chunks_in_view(p, 32, -1000, 1000);
  ASSERT_FALSE(view.empty());
  EXPECT_EQ(view.front(), (Vec3i{0, 0, 0}));
  // The six face neighbours are equally far: y first, then z, then x.
  const std::vector<Vec3i> faces(view.begin() + 1, view.begin() + 7);
  EXPECT_EQ(faces, (std::vector<Vec3i>{{0, -1, 0}, {0, 0, -1}, {-1, 0, 0}, {1, 0, 0}, {0, 0, 1}, {0, 1, 0}}));
  for (std::size_t i = 1; i < view.size(); ++i)
    EXPECT_LE(chunk_center_dist2(p, view[i - 1]), chunk_center_dist2(p, view[i]));
}

TEST(View, VerticalBoundsCutTheView) {
  const auto view = chunks_in_view({0, 0, 0}, 200, 0, 64);
  ASSERT_FALSE(view.empty());
  for (const Vec3i c : view) {
    EXPECT_GE(c.y, 0);
    EXPECT_LE(c.y, 1);
  }
}

TEST(View, LevelsGrowWithDistanceInSteps) {
  const Vec3f p{0.5f, 0.5f, 0.5f};
  // full 64: step 64; level 1 to 128, level 2 to 256, then 3.
  EXPECT_EQ(desired_level(p, {2, 0, 0}, 64), 0);   // 63.5 away
  EXPECT_EQ(desired_level(p, {3, 0, 0}, 64), 1);   // 95.5
  EXPECT_EQ(desired_level(p, {5, 0, 0}, 64), 2);   // 159.5
  EXPECT_EQ(desired_level(p, {8, 0, 0}, 64), 2);   // 255.5
  EXPECT_EQ(desired_level(p, {9, 0, 0}, 64), 3);   // 287.5
  // A full-resolution radius below a chunk still steps by a chunk.
  EXPECT_EQ(desired_level(p, {1, 0, 0}, 0), 1);    // 31.5 <= 64
  EXPECT_EQ(desired_level(p, {0, 0, 0}, 0), 0);    // inside
}

}  // namespace
}  // namespace terrane
