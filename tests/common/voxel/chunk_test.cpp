#include "common/voxel/chunk.h"

#include "common/codec/net_codec.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <random>
#include <string>
#include <vector>

namespace terrane {
namespace {

using materials::kGrass;
using materials::kRock;
using materials::kSand;

TEST(Downsample, AllAirChildrenGiveAir) {
  const Voxel c[8] = {};
  EXPECT_EQ(downsample(c), Voxel{});
}

TEST(Downsample, OneSolidChildIsEnoughToBeNonAir) {
  Voxel c[8] = {};
  c[5] = make_voxel(kSand, 0);  // the smallest non-zero occupancy
  const Voxel v = downsample(c);
  EXPECT_EQ(v.material, kSand);
  EXPECT_EQ(v.occupancy, 0);  // mean 1/2048 is kept at the smallest non-zero value
}

TEST(Downsample, MostCommonMaterialWinsTiesToLowestId) {
  Voxel c[8] = {solid(kSand), solid(kSand), solid(kRock), solid(kRock), solid(kGrass), {}, {}, {}};
  EXPECT_EQ(downsample(c).material, kSand);  // Sand(6) and Rock(8) both twice, Grass once
  Voxel d[8] = {solid(kSand), solid(kSand), solid(kRock), solid(kRock), {}, {}, {}, {}};
  EXPECT_EQ(downsample(d).material, kSand);  // tie between Sand(6) and Rock(8): lowest id
}

TEST(Downsample, OccupancyIsMeanOfChildren) {
  Voxel c[8] = {solid(kRock), solid(kRock), solid(kRock), solid(kRock), {}, {}, {}, {}};
  // mean fraction = 4 * 1.0 / 8 = 0.5 -> byte 127 ((127 + 1) / 256 = 0.5).
  EXPECT_EQ(downsample(c), make_voxel(kRock, 127));
  Voxel full[8];
  for (auto& v : full) v = solid(kRock);
  EXPECT_EQ(downsample(full), solid(kRock));
}

// The rule as first written (a count per material): the fast version must
// agree with it on every input.
Voxel downsample_by_table(const Voxel children[8]) {
  std::array<std::uint8_t, kMaterialCount> counts{};
  int sum = 0, solid_children = 0;
  for (int i = 0; i < 8; ++i) {
    if (children[i].material == kAir) continue;
    ++counts[children[i].material];
    sum += children[i].occupancy + 1;
    ++solid_children;
  }
  if (solid_children == 0) return Voxel{};
  Material best = 1;
  for (int m = 2; m < kMaterialCount; ++m)
    if (counts[m] > counts[best]) best = static_cast<Material>(m);
  return make_voxel(best, static_cast<std::uint8_t>(std::clamp((sum + 4) / 8 - 1, 0, 255)));
}

TEST(Downsample, AgreesWithTheCountPerMaterialRuleOnRandomChildren) {
  std::mt19937 rng(11);
  // Few materials and occupancies so ties, equal children and Air are common.
  std::uniform_int_distribution<int> material(0, 4), occupancy(0, 3), wide(0, 63), byte(0, 255);
  for (int n = 0; n < 200000; ++n) {
    Voxel c[8];
    const bool narrow = n % 2 == 0;
    for (auto& v : c) {
      const int m = narrow ? material(rng) : wide(rng);
      const int o = narrow ? occupancy(rng) * 85 : byte(rng);
      v = m == 0 ? Voxel{} : make_voxel(static_cast<Material>(m), static_cast<std::uint8_t>(o));
    }
    if (n % 7 == 0)
      for (auto& v : c) v = c[0];  // all eight equal
    ASSERT_EQ(downsample(c), downsample_by_table(c)) << "case " << n;
  }
}

// Reference mip pyramid computed from a plain Box, voxel by voxel.
Box reference_mip(const Box& fine) { return downsample_box(fine); }

double matter(const Box& b) {
  double s = 0;
  for (const Voxel v : b.voxels()) s += occupancy_fraction(v);
  return s;
}

class ChunkMipTest : public ::testing::Test {
 protected:
  void check_mips(const char* when) {
    Box level0;
    chunk_.read_level(0, level0);
    Box expected = level0;
    const double matter0 = matter(level0);
    double tolerance = 0;
    for (int level = 1; level < kMipLevels; ++level) {
      expected = reference_mip(expected);
      Box actual;
      chunk_.read_level(level, actual);
      ASSERT_EQ(actual, expected) << "mip level " << level << " " << when;
      // Air guarantee: an Air mip voxel covers only Air at level 0.
      const int scale = 1 << level;
      for (int y = 0; y < 32 / scale; ++y)
        for (int z = 0; z < 32 / scale; ++z)
          for (int x = 0; x < 32 / scale; ++x) {
            if (actual.get(x, y, z).material != kAir) continue;
            for (int dy = 0; dy < scale; ++dy)
              for (int dz = 0; dz < scale; ++dz)
                for (int dx = 0; dx < scale; ++dx)
                  ASSERT_EQ(level0.get(x * scale + dx, y * scale + dy, z * scale + dz).material, kAir);
          }
      // Matter conserved up to quantization: each non-Air mip voxel may be off
      // by one byte step (1/256) of its volume, accumulating level by level.
      std::size_t non_air = 0;
      for (const Voxel v : actual.voxels()) non_air += v.material != kAir;
      const double volume = std::pow(8.0, level);
      tolerance += static_cast<double>(non_air) * volume / 256.0;
      EXPECT_NEAR(matter(actual) * volume, matter0, tolerance + 1e-6) << "level " << level << " " << when;
    }
    EXPECT_EQ(chunk_.empty(), matter0 == 0.0);
  }

  Chunk chunk_;
};

TEST_F(ChunkMipTest, MipsFollowTheRuleUnderRandomEdits) {
  std::mt19937 rng(99);
  std::uniform_int_distribution<int> c(0, 31), len(1, 12), mat(1, 12), occ(0, 255), kind(0, 3);
  for (int step = 0; step < 120; ++step) {
    const Vec3i lo{c(rng), c(rng), c(rng)};
    const Vec3i hi = min3(lo + Vec3i{len(rng), len(rng), len(rng)}, Vec3i{32, 32, 32});
    const int k = kind(rng);
    chunk_.modify(Region{lo, hi}, [&](Vec3i, Voxel old) -> Voxel {
      switch (k) {
        case 0: return Voxel{};
        case 1: return solid(static_cast<Material>(mat(rng)));
        case 2: return make_voxel(static_cast<Material>(mat(rng)), static_cast<std::uint8_t>(occ(rng)));
        default: return old.material == kAir ? solid(kRock) : Voxel{};
      }
    });
    check_mips("after random edit");
    if (HasFatalFailure()) return;
  }
}

TEST_F(ChunkMipTest, SingleVoxelMakesEveryLevelNonEmpty) {
  chunk_.set({31, 0, 17}, make_voxel(kSand, 3));
  EXPECT_FALSE(chunk_.empty());
  EXPECT_NE(chunk_.mip_get(3, 3, 0, 2).material, kAir);
  check_mips("one voxel");
  chunk_.set({31, 0, 17}, Voxel{});
  EXPECT_TRUE(chunk_.empty());
}

TEST_F(ChunkMipTest, UniformChunkHasUniformMips) {
  chunk_.fill(kRock);
  EXPECT_TRUE(chunk_.uniform());
  EXPECT_EQ(chunk_.mip_get(3, 0, 0, 0), solid(kRock));
  EXPECT_EQ(chunk_.memory().level0_bytes + chunk_.memory().mip_bytes, 0u);
  check_mips("uniform");
}

}  // namespace
}  // namespace terrane

namespace terrane {
namespace {
TEST(Chunk, EmptyAfterHeavyEditingThatUnpackedLevel0) {
  Chunk chunk;
  chunk.set({0, 0, 0}, solid(materials::kRock));  // keeps the chunk alive meanwhile
  for (int i = 0; i < 40; ++i) {
    chunk.set({5, 5, 5}, make_voxel(materials::kSand, static_cast<std::uint8_t>(i)));
    chunk.set({5, 5, 5}, Voxel{});
  }
  EXPECT_TRUE(chunk.level0().unpacked());
  chunk.set({0, 0, 0}, Voxel{});
  EXPECT_TRUE(chunk.empty());
}

TEST(Chunk, EditedEveryTickLikeTheWorldStrandStaysPacked) {
  // The world strand clones a chunk, edits it and packs its mips every tick:
  // each clone starts its own repack budget, so level 0 never unpacks.
  Box content({32, 32, 32});
  for (int y = 0; y < 32; ++y)
    for (int z = 0; z < 32; ++z)
      for (int x = 0; x < 32; ++x)
        content.set(x, y, z, y < 12 + (x + z) % 7 ? solid(materials::kRock) : Voxel{});
  Chunk current = Chunk::from_box(content);
  std::mt19937 rng(3);
  std::uniform_int_distribution<int> c(2, 29), occ(0, 255);
  for (int tick = 0; tick < 200; ++tick) {
    Chunk next = current.clone();
    const Vec3i at{c(rng), c(rng), c(rng)};
    next.modify(Region{at - Vec3i{2, 2, 2}, at + Vec3i{3, 3, 3}}, [&](Vec3i, Voxel old) {
      return old.material == kAir ? make_voxel(materials::kSand, static_cast<std::uint8_t>(occ(rng))) : Voxel{};
    });
    next.pack_mips();
    current = std::move(next);
    ASSERT_FALSE(current.level0().unpacked()) << "tick " << tick;
    ASSERT_TRUE(current.mips_packed());
  }
}

TEST(Chunk, MovedFromChunkIsEmptyAir) {
  Chunk a(materials::kRock);
  Chunk b(std::move(a));
  EXPECT_FALSE(b.empty());
  EXPECT_TRUE(a.empty());  // NOLINT(bugprone-use-after-move): documented state
  Box top;
  a.read_level(3, top);
  EXPECT_EQ(top.get(0, 0, 0), Voxel{});
}

TEST(Chunk, MipUnitsAreTheEncodingsOfTheLevels) {
  Chunk chunk(materials::kRock);
  for (int level = 1; level < kMipLevels; ++level) EXPECT_TRUE(chunk.mip_unit(level).empty());  // uniform: none kept
  chunk.modify(Region{{3, 4, 5}, {20, 9, 30}}, [](Vec3i p, Voxel) {
    return p.x % 3 ? Voxel{} : make_voxel(materials::kSand, static_cast<std::uint8_t>(p.z * 8));
  });
  // Written: the mips wait unpacked, readable, for pack_mips().
  EXPECT_FALSE(chunk.mips_packed());
  EXPECT_TRUE(chunk.mip_unit(1).empty());
  Box before[kMipLevels];
  for (int level = 1; level < kMipLevels; ++level) chunk.read_level(level, before[level]);
  chunk.pack_mips();
  EXPECT_TRUE(chunk.mips_packed());
  for (int level = 1; level < kMipLevels; ++level) {
    Box after;
    chunk.read_level(level, after);
    EXPECT_TRUE(before[level] == after) << "level " << level;
  }
  for (int level = 1; level < kMipLevels; ++level) {
    Box box;
    chunk.read_level(level, box);
    std::vector<std::uint8_t> expected;  // a chunk encodes its mips in version 1
    net_codec_encode(kChunkSize >> level, box.voxels(), expected, kNetCodecVersion1);
    const auto unit = chunk.mip_unit(level);
    EXPECT_EQ(std::vector<std::uint8_t>(unit.begin(), unit.end()), expected) << "level " << level;
  }
  const ChunkMemory m = chunk.memory();
  EXPECT_EQ(m.mip_bytes, chunk.mip_unit(1).size() + chunk.mip_unit(2).size() + chunk.mip_unit(3).size());
  // Back to uniform: the units go.
  chunk.fill(materials::kMud);
  EXPECT_TRUE(chunk.mip_unit(1).empty());
  EXPECT_EQ(chunk.memory().mip_bytes, 0u);
  Box top;
  chunk.read_level(3, top);
  EXPECT_EQ(top.get(1, 2, 3), solid(materials::kMud));
}

// Terrain with partial occupancies and several materials: every mip level
// differs from a plain downsample of one material.
Box derived_mips_terrain() {
  Box b({32, 32, 32});
  for (int y = 0; y < 32; ++y)
    for (int z = 0; z < 32; ++z)
      for (int x = 0; x < 32; ++x) {
        const int ground = 10 + (x * 3 + z * 5) % 9;
        if (y < ground - 3) b.set(x, y, z, solid(kRock));
        else if (y < ground) b.set(x, y, z, solid((x + z) % 3 == 0 ? kSand : kGrass));
        else if (y == ground) b.set(x, y, z, make_voxel(kGrass, static_cast<std::uint8_t>((x * 37 + z * 11) % 256)));
      }
  return b;
}

void expect_same_mips(const Chunk& a, const Chunk& b, const std::string& where) {
  EXPECT_EQ(a.empty(), b.empty()) << where;
  for (int level = 1; level < kMipLevels; ++level) {
    Box la, lb;
    a.read_level(level, la);
    b.read_level(level, lb);
    ASSERT_TRUE(la == lb) << where << " level " << level;
    const int n = kChunkSize >> level;
    EXPECT_EQ(a.mip_get(level, n - 1, n / 2, 1), b.mip_get(level, n - 1, n / 2, 1)) << where << " level " << level;
  }
}

TEST(ChunkDerivedMips, ReadAsTheKeptMipsAndHoldNone) {
  const Box content = derived_mips_terrain();
  const Chunk kept = Chunk::from_box(content);
  const Chunk derived = Chunk::from_box(content, Chunk::Mips::kDerived);
  EXPECT_EQ(kept.mips(), Chunk::Mips::kKept);
  EXPECT_EQ(derived.mips(), Chunk::Mips::kDerived);
  expect_same_mips(kept, derived, "from the box");
  EXPECT_GT(kept.memory().mip_bytes, 0u);
  EXPECT_EQ(derived.memory().mip_bytes, 0u);
  for (int level = 1; level < kMipLevels; ++level) {
    EXPECT_FALSE(kept.mip_unit(level).empty());
    EXPECT_TRUE(derived.mip_unit(level).empty());  // not stored: callers read the level
  }
}

TEST(ChunkDerivedMips, WritesKeepThemCurrentAndEmptyFollowsLevel0) {
  Chunk kept = Chunk::from_box(derived_mips_terrain());
  Chunk derived = Chunk::from_box(derived_mips_terrain(), Chunk::Mips::kDerived);
  std::mt19937 rng(7);
  std::uniform_int_distribution<int> c(0, 31), occ(0, 255);
  for (int edit = 0; edit < 40; ++edit) {
    const Vec3i at{c(rng), c(rng), c(rng)};
    const auto v = make_voxel(edit % 2 == 0 ? kSand : kRock, static_cast<std::uint8_t>(occ(rng)));
    auto fn = [&](Vec3i, Voxel old) { return old.material == kAir ? v : Voxel{}; };
    kept.modify(Region{at - Vec3i{2, 2, 2}, at + Vec3i{3, 3, 3}}, fn);
    derived.modify(Region{at - Vec3i{2, 2, 2}, at + Vec3i{3, 3, 3}}, fn);
    kept.pack_mips();
    derived.pack_mips();
    expect_same_mips(kept, derived, "edit " + std::to_string(edit));
    ASSERT_EQ(derived.mips(), Chunk::Mips::kDerived);
  }
  // A clone and a move keep the choice.
  Chunk copy = derived.clone();
  EXPECT_EQ(copy.mips(), Chunk::Mips::kDerived);
  expect_same_mips(kept, copy, "clone");
  Chunk moved(std::move(copy));
  EXPECT_EQ(moved.mips(), Chunk::Mips::kDerived);
  expect_same_mips(kept, moved, "moved");
  // Everything Air: empty, as level 0 says.
  auto air = [](Vec3i, Voxel) { return Voxel{}; };
  derived.modify(Region{{0, 0, 0}, {32, 32, 32}}, air);
  kept.modify(Region{{0, 0, 0}, {32, 32, 32}}, air);
  EXPECT_TRUE(derived.empty());
  expect_same_mips(kept, derived, "all Air");
  // One voxel of the smallest occupancy makes it non-empty again.
  derived.set({5, 6, 7}, make_voxel(kSand, 0));
  kept.set({5, 6, 7}, make_voxel(kSand, 0));
  EXPECT_FALSE(derived.empty());
  expect_same_mips(kept, derived, "one voxel");
}

TEST(ChunkDerivedMips, ImageHoldsTheMipsAsAKeptChunkWritesThem) {
  const Chunk kept = Chunk::from_box(derived_mips_terrain());
  const Chunk derived = Chunk::from_box(derived_mips_terrain(), Chunk::Mips::kDerived);
  std::vector<std::uint8_t> a, b;
  ASSERT_TRUE(kept.write_image(a));
  ASSERT_TRUE(derived.write_image(b));
  EXPECT_EQ(a, b);
  std::size_t pos = 0;
  auto read = Chunk::read_image(b, pos);
  ASSERT_TRUE(read.ok());
  EXPECT_EQ(read->mips(), Chunk::Mips::kKept);
  expect_same_mips(kept, *read, "read back");
}
}  // namespace
}  // namespace terrane
