// ChunkVersion: lazily made, shared derived bytes equal what the codecs
// make directly; level_since; update pieces join into the batch one encoder
// writes.
#include "server/base/chunk_version.h"

#include <gtest/gtest.h>

#include <thread>

#include "common/codec/update_batch.h"
#include "common/world/sqlite_store.h"
#include "protocol/messages.h"

namespace terrane {
namespace {

Chunk sample_chunk() {
  Chunk c;
  c.modify(Region{{0, 0, 0}, {32, 10, 32}}, [](Vec3i p, Voxel) {
    return make_voxel(static_cast<Material>(1 + (p.x / 5 + p.z / 7) % 4), 255);
  });
  c.set({3, 10, 4}, make_voxel(materials::kGrass, 100));
  return c;
}

TEST(ChunkVersion, DerivedBytesAreTheCodecsOwn) {
  auto chunk = std::make_shared<const Chunk>(sample_chunk());
  const ChunkVersion v({2, -1, 5}, 7, chunk);
  for (int level = 1; level < kMipLevels; ++level) {
    const int n = kChunkSize >> level;
    Box box({n, n, n});
    chunk->read_level(level, box);
    std::vector<std::uint8_t> want;
    net_codec_encode(n, box.voxels(), want);
    EXPECT_TRUE(std::equal(want.begin(), want.end(), v.encoded(level).begin(), v.encoded(level).end())) << level;
  }
  EXPECT_EQ(v.hash(), chunk_hash(chunk.get(), 7));
  const auto blob = encode_chunk_blob(*chunk);
  EXPECT_TRUE(std::equal(blob.begin(), blob.end(), v.blob().begin(), v.blob().end()));
  // Full: eight 16^3 units that decode to the chunk.
  std::vector<Voxel> unit(16 * 16 * 16);
  std::span<const std::uint8_t> rest = v.encoded(0);
  for (int i = 0; i < 8; ++i) {
    auto used = net_codec_decode_prefix(16, rest, unit);
    ASSERT_TRUE(used.ok());
    rest = rest.subspan(*used);
    const Vec3i o = Vec3i{i & 1, (i >> 1) & 1, (i >> 2) & 1} * 16;
    EXPECT_EQ(unit[static_cast<std::size_t>((3 * 16 + 4) * 16 + 5)], chunk->get(o + Vec3i{5, 3, 4}));
  }
  EXPECT_TRUE(rest.empty());
}

TEST(ChunkVersion, ReadersOnManyThreadsShareOneEncoding) {
  auto v = std::make_shared<const ChunkVersion>(Vec3i{0, 0, 0}, 1, std::make_shared<const Chunk>(sample_chunk()));
  std::vector<const std::uint8_t*> seen(8);
  std::vector<std::thread> ts;
  for (std::size_t i = 0; i < seen.size(); ++i) ts.emplace_back([&, i] { seen[i] = v->encoded(1).data(); });
  for (auto& t : ts) t.join();
  for (const auto* p : seen) EXPECT_EQ(p, seen.front());
}

TEST(ChunkVersion, LevelsChangedSeesOnlyLevelsWhoseVoxelsDiffer) {
  const Chunk a = sample_chunk();
  Chunk b = a.clone();
  // One voxel inside a solid 8^3 block, same occupancy, another material:
  // the level-3 mode of that block does not change, level 1's voxel does.
  b.set({1, 1, 1}, make_voxel(materials::kSnow, 255));
  const auto d = levels_changed(&a, &b);
  EXPECT_TRUE(d[0]);
  EXPECT_FALSE(d[3]);
  const auto same = levels_changed(&a, &a);
  EXPECT_FALSE(same[1] || same[2] || same[3]);
  const auto gone = levels_changed(&a, nullptr);
  EXPECT_TRUE(gone[1] && gone[2] && gone[3]);
}

TEST(UpdatePieces, JoinedPiecesAreTheBatchOneEncoderWrites) {
  std::vector<UnitUpdate> all;
  std::vector<UpdatePiece> pieces;
  for (const Vec3i cp : {Vec3i{0, 0, 0}, Vec3i{0, 0, 1}, Vec3i{-3, 2, 1}, Vec3i{5, 2, -9}}) {
    std::vector<UnitUpdate> units;
    for (const int idx : {0, 7, 8, 200, 511}) {
      UnitUpdate u;
      u.chunk_pos = cp;
      u.unit_index = static_cast<std::uint16_t>(idx);
      for (std::size_t i = 0; i < u.voxels.size(); ++i)
        u.voxels[i] = make_voxel(static_cast<Material>(1 + (i + static_cast<std::size_t>(idx)) % 3), 255);
      units.push_back(u);
    }
    all.insert(all.end(), units.begin(), units.end());
    pieces.push_back(net_codec_encode_update_piece(units));
  }
  std::vector<const UpdatePiece*> order;
  for (const auto& p : pieces) order.push_back(&p);
  std::sort(order.begin(), order.end(), [](const UpdatePiece* a, const UpdatePiece* b) {
    return std::tie(a->chunk_pos.y, a->chunk_pos.z, a->chunk_pos.x) < std::tie(b->chunk_pos.y, b->chunk_pos.z, b->chunk_pos.x);
  });
  std::vector<std::uint8_t> joined, direct;
  net_codec_join_update_pieces(order, joined);
  net_codec_encode_update_batch(all, direct);
  EXPECT_EQ(joined, direct);
  // Any order decodes to the same set.
  std::vector<const UpdatePiece*> reversed(order.rbegin(), order.rend());
  std::vector<std::uint8_t> other;
  net_codec_join_update_pieces(reversed, other);
  std::vector<UnitUpdate> out(all.size());
  auto n = net_codec_decode_update_batch(other, out);
  ASSERT_TRUE(n.ok());
  EXPECT_EQ(*n, all.size());
}

}  // namespace
}  // namespace terrane
