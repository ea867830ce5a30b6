#include "common/world/terrain_field.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>

namespace terrane {
namespace {

constexpr int kF = TerrainField::kFieldCount;

std::uint32_t bits(float v) {
  std::uint32_t b = 0;
  std::memcpy(&b, &v, sizeof b);
  return b;
}

bool same_surface(const TerrainField::Surface& a, const TerrainField::Surface& b) {
  const float fa[] = {a.height, a.cont, a.mountain, a.highland, a.desert, a.swamp, a.lake,
                      a.temperature, a.humidity, a.strata_warp, a.entrance, a.cave_amount};
  const float fb[] = {b.height, b.cont, b.mountain, b.highland, b.desert, b.swamp, b.lake,
                      b.temperature, b.humidity, b.strata_warp, b.entrance, b.cave_amount};
  for (std::size_t i = 0; i < std::size(fa); ++i)
    if (bits(fa[i]) != bits(fb[i])) return false;
  return a.water_level == b.water_level;
}

TEST(TerrainField, SameSeedGivesTheSameBits) {
  GeneratorParams p;
  p.seed = 1234;
  const TerrainField a(p), b(p);
  const TerrainField copy = a;
  for (int i = 0; i < 200; ++i) {
    const std::int32_t x = i * 131 - 9000, z = i * 71 - 4000;
    EXPECT_TRUE(same_surface(a.surface(x, z), b.surface(x, z))) << x << "," << z;
    EXPECT_TRUE(same_surface(a.surface(x, z), copy.surface(x, z))) << x << "," << z;
    float fa[kF], fb[kF];
    a.fields_at(x * 0.37, i * 1.5 - 100.0, z * 0.91, fa);
    b.fields_at(x * 0.37, i * 1.5 - 100.0, z * 0.91, fb);
    for (int f = 0; f < kF; ++f) EXPECT_EQ(bits(fa[f]), bits(fb[f]));
  }
  EXPECT_EQ(a.strata_seed(), b.strata_seed());
}

TEST(TerrainField, OtherSeedGivesOtherTerrain) {
  GeneratorParams p;
  const TerrainField a(p);
  p.seed = 2;
  const TerrainField b(p);
  int differ = 0;
  for (int i = 0; i < 100; ++i) differ += a.surface(i * 97, i * 53).height != b.surface(i * 97, i * 53).height;
  EXPECT_GT(differ, 95);
  EXPECT_NE(a.strata_seed(), b.strata_seed());
}

// The height is a continuous function of the scaled position: sampled 8
// times finer (terrain_scale 8), neighbouring columns differ by a few
// voxels at most, where at scale 1 the steepest canyon walls and ridges
// step by tens of voxels. A jump (a feature cut off at a cell's edge) would
// stay as large at any scale.
TEST(TerrainField, HeightIsContinuous) {
  auto max_step = [](float scale, float& range) {
    GeneratorParams p;
    p.terrain_scale = scale;
    const TerrainField field(p);
    float steepest = 0.0f, lo = 1e9f, hi = -1e9f;
    for (std::int32_t z = -3000; z < 3000; z += 97) {
      float prev = field.surface(-3000, z).height;
      for (std::int32_t x = -2999; x < 3000; ++x) {
        const float h = field.surface(x, z).height;
        EXPECT_TRUE(std::isfinite(h));
        steepest = std::max(steepest, std::abs(h - prev));
        lo = std::min(lo, h);
        hi = std::max(hi, h);
        prev = h;
      }
    }
    range = hi - lo;
    return steepest;
  };
  float range_fine = 0.0f, range_coarse = 0.0f;
  const float fine = max_step(8.0f, range_fine);
  const float coarse = max_step(1.0f, range_coarse);
  EXPECT_GT(range_fine, 60.0f);  // varied terrain, not a flat plain
  EXPECT_GT(range_coarse, 60.0f);
  EXPECT_LT(fine, 10.0f);
  EXPECT_GT(coarse, 4.0f * fine);
}

// The 3D fields are smooth and bounded: a hundredth of a voxel moves each by
// little; lattice_sample() is fields_at() on the lattice.
TEST(TerrainField, ThreeDFieldsAreContinuousAndBounded) {
  const TerrainField field(GeneratorParams{});
  for (int i = 0; i < 2000; ++i) {
    const double x = i * 3.7 - 2000.0, y = i * 0.3 - 300.0, z = i * 5.3 - 4000.0;
    float a[kF], b[kF];
    field.fields_at(x, y, z, a);
    field.fields_at(x + 0.01, y + 0.01, z + 0.01, b);
    for (int f = 0; f < kF; ++f) {
      EXPECT_LT(std::abs(a[f] - b[f]), 0.02f) << "field " << f << " at " << x << "," << y << "," << z;
      EXPECT_LE(std::abs(a[f]), 1.5f) << "field " << f;
    }
    EXPECT_LE(std::abs(a[0]), 1.0f);  // the overhang is clamped
  }
  const std::int32_t step = TerrainField::kLatticeStep;
  for (std::int32_t l = -20; l < 20; ++l) {
    float a[kF], b[kF];
    field.lattice_sample(l * 3, l, -l * 5, a);
    field.fields_at(l * 3 * step, l * step, -l * 5 * step, b);
    for (int f = 0; f < kF; ++f) EXPECT_EQ(bits(a[f]), bits(b[f]));
  }
}

TEST(TerrainField, CaveFieldsAreZeroWithoutCaves) {
  GeneratorParams p;
  p.caves = false;
  const TerrainField field(p);
  for (int i = 0; i < 100; ++i) {
    float v[kF];
    field.fields_at(i * 7.5, i - 50.0, i * -3.25, v);
    EXPECT_EQ(v[1], 0.0f);
    EXPECT_EQ(v[2], 0.0f);
    EXPECT_EQ(v[3], 0.0f);
    field.fields_at(i * 7.5, i - 50.0, i * -3.25, v, /*overhang=*/false);
    EXPECT_EQ(v[0], 0.0f);
    const TerrainField::Surface s = field.surface(i * 31, i * 17);
    EXPECT_EQ(s.entrance, 0.0f);
    EXPECT_EQ(s.cave_amount, 0.0f);
  }
}

// Open water is the sea's, except in lakes: a lake's columns lie in a bowl
// no higher than two voxels above its level (its shore), deepest well below
// it, and the level is above the sea.
TEST(TerrainField, LakesHoldWaterAboveTheSea) {
  const TerrainField field(GeneratorParams{});
  int lake_columns = 0;
  float deepest = 0.0f;  // below the lake's level
  for (std::int32_t z = -1024; z < 1024; z += 4) {
    for (std::int32_t x = -1024; x < 1024; x += 4) {
      const TerrainField::Surface s = field.surface(x, z);
      if (s.water_level == field.params().sea_level) continue;
      ++lake_columns;
      EXPECT_GT(s.water_level, field.params().sea_level);
      EXPECT_LE(s.height, static_cast<float>(s.water_level) + 2.0f);
      EXPECT_GT(s.lake, 0.0f);
      deepest = std::max(deepest, static_cast<float>(s.water_level) - s.height);
    }
  }
  EXPECT_GT(lake_columns, 50);
  EXPECT_GT(deepest, 4.0f);
}

TEST(TerrainField, ParamsAreClamped) {
  GeneratorParams p;
  p.terrain_scale = 100.0f;
  p.sea_level = 9000;
  const TerrainField field(p);
  EXPECT_EQ(validate(field.params()), "");
  EXPECT_EQ(field.params(), clamped(p));
  EXPECT_TRUE(std::isfinite(field.surface(5, 5).height));
}

}  // namespace
}  // namespace terrane
