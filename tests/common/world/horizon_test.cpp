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

}  // namespace
}  // namespace terrane
