// The view rule (common/world/view.h): distances from the client's chunk centre
// to a chunk's closed cube, ties inside, levels by distance, nearest-first
// order.
#include "common/world/view.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <tuple>


namespace terrane {
namespace {

bool contains(const std::vector<Vec3i>& v, Vec3i c) { return std::find(v.begin(), v.end(), c) != v.end(); }

TEST(View, PROTOCOLsWorkedExample) {
  // A client at (232, 128, -88) is in chunk (7, 4, -3), centre
  // (240, 144, -80). Chunk (7, 6, -3) starts 48 above the centre, chunk
  // (7, 1, -3) ends 80 below it: at radius 64 the first is in view, the
  // second is not, and the same holds mirrored.
  const Vec3f p{232.0f, 128.0f, -88.0f};
  EXPECT_EQ(view_chunk(p), (Vec3i{7, 4, -3}));
  EXPECT_EQ(offset_dist2({0, 2, 0}), 48 * 48);
  EXPECT_EQ(offset_dist2({0, -3, 0}), 80 * 80);
  EXPECT_TRUE(within(p, {7, 6, -3}, 64));
  EXPECT_TRUE(within(p, {7, 2, -3}, 64));
  EXPECT_FALSE(within(p, {7, 1, -3}, 64));
  EXPECT_FALSE(within(p, {7, 7, -3}, 64));
  // Exactly at the radius is inside.
  EXPECT_TRUE(within(p, {7, 6, -3}, 48));
  EXPECT_FALSE(within(p, {7, 6, -3}, 47));
  EXPECT_EQ(desired_level(p, {7, 6, -3}, 48), 0);
  EXPECT_EQ(desired_level(p, {7, 6, -3}, 47), 1);
  // A diagonal neighbour: (16, 16, 16) away.
  EXPECT_EQ(offset_dist2({1, 1, -1}), 3 * 16 * 16);
}

TEST(View, OnlyTheClientsChunkMatters) {
  for (const Vec3f p : {Vec3f{0.0f, 0.0f, 0.0f}, Vec3f{31.9f, 0.5f, 17.0f}, Vec3f{16.0f, 31.99f, 0.01f}})
    EXPECT_EQ(chunks_in_view(p, 100, WorldBounds{-1000, 1000}), chunks_in_view({1, 1, 1}, 100, WorldBounds{-1000, 1000}));
  EXPECT_NE(chunks_in_view({-0.5f, 0, 0}, 100, WorldBounds{-1000, 1000}), chunks_in_view({0.5f, 0, 0}, 100, WorldBounds{-1000, 1000}));
}

TEST(View, EveryOffsetWithinTheRadiusAndNoOtherIsListed) {
  for (const std::int32_t r : {0, 15, 16, 47, 48, 64, 100, 256}) {
    const auto offsets = view_offsets(r);
    for (int y = -10; y <= 10; ++y)
      for (int z = -10; z <= 10; ++z)
        for (int x = -10; x <= 10; ++x) EXPECT_EQ(contains(offsets, {x, y, z}), offset_within({x, y, z}, r)) << r;
  }
  EXPECT_EQ(view_offsets(15).size(), 1u);   // the client's own chunk
  EXPECT_EQ(view_offsets(16).size(), 7u);   // and its face neighbours
}

TEST(View, NearestFirstWithTiesByYThenZThenX) {
  const auto view = view_offsets(32);
  ASSERT_GE(view.size(), 7u);
  EXPECT_EQ(view.front(), (Vec3i{0, 0, 0}));
  const std::vector<Vec3i> faces(view.begin() + 1, view.begin() + 7);
  EXPECT_EQ(faces, (std::vector<Vec3i>{{0, -1, 0}, {0, 0, -1}, {-1, 0, 0}, {1, 0, 0}, {0, 0, 1}, {0, 1, 0}}));
  for (std::size_t i = 1; i < view.size(); ++i)
    EXPECT_LE(offset_center_dist2(view[i - 1]), offset_center_dist2(view[i]));
}

// The order is the rule's exactly: nearest by the centre-to-centre
// distance, ties by y, then z, then x (what a comparison sort gives), for
// every offset in view and for a view cut to a world's layers.
TEST(View, TheOrderIsTheRulesForEveryRadiusAndAnyLayers) {
  const auto rule = [](Vec3i a, Vec3i b) {
    const std::int64_t da = offset_center_dist2(a), db = offset_center_dist2(b);
    if (da != db) return da < db;
    return std::tie(a.y, a.z, a.x) < std::tie(b.y, b.z, b.x);
  };
  for (const std::int32_t r : {0, 16, 33, 100, 512, 1000}) {
    const auto offsets = view_offsets(r);
    auto sorted = offsets;
    std::sort(sorted.begin(), sorted.end(), rule);
    EXPECT_EQ(offsets, sorted) << r;
    for (const Vec3f p : {Vec3f{5, 40, -300}, Vec3f{0, -500, 0}, Vec3f{1e6f, 300, 17}}) {
      const WorldBounds b{-128, 256};
      std::vector<Vec3i> expect;
      for (const Vec3i o : offsets)
        if (b.touches_chunk(view_chunk(p) + o)) expect.push_back(view_chunk(p) + o);
      EXPECT_EQ(chunks_in_view(p, r, b), expect) << r << " at y " << p.y;
    }
  }
}

TEST(View, AHorizontalBorderCutsTheView) {
  // A border from x = 10 to 70, z = -40 to 20: chunks x 0..2, z -2..0.
  const WorldBounds b{-1000, 1000, true, 10, 70, -40, 20};
  const auto view = chunks_in_view({30, 0, 0}, 200, b);
  ASSERT_FALSE(view.empty());
  for (const Vec3i c : view) {
    EXPECT_TRUE(c.x >= 0 && c.x <= 2) << c.x;
    EXPECT_TRUE(c.z >= -2 && c.z <= 0) << c.z;
  }
  EXPECT_GT(chunks_in_view({30, 0, 0}, 200, WorldBounds{-1000, 1000}).size(), view.size());
}

TEST(View, VerticalBoundsCutTheView) {
  const auto view = chunks_in_view({0, 0, 0}, 200, WorldBounds{0, 64});
  ASSERT_FALSE(view.empty());
  for (const Vec3i c : view) {
    EXPECT_GE(c.y, 0);
    EXPECT_LE(c.y, 1);
  }
}

TEST(View, LevelsGrowWithDistanceInSteps) {
  // full 64, step 64: level 1 to 128, level 2 to 256, then 3. Offsets along
  // x are 32 |o| - 16 away.
  EXPECT_EQ(offset_level({2, 0, 0}, 64), 0);   // 48
  EXPECT_EQ(offset_level({3, 0, 0}, 64), 1);   // 80
  EXPECT_EQ(offset_level({4, 0, 0}, 64), 1);   // 112
  EXPECT_EQ(offset_level({5, 0, 0}, 64), 2);   // 144
  EXPECT_EQ(offset_level({8, 0, 0}, 64), 2);   // 240
  EXPECT_EQ(offset_level({9, 0, 0}, 64), 3);   // 272
  // A full-resolution radius below a chunk still steps by a chunk.
  EXPECT_EQ(offset_level({0, 0, 0}, 0), 0);
  EXPECT_EQ(offset_level({1, 0, 0}, 0), 1);    // 16 <= 64
  EXPECT_EQ(offset_level({3, 0, 0}, 0), 2);    // 80 <= 128
}

}  // namespace
}  // namespace terrane
