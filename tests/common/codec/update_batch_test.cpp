#include "common/codec/update_batch.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <vector>

#include "common/voxel/chunk.h"
#include "tests/common/codec/test_units.h"

namespace terrane {
namespace {

using namespace test_units;

UnitUpdate make_update(Vec3i chunk, int unit, std::vector<Voxel> v) {
  UnitUpdate u;
  u.chunk_pos = chunk;
  u.unit_index = static_cast<std::uint16_t>(unit);
  std::copy(v.begin(), v.end(), u.voxels.begin());
  return u;
}

TEST(NetCodecUpdateBatch, RoundTrips) {
  std::mt19937 rng(5);
  std::vector<UnitUpdate> updates = {
      make_update({0, 0, 0}, 0, make_unit(4)),
      make_update({-3, 2, 7}, 511, terrain_unit(4, 1.2f, 0.5f)),
      make_update({-3, 2, 7}, 12, random_unit(4, rng, 64, true)),
      make_update({-3, 2, 7}, 13, make_unit(4, solid(9))),
      make_update({2147483647, -2147483647 - 1, 5}, 300, random_unit(4, rng, 3, false)),
      make_update({-2147483647 - 1, 2147483647, -5}, 1, make_unit(4, make_voxel(4, 77))),
  };
  std::vector<std::uint8_t> bytes;
  net_codec_encode_update_batch(updates, bytes);
  std::vector<UnitUpdate> out(updates.size());
  auto n = net_codec_decode_update_batch(bytes, out);
  ASSERT_TRUE(n.ok()) << n.error().describe();
  ASSERT_EQ(*n, updates.size());
  std::sort(updates.begin(), updates.end(), update_batch_order);
  EXPECT_EQ(out, updates);

  // Too small an output is over limit; every prefix is rejected; trailing
  // bytes are rejected.
  std::vector<UnitUpdate> small(updates.size() - 1);
  auto over = net_codec_decode_update_batch(bytes, small);
  ASSERT_FALSE(over.ok());
  EXPECT_EQ(over.error().code, DecodeErrorCode::kOverLimit);
  for (std::size_t len = 0; len < bytes.size(); ++len) {
    std::vector<std::uint8_t> prefix(bytes.begin(), bytes.begin() + static_cast<std::ptrdiff_t>(len));
    EXPECT_FALSE(net_codec_decode_update_batch(prefix, out).ok()) << len;
  }
  bytes.push_back(0);
  auto trailing = net_codec_decode_update_batch(bytes, out);
  ASSERT_FALSE(trailing.ok());
  EXPECT_EQ(trailing.error().code, DecodeErrorCode::kTrailingBytes);
}

TEST(NetCodecUpdateBatch, EmptyBatchAndBadIndices) {
  std::vector<std::uint8_t> bytes;
  net_codec_encode_update_batch({}, bytes);
  EXPECT_EQ(bytes, (std::vector<std::uint8_t>{0x01, 0x00}));
  std::vector<UnitUpdate> out(4);
  auto n = net_codec_decode_update_batch(bytes, out);
  ASSERT_TRUE(n.ok());
  EXPECT_EQ(*n, 0u);
  // Unit index 512 (tag 1024 = varint 0x80 0x08), chunk deltas 0, all-Air unit.
  auto bad = net_codec_decode_update_batch(std::vector<std::uint8_t>{0x01, 0x01, 0x80, 0x08, 0, 0, 0, 0x01}, out);
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.error().code, DecodeErrorCode::kInvalidValue);
  // Over-long varint count.
  auto big = net_codec_decode_update_batch(std::vector<std::uint8_t>{0x01, 0xFF, 0xFF, 0xFF, 0xFF, 0x7F}, out);
  ASSERT_FALSE(big.ok());
  // Wrong batch version.
  auto ver = net_codec_decode_update_batch(std::vector<std::uint8_t>{0x02, 0x00}, out);
  ASSERT_FALSE(ver.ok());
  EXPECT_EQ(ver.error().code, DecodeErrorCode::kBadVersion);
}

TEST(ChunkUnitsTest, EachVoxelOfTheBoxIsItsUnitsOrLeftAsItWas) {
  ChunkUnits units;
  EXPECT_TRUE(units.empty());
  EXPECT_EQ(units.box(), Region{});
  // Units 1 (x 4..8) and 8 * 8 * 2 + 3 (y 8..12, x 12..16), each voxel
  // telling its place.
  UnitUpdate a{{0, 0, 0}, 1, {}}, b{{0, 0, 0}, 8 * 8 * 2 + 3, {}};
  for (int i = 0; i < kUpdateUnitVoxels; ++i) {
    a.voxels[static_cast<std::size_t>(i)] = Voxel{static_cast<Material>(1 + i % 60), static_cast<std::uint8_t>(i)};
    b.voxels[static_cast<std::size_t>(i)] = Voxel{static_cast<Material>(2 + i % 60), static_cast<std::uint8_t>(i)};
  }
  EXPECT_TRUE(units.add(a));
  EXPECT_TRUE(units.add(b));
  EXPECT_EQ(units.box(), (Region{{4, 0, 0}, {16, 12, 4}}));
  const Voxel old{3, 7};
  // Voxel (x, y, z) of a unit is its voxels[(y * 4 + z) * 4 + x].
  EXPECT_EQ(units.at({4 + 1, 2, 3}, old), a.voxels[(2 * 4 + 3) * 4 + 1]);
  EXPECT_EQ(units.at({12 + 3, 8 + 1, 2}, old), b.voxels[(1 * 4 + 2) * 4 + 3]);
  EXPECT_EQ(units.at({0, 0, 0}, old), old);    // unit 0: not added
  EXPECT_EQ(units.at({8, 8, 0}, old), old);    // inside the box, no unit there
  // A unit added twice: the last one stands, and add says so.
  UnitUpdate a2 = a;
  a2.voxels.fill(Voxel{9, 9});
  EXPECT_FALSE(units.add(a2));
  EXPECT_EQ(units.at({4, 0, 0}, old), (Voxel{9, 9}));
  units.clear();
  EXPECT_TRUE(units.empty());
  EXPECT_EQ(units.at({4, 0, 0}, old), old);
}

// A chunk's batch of units is written into the chunk whole, or, when it
// does not decode, holds no unit, a unit of another chunk or a unit twice,
// refused before anything is written.
TEST(ApplyChunkUpdateBatchTest, WritesEveryUnitOfTheBatchOrNothing) {
  const Vec3i cp{4, -1, 2};
  UnitUpdate a{cp, 1, {}}, b{cp, 200, {}};
  a.voxels.fill(Voxel{5, 255});
  b.voxels.fill(Voxel{7, 100});
  std::vector<std::uint8_t> batch;
  net_codec_encode_update_batch(std::vector<UnitUpdate>{a, b}, batch);
  Chunk chunk(kAir);
  std::vector<UnitUpdate> scratch;
  auto written = apply_chunk_update_batch(batch, cp, chunk, scratch);
  ASSERT_TRUE(written.ok()) << written.error().describe();
  EXPECT_EQ(written->count(), 2u);
  EXPECT_TRUE(written->test(1) && written->test(200));
  EXPECT_EQ(chunk.get({4 + 3, 3, 3}), (Voxel{5, 255}));  // unit 1: x 4..8
  const Vec3i b_base{200 % 8 * 4, 200 / 64 * 4, 200 / 8 % 8 * 4};
  EXPECT_EQ(chunk.get(b_base), (Voxel{7, 100}));
  EXPECT_EQ(chunk.get({0, 0, 0}), Voxel{});

  const Chunk before = chunk.clone();
  auto unchanged = [&] {
    for (int y = 0; y < kChunkSize; ++y)
      for (int z = 0; z < kChunkSize; ++z)
        for (int x = 0; x < kChunkSize; ++x)
          if (chunk.get(x, y, z) != before.get(x, y, z)) return false;
    return true;
  };
  UnitUpdate elsewhere{cp + Vec3i{1, 0, 0}, 3, {}};
  elsewhere.voxels.fill(Voxel{9, 9});
  UnitUpdate c{cp, 2, {}};
  c.voxels.fill(Voxel{9, 9});
  for (const auto& [units, why] : std::vector<std::pair<std::vector<UnitUpdate>, const char*>>{
           {{c, elsewhere}, "a unit of another chunk"}, {{}, "none"}}) {
    std::vector<std::uint8_t> bad;
    net_codec_encode_update_batch(units, bad);
    auto refused = apply_chunk_update_batch(bad, cp, chunk, scratch);
    ASSERT_FALSE(refused.ok()) << why;
    EXPECT_NE(refused.error().describe().find(why), std::string::npos) << refused.error().describe();
    EXPECT_TRUE(unchanged()) << why;
  }
  // A unit twice (a batch is a set; this one is made by hand: both pieces
  // joined) and bytes that do not decode.
  const UnitUpdate c2 = c;
  std::vector<std::uint8_t> twice;
  std::vector<UpdatePiece> pieces{net_codec_encode_update_piece(std::span(&c, 1)),
                                  net_codec_encode_update_piece(std::span(&c2, 1))};
  const UpdatePiece* joined[] = {&pieces[0], &pieces[1]};
  net_codec_join_update_pieces(joined, twice);
  auto doubled = apply_chunk_update_batch(twice, cp, chunk, scratch);
  ASSERT_FALSE(doubled.ok());
  EXPECT_TRUE(unchanged());
  std::vector<std::uint8_t> cut(batch.begin(), batch.begin() + static_cast<std::ptrdiff_t>(batch.size() / 2));
  EXPECT_FALSE(apply_chunk_update_batch(cut, cp, chunk, scratch).ok());
  EXPECT_TRUE(unchanged());
}

}  // namespace
}  // namespace terrane
