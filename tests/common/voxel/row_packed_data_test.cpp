// Row-packed storage over real and generated terrain: every voxel of every
// dataset in tests/data and of a piece of the default generated world reads
// back exactly after packing (through read_row's SIMD path and get()'s
// scalar one), after the pessimistic full unpack, and after repacking; every
// chunk's mip units decode to the levels the downsampling rule gives.
#include <gtest/gtest.h>

#include <string>

#include "common/codec/net_codec.h"
#include "common/voxel/grid.h"
#include "common/vxraw/vxraw.h"
#include "common/world/terrain_generator.h"
#include "tests/common/voxel/mips_check.h"

namespace terrane {
namespace {

struct Dataset {
  std::string name;
  Vec3i origin;
  Box box;
};

Dataset load(const std::string& name) {
  const std::string path = std::string(TERRANE_TEST_DATA_DIR) + "/" + name + ".vxraw.gz";
  auto file = vxraw_read_file(path, VxrawLimits{});
  EXPECT_TRUE(file.ok()) << path;
  if (!file) return {};
  return {name, file->origin, std::move(file->box)};
}

Dataset generated() {
  // The default world's surface around the spawn: smooth partial occupancy,
  // caves and several materials.
  TerrainGenerator gen(GeneratorParams{});
  const Region r{{-64, -32, -64}, {64, 96, 64}};
  Dataset d{"default world", r.min, Box{}};
  gen.generate(r, d.box);
  return d;
}

void expect_level0(const RowPackedBox<32>& box, const Box& ref, const char* when) {
  RowPackedBox<32>::Row scratch;
  for (int y = 0; y < 32; ++y)
    for (int z = 0; z < 32; ++z) {
      const Voxel* row = box.read_row(y, z, scratch);
      for (int x = 0; x < 32; ++x) {
        ASSERT_EQ(row[x], ref.get(x, y, z)) << when << " read_row at " << x << "," << y << "," << z;
        ASSERT_EQ(box.get(x, y, z), ref.get(x, y, z)) << when << " get at " << x << "," << y << "," << z;
      }
    }
}

void check_dataset(const Dataset& d) {
  ASSERT_GT(d.box.voxel_count(), 0u) << d.name;
  Grid grid;
  grid.write_box(d.origin, d.box);
  grid.compact();
  Box back(d.box.size());
  grid.read_box(d.origin, back);
  ASSERT_TRUE(back == d.box) << d.name << ": packed grid differs from its source";
  std::size_t chunks = 0, unpacked_checked = 0;
  grid.for_each_chunk([&](Vec3i pos, const Chunk& chunk) {
    if (::testing::Test::HasFatalFailure()) return;
    ++chunks;
    Box level0;
    chunk.read_level(0, level0);
    Box ref({32, 32, 32});
    grid.read_box(chunk_origin(pos), ref);
    ASSERT_TRUE(level0 == ref) << d.name;
    expect_level0(chunk.level0(), ref, "packed");
    // Mips: the stored units decode to the rule's levels.
    test_mips::expect_mips_as_rebuilt(chunk, Chunk::from_box(ref), d.name);
    if (::testing::Test::HasFatalFailure()) return;
    // The pessimistic path on a third of the chunks: unpack, read, repack.
    if (chunks % 3 != 0) return;
    RowPackedBox<32> copy = chunk.level0().clone();
    copy.unpack_all();
    ASSERT_TRUE(copy.unpacked());
    expect_level0(copy, ref, "unpacked");
    copy.set(1, 2, 3, make_voxel(materials::kSand, 77));
    ref.set(1, 2, 3, make_voxel(materials::kSand, 77));
    expect_level0(copy, ref, "written unpacked");
    copy.compact();
    ASSERT_FALSE(copy.unpacked());
    // At most the written row's raw record and, if its layer was uniform
    // with one material, that layer's 32 headers.
    EXPECT_LE(copy.heap_bytes(), chunk.level0().heap_bytes() + 2 * 32 + 8 + 2 * 32) << d.name;
    expect_level0(copy, ref, "repacked");
    ++unpacked_checked;
  });
  EXPECT_GT(chunks, 10u) << d.name;
  EXPECT_GT(unpacked_checked, 3u) << d.name;
}

TEST(RowPackedData, Mc19RoundTrips) { check_dataset(load("mc-1.9")); }
TEST(RowPackedData, Mc116RoundTrips) { check_dataset(load("mc-1.16")); }
TEST(RowPackedData, GeneratedWorldRoundTrips) { check_dataset(generated()); }

}  // namespace
}  // namespace terrane
