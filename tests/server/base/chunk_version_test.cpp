// ChunkVersion: lazily made, shared derived bytes equal what the codecs
// make directly; level_since; update pieces join into the batch one encoder
// writes.
#include "server/base/chunk_version.h"

#include <gtest/gtest.h>

#include <bit>
#include <random>
#include <thread>

#include "common/codec/net_codec.h"
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
    // The chunk's own units when it keeps its mips so, else the served
    // codec version's encoding of the level.
    std::vector<std::uint8_t> want(chunk->mip_unit(level).begin(), chunk->mip_unit(level).end());
    if (want.empty()) net_codec_encode(n, box.voxels(), want, kServedCodecVersion);
    EXPECT_TRUE(std::equal(want.begin(), want.end(), v.encoded(level).begin(), v.encoded(level).end())) << level;
  }
  EXPECT_EQ(v.hash(), chunk_hash(chunk.get(), 7));
  const auto blob = encode_chunk_blob(*chunk);
  EXPECT_EQ(v.blob(), blob);
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

// Level's mip of a version, decoded from its own bytes.
Box mip_of(const ChunkVersion& v, int level) {
  const int n = kChunkSize >> level;
  Box box({n, n, n});
  EXPECT_TRUE(net_codec_decode(n, v.encoded(level), box.voxels()).ok());
  return box;
}

// What a client holding `held` at level makes of a Mip patch from v.
Box patched(const Box& held, const ChunkVersion& v, int level, std::uint64_t mask) {
  std::vector<std::uint8_t> units;
  v.append_patch_units(level, mask, units);
  Box out = held;
  std::span<const std::uint8_t> rest = units;
  Box unit({4, 4, 4});
  for (std::uint64_t m = mask; m != 0; m &= m - 1) {
    auto used = net_codec_decode_prefix(4, rest, unit.voxels());
    EXPECT_TRUE(used.ok());
    if (!used.ok()) return out;
    rest = rest.subspan(*used);
    const int side = (kChunkSize >> level) / 4, i = std::countr_zero(m);
    const Vec3i o = Vec3i{i % side, i / (side * side), (i / side) % side} * 4;
    for (int y = 0; y < 4; ++y)
      for (int z = 0; z < 4; ++z)
        for (int x = 0; x < 4; ++x) out.set(o.x + x, o.y + y, o.z + z, unit.get(x, y, z));
  }
  EXPECT_TRUE(rest.empty());
  return out;
}

TEST(ChunkVersion, AMipPatchFromAnyRevisionInItsHistoryMakesTheNewMip) {
  std::vector<std::shared_ptr<const ChunkVersion>> versions;
  versions.push_back(std::make_shared<const ChunkVersion>(Vec3i{1, 0, 2}, 10, std::make_shared<const Chunk>(sample_chunk())));
  // A version loaded or generated has no history to patch from.
  EXPECT_FALSE(versions[0]->changed_since(1, 9).has_value());
  std::mt19937 rng(5);
  for (int k = 0; k < 12; ++k) {
    // A small box edit somewhere in the chunk; its changed 4^3 units.
    auto next = std::make_unique<Chunk>(versions.back()->chunk()->clone());
    const Vec3i lo{static_cast<int>(rng() % 28), static_cast<int>(rng() % 28), static_cast<int>(rng() % 28)};
    const Region r{lo, lo + Vec3i{1 + static_cast<int>(rng() % 4), 1 + static_cast<int>(rng() % 4), 3}};
    const Material m = static_cast<Material>(1 + rng() % 5);
    next->modify(r, [&](Vec3i, Voxel) { return make_voxel(m, static_cast<std::uint8_t>(60 + rng() % 190)); });
    UnitBits changed;
    for (int y = r.min.y / 4; y <= (r.max.y - 1) / 4; ++y)
      for (int z = r.min.z / 4; z <= (r.max.z - 1) / 4; ++z)
        for (int x = r.min.x / 4; x <= (r.max.x - 1) / 4; ++x) changed.set(static_cast<std::size_t>((y * 8 + z) * 8 + x));
    versions.push_back(ChunkVersion::after(*versions.back(), std::move(next), changed));
  }
  for (std::size_t now = 1; now < versions.size(); ++now) {
    const ChunkVersion& v = *versions[now];
    for (std::size_t held = 0; held < now; ++held) {
      for (int level = 1; level <= 2; ++level) {
        const auto mask = v.changed_since(level, versions[held]->revision());
        if (now - held > static_cast<std::size_t>(ChunkVersion::kPatchHistory)) {
          EXPECT_FALSE(mask.has_value()) << now << " from " << held;
          continue;
        }
        ASSERT_TRUE(mask.has_value()) << now << " from " << held;
        EXPECT_NE(*mask, 0u);
        if (level == 2) {
          EXPECT_LT(*mask, 256u);
        }
        EXPECT_EQ(patched(mip_of(*versions[held], level), v, level, *mask), mip_of(v, level))
            << "level " << level << ", revision " << v.revision() << " from " << versions[held]->revision();
      }
    }
    EXPECT_FALSE(v.changed_since(1, v.revision()).has_value()) << "nothing is newer than itself";
  }
  // A version keeping only its mips keeps its history, not its changed
  // units (it has no voxels to read them from).
  ASSERT_TRUE(versions.back()->changed_units().any());
  const auto mips = ChunkVersion::mips_only(*versions.back());
  EXPECT_TRUE(mips->changed_units().none());
  const auto held = versions[versions.size() - 3];
  const auto mask = mips->changed_since(1, held->revision());
  ASSERT_TRUE(mask.has_value());
  EXPECT_EQ(patched(mip_of(*held, 1), *mips, 1, *mask), mip_of(*versions.back(), 1));
  // Changed units given to the constructor are its own, with no history
  // to patch from (only after() makes one).
  UnitBits some;
  some.set(7);
  const ChunkVersion given({1, 0, 2}, 30, std::make_shared<const Chunk>(sample_chunk()), some, {30, 30, 30, 30});
  EXPECT_EQ(given.changed_units(), some);
  EXPECT_FALSE(given.changed_since(1, 29).has_value());
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
