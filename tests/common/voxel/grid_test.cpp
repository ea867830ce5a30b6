#include "common/voxel/grid.h"

#include <gtest/gtest.h>

#include <limits>
#include <map>
#include <random>
#include <tuple>

namespace terrane {
namespace {

using materials::kRock;
using materials::kSand;

TEST(FloorDiv, NegativeCoordinatesRoundDown) {
  EXPECT_EQ(chunk_of({-1, 0, 31}), (Vec3i{-1, 0, 0}));
  EXPECT_EQ(chunk_of({-32, -33, 32}), (Vec3i{-1, -2, 1}));
  EXPECT_EQ(local_of({-1, -33, 32}), (Vec3i{31, 31, 0}));
}

TEST(Grid, EmptyGridReadsAir) {
  Grid g;
  EXPECT_EQ(g.get({123, -456, 789}), Voxel{});
  EXPECT_EQ(g.chunk_count(), 0u);
}

TEST(Grid, BoxWritesAndReadsAcrossChunkBordersAndNegativeCoordinates) {
  Grid g;
  std::map<std::tuple<int, int, int>, Voxel> ref;
  std::mt19937 rng(5);
  std::uniform_int_distribution<int> pos(-70, 70), len(1, 40), mat(0, 9), occ(0, 255);
  for (int step = 0; step < 40; ++step) {
    const Vec3i min{pos(rng), pos(rng), pos(rng)};
    Box src({len(rng), len(rng), len(rng)});
    for (auto& v : src.voxels()) v = make_voxel(static_cast<Material>(mat(rng)), static_cast<std::uint8_t>(occ(rng)));
    g.write_box(min, src);
    for (int y = 0; y < src.size().y; ++y)
      for (int z = 0; z < src.size().z; ++z)
        for (int x = 0; x < src.size().x; ++x) ref[{min.x + x, min.y + y, min.z + z}] = src.get(x, y, z);
  }
  // Read a box covering everything and compare with the reference.
  const Vec3i lo{-72, -72, -72};
  Box all({72 + 112, 72 + 112, 72 + 112});
  g.read_box(lo, all);
  for (int y = 0; y < all.size().y; ++y)
    for (int z = 0; z < all.size().z; ++z)
      for (int x = 0; x < all.size().x; ++x) {
        auto it = ref.find({lo.x + x, lo.y + y, lo.z + z});
        const Voxel want = it == ref.end() ? Voxel{} : it->second;
        ASSERT_EQ(all.get(x, y, z), want) << lo.x + x << "," << lo.y + y << "," << lo.z + z;
        if ((x + y + z) % 97 == 0) {
          ASSERT_EQ(g.get(lo + Vec3i{x, y, z}), want);
        }
      }
}

TEST(Grid, ChunksThatBecomeAirAreFreed) {
  Grid g;
  g.fill(Region{{-40, -40, -40}, {40, 40, 40}}, solid(kRock));
  EXPECT_EQ(g.chunk_count(), 64u);  // chunks -2..1 on each axis overlap [-40, 40)
  g.fill(Region{{-40, -40, -40}, {40, 40, 40}}, Voxel{});
  EXPECT_EQ(g.chunk_count(), 0u);
  g.fill(Region{{0, 0, 0}, {4, 4, 4}}, Voxel{});  // writing Air creates nothing
  EXPECT_EQ(g.chunk_count(), 0u);
}

TEST(Grid, MemoryCountsEveryPart) {
  Grid g;
  const std::size_t empty_map = g.memory().map_bytes;
  g.fill(Region{{0, 0, 0}, {64, 10, 64}}, solid(kRock));
  g.set({3, 3, 3}, make_voxel(kSand, 50));
  const GridMemory m = g.memory();
  EXPECT_EQ(m.chunks, 4u);
  EXPECT_GT(m.map_bytes, empty_map);
  EXPECT_EQ(m.object_bytes, 4 * sizeof(Chunk));
  EXPECT_GT(m.level0_bytes, 0u);
  EXPECT_GT(m.mip_bytes, 0u);
  EXPECT_EQ(m.level0_rows.occupancy_rows, 1u);  // the sand voxel's row
}

TEST(Grid, ASharedChunkIsReadAsItIsAndCopiedByTheFirstWrite) {
  Chunk made;
  made.modify(Region{{0, 0, 0}, {32, 9, 32}}, [](Vec3i p, Voxel) { return make_voxel(p.x % 2 ? kRock : kSand, 200); });
  made.pack_mips();
  auto shared = std::make_shared<const Chunk>(std::move(made));
  Grid a, b;
  a.put_shared_chunk({1, 0, 0}, shared);
  b.put_shared_chunk({1, 0, 0}, shared);
  EXPECT_EQ(a.find_chunk({1, 0, 0}), shared.get());
  EXPECT_EQ(a.get({33, 3, 3}), make_voxel(kRock, 200));
  EXPECT_EQ(a.memory().shared_chunks, 1u);
  // Three holders: each grid counts a third of the chunk.
  EXPECT_LT(3 * a.memory().level0_bytes, shared->memory().level0_bytes + 3);
  // A write in one grid changes its own copy: the other grid and the
  // shared chunk keep their voxels.
  a.set({33, 3, 3}, solid(materials::kBrick));
  EXPECT_EQ(a.get({33, 3, 3}), solid(materials::kBrick));
  EXPECT_NE(a.find_chunk({1, 0, 0}), shared.get());
  EXPECT_EQ(a.memory().shared_chunks, 0u);
  EXPECT_EQ(b.get({33, 3, 3}), make_voxel(kRock, 200));
  EXPECT_EQ(shared->get(1, 3, 3), make_voxel(kRock, 200));
  // Taken out, a shared chunk is a copy; an empty one is never held.
  auto taken = b.take_chunk({1, 0, 0});
  ASSERT_NE(taken, nullptr);
  EXPECT_NE(taken.get(), shared.get());
  EXPECT_EQ(taken->get(1, 3, 3), make_voxel(kRock, 200));
  b.put_shared_chunk({0, 0, 0}, std::make_shared<const Chunk>());
  EXPECT_EQ(b.chunk_count(), 0u);
}

class RaycastTest : public ::testing::Test {
 protected:
  void SetUp() override {
    // A wall at x = 5 (y, z in [-10, 10)), a floor at y = -3, a faint voxel.
    g_.fill(Region{{5, -10, -10}, {6, 10, 10}}, solid(kRock));
    g_.fill(Region{{-20, -3, -20}, {20, -2, 20}}, solid(kSand));
    g_.set({2, 0, 0}, make_voxel(kSand, 10));
  }
  Grid g_;
};

TEST_F(RaycastTest, HitsWallWithFaceAndDistance) {
  auto hit = g_.raycast({0.5f, 0.5f, 0.5f}, {1, 0, 0}, 100, 128);
  ASSERT_TRUE(hit.has_value());
  EXPECT_EQ(hit->voxel, (Vec3i{5, 0, 0}));
  EXPECT_EQ(hit->normal, (Vec3i{-1, 0, 0}));
  EXPECT_FLOAT_EQ(hit->distance, 4.5f);
  EXPECT_EQ(hit->value, solid(kRock));
}

TEST_F(RaycastTest, ThresholdDecidesWhetherFaintVoxelsStopTheRay) {
  auto low = g_.raycast({0.5f, 0.5f, 0.5f}, {1, 0, 0}, 100, 0);
  ASSERT_TRUE(low.has_value());
  EXPECT_EQ(low->voxel, (Vec3i{2, 0, 0}));
}

TEST_F(RaycastTest, DownwardRayHitsFloorFromAboveInNegativeSpace) {
  auto hit = g_.raycast({-7.5f, 4.25f, -9.5f}, {0, -2, 0}, 100);
  ASSERT_TRUE(hit.has_value());
  EXPECT_EQ(hit->voxel, (Vec3i{-8, -3, -10}));
  EXPECT_EQ(hit->normal, (Vec3i{0, 1, 0}));
  EXPECT_FLOAT_EQ(hit->distance, 6.25f);
}

TEST_F(RaycastTest, MissesBeyondMaxDistanceAndInEmptySpace) {
  EXPECT_FALSE(g_.raycast({0.5f, 0.5f, 0.5f}, {1, 0, 0}, 4.0f, 128).has_value());
  EXPECT_FALSE(g_.raycast({0.5f, 0.5f, 0.5f}, {0, 1, 0}, 500).has_value());
  EXPECT_FALSE(g_.raycast({0.5f, 0.5f, 0.5f}, {0, 0, 0}, 10).has_value());
}

TEST_F(RaycastTest, StartingInsideSolidHitsAtZero) {
  auto hit = g_.raycast({5.5f, 0.5f, 0.5f}, {1, 1, 0}, 10);
  ASSERT_TRUE(hit.has_value());
  EXPECT_EQ(hit->voxel, (Vec3i{5, 0, 0}));
  EXPECT_EQ(hit->distance, 0.0f);
  EXPECT_EQ(hit->normal, (Vec3i{0, 0, 0}));
}

TEST_F(RaycastTest, DiagonalRayEntersThroughTheRightFace) {
  // From (0.5, 0.5, 0.5) towards +x,-y: reaches x = 5 at t where y = -4 (floor at y = -3 first?)
  auto hit = g_.raycast({0.5f, 0.5f, 0.5f}, {1, -1, 0}, 100, 128);
  ASSERT_TRUE(hit.has_value());
  // y drops 1 per unit x: y = -2 is reached at x = 3, i.e. the floor voxel
  // below (-3) is entered from above at x in [3.5, 4.5).
  EXPECT_EQ(hit->voxel, (Vec3i{3, -3, 0}));
  EXPECT_EQ(hit->normal, (Vec3i{0, 1, 0}));
}

TEST(Collision, OverlapCollidesTouchingDoesNot) {
  Grid g;
  g.fill(Region{{0, 0, 0}, {4, 1, 4}}, solid(kRock));  // a slab y in [0, 1)
  EXPECT_FALSE(g.collides(Aabb{{0.5f, 1.0f, 0.5f}, {1.5f, 2.8f, 1.5f}}));   // standing on it
  EXPECT_TRUE(g.collides(Aabb{{0.5f, 0.9f, 0.5f}, {1.5f, 2.7f, 1.5f}}));    // sunk in
  EXPECT_FALSE(g.collides(Aabb{{4.0f, 0.0f, 0.0f}, {5.0f, 1.0f, 1.0f}}));   // beside it
  EXPECT_FALSE(g.collides(Aabb{{-3.0f, -3.0f, -3.0f}, {-1.0f, -1.0f, -1.0f}}));
  g.set({-2, -2, -2}, make_voxel(kSand, 20));
  EXPECT_TRUE(g.collides(Aabb{{-3.0f, -3.0f, -3.0f}, {-1.0f, -1.0f, -1.0f}}));
  EXPECT_FALSE(g.collides(Aabb{{-3.0f, -3.0f, -3.0f}, {-1.0f, -1.0f, -1.0f}}, 128));
}

}  // namespace
}  // namespace terrane

namespace terrane {
namespace {
TEST(Raycast, HugeOrInfiniteMaxDistanceStillHits) {
  Grid g;
  g.set({5, 0, 0}, solid(materials::kRock));
  for (float d : {1e9f, std::numeric_limits<float>::infinity()}) {
    auto hit = g.raycast({0.5f, 0.5f, 0.5f}, {1, 0, 0}, d);
    ASSERT_TRUE(hit.has_value()) << d;
    EXPECT_EQ(hit->voxel, (Vec3i{5, 0, 0}));
  }
  EXPECT_FALSE(g.raycast({std::numeric_limits<float>::quiet_NaN(), 0, 0}, {1, 0, 0}, 10).has_value());
}

TEST(Grid, ChunkFreedAfterChurnThatUnpackedIt) {
  Grid g;
  g.set({0, 0, 0}, solid(materials::kRock));
  for (int i = 0; i < 40; ++i) {
    g.set({5, 5, 5}, make_voxel(materials::kSand, static_cast<std::uint8_t>(i)));
    g.set({5, 5, 5}, Voxel{});
  }
  g.set({0, 0, 0}, Voxel{});
  EXPECT_EQ(g.chunk_count(), 0u);
}
}  // namespace
}  // namespace terrane
