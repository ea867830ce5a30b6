#include "common/enhance/lighting.h"

#include <gtest/gtest.h>

#include <cstdint>

#include "common/enhance/enhance.h"

namespace terrane {
namespace {

namespace m = materials;

void fill(Box& box, const Region& r, Voxel v) {
  for (int y = r.min.y; y < r.max.y; ++y)
    for (int z = r.min.z; z < r.max.z; ++z)
      for (int x = r.min.x; x < r.max.x; ++x) box.set(x, y, z, v);
}

LightingParams quick_params() {
  LightingParams p;
  p.sun_direction = {1.0f, 1.0f, 0.0f};  // sun towards +x, 45 degrees up
  p.sun_particles = 24;
  p.sky_particles = 24;
  p.steps = 16;
  return p;
}

TEST(Lighting, ValidateNamesTheBadField) {
  EXPECT_TRUE(validate(LightingParams{}).empty());
  LightingParams p;
  p.sun_direction = {0, 0, 0};
  EXPECT_NE(validate(p).find("sun_direction"), std::string::npos);
  p = {};
  p.steps = 0;
  EXPECT_NE(validate(p).find("steps"), std::string::npos);
  p = {};
  p.sky_particles = 0;
  EXPECT_NE(validate(p).find("sky_particles"), std::string::npos);
  p = {};
  p.follow = 1.5f;
  EXPECT_NE(validate(p).find("follow"), std::string::npos);
}

TEST(Lighting, OnlySurfaceFragmentsAreLit) {
  Box box({12, 12, 12});
  fill(box, {{0, 0, 0}, {12, 6, 12}}, solid(m::kRock));
  EXPECT_TRUE(is_surface_fragment(box, {5, 5, 5}));
  EXPECT_FALSE(is_surface_fragment(box, {5, 4, 5}));
  EXPECT_FALSE(is_surface_fragment(box, {5, 6, 5}));
  EXPECT_TRUE(is_surface_fragment(box, {0, 2, 5}));  // the box side is open
  const LightMap map = compute_lighting(box, {0, 0, 0}, quick_params());
  EXPECT_EQ(map.at({5, 4, 5}), 0);
  EXPECT_EQ(map.at({5, 8, 5}), 0);
  EXPECT_GT(map.at({5, 5, 5}), 64);
}

TEST(Lighting, OpenGroundIsEvenlyLit) {
  Box box({16, 8, 16});
  fill(box, {{0, 0, 0}, {16, 3, 16}}, solid(m::kGround));
  const Vec3i origin{-8, 40, -8};
  const LightMap map = compute_lighting(box, origin, quick_params());
  // Same geometry everywhere away from the sides: similar light.
  const int a = map.at(origin + Vec3i{5, 2, 5});
  const int b = map.at(origin + Vec3i{10, 2, 9});
  EXPECT_NEAR(a, b, 40);
  // All sunlight escapes bar early downward jitter; about half the sky.
  EXPECT_GT(a, 150);
}

TEST(Lighting, CaveIsDarkerThanOpenGround) {
  // A solid block with a chamber inside, reached by a narrow tunnel from the
  // -x side.
  Box box({40, 24, 40});
  fill(box, {{0, 0, 0}, {40, 16, 40}}, solid(m::kRock));
  fill(box, {{14, 4, 14}, {26, 9, 26}}, Voxel{kAir, 0});  // chamber
  fill(box, {{0, 4, 19}, {14, 6, 21}}, Voxel{kAir, 0});   // tunnel
  const LightingParams p = quick_params();
  const LightMap map = compute_lighting(box, {0, 0, 0}, p);
  const int cave_floor = map.at({22, 3, 22});
  const int open_ground = map.at({22, 15, 22});
  EXPECT_TRUE(is_surface_fragment(box, {22, 3, 22}));
  EXPECT_LT(cave_floor, open_ground / 4);
  EXPECT_GT(open_ground, 100);
}

TEST(Lighting, TowerCastsAShadowAwayFromTheSun) {
  Box box({48, 32, 24});
  fill(box, {{0, 0, 0}, {48, 4, 24}}, solid(m::kGround));
  fill(box, {{22, 4, 10}, {26, 28, 14}}, solid(m::kBrick));  // the tower
  const LightMap map = compute_lighting(box, {0, 0, 0}, quick_params());
  // The sun is towards +x: the shadow falls on the -x side.
  const int shadow = map.at({18, 3, 12});
  const int sunny = map.at({30, 3, 12});
  EXPECT_LT(shadow + 40, sunny);
  // Far from the tower both sides are lit alike.
  EXPECT_NEAR(map.at({2, 3, 12}), map.at({45, 3, 12}), 50);
}

TEST(Lighting, DeterministicAndRelightEqualsFullRecomputation) {
  Box box({24, 20, 24});
  fill(box, {{0, 0, 0}, {24, 5, 24}}, solid(m::kGround));
  fill(box, {{6, 5, 6}, {10, 12, 9}}, solid(m::kRock));
  const Vec3i origin{-30, 7, 11};
  const LightingParams p = quick_params();
  LightMap map = compute_lighting(box, origin, p);
  EXPECT_EQ(map.light, compute_lighting(box, origin, p).light);
  // Add a block on the ground and relight only what it can affect.
  const Region edit_local{{15, 5, 15}, {18, 9, 17}};
  fill(box, edit_local, solid(m::kBrick));
  const Region changed{origin + edit_local.min, origin + edit_local.max};
  const Region r = relight(box, origin, p, changed, map);
  EXPECT_EQ(r, intersect(lighting_affected_region(changed, p), map.region));
  EXPECT_EQ(map.light, compute_lighting(box, origin, p).light);
}

TEST(Lighting, DifferentSeedsGiveDifferentNoise) {
  Box box({16, 10, 16});
  fill(box, {{0, 0, 0}, {16, 3, 16}}, solid(m::kGround));
  fill(box, {{6, 3, 6}, {9, 8, 9}}, solid(m::kRock));
  LightingParams p = quick_params();
  const LightMap a = compute_lighting(box, {0, 0, 0}, p);
  p.seed = 2;
  EXPECT_NE(a.light, compute_lighting(box, {0, 0, 0}, p).light);
}

TEST(Lighting, WorksOnEnhancedFragments) {
  Box coarse({6, 6, 6});
  fill(coarse, {{0, 0, 0}, {6, 2, 6}}, solid(m::kGround));
  coarse.set(2, 2, 2, solid(m::kRock));
  const Box fine = subdivide(coarse, {0, 0, 0}, SubdivisionParams{2, SubdivisionThreshold::constant(2)});
  const LightMap map = compute_lighting(fine, {0, 0, 0}, quick_params());
  std::uint64_t lit = 0, surface = 0;
  for (int y = 0; y < 24; ++y)
    for (int z = 0; z < 24; ++z)
      for (int x = 0; x < 24; ++x) {
        surface += is_surface_fragment(fine, {x, y, z});
        lit += map.at({x, y, z}) > 0;
      }
  // The box sides count as open here, not in count_surface().
  EXPECT_GE(surface, count_surface(fine));
  EXPECT_GT(lit, surface * 9 / 10);
}

// Pins the light of version 1: a change here needs a kEnhanceVersion bump.
TEST(LightingGolden, Version1Output) {
  Box box({16, 12, 16});
  fill(box, {{0, 0, 0}, {16, 3, 16}}, solid(m::kGround));
  fill(box, {{6, 3, 6}, {9, 9, 9}}, solid(m::kRock));
  const LightMap map = compute_lighting(box, {-3, 5, 2}, quick_params());
  std::uint64_t h = 0xCBF29CE484222325ull;
  for (const std::uint8_t v : map.light) {
    h ^= v;
    h *= 0x100000001B3ull;
  }
  EXPECT_EQ(h, 0x4d0c545ceffae3dull) << std::hex << h;
}

// A coarse edit: re-enhance what it affects, relight what that affects; the
// result equals enhancing and lighting from scratch.
TEST(Lighting, CoarseEditPipelineEqualsFullRecomputation) {
  Box coarse({8, 8, 8});
  fill(coarse, {{0, 0, 0}, {8, 3, 8}}, solid(m::kGround));
  const Vec3i origin{2, -1, -5};
  const SubdivisionParams sub{2, SubdivisionThreshold::constant(2)};
  LightingParams p = quick_params();
  p.steps = 8;
  Box fine = subdivide(coarse, origin, sub);
  const Vec3i fine_origin = origin * 4;
  LightMap map = compute_lighting(fine, fine_origin, p);
  coarse.set(4, 3, 4, solid(m::kRock));
  const Region changed =
      subdivide_update(coarse, origin, sub, Region::from_min_size(origin + Vec3i{4, 3, 4}, {1, 1, 1}), fine);
  relight(fine, fine_origin, p, changed, map);
  const Box full = subdivide(coarse, origin, sub);
  ASSERT_EQ(fine, full);
  EXPECT_EQ(map.light, compute_lighting(full, fine_origin, p).light);
}

}  // namespace
}  // namespace terrane
