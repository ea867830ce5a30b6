#include "common/enhance/enhance.h"

#include <gtest/gtest.h>

#include <string>
#include <cstdint>
#include <cstdlib>
#include <vector>

#include "common/world/noise.h"
#include "common/world/terrain_generator.h"

namespace terrane {
namespace {

namespace m = materials;

// A terrain-like coarse map: thresholded 3D gradient noise over a vertical
// gradient (solid below about half height), as in the paper's figures.
Box perlin_box(Vec3i size, Vec3i origin, std::uint32_t seed) {
  Box box(size);
  for (int y = 0; y < size.y; ++y)
    for (int z = 0; z < size.z; ++z)
      for (int x = 0; x < size.x; ++x) {
        const Vec3i p = origin + Vec3i{x, y, z};
        const float n = gradient_noise3(p.x / 5.0, p.y / 5.0, p.z / 5.0, seed);
        const float gradient =
            (static_cast<float>(origin.y) + static_cast<float>(size.y) * 0.5f - static_cast<float>(p.y)) /
            static_cast<float>(size.y);
        if (n * 2.0f + gradient > 0.0f) box.set(x, y, z, solid(y < size.y / 3 ? m::kRock : m::kGround));
      }
  return box;
}

double solid_share(const Box& box) {
  return static_cast<double>(count_solid(box)) / static_cast<double>(box.voxel_count());
}

// The part of `whole` (covering whole_region) inside `r`.
Box slice(const Box& whole, const Region& whole_region, const Region& r) {
  Box out(r.size());
  for (int y = r.min.y; y < r.max.y; ++y)
    for (int z = r.min.z; z < r.max.z; ++z)
      for (int x = r.min.x; x < r.max.x; ++x)
        out.set(x - r.min.x, y - r.min.y, z - r.min.z,
                whole.get(x - whole_region.min.x, y - whole_region.min.y, z - whole_region.min.z));
  return out;
}

bool fine_solid(const Box& fine, int x, int y, int z) { return enhance_solid(fine.get(x, y, z)); }

// Highest solid y of column (x, z), or -1.
int column_top(const Box& fine, int x, int z) {
  for (int y = fine.size().y - 1; y >= 0; --y)
    if (fine_solid(fine, x, y, z)) return y;
  return -1;
}

SubdivisionParams sub(int levels, int threshold) { return {levels, SubdivisionThreshold::constant(threshold)}; }

// --- The lookup table ------------------------------------------------------

TEST(SubdivisionTable, MatchesTheCountRuleForEveryConfiguration) {
  for (int t = 1; t <= 4; ++t) {
    for (unsigned cfg = 0; cfg < 128; ++cfg) {
      for (int o = 0; o < 8; ++o) {
        const bool c = cfg & 1u;
        const bool nx = (o & 1) ? (cfg >> 2) & 1u : (cfg >> 1) & 1u;
        const bool ny = (o & 2) ? (cfg >> 4) & 1u : (cfg >> 3) & 1u;
        const bool nz = (o & 4) ? (cfg >> 6) & 1u : (cfg >> 5) & 1u;
        const bool expect = c + nx + ny + nz >= t;
        EXPECT_EQ(((kSubdivisionTable[static_cast<std::size_t>(t - 1)][cfg] >> o) & 1) != 0, expect)
            << "t=" << t << " cfg=" << cfg << " o=" << o;
      }
    }
  }
}

TEST(SubdivisionTable, KnownRows) {
  // Nothing solid: nothing. Everything solid: everything.
  for (int t = 0; t < 4; ++t) {
    EXPECT_EQ(kSubdivisionTable[static_cast<std::size_t>(t)][0], 0);
    EXPECT_EQ(kSubdivisionTable[static_cast<std::size_t>(t)][127], 0xFF);
  }
  // A lone solid voxel: threshold 1 keeps it, 2 and up erase it.
  EXPECT_EQ(kSubdivisionTable[0][1], 0xFF);
  EXPECT_EQ(kSubdivisionTable[1][1], 0);
  // An empty voxel with one solid +x neighbour grows its four +x fragments
  // under threshold 1 only.
  EXPECT_EQ(kSubdivisionTable[0][1u << kCfgPlusX], 0xAA);
  EXPECT_EQ(kSubdivisionTable[1][1u << kCfgPlusX], 0);
  // Higher thresholds never add fragments.
  for (int t = 1; t < 4; ++t)
    for (std::size_t cfg = 0; cfg < 128; ++cfg) {
      const auto lo = kSubdivisionTable[static_cast<std::size_t>(t - 1)][cfg];
      const auto hi = kSubdivisionTable[static_cast<std::size_t>(t)][cfg];
      EXPECT_EQ(hi & ~lo, 0);
    }
}

TEST(SubdivisionThresholdPattern, FollowsAltitudeAsInFigureOne) {
  const SubdivisionThreshold t{1, 3, 4, 8};
  EXPECT_EQ(t.at(0, 2), 1);
  EXPECT_EQ(t.at(15, 2), 1);  // below 8 * 2
  EXPECT_EQ(t.at(16, 2), 3);  // even
  EXPECT_EQ(t.at(17, 2), 4);  // odd
  EXPECT_EQ(t.at(127, 16), 1);
  EXPECT_EQ(t.at(129, 16), 4);
  const SubdivisionThreshold neg{1, 3, 4, -4};
  EXPECT_EQ(neg.at(-8, 2), 3);
  EXPECT_EQ(neg.at(-7, 2), 4);
  EXPECT_EQ(neg.at(-9, 2), 1);
  EXPECT_TRUE(validate(SubdivisionParams{4, t}).empty());
  EXPECT_FALSE(validate(SubdivisionParams{0, t}).empty());
  EXPECT_FALSE(validate(SubdivisionParams{7, t}).empty());
  EXPECT_FALSE(validate(SubdivisionParams{1, SubdivisionThreshold{0, 3, 4, 0}}).empty());
  EXPECT_FALSE(validate(SubdivisionParams{1, SubdivisionThreshold{1, 3, 5, 0}}).empty());
}

// --- Hand-made cases -------------------------------------------------------

TEST(Subdivide, SingleSolidVoxelGrowsACrossUnderThresholdOne) {
  Box coarse({3, 3, 3});
  coarse.set(1, 1, 1, solid(m::kRock));
  const Box fine = subdivide(coarse, {0, 0, 0}, sub(1, 1));
  ASSERT_EQ(fine.size(), (Vec3i{6, 6, 6}));
  // The voxel's own 8 fragments plus, in each face neighbour, the 4
  // fragments facing it.
  EXPECT_EQ(count_solid(fine), 8u + 6u * 4u);
  for (int y = 2; y < 4; ++y)
    for (int z = 2; z < 4; ++z)
      for (int x = 2; x < 4; ++x) EXPECT_EQ(fine.get(x, y, z), solid(m::kRock));
  EXPECT_EQ(fine.get(4, 2, 2), solid(m::kRock));   // +x neighbour, facing half
  EXPECT_EQ(fine.get(5, 2, 2), (Voxel{kAir, 0}));  // +x neighbour, far half
  EXPECT_EQ(fine.get(1, 2, 3), solid(m::kRock));
  EXPECT_EQ(fine.get(4, 4, 2), (Voxel{kAir, 0}));  // edge neighbour: not a face
}

TEST(Subdivide, SingleSolidVoxelVanishesUnderHigherThresholds) {
  Box coarse({3, 3, 3});
  coarse.set(1, 1, 1, solid(m::kRock));
  for (int t = 2; t <= 4; ++t) EXPECT_EQ(count_solid(subdivide(coarse, {0, 0, 0}, sub(1, t))), 0u) << t;
}

TEST(Subdivide, FlatFloorStaysFlat) {
  Box coarse({4, 6, 4});
  for (int y = 0; y < 3; ++y)
    for (int z = 0; z < 4; ++z)
      for (int x = 0; x < 4; ++x) coarse.set(x, y, z, solid(m::kGround));
  for (int levels = 1; levels <= 3; ++levels) {
    for (int t = 1; t <= 4; ++t) {
      const Box fine = subdivide(coarse, {-2, 5, 7}, sub(levels, t));
      const int f = 1 << levels;
      const int top = column_top(fine, 0, 0);
      // Within a coarse voxel of the original top (3 * f - 1): each level
      // moves it by at most one of its own fragments.
      EXPECT_LE(std::abs(top - (3 * f - 1)), f - 1) << levels << " " << t;
      for (int z = 0; z < fine.size().z; ++z)
        for (int x = 0; x < fine.size().x; ++x)
          for (int y = 0; y < fine.size().y; ++y)
            ASSERT_EQ(fine_solid(fine, x, y, z), y <= top) << levels << " " << t << " " << x << "," << y << "," << z;
    }
  }
  // Thresholds 2 and 3 keep a flat floor exactly where it was.
  EXPECT_EQ(column_top(subdivide(coarse, {0, 0, 0}, sub(1, 2)), 3, 3), 5);
  EXPECT_EQ(column_top(subdivide(coarse, {0, 0, 0}, sub(1, 3)), 3, 3), 5);
}

TEST(Subdivide, DiagonalStaircaseBecomesSingleFragmentSteps) {
  // Coarse solid where x + y <= 7: a staircase of one-voxel steps, which a
  // plain 2x upscale would turn into two-fragment steps.
  constexpr int kK = 7;
  Box coarse({8, 8, 2});
  for (int y = 0; y < 8; ++y)
    for (int z = 0; z < 2; ++z)
      for (int x = 0; x < 8; ++x)
        if (x + y <= kK) coarse.set(x, y, z, solid(m::kRock));
  // Per the table: top(X) = 2K - X + c with c = 3, 2, 1, 0 for t = 1..4.
  for (int t = 1; t <= 4; ++t) {
    const Box fine = subdivide(coarse, {0, 0, 0}, sub(1, t));
    for (int x = 4; x <= 11; ++x) {
      for (int z = 0; z < 4; ++z) {
        EXPECT_EQ(column_top(fine, x, z), 2 * kK - x + (4 - t)) << "t=" << t << " x=" << x;
        // Each column is solid up to its top: no holes.
        for (int y = 0; y <= column_top(fine, x, z); ++y) ASSERT_TRUE(fine_solid(fine, x, y, z));
      }
    }
    for (const Voxel v : fine.voxels()) EXPECT_TRUE(v.material == kAir || v == solid(m::kRock));
  }
}

TEST(Subdivide, EmptySourceFragmentsTakeTheMostCommonNeighbourMaterial) {
  Box coarse({3, 3, 3});
  coarse.set(0, 1, 1, solid(m::kRock));  // -x of the centre
  coarse.set(1, 0, 1, solid(m::kSand));  // -y
  coarse.set(1, 1, 0, solid(m::kSand));  // -z
  const Box fine = subdivide(coarse, {0, 0, 0}, sub(1, 1));
  // Centre voxel's fragments are at fine 2..3.
  EXPECT_EQ(fine.get(2, 2, 2), solid(m::kSand));   // Rock, Sand, Sand
  EXPECT_EQ(fine.get(3, 2, 2), solid(m::kSand));   // -, Sand, Sand
  EXPECT_EQ(fine.get(2, 3, 3), solid(m::kRock));   // Rock, -, -
  EXPECT_EQ(fine.get(3, 3, 3), (Voxel{kAir, 0}));  // nothing solid towards it
  coarse.set(1, 1, 0, solid(m::kBrick));           // now Rock, Sand, Brick: tie
  const Box tie = subdivide(coarse, {0, 0, 0}, sub(1, 1));
  EXPECT_EQ(tie.get(2, 2, 2), solid(m::kRock));  // first in x, y, z order
  EXPECT_EQ(tie.get(3, 2, 2), solid(m::kSand));
}

TEST(Subdivide, SolidMeansHalfOccupancy) {
  Box coarse({3, 3, 3});
  coarse.set(1, 1, 1, make_voxel(m::kRock, 127));  // (127 + 1) / 256 = 0.5
  coarse.set(0, 0, 0, make_voxel(m::kRock, 126));  // just below
  const Box fine = subdivide(coarse, {0, 0, 0}, sub(1, 1));
  EXPECT_EQ(fine.get(2, 2, 2), solid(m::kRock));
  EXPECT_EQ(fine.get(0, 0, 0), (Voxel{kAir, 0}));
  EXPECT_EQ(count_solid(fine), 32u);
}

TEST(Subdivide, SkipsVoxelsWhoseNeighboursAgree) {
  Box coarse({8, 8, 8});
  for (int y = 0; y < 4; ++y)
    for (int z = 0; z < 8; ++z)
      for (int x = 0; x < 8; ++x) coarse.set(x, y, z, solid(m::kRock));
  EnhanceStats stats;
  const Box fine = subdivide(coarse, {0, 0, 0}, sub(1, 2), &stats);
  // Only the layers on either side of the surface are evaluated.
  EXPECT_EQ(stats.voxels_evaluated, 2u * 8u * 8u);
  EXPECT_EQ(stats.voxels_skipped, 6u * 8u * 8u);
  EXPECT_EQ(stats.solid_fragments, count_solid(fine));
}

// --- Determinism, regions, updates -----------------------------------------

TEST(Subdivide, DeterministicAndRegionIndependent) {
  const Vec3i origin{-5, -3, -7};
  const Box coarse = perlin_box({8, 8, 8}, origin, 11);
  const SubdivisionParams params{3, SubdivisionThreshold{1, 3, 4, 0}};
  const Box a = subdivide(coarse, origin, params);
  const Box b = subdivide(coarse, origin, params);
  EXPECT_EQ(a, b);
  const Region whole = fine_region_of(coarse, origin, 8);
  ASSERT_EQ(a.size(), whole.size());
  for (const Region r :
       {Region{{-40, -24, -56}, {-30, -10, -50}}, Region{{-13, -3, -20}, {1, 9, 0}}, Region{{0, 0, 0}, {24, 40, 8}}}) {
    Box part;
    subdivide_region(coarse, origin, params, r, part);
    EXPECT_EQ(part, slice(a, whole, intersect(r, whole))) << r.min.x << "," << r.min.y << "," << r.min.z;
  }
}

TEST(Subdivide, AffectedRegionStaysNearTheChange) {
  for (int levels = 1; levels <= 4; ++levels) {
    const int f = 1 << levels;
    const Region r = subdivision_affected_region({{3, 3, 3}, {4, 4, 4}}, sub(levels, 2));
    EXPECT_GE(r.min.x, (3 - 1) * f);
    EXPECT_LE(r.max.x, (4 + 2) * f);
    EXPECT_LE(r.min.x, 3 * f - 1);
    EXPECT_GE(r.max.x, 4 * f + 1);
  }
}

TEST(Subdivide, UpdateAfterOneVoxelChangeEqualsFullRecomputation) {
  const Vec3i origin{-4, 2, -9};
  Box coarse = perlin_box({10, 10, 10}, origin, 5);
  const SubdivisionParams params{3, SubdivisionThreshold{1, 3, 4, 6}};
  Box fine = subdivide(coarse, origin, params);
  const Vec3i edits[] = {{5, 5, 5}, {0, 0, 0}, {9, 9, 9}, {3, 9, 0}, {9, 4, 6}};
  for (const Vec3i e : edits) {
    const Voxel old = coarse.get(e);
    coarse.set(e, enhance_solid(old) ? Voxel{kAir, 0} : solid(m::kBrick));
    const Region changed = Region::from_min_size(origin + e, {1, 1, 1});
    const Region r = subdivide_update(coarse, origin, params, changed, fine);
    EXPECT_LE(r.volume(), std::int64_t{4 * 8} * 4 * 8 * 4 * 8);
    EXPECT_EQ(fine, subdivide(coarse, origin, params)) << e.x << "," << e.y << "," << e.z;
  }
}

// --- Direct resampling -----------------------------------------------------

TEST(Resample, PatternStaysWithinTheSpread) {
  const Resampler r(ResampleParams{16, 512, 1.0f, 0.25f, 3});
  ASSERT_EQ(r.pattern().size(), 512u);
  for (const Vec3f o : r.pattern()) {
    EXPECT_LE(std::abs(o.x), 1.0f);
    EXPECT_LE(std::abs(o.y), 1.0f);
    EXPECT_LE(std::abs(o.z), 1.0f);
  }
  EXPECT_EQ(r.reach(), 1);
  EXPECT_EQ(r.min_solid_probes(), 129);  // more than 25% of 512
  EXPECT_EQ(Resampler(ResampleParams{16, 4, 1.0f, 0.25f, 3}).min_solid_probes(), 2);
  const int wide = Resampler(ResampleParams{4, 64, 2.5f, 0.5f, 3}).reach();
  EXPECT_GE(wide, 2);
  EXPECT_LE(wide, 3);
  EXPECT_NE(Resampler(ResampleParams{16, 4, 1.0f, 0.25f, 4}).pattern(),
            Resampler(ResampleParams{16, 4, 1.0f, 0.25f, 3}).pattern());
}

TEST(Resample, ValidateNamesTheBadField) {
  EXPECT_TRUE(validate(ResampleParams{}).empty());
  EXPECT_NE(validate(ResampleParams{0, 4, 1.0f, 0.25f, 1}).find("factor"), std::string::npos);
  EXPECT_NE(validate(ResampleParams{4, 0, 1.0f, 0.25f, 1}).find("probes"), std::string::npos);
  EXPECT_NE(validate(ResampleParams{4, 4, 0.0f, 0.25f, 1}).find("spread"), std::string::npos);
  EXPECT_NE(validate(ResampleParams{4, 4, 1.0f, 1.0f, 1}).find("threshold"), std::string::npos);
}

TEST(Resample, FactorOneWithATinySpreadIsTheIdentity) {
  const Vec3i origin{3, -6, 0};
  Box coarse = perlin_box({8, 8, 8}, origin, 2);
  coarse.set(1, 1, 1, make_voxel(m::kSand, 40));  // partial: not solid
  Resampler r(ResampleParams{1, 1, 0.01f, 0.0f, 9});
  const Box fine = r.resample(coarse, origin);
  ASSERT_EQ(fine.size(), coarse.size());
  for (std::size_t i = 0; i < fine.voxel_count(); ++i) {
    const Voxel c = coarse.voxels()[i];
    EXPECT_EQ(fine.voxels()[i], enhance_solid(c) ? solid(c.material) : (Voxel{kAir, 0}));
  }
}

TEST(Resample, FlatFloorStaysFlatForAnyFactor) {
  Box coarse({4, 6, 4});
  for (int y = 0; y < 3; ++y)
    for (int z = 0; z < 4; ++z)
      for (int x = 0; x < 4; ++x) coarse.set(x, y, z, solid(m::kGround));
  for (const int f : {3, 5, 16}) {
    Resampler r(ResampleParams{f, 64, 1.0f, 0.25f, 7});
    const Box fine = r.resample(coarse, {0, -3, 0});
    ASSERT_EQ(fine.size(), (Vec3i{4 * f, 6 * f, 4 * f}));
    const int top = column_top(fine, 0, 0);
    EXPECT_LE(std::abs(top - (3 * f - 1)), f) << f;
    for (int z = 0; z < fine.size().z; ++z)
      for (int x = 0; x < fine.size().x; ++x) ASSERT_EQ(column_top(fine, x, z), top) << f;
  }
}

TEST(Resample, EmptySourceFragmentsTakeANeighbourMaterial) {
  Box coarse({3, 3, 3});
  for (int z = 0; z < 3; ++z)
    for (int x = 0; x < 3; ++x) coarse.set(x, 0, z, solid(m::kSand));
  Resampler r(ResampleParams{4, 64, 1.0f, 0.25f, 1});
  const Box fine = r.resample(coarse, {0, 0, 0});
  std::uint64_t above = 0;
  for (int y = 4; y < 12; ++y)
    for (int z = 0; z < 12; ++z)
      for (int x = 0; x < 12; ++x) {
        const Voxel v = fine.get(x, y, z);
        EXPECT_TRUE(v.material == kAir || v == solid(m::kSand));
        above += v.material != kAir;
      }
  EXPECT_GT(above, 0u);  // a 25% threshold grows the floor into the empty layer
}

TEST(Resample, DeterministicRegionIndependentAndCached) {
  const Vec3i origin{-6, -2, 1};
  const Box coarse = perlin_box({8, 8, 8}, origin, 17);
  const ResampleParams params{5, 48, 1.0f, 0.3f, 21};
  Resampler a(params);
  Resampler b(params);
  EnhanceStats stats;
  const Box fa = a.resample(coarse, origin, &stats);
  EXPECT_EQ(fa, b.resample(coarse, origin));
  EXPECT_GT(stats.voxels_skipped, 0u);
  EXPECT_EQ(stats.cache_hits + stats.cache_misses, stats.voxels_evaluated);
  EXPECT_EQ(a.cache_entries(), stats.cache_misses);
  // A second pass is answered from the cache and gives the same fragments.
  EnhanceStats again;
  EXPECT_EQ(a.resample(coarse, origin, &again), fa);
  EXPECT_EQ(again.cache_misses, 0u);
  const Region whole = fine_region_of(coarse, origin, 5);
  for (const Region r : {Region{{-33, -12, 3}, {-20, 0, 17}}, Region{{-7, 20, 30}, {4, 41, 45}}}) {
    Box part;
    b.resample_region(coarse, origin, intersect(r, whole), part);
    EXPECT_EQ(part, slice(fa, whole, intersect(r, whole)));
  }
}

TEST(Resample, UpdateAfterOneVoxelChangeEqualsFullRecomputation) {
  const Vec3i origin{-3, -3, -3};
  Box coarse = perlin_box({8, 8, 8}, origin, 23);
  Resampler r(ResampleParams{6, 32, 1.3f, 0.25f, 2});
  ASSERT_EQ(r.reach(), 2);
  Box fine = r.resample(coarse, origin);
  for (const Vec3i e : {Vec3i{4, 4, 4}, Vec3i{0, 7, 0}, Vec3i{7, 0, 3}}) {
    const Voxel old = coarse.get(e);
    coarse.set(e, enhance_solid(old) ? Voxel{kAir, 0} : solid(m::kBrick));
    const Region changed = Region::from_min_size(origin + e, {1, 1, 1});
    const Region rr = r.update(coarse, origin, changed, fine);
    EXPECT_LE(rr.volume(), std::int64_t{5 * 6} * 5 * 6 * 5 * 6);
    Resampler fresh(r.params());
    EXPECT_EQ(fine, fresh.resample(coarse, origin));
  }
}

// --- Terrain: surface fragments grow about quadratically --------------------

// A 16^3 box of generated terrain crossing the surface.
Box terrain_box(Vec3i* origin) {
  *origin = {0, 32, 0};  // above sea level (water counts as solid), about half solid
  Box box;
  TerrainGenerator(GeneratorParams{}).generate(Region::from_min_size(*origin, {16, 16, 16}), box);
  return box;
}

TEST(EnhanceTerrain, GeneratedBoxCrossesTheSurface) {
  Vec3i origin;
  const Box box = terrain_box(&origin);
  const double share = solid_share(box);
  EXPECT_GT(share, 0.1);
  EXPECT_LT(share, 0.9);
}

TEST(EnhanceTerrain, SurfaceFragmentsGrowAboutQuadraticallyWithSubdivision) {
  Vec3i origin;
  const Box coarse = terrain_box(&origin);
  std::uint64_t prev = count_surface(coarse);
  for (int levels = 1; levels <= 3; ++levels) {
    const Box fine = subdivide(coarse, origin, sub(levels, 2));
    const std::uint64_t s = count_surface(fine);
    const double ratio = static_cast<double>(s) / static_cast<double>(prev);
    EXPECT_GT(ratio, 2.5) << levels;  // quadratic: 4 per doubling
    EXPECT_LT(ratio, 6.0) << levels;  // far from the cubic 8
    EXPECT_NEAR(solid_share(fine), solid_share(coarse), 0.08);
    prev = s;
  }
}

TEST(EnhanceTerrain, SurfaceFragmentsGrowAboutQuadraticallyWithResampling) {
  Vec3i origin;
  const Box coarse = terrain_box(&origin);
  std::vector<double> per_voxel;
  for (const int f : {2, 4, 8}) {
    Resampler r(ResampleParams{f, 64, 1.0f, 0.5f, 1});
    const Box fine = r.resample(coarse, origin);
    per_voxel.push_back(static_cast<double>(count_surface(fine)) / (f * f));
    EXPECT_NEAR(solid_share(fine), solid_share(coarse), 0.1) << f;
  }
  // Surface fragments / f^2 roughly constant.
  EXPECT_NEAR(per_voxel[1] / per_voxel[0], 1.0, 0.35);
  EXPECT_NEAR(per_voxel[2] / per_voxel[1], 1.0, 0.35);
}

// --- The paper's settings ---------------------------------------------------

// Figure 1: 16^3 -> 256^3 by four subdivisions, threshold 1 below an
// altitude and 3/4 alternating above.
TEST(EnhancePaper, FigureOneSubdivision16To256) {
  const Vec3i origin{0, 0, 0};
  const Box coarse = perlin_box({16, 16, 16}, origin, 1);
  const SubdivisionParams params{4, SubdivisionThreshold{1, 3, 4, 8}};
  EnhanceStats stats;
  const Box fine = subdivide(coarse, origin, params, &stats);
  ASSERT_EQ(fine.size(), (Vec3i{256, 256, 256}));
  EXPECT_EQ(fine, subdivide(coarse, origin, params));
  EXPECT_NEAR(solid_share(fine), solid_share(coarse), 0.1);
  EXPECT_GT(stats.voxels_skipped, stats.voxels_evaluated);
}

// Figure 2: 8^3 -> 128^3 by resampling with 4 and 512 probes, spread 1.0,
// threshold 25%.
TEST(EnhancePaper, FigureTwoResampling8To128) {
  const Vec3i origin{0, 0, 0};
  const Box coarse = perlin_box({8, 8, 8}, origin, 1);
  for (const int probes : {4, 512}) {
    Resampler r(ResampleParams{16, probes, 1.0f, 0.25f, 1});
    const Box fine = r.resample(coarse, origin);
    ASSERT_EQ(fine.size(), (Vec3i{128, 128, 128}));
    Resampler again(r.params());
    EXPECT_EQ(fine, again.resample(coarse, origin));
    EXPECT_NEAR(solid_share(fine), solid_share(coarse), 0.15) << probes;
  }
}

std::uint64_t fnv1a(const Box& box) {
  std::uint64_t h = 0xCBF29CE484222325ull;
  for (const Voxel v : box.voxels()) {
    for (const std::uint8_t b : {v.material, v.occupancy}) {
      h ^= b;
      h *= 0x100000001B3ull;
    }
  }
  return h;
}

// Pins the output of version 1 (kEnhanceVersion): a change here needs a
// version bump and new hashes.
TEST(EnhanceGolden, Version1Outputs) {
  EXPECT_EQ(kEnhanceVersion, 1u);
  const Vec3i origin{-4, -4, -4};
  const Box coarse = perlin_box({8, 8, 8}, origin, 42);
  const SubdivisionParams params{2, SubdivisionThreshold{1, 3, 4, 0}};
  const std::uint64_t sub_hash = fnv1a(subdivide(coarse, origin, params));
  Resampler r(ResampleParams{3, 16, 1.0f, 0.25f, 7});
  const std::uint64_t res_hash = fnv1a(r.resample(coarse, origin));
  EXPECT_EQ(sub_hash, 0xa2766f1ac0a989a5ull) << std::hex << sub_hash;
  EXPECT_EQ(res_hash, 0x82f1249a19cec68full) << std::hex << res_hash;
}

// Many random edits on terrain, each update checked against a full run.
TEST(EnhanceUpdateHeavy, RandomEditsMatchFullRecomputation) {
  Vec3i origin;
  Box coarse = terrain_box(&origin);
  const SubdivisionParams params{4, SubdivisionThreshold{1, 3, 4, 40}};
  Resampler resampler(ResampleParams{8, 128, 1.5f, 0.25f, 5});
  Box sub_fine = subdivide(coarse, origin, params);
  Box res_fine = resampler.resample(coarse, origin);
  std::uint64_t rng = 99;
  for (int i = 0; i < 30; ++i) {
    rng = mix64(rng + 1);
    const Vec3i e{static_cast<int>(rng % 16), static_cast<int>((rng >> 8) % 16), static_cast<int>((rng >> 16) % 16)};
    coarse.set(e, enhance_solid(coarse.get(e)) ? Voxel{kAir, 0} : solid(m::kSnow));
    const Region changed = Region::from_min_size(origin + e, {1, 1, 1});
    (void)subdivide_update(coarse, origin, params, changed, sub_fine);
    (void)resampler.update(coarse, origin, changed, res_fine);
    ASSERT_EQ(sub_fine, subdivide(coarse, origin, params)) << i;
    Resampler fresh(resampler.params());
    ASSERT_EQ(res_fine, fresh.resample(coarse, origin)) << i;
  }
}

}  // namespace
}  // namespace terrane
