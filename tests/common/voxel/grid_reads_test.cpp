#include "common/voxel/grid_reads.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <map>
#include <memory>
#include <random>
#include <tuple>

#include "common/voxel/grid.h"

namespace terrane {
namespace {

// A chunk map of plain boxes: the reads of grid_reads.h over it must answer
// as over a Grid of row-packed chunks holding the same voxels.
class PlainChunk {
 public:
  explicit PlainChunk(const Chunk& c) { c.read_level(0, box_); }
  Voxel get(Vec3i p) const { return box_.get(p); }
  const Voxel* read_row(int y, int z, std::array<Voxel, kChunkSize>&) const { return box_.read_row(y, z); }
  bool box_has_solid(Vec3i min, Vec3i max, std::uint8_t min_occupancy) const {
    return terrane::box_has_solid(box_, min, max, min_occupancy);
  }
  void read_box(Vec3i min, Box& out, Vec3i out_offset, Vec3i size) const {
    for (int y = 0; y < size.y; ++y)
      for (int z = 0; z < size.z; ++z)
        for (int x = 0; x < size.x; ++x)
          out.set(out_offset + Vec3i{x, y, z}, box_.get(min + Vec3i{x, y, z}));
  }

 private:
  Box box_;
};

struct PlainGrid {
  std::map<std::tuple<int, int, int>, std::unique_ptr<PlainChunk>> chunks;
  const PlainChunk* find_chunk(Vec3i p) const {
    auto it = chunks.find({p.x, p.y, p.z});
    return it == chunks.end() ? nullptr : it->second.get();
  }
};

// Rough terrain across chunk borders in negative space, with caves, ore
// runs and partial occupancy: every record kind of the packed rows.
Grid terrain() {
  Grid g;
  std::mt19937 rng(17);
  std::uniform_int_distribution<int> occ(1, 255), coin(0, 9);
  g.modify(Region{{-40, -40, -40}, {40, 24, 40}}, [&](Vec3i p, Voxel) {
    const int h = (p.x * 7 + p.z * 3) % 11 - 2;
    if (p.y > h) return Voxel{};
    if ((p.x + p.y * 3 + p.z) % 13 == 0) return Voxel{};  // caves
    if (p.y == h && coin(rng) < 3) return make_voxel(materials::kGrass, static_cast<std::uint8_t>(occ(rng)));
    return solid(p.x % 5 == 0 ? materials::kBasalt : p.y < -20 ? materials::kSlate : materials::kRock);
  });
  g.compact();
  return g;
}

TEST(GridReads, AMapOfPlainChunksAnswersAsTheRowPackedGrid) {
  const Grid g = terrain();
  PlainGrid plain;
  g.for_each_chunk([&](Vec3i p, const Chunk& c) { plain.chunks[{p.x, p.y, p.z}] = std::make_unique<PlainChunk>(c); });
  ASSERT_GT(plain.chunks.size(), 8u);

  std::mt19937 rng(3);
  std::uniform_real_distribution<float> pos(-48.0f, 48.0f), dir(-1.0f, 1.0f), half(0.1f, 2.5f);
  std::uniform_int_distribution<int> coord(-48, 47), threshold(0, 255);
  int hits = 0, collisions = 0;
  for (int i = 0; i < 2000; ++i) {
    const Vec3i p{coord(rng), coord(rng), coord(rng)};
    ASSERT_EQ(grid_get(g, p), grid_get(plain, p));
    ASSERT_EQ(g.get(p), grid_get(plain, p));

    const Vec3f o{pos(rng), pos(rng), pos(rng)}, d{dir(rng), dir(rng), dir(rng)};
    const auto min_occ = static_cast<std::uint8_t>(threshold(rng));
    const auto a = g.raycast(o, d, 80.0f, min_occ), b = grid_raycast(plain, o, d, 80.0f, min_occ);
    ASSERT_EQ(a.has_value(), b.has_value());
    if (a) {
      ++hits;
      EXPECT_EQ(a->voxel, b->voxel);
      EXPECT_EQ(a->normal, b->normal);
      EXPECT_EQ(a->value, b->value);
    }

    const Vec3f e{half(rng), half(rng), half(rng)};
    const Aabb box{o - e, o + e};
    const bool c = g.collides(box, min_occ);
    ASSERT_EQ(c, grid_collides(plain, box, min_occ));
    // Against the voxels themselves: any solid-enough voxel overlapping the open box.
    bool want = false;
    for (int y = static_cast<int>(std::floor(box.min.y)); y < static_cast<int>(std::ceil(box.max.y)); ++y)
      for (int z = static_cast<int>(std::floor(box.min.z)); z < static_cast<int>(std::ceil(box.max.z)); ++z)
        for (int x = static_cast<int>(std::floor(box.min.x)); x < static_cast<int>(std::ceil(box.max.x)); ++x) {
          const Voxel v = g.get({x, y, z});
          want = want || (v.material != kAir && v.occupancy >= min_occ);
        }
    ASSERT_EQ(c, want);
    collisions += c ? 1 : 0;

    Box from_grid({13, 9, 21}), from_plain({13, 9, 21});
    g.read_box(p, from_grid);
    grid_read_box(plain, p, from_plain);
    ASSERT_EQ(from_grid, from_plain);
  }
  // Both answers occur.
  EXPECT_GT(hits, 100);
  EXPECT_GT(collisions, 100);
  EXPECT_LT(collisions, 1900);
}

}  // namespace
}  // namespace terrane
