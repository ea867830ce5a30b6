#include "common/world/terrain_shading.h"

#include <gtest/gtest.h>

#include <array>
#include <cstdint>

#include "common/world/terrain_field.h"

namespace terrane {
namespace {

namespace m = materials;

constexpr int kF = TerrainField::kFieldCount;
using Corners = std::array<float, kF * 8>;

// Lattice corners with each field constant: overhang, worm a, worm b, cavern.
Corners uniform_corners(float overhang, float worm_a, float worm_b, float cavern) {
  Corners c{};
  const float v[kF] = {overhang, worm_a, worm_b, cavern};
  for (int f = 0; f < kF; ++f)
    for (int i = 0; i < 8; ++i) c[static_cast<std::size_t>(f * 8 + i)] = v[f];
  return c;
}
// No overhang, worms far from a tube, caverns below their threshold: solid.
const Corners kNoCave = uniform_corners(0.0f, 1.0f, 1.0f, -1.0f);

// A flat column at `height` with open water up to `water_level`.
TerrainField::Surface flat(float height, std::int32_t water_level) {
  TerrainField::Surface s;
  s.height = height;
  s.cont = 0.5f;
  s.water_level = water_level;
  return s;
}

TerrainShading::Column column_at(const TerrainField& field, const TerrainShading& shading, std::int32_t x,
                                 std::int32_t z) {
  return shading.column(field.surface(x, z), field.surface(x - 1, z).height, field.surface(x + 1, z).height,
                        field.surface(x, z - 1).height, field.surface(x, z + 1).height);
}

// Above a column's band everything is Air, except open water below the
// water level (Ice on its top voxel where the column is cold).
TEST(TerrainShading, AirAboveTheSurfaceWaterBelowTheWaterLevel) {
  const TerrainField field(GeneratorParams{});
  const TerrainShading shading(field);
  int water = 0, air = 0;
  for (std::int32_t z = -400; z < 400; z += 13) {
    for (std::int32_t x = -400; x < 400; x += 11) {
      const TerrainShading::Column col = column_at(field, shading, x, z);
      ASSERT_GE(static_cast<float>(col.top_y), col.height);
      for (std::int32_t y = col.top_y; y < col.top_y + 48; ++y) {
        const Voxel v = shading.shade(col, x, y, z, nullptr);
        if (y < col.water_level) {
          const bool ice = col.cold && y == col.water_level - 1;
          EXPECT_EQ(v, solid(ice ? m::kIce : m::kWater)) << x << "," << y << "," << z;
          ++water;
        } else {
          EXPECT_EQ(v, Voxel{}) << x << "," << y << "," << z;
          ++air;
        }
      }
    }
  }
  EXPECT_GT(water, 1000);
  EXPECT_GT(air, 10000);
}

// Without caves, everything from the bedrock up to the band's bottom is
// fully solid terrain, and below the bedrock line it is Basalt.
TEST(TerrainShading, SolidBelowTheSurfaceWithoutCaves) {
  GeneratorParams p;
  p.caves = false;
  const TerrainField field(p);
  const TerrainShading shading(field);
  for (std::int32_t z = -300; z < 300; z += 29) {
    for (std::int32_t x = -300; x < 300; x += 31) {
      const TerrainShading::Column col = column_at(field, shading, x, z);
      ASSERT_GT(col.lattice_lo, col.bot_y);  // no lattice read below the band
      for (std::int32_t y = TerrainShading::kBedrockY - 8; y <= col.bot_y; ++y) {
        const Voxel v = shading.shade(col, x, y, z, nullptr);
        EXPECT_NE(v.material, kAir) << x << "," << y << "," << z;
        EXPECT_EQ(v.occupancy, kFullOccupancy) << x << "," << y << "," << z;
        if (y < TerrainShading::kBedrockY) {
          EXPECT_EQ(v, solid(m::kBasalt));
        }
      }
    }
  }
}

// A flat plain: subsoil, then topsoil, then one partial voxel where the
// density crosses zero, then Air; a coarse cell's wider ramp (sharpness
// below 1) reaches further.
TEST(TerrainShading, FlatPlainHasSoilAndARampAcrossTheSurface) {
  const TerrainField field(GeneratorParams{});
  const TerrainShading shading(field);
  const TerrainShading::Column col = shading.column(flat(50.0f, 32), 50.0f, 50.0f, 50.0f, 50.0f);
  EXPECT_EQ(col.biome, Biome::kPlains);
  EXPECT_EQ(col.slope, 0.0f);
  const auto at = [&](std::int32_t y, float sharpness = 1.0f) {
    return shading.shade(col, 0, y, 0, kNoCave.data(), sharpness);
  };
  EXPECT_EQ(at(47), solid(m::kGround));
  EXPECT_EQ(at(49), solid(m::kGrass));
  EXPECT_EQ(at(50).material, m::kGrass);
  EXPECT_GT(at(50).occupancy, 100);
  EXPECT_LT(at(50).occupancy, 160);
  EXPECT_EQ(at(51), Voxel{});
  const Voxel wide = at(51, 0.25f);
  EXPECT_EQ(wide.material, m::kGrass);
  EXPECT_GT(wide.occupancy, 0);
  EXPECT_LT(wide.occupancy, at(50).occupancy);
}

// A sea floor: Ocean, water from the floor up to the level, Ice on top when
// the column is cold.
TEST(TerrainShading, SeaFloorIsOceanUnderWater) {
  const TerrainField field(GeneratorParams{});
  const TerrainShading shading(field);
  TerrainField::Surface s = flat(20.0f, 32);
  for (const bool cold : {false, true}) {
    s.temperature = cold ? -1.0f : 0.0f;
    const TerrainShading::Column col = shading.column(s, 20.0f, 20.0f, 20.0f, 20.0f);
    EXPECT_EQ(col.biome, Biome::kOcean);
    EXPECT_EQ(col.cold, cold);
    EXPECT_NE(shading.shade(col, 0, 19, 0, kNoCave.data()).material, kAir);
    for (std::int32_t y = 21; y < 31; ++y) EXPECT_EQ(shading.shade(col, 0, y, 0, kNoCave.data()), solid(m::kWater));
    EXPECT_EQ(shading.shade(col, 0, 31, 0, kNoCave.data()), solid(cold ? m::kIce : m::kWater));
    EXPECT_EQ(shading.shade(col, 0, 32, 0, kNoCave.data()), Voxel{});
  }
}

// Where both worm fields are zero, deep underground, a cave is carved: Air,
// or CrackedLava below the lava line. Far from a tube the rock stays.
TEST(TerrainShading, CavesCarveWhereTheWormsMeet) {
  const TerrainField field(GeneratorParams{});
  const TerrainShading shading(field);
  TerrainField::Surface s = flat(50.0f, 32);
  s.cave_amount = 1.0f;  // the widest worms
  const TerrainShading::Column col = shading.column(s, 50.0f, 50.0f, 50.0f, 50.0f);
  const Corners tube = uniform_corners(0.0f, 0.0f, 0.0f, -1.0f);
  EXPECT_EQ(shading.shade(col, 0, -20, 0, tube.data()), Voxel{});
  EXPECT_EQ(shading.shade(col, 0, TerrainShading::kLavaY - 1, 0, tube.data()), solid(m::kCrackedLava));
  EXPECT_NE(shading.shade(col, 0, -20, 0, kNoCave.data()).material, kAir);
  // Near the surface the caves fade out (no entrance here).
  EXPECT_NE(shading.shade(col, 0, 47, 0, tube.data()).material, kAir);

  GeneratorParams p;
  p.caves = false;
  const TerrainField solid_field(p);
  const TerrainShading no_caves(solid_field);
  const TerrainShading::Column solid_col = no_caves.column(s, 50.0f, 50.0f, 50.0f, 50.0f);
  EXPECT_EQ(no_caves.shade(solid_col, 0, -20, 0, tube.data()).occupancy, kFullOccupancy);
}

// Rock strata are bands in y, the same in every column with the same warp,
// so layers line up across canyon walls.
TEST(TerrainShading, StrataLineUpAcrossColumns) {
  const TerrainField field(GeneratorParams{});
  const TerrainShading shading(field);
  const TerrainShading::Column low = shading.column(flat(60.0f, 32), 60.0f, 60.0f, 60.0f, 60.0f);
  const TerrainShading::Column high = shading.column(flat(90.0f, 32), 90.0f, 90.0f, 90.0f, 90.0f);
  int kinds = 0;
  Material last = kAir;
  for (std::int32_t y = -30; y < 40; ++y) {
    const Voxel a = shading.shade(low, 3, y, 7, kNoCave.data());
    EXPECT_EQ(a, shading.shade(high, -90, y, 1000, kNoCave.data())) << "y " << y;
    kinds += a.material != last;
    last = a.material;
  }
  EXPECT_GT(kinds, 3);
}

}  // namespace
}  // namespace terrane
