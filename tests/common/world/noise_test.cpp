#include "common/world/noise.h"

#include <gtest/gtest.h>

#include <cmath>
#include <set>

namespace terrane {
namespace {

TEST(Noise, HashesArePureAndSeedDependent) {
  EXPECT_EQ(hash3(1, 2, 3, 7), hash3(1, 2, 3, 7));
  EXPECT_NE(hash3(1, 2, 3, 7), hash3(1, 2, 3, 8));
  EXPECT_NE(hash3(1, 2, 3, 7), hash3(3, 2, 1, 7));
  EXPECT_NE(hash2(-1, 0, 7), hash2(0, -1, 7));
  // Pinned values: these feed every generated world, so they must never change
  // without bumping kGeneratorVersion.
  EXPECT_EQ(hash_u32(0), 0u);
  EXPECT_EQ(hash_u32(1), 0x688990C0u) << std::hex << hash_u32(1);
  EXPECT_EQ(derive_seed(1, 0), derive_seed(1, 0));
  std::set<std::uint32_t> seeds;
  for (std::uint32_t i = 0; i < 64; ++i) seeds.insert(derive_seed(1, i));
  EXPECT_EQ(seeds.size(), 64u);
}

TEST(Noise, HashUnitIsInUnitInterval) {
  for (std::uint32_t i = 0; i < 10000; ++i) {
    const float u = hash_unit(hash_u32(i));
    EXPECT_GE(u, 0.0f);
    EXPECT_LT(u, 1.0f);
  }
}

TEST(Noise, GradientNoiseIsZeroOnLatticePoints) {
  for (int i = -5; i <= 5; ++i) {
    EXPECT_EQ(gradient_noise2(i, -i * 3, 11), 0.0f);
    EXPECT_EQ(gradient_noise3(i, 2 * i, -i, 11), 0.0f);
  }
}

TEST(Noise, ValuesStayInRangeAndVary) {
  float lo2 = 0, hi2 = 0, lo3 = 0, hi3 = 0;
  for (int i = 0; i < 20000; ++i) {
    const double x = (i % 173) * 0.173 - 11.0, y = (i / 173) * 0.291 - 7.5, z = i * 0.0137 - 40.0;
    const float n2 = gradient_noise2(x, z, 5), n3 = gradient_noise3(x, y, z, 5);
    lo2 = std::min(lo2, n2), hi2 = std::max(hi2, n2);
    lo3 = std::min(lo3, n3), hi3 = std::max(hi3, n3);
    const float f = fbm2(x, z, 9, 4), g = fbm3(x, y, z, 9, 3), r = ridged2(x, z, 9, 5);
    ASSERT_GE(f, -1.0f);
    ASSERT_LE(f, 1.0f);
    ASSERT_GE(g, -1.1f);
    ASSERT_LE(g, 1.1f);
    ASSERT_GE(r, 0.0f);
    ASSERT_LE(r, 1.0f);
  }
  EXPECT_GE(lo2, -1.0f);
  EXPECT_LE(hi2, 1.0f);
  EXPECT_GE(lo3, -1.1f);
  EXPECT_LE(hi3, 1.1f);
  // Not degenerate: both signs with a useful amplitude.
  EXPECT_LT(lo2, -0.4f);
  EXPECT_GT(hi2, 0.4f);
  EXPECT_LT(lo3, -0.4f);
  EXPECT_GT(hi3, 0.4f);
}

TEST(Noise, IsContinuous) {
  // Gradient noise is Lipschitz: a step of 1e-3 cells moves it by well under 0.01.
  for (int i = 0; i < 2000; ++i) {
    const double x = i * 0.0371 - 20.0, z = i * 0.0193 + 3.0;
    EXPECT_LT(std::fabs(gradient_noise2(x + 1e-3, z, 3) - gradient_noise2(x, z, 3)), 0.01f);
    EXPECT_LT(std::fabs(gradient_noise3(x, z, x + 1e-3, 3) - gradient_noise3(x, z, x, 3)), 0.01f);
  }
}

TEST(Noise, NegativeAndFarCoordinatesWork) {
  // Cells wrap modulo 2^32 but nothing misbehaves far from the origin.
  const float a = gradient_noise2(-1.0e9 + 0.5, 3.25, 1);
  const float b = gradient_noise3(4.0e9 + 0.25, -2.5e9 + 0.5, 0.75, 1);
  EXPECT_TRUE(std::isfinite(a));
  EXPECT_TRUE(std::isfinite(b));
  EXPECT_LE(std::fabs(a), 1.0f);
  EXPECT_LE(std::fabs(b), 1.1f);
}

TEST(Noise, SeedsGiveDifferentPatterns) {
  int differ = 0;
  for (int i = 0; i < 100; ++i) {
    if (gradient_noise2(i * 0.37 + 0.1, i * 0.11 + 0.2, 1) != gradient_noise2(i * 0.37 + 0.1, i * 0.11 + 0.2, 2)) {
      ++differ;
    }
  }
  EXPECT_GT(differ, 90);
}

TEST(Noise, SmoothstepAndClamp) {
  EXPECT_EQ(smoothstep(0.0f, 1.0f, -1.0f), 0.0f);
  EXPECT_EQ(smoothstep(0.0f, 1.0f, 2.0f), 1.0f);
  EXPECT_FLOAT_EQ(smoothstep(0.0f, 1.0f, 0.5f), 0.5f);
  EXPECT_EQ(smoothstep(1.0f, 0.0f, 2.0f), 0.0f);  // reversed edges fall
  EXPECT_EQ(clampf(3.0f, -1.0f, 1.0f), 1.0f);
  EXPECT_EQ(clampf(-3.0f, -1.0f, 1.0f), -1.0f);
}

}  // namespace
}  // namespace terrane
