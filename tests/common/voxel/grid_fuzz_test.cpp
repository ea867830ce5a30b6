// Write-heavy fuzz of the grid against a dense reference: random boxes and
// spheres (dig, fill, paint with partial occupancy, noise) over a region
// crossing chunk borders, every voxel compared after every few edits and
// every chunk's mips checked against the downsampling rule at the end; boxes
// are compacted now and then, and tiny writes drive some into unpacked mode.
#include <gtest/gtest.h>

#include <random>
#include <string>

#include "common/voxel/grid.h"
#include "tests/common/voxel/mips_check.h"

namespace terrane {
namespace {

TEST(GridFuzz, RandomBoxesAndSpheresMatchADenseReference) {
  const Vec3i origin{-40, -24, -40};
  const Vec3i size{96, 64, 96};
  Grid grid;
  Box ref(size);
  std::mt19937 rng(20261124);
  std::uniform_int_distribution<int> px(0, size.x - 1), py(0, size.y - 1), pz(0, size.z - 1), radius(1, 9),
      extent(1, 24), kind(0, 5), mat(1, 20), occ(0, 255), coin(0, 3);
  // Ground to start from: rock below y = 0 with a grass layer.
  grid.fill(Region{origin, origin + Vec3i{size.x, 24, size.z}}, solid(materials::kRock));
  grid.fill(Region{origin + Vec3i{0, 24, 0}, origin + Vec3i{size.x, 26, size.z}}, solid(materials::kGrass));
  grid.read_box(origin, ref);
  bool saw_unpacked = false;
  for (int step = 0; step < 600; ++step) {
    const Vec3i c{px(rng), py(rng), pz(rng)};
    const int k = kind(rng);
    const Material m = static_cast<Material>(mat(rng));
    const std::uint8_t o = static_cast<std::uint8_t>(occ(rng));
    Region r;
    bool sphere = coin(rng) != 0;
    int rad = radius(rng);
    if (k == 5) {  // a burst of single-voxel writes in one chunk
      sphere = false;
      rad = 0;
    }
    if (sphere) {
      r = Region{c - Vec3i{rad, rad, rad}, c + Vec3i{rad + 1, rad + 1, rad + 1}};
    } else {
      r = Region::from_min_size(c, rad == 0 ? Vec3i{1, 1, 1} : Vec3i{extent(rng), extent(rng), extent(rng)});
    }
    r = intersect(r, Region{{0, 0, 0}, size});
    auto value = [&](Vec3i p, Voxel old) -> Voxel {
      if (sphere) {
        const Vec3i d = p - c;
        if (d.x * d.x + d.y * d.y + d.z * d.z > rad * rad) return old;
      }
      switch (k) {
        case 0: return Voxel{};                                  // dig
        case 1: return solid(m);                                 // fill
        case 2: return old.material == kAir ? old : solid(m);    // paint
        case 3: return make_voxel(m, o);                         // partial occupancy
        case 4: return make_voxel(static_cast<Material>((p.x * 7 + p.y * 3 + p.z) % 40),
                                  static_cast<std::uint8_t>((p.x * 31 + p.z * 17) % 256));  // noise
        default: return make_voxel(m, static_cast<std::uint8_t>(step));
      }
    };
    const int repeats = k == 5 ? 40 : 1;
    for (int i = 0; i < repeats; ++i) {
      const Vec3i at = k == 5 ? Vec3i{px(rng) % 32, py(rng) % 32, pz(rng) % 32} : Vec3i{};
      const Region w = k == 5 ? Region{at, at + Vec3i{1, 1, 1}} : r;
      grid.modify(Region{w.min + origin, w.max + origin}, [&](Vec3i p, Voxel old) { return value(p - origin, old); });
      for (int y = w.min.y; y < w.max.y; ++y)
        for (int z = w.min.z; z < w.max.z; ++z)
          for (int x = w.min.x; x < w.max.x; ++x) ref.set(x, y, z, value({x, y, z}, ref.get(x, y, z)));
    }
    grid.for_each_chunk([&](Vec3i, const Chunk& ch) { saw_unpacked |= ch.level0().unpacked(); });
    if (step % 10 == 9 || step == 599) {
      Box back(size);
      grid.read_box(origin, back);
      for (int y = 0; y < size.y; ++y)
        for (int z = 0; z < size.z; ++z)
          for (int x = 0; x < size.x; ++x)
            ASSERT_EQ(back.get(x, y, z), ref.get(x, y, z)) << "step " << step << " at " << x << "," << y << "," << z;
    }
    if (step % 150 == 149 && step != 599) grid.compact();
  }
  EXPECT_TRUE(saw_unpacked);
  // The mips as writes left them (unpacked), then packed.
  for (int pass = 0; pass < 2; ++pass) {
    if (pass == 1) grid.compact();
    grid.for_each_chunk([&](Vec3i pos, const Chunk& chunk) {
      Box level0;
      chunk.read_level(0, level0);
      const Chunk fresh = Chunk::from_box(level0);
      test_mips::expect_mips_as_rebuilt(
          chunk, fresh, "chunk " + std::to_string(pos.x) + "," + std::to_string(pos.y) + "," + std::to_string(pos.z));
      EXPECT_EQ(chunk.empty(), fresh.empty());
    });
  }
}

}  // namespace
}  // namespace terrane
