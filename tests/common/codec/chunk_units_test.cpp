#include "common/codec/chunk_units.h"

#include <gtest/gtest.h>

#include <random>
#include <vector>

#include "common/voxel/chunk.h"

namespace terrane {
namespace {

// A chunk with every row kind: uniform, index and run records, occupancy.
Chunk mixed_chunk() {
  Box b({kChunkSize, kChunkSize, kChunkSize});
  std::mt19937 rng(9);
  std::uniform_int_distribution<int> m(1, 6), occ(1, 255), coin(0, 3);
  for (int y = 0; y < kChunkSize; ++y)
    for (int z = 0; z < kChunkSize; ++z)
      for (int x = 0; x < kChunkSize; ++x) {
        Voxel v{};
        if (y < 10) v = solid(materials::kRock);
        else if (y < 16) v = solid(static_cast<Material>(x < 11 ? 2 : x < 20 ? 3 : 4));
        else if (y < 22) v = solid(static_cast<Material>(m(rng)));
        else if (y < 24 && coin(rng) == 0) v = make_voxel(materials::kSand, static_cast<std::uint8_t>(occ(rng)));
        b.set(x, y, z, v);
      }
  return Chunk::from_box(b);
}

TEST(ChunkUnits, UpdateUnitsHoldTheChunksVoxelsWhateverTheirOrderOrGrouping) {
  const Chunk c = mixed_chunk();
  std::mt19937 rng(4);
  std::uniform_int_distribution<int> unit(0, kUpdateUnitsPerChunk - 1);
  std::vector<UnitUpdate> units;
  for (int i = 0; i < kUpdateUnitsPerChunk; ++i) {  // all of them, in index order
    UnitUpdate u;
    u.unit_index = static_cast<std::uint16_t>(i);
    units.push_back(u);
  }
  for (int i = 0; i < 200; ++i) {  // and some again, in no order
    UnitUpdate u;
    u.unit_index = static_cast<std::uint16_t>(unit(rng));
    units.push_back(u);
  }
  read_update_units(&c, std::span<UnitUpdate>(units));
  for (const UnitUpdate& u : units) {
    const int i = u.unit_index;
    const Vec3i base{(i % 8) * 4, (i / 64) * 4, ((i / 8) % 8) * 4};
    for (int y = 0; y < 4; ++y)
      for (int z = 0; z < 4; ++z)
        for (int x = 0; x < 4; ++x)
          ASSERT_EQ(u.voxels[static_cast<std::size_t>((y * 4 + z) * 4 + x)], c.get(base + Vec3i{x, y, z}))
              << "unit " << i;
  }
  // A null chunk is all Air.
  units.resize(3);
  units[1].voxels.fill(solid(materials::kRock));
  read_update_units(static_cast<const Chunk*>(nullptr), std::span<UnitUpdate>(units));
  for (const UnitUpdate& u : units)
    for (const Voxel v : u.voxels) ASSERT_EQ(v, Voxel{});
}

TEST(ChunkUnits, FullUnitsDecodeToTheChunksEightHalves) {
  const Chunk c = mixed_chunk();
  std::vector<std::uint8_t> bytes;
  encode_full_units(&c, bytes);
  constexpr int u = kChunkSize / 2;
  std::span<const std::uint8_t> rest(bytes);
  for (int i = 0; i < 8; ++i) {
    Box half({u, u, u});
    auto n = net_codec_decode_prefix(u, rest, half.voxels());
    ASSERT_TRUE(n.ok()) << n.error().describe();
    rest = rest.subspan(*n);
    const Vec3i o = Vec3i{i & 1, (i >> 1) & 1, (i >> 2) & 1} * u;
    for (int y = 0; y < u; ++y)
      for (int z = 0; z < u; ++z)
        for (int x = 0; x < u; ++x) ASSERT_EQ(half.get(x, y, z), c.get(o + Vec3i{x, y, z})) << "unit " << i;
  }
  EXPECT_TRUE(rest.empty());
}

}  // namespace
}  // namespace terrane
