#include "common/voxel/voxel.h"

#include <gtest/gtest.h>

#include "common/voxel/box.h"

namespace terrane {
namespace {

TEST(Voxel, AirNeverCarriesOccupancy) {
  for (int occ = 0; occ < 256; ++occ) {
    const Voxel v = make_voxel(kAir, static_cast<std::uint8_t>(occ));
    EXPECT_EQ(v.material, kAir);
    EXPECT_EQ(v.occupancy, 0) << "occupancy byte " << occ;
  }
}

TEST(Voxel, NonAirKeepsOccupancyForEveryMaterial) {
  for (int m = 1; m < kMaterialCount; ++m) {
    for (int occ = 0; occ < 256; occ += 17) {
      const Voxel v = make_voxel(static_cast<Material>(m), static_cast<std::uint8_t>(occ));
      EXPECT_EQ(v.material, m);
      EXPECT_EQ(v.occupancy, occ);
    }
  }
}

TEST(Voxel, OccupancyDecodesAsVPlusOneOver256) {
  EXPECT_FLOAT_EQ(occupancy_fraction(make_voxel(materials::kRock, 255)), 1.0f);
  EXPECT_FLOAT_EQ(occupancy_fraction(make_voxel(materials::kRock, 0)), 1.0f / 256.0f);
  EXPECT_FLOAT_EQ(occupancy_fraction(make_voxel(materials::kRock, 127)), 0.5f);
  EXPECT_FLOAT_EQ(occupancy_fraction(make_voxel(kAir, 200)), 0.0f);
  for (int b = 0; b < 256; ++b) {
    const Voxel v = make_voxel(materials::kSand, static_cast<std::uint8_t>(b));
    EXPECT_EQ(occupancy_byte(occupancy_fraction(v)), b) << "byte " << b << " does not round-trip";
  }
}

TEST(Voxel, DefaultOccupancyIsFullForSolidsAndZeroForAir) {
  EXPECT_EQ(default_occupancy(kAir), 0);
  EXPECT_EQ(default_occupancy(materials::kGrass), 255);
  EXPECT_TRUE(has_default_occupancy(solid(materials::kGrass)));
  EXPECT_FALSE(has_default_occupancy(make_voxel(materials::kGrass, 3)));
}

TEST(Box, SetEnforcesAirInvariant) {
  Box box({3, 2, 4});
  box.set(1, 1, 2, Voxel{kAir, 99});
  EXPECT_EQ(box.get(1, 1, 2), (Voxel{kAir, 0}));
}

TEST(Box, RowsAreContiguousAlongXInVxrawOrder) {
  Box box({5, 3, 4});
  box.set(2, 1, 3, solid(materials::kBrick));
  const Voxel* row = box.read_row(1, 3);
  EXPECT_EQ(row[2], solid(materials::kBrick));
  EXPECT_EQ(box.index(2, 1, 3), static_cast<std::size_t>((1 * 4 + 3) * 5 + 2));
}

}  // namespace
}  // namespace terrane
