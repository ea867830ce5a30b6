#include "common/world/horizon.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <unistd.h>

#include "common/codec/net_codec.h"
#include "common/world/world.h"

namespace terrane {
namespace {

namespace fs = std::filesystem;

Box decode(const HorizonImage& img) {
  const int n = horizon_side(img.level);
  Box b({n, n, n});
  EXPECT_TRUE(net_codec_decode(n, img.unit, b.voxels()).ok());
  return b;
}

TEST(Horizon, AStoredChunksImageIsItsMipDownsampledFurther) {
  // A chunk whose lower half is rock and upper half Air, in region (-1, 0, 2).
  Box box({32, 32, 32});
  for (int y = 0; y < 16; ++y)
    for (int z = 0; z < 32; ++z)
      for (int x = 0; x < 32; ++x) box.set(x, y, z, solid(materials::kRock));
  const Chunk chunk = Chunk::from_box(box);
  const Vec3i cp{-3, 1, 17};  // local (5, 1, 1) in region (-1, 0, 2)
  Box mip2, mip1;
  chunk.read_level(kMipLevels - 1, mip2);
  mip2 = downsample_box(mip2);
  mip1 = downsample_box(mip2);
  for (const int level : {kHorizonNearLevel, kHorizonFarLevel}) {
    HorizonBuilder b(coarse_region_of(cp), level);
    b.put_coarse(cp, coarse_voxels(&chunk));
    const HorizonPtr img = encode_horizon(b);
    EXPECT_EQ(img->region, (Vec3i{-1, 0, 2}));
    const Box got = decode(*img);
    const Box& want = level == kHorizonNearLevel ? mip2 : mip1;
    const int n = want.size().x;
    for (int y = 0; y < n; ++y)
      for (int z = 0; z < n; ++z)
        for (int x = 0; x < n; ++x)
          EXPECT_EQ(got.get(Vec3i{5, 1, 1} * n + Vec3i{x, y, z}), want.get(x, y, z)) << "level " << level;
    // Every other chunk of the region is Air.
    std::size_t solid_voxels = 0;
    for (const Voxel v : got.voxels()) solid_voxels += v.material != kAir;
    EXPECT_EQ(solid_voxels, level == kHorizonNearLevel ? 4u : 1u);
  }
  EXPECT_EQ(mip2.get(0, 0, 0), solid(materials::kRock));
  EXPECT_EQ(mip2.get(0, 1, 0), Voxel{});
}

TEST(Horizon, ALevel6ImageIsTheLevel5ImageDownsampled) {
  // Chunks of region (0, 0, 0) with different halves of rock, some in one
  // block of 2^3 chunks and some alone in theirs.
  HorizonBuilder five(Vec3i{0, 0, 0}, kHorizonFarLevel), six(Vec3i{0, 0, 0}, kHorizonOuterLevel);
  EXPECT_EQ(six.per_chunk(), 1);
  int k = 0;
  for (const Vec3i cp : {Vec3i{0, 0, 0}, Vec3i{1, 0, 0}, Vec3i{1, 1, 1}, Vec3i{6, 3, 2}, Vec3i{7, 7, 7}}) {
    Box box({32, 32, 32});
    for (int y = 0; y < 8 * ++k && y < 32; ++y)
      for (int z = 0; z < 32; ++z)
        for (int x = 0; x < 32; ++x) box.set(x, y, z, solid(k % 2 ? materials::kRock : materials::kSand));
    const Chunk chunk = Chunk::from_box(box);
    five.put_coarse(cp, coarse_voxels(&chunk));
    six.put_coarse(cp, coarse_voxels(&chunk));
  }
  const Box got = decode(*encode_horizon(six));
  ASSERT_EQ(got.size(), (Vec3i{4, 4, 4}));
  EXPECT_EQ(got, downsample_box(decode(*encode_horizon(five))));
  std::size_t solid_voxels = 0;
  for (const Voxel v : got.voxels()) solid_voxels += v.material != kAir;
  EXPECT_EQ(solid_voxels, 3u) << "blocks (0,0,0), (3,1,1) and (3,3,3)";
  // Held as level 5: each voxel repeated over its block's 2^3 chunks, and
  // downsampled back it is the image again.
  const Box held = horizon_upsample(got);
  ASSERT_EQ(held.size(), (Vec3i{8, 8, 8}));
  for (int y = 0; y < 8; ++y)
    for (int z = 0; z < 8; ++z)
      for (int x = 0; x < 8; ++x) EXPECT_EQ(held.get(x, y, z), got.get(x / 2, y / 2, z / 2));
  EXPECT_EQ(downsample_box(held), got);
}

TEST(Horizon, EstimatesFollowTheGeneratedTerrain) {
  const fs::path dir = fs::temp_directory_path() / ("terrane-horizon-" + std::to_string(::getpid()));
  fs::remove_all(dir);
  auto world = World::create(dir.string(), default_world_meta(7));
  ASSERT_TRUE(world.ok());
  const World& w = **world;
  // A column well inside the bounds: chunks far below its surface are solid,
  // chunks far above it Air, at both levels.
  const std::int32_t h = static_cast<std::int32_t>(w.generator()->surface_height(100, 100));
  const Vec3i deep = chunk_of(Vec3i{100, h - 64, 100}), sky = chunk_of(Vec3i{100, h + 96, 100});
  ASSERT_TRUE(w.meta().bounds.contains(chunk_origin(deep))) << "the premise: the deep chunk is in the world";
  ASSERT_TRUE(w.meta().bounds.contains(chunk_origin(sky) + Vec3i{0, 31, 0})) << "and the sky chunk";
  for (const int level : {kHorizonNearLevel, kHorizonFarLevel}) {
    for (const Vec3i cp : {deep, sky}) {
      HorizonBuilder b(coarse_region_of(cp), level);
      const std::vector<Vec3i> chunks{cp};
      w.estimate_horizon(chunks, b);
      const int n = b.per_chunk();
      const Vec3i at = floor_mod(cp, kHorizonRegionChunks) * n;
      for (int i = 0; i < n * n * n; ++i) {
        const Voxel v = b.image().get(at + Vec3i{i % n, i / (n * n), (i / n) % n});
        if (cp == deep)
          EXPECT_NE(v.material, kAir) << "level " << level;
        else
          EXPECT_EQ(v, Voxel{}) << "level " << level;
      }
    }
  }
  world->reset();
  fs::remove_all(dir);
}

TEST(Horizon, Level6EstimatesOneVoxelPerBlockOfChunks) {
  const fs::path dir = fs::temp_directory_path() / ("terrane-horizon6-" + std::to_string(::getpid()));
  fs::remove_all(dir);
  auto world = World::create(dir.string(), default_world_meta(7));
  ASSERT_TRUE(world.ok());
  const World& w = **world;
  // Region (0, -1, 0)'s chunks of blocks (1, -2, 1) and (1, -1, 1) (y -128
  // to -1), and of block (1, -4, 1) (y -256 to -193, below the world's
  // bounds).
  std::vector<Vec3i> chunks;
  for (const int by : {-2, -1, -4})
    for (int y = 0; y < 2; ++y)
      for (int z = 0; z < 2; ++z)
        for (int x = 0; x < 2; ++x) chunks.push_back(Vec3i{2 + x, by * 2 + y, 2 + z});
  HorizonBuilder b(Vec3i{0, -1, 0}, kHorizonOuterLevel);
  w.estimate_horizon(chunks, b);
  std::size_t solid_voxels = 0;
  for (const Vec3i cp : chunks) {
    const Voxel v = b.image().get(floor_mod(cp, kHorizonRegionChunks));
    if (cp.y < -4) {
      EXPECT_EQ(v, Voxel{}) << "outside the bounds";
      continue;
    }
    // The block's one evaluation, a cell of 64 voxels.
    Box cell;
    w.generator()->coarse_sample(floor_div(cp, 2) * 64, 64, Vec3i{1, 1, 1}, cell);
    EXPECT_EQ(v, cell.get(0, 0, 0)) << cp.x << "," << cp.y << "," << cp.z;
    solid_voxels += v.material != kAir;
  }
  EXPECT_GT(solid_voxels, 0u) << "the premise: the lower block is ground";
  const Box got = decode(*encode_horizon(b));
  ASSERT_EQ(got.size(), (Vec3i{4, 4, 4}));
  EXPECT_EQ(got, downsample_box(b.image()));
  world->reset();
  fs::remove_all(dir);
}

}  // namespace
}  // namespace terrane
