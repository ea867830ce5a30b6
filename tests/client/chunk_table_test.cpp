#include "client/chunk_table.h"

#include <gtest/gtest.h>

#include <map>
#include <random>
#include <tuple>

namespace terrane {
namespace {

struct ByPos {
  bool operator()(Vec3i a, Vec3i b) const { return std::tie(a.x, a.y, a.z) < std::tie(b.x, b.y, b.z); }
};

TEST(ChunkTable, AgreesWithAMapThroughInsertsAndErasesAcrossBlocksAndNegativeCoordinates) {
  ChunkTable<std::uint64_t> t;
  std::map<Vec3i, std::uint64_t, ByPos> want;
  std::mt19937 rng(7);
  std::uniform_int_distribution<int> coord(-20, 19);
  for (int step = 0; step < 20000; ++step) {
    const Vec3i cp{coord(rng), coord(rng) / 4, coord(rng)};
    if (rng() % 3 == 0) {
      EXPECT_EQ(t.erase(cp), want.erase(cp) == 1);
    } else {
      const std::uint64_t v = rng();
      t[cp] = v;
      want[cp] = v;
    }
    if (step % 997 == 0) {
      ASSERT_EQ(t.size(), want.size());
      for (const auto& [pos, v] : want) {
        const std::uint64_t* got = t.find(pos);
        ASSERT_NE(got, nullptr);
        ASSERT_EQ(*got, v);
      }
    }
  }
  ASSERT_EQ(t.size(), want.size());
  std::map<Vec3i, std::uint64_t, ByPos> seen;
  t.for_each([&](Vec3i cp, const std::uint64_t& v) { EXPECT_TRUE(seen.emplace(cp, v).second); });
  EXPECT_EQ(seen, want);
  EXPECT_EQ(t.find({100, 100, 100}), nullptr);
}

TEST(ChunkTable, AChunkInsertedHasAValueInitialisedValueAndErasingTheLastOfABlockFreesIt) {
  ChunkTable<int> t;
  EXPECT_EQ((t[Vec3i{-1, -1, -1}]), 0);
  t[{-1, -1, -1}] = 5;
  t[{-4, -4, -4}] = 6;  // the same block (-1, -1, -1)
  t[{0, 0, 0}] = 7;     // another
  EXPECT_EQ(t.size(), 3u);
  EXPECT_EQ(*t.find({-1, -1, -1}), 5);
  EXPECT_EQ(*t.find({-4, -4, -4}), 6);
  const std::size_t three = t.heap_bytes();
  EXPECT_TRUE(t.erase({0, 0, 0}));
  EXPECT_FALSE(t.erase({0, 0, 0}));
  EXPECT_LT(t.heap_bytes(), three);
  EXPECT_EQ(t.size(), 2u);
  EXPECT_TRUE(t.erase({-1, -1, -1}));
  EXPECT_TRUE(t.erase({-4, -4, -4}));
  EXPECT_TRUE(t.empty());
}

TEST(ChunkTable, AValueCostsItsOwnBytesNotASlotOfAHashTable) {
  // A replica's view: 6,000 chunks, side by side.
  ChunkTable<std::uint64_t> t;
  int n = 0;
  for (int y = 0; y < 12 && n < 6000; ++y)
    for (int z = -16; z < 16 && n < 6000; ++z)
      for (int x = -16; x < 16 && n < 6000; ++x, ++n) t[{x, y, z}] = 1;
  EXPECT_EQ(t.size(), 6000u);
  EXPECT_LT(t.heap_bytes(), 6000u * sizeof(std::uint64_t) * 3 / 2 + 64 * 1024);
}

}  // namespace
}  // namespace terrane
