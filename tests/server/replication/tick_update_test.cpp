// TickUpdate: one tick's UpdateBatch frame for a client joins the versions'
// pieces in chunk order (y, z, x) whatever order they were added in, so the
// batch is what one encoder writes of the same units, lists each chunk's
// new revision in that order and counts the units; the test seam may drop
// the batch.
#include "server/replication/tick_update.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <memory>
#include <random>

#include "common/codec/update_batch.h"
#include "protocol/messages.h"

namespace terrane {
namespace {

// The version after an all-Air revision 4 of cp with one voxel of each
// unit in units made solid.
VersionPtr changed(Vec3i cp, std::initializer_list<int> units) {
  const ChunkVersion prev(cp, 4, nullptr);
  auto chunk = std::make_unique<Chunk>();
  UnitBits bits;
  for (const int u : units) {
    const int ux = u % 8, uz = (u / 8) % 8, uy = u / 64;
    chunk->set({ux * 4, uy * 4, uz * 4}, solid(materials::kRock));
    bits.set(static_cast<std::size_t>(u));
  }
  return ChunkVersion::after(prev, std::move(chunk), bits);
}

// Drops every batch.
class DropAll final : public UpdateFaults {
 public:
  bool tamper(std::vector<const UpdatePiece*>&, UpdatePiece&) override { return false; }
};

TEST(TickUpdate, TheBatchJoinsThePiecesInChunkOrderWithEachChunksRevision) {
  const VersionPtr a = changed({0, 1, 0}, {0, 9}), b = changed({5, 0, 0}, {3}), c = changed({0, 0, 2}, {511});
  TickUpdate update;
  EXPECT_TRUE(update.empty());
  update.add(a);
  update.add(b);
  update.add(c);
  EXPECT_FALSE(update.empty());
  std::size_t units = 0;
  auto frame = update.finish(42, nullptr, units);
  ASSERT_TRUE(frame);
  EXPECT_EQ(units, 4u);
  const Frame bytes = frame->flatten();
  auto m = verify_message(std::span<const std::uint8_t>(bytes).subspan(kFrameHeaderBytes));
  ASSERT_TRUE(m.ok());
  ASSERT_EQ((*m)->body_type(), wire::Body::UpdateBatch);
  auto batch = parse_update_batch(*(*m)->body_as_UpdateBatch());
  ASSERT_TRUE(batch.ok());
  EXPECT_EQ(batch->tick, 42u);
  // y, then z, then x: b (y 0, z 0), c (y 0, z 2), a (y 1).
  ASSERT_EQ(batch->revisions.size(), 3u);
  EXPECT_EQ(batch->revisions[0].chunk_pos, b->pos());
  EXPECT_EQ(batch->revisions[1].chunk_pos, c->pos());
  EXPECT_EQ(batch->revisions[2].chunk_pos, a->pos());
  for (const auto& r : batch->revisions) EXPECT_EQ(r.revision, 5u);
  std::vector<std::uint8_t> expected;
  const std::vector<const UpdatePiece*> in_order{&b->update_piece(), &c->update_piece(), &a->update_piece()};
  net_codec_join_update_pieces(in_order, expected);
  EXPECT_TRUE(std::equal(batch->data.begin(), batch->data.end(), expected.begin(), expected.end()));
  std::vector<UnitUpdate> decoded(8);
  auto n = net_codec_decode_update_batch(batch->data, decoded);
  ASSERT_TRUE(n.ok());
  EXPECT_EQ(*n, 4u);
}

// The version after an all-Air revision 4 of cp whose first n units are
// noise: pieces of over a kilobyte.
VersionPtr noisy(Vec3i cp, int n, unsigned seed) {
  const ChunkVersion prev(cp, 4, nullptr);
  auto chunk = std::make_unique<Chunk>();
  std::mt19937 rng(seed);
  UnitBits bits;
  for (int u = 0; u < n; ++u) {
    const Vec3i at{u % 8 * 4, u / 64 * 4, u / 8 % 8 * 4};
    for (int y = 0; y < 4; ++y)
      for (int z = 0; z < 4; ++z)
        for (int x = 0; x < 4; ++x)
          chunk->set(at + Vec3i{x, y, z},
                     make_voxel(static_cast<Material>(1 + rng() % 8), static_cast<std::uint8_t>(rng() | 1)));
    bits.set(static_cast<std::size_t>(u));
  }
  return ChunkVersion::after(prev, std::move(chunk), bits);
}

// Puts a copy of the first piece in its place (what the corrupting seam
// does, minus the corruption).
class CopyFirst final : public UpdateFaults {
 public:
  bool tamper(std::vector<const UpdatePiece*>& pieces, UpdatePiece& scratch) override {
    scratch = *pieces.front();
    pieces.front() = &scratch;
    return true;
  }
};

TEST(TickUpdate, TheFrameSharesThePiecesAndIsTheCopiedFrameByteForByte) {
  const VersionPtr a = noisy({0, 1, 0}, 20, 1), b = changed({5, 0, 0}, {3}), c = noisy({0, 0, 2}, 30, 2);
  ASSERT_GE(a->update_piece().rest.size(), OutFrame::kMinSharedBytes);
  ASSERT_GE(c->update_piece().rest.size(), OutFrame::kMinSharedBytes);
  ASSERT_LT(b->update_piece().rest.size(), OutFrame::kMinSharedBytes);
  const std::vector<const UpdatePiece*> in_order{&b->update_piece(), &c->update_piece(), &a->update_piece()};
  std::vector<std::uint8_t> data;
  net_codec_join_update_pieces(in_order, data);
  const std::vector<ChunkRevisionMsg> revisions{{b->pos(), 5}, {c->pos(), 5}, {a->pos(), 5}};
  const Frame expected = build_update_batch(7, data, revisions);
  for (const bool tampered : {false, true}) {
    TickUpdate update;
    update.add(a);
    update.add(c);
    update.add(b);
    CopyFirst copy_first;
    std::size_t units = 0;
    const auto frame = update.finish(7, tampered ? &copy_first : nullptr, units);
    ASSERT_TRUE(frame);
    EXPECT_EQ(units, 51u);
    EXPECT_EQ(frame->flatten(), expected) << tampered;
    // c's and a's rests are the versions' own bytes in the frame; b's is
    // copied (short), and so is a piece the seam replaced (its scratch is
    // gone once finish returns).
    EXPECT_EQ(frame->shared_bytes(), c->update_piece().rest.size() + a->update_piece().rest.size());
    std::vector<const std::uint8_t*> starts;
    frame->for_each_segment([&](std::span<const std::uint8_t> s) { starts.push_back(s.data()); });
    for (const auto& v : {a, c})
      EXPECT_NE(std::find(starts.begin(), starts.end(), v->update_piece().rest.data()), starts.end());
  }
  // The first piece replaced, when it is one to share: copied.
  TickUpdate update;
  update.add(c);
  CopyFirst copy_first;
  std::size_t units = 0;
  const auto frame = update.finish(7, &copy_first, units);
  ASSERT_TRUE(frame);
  EXPECT_EQ(frame->shared_bytes(), 0u);
}

TEST(TickUpdate, TheTestSeamMayDropTheBatch) {
  TickUpdate update;
  update.add(changed({0, 0, 0}, {1}));
  DropAll drop;
  std::size_t units = 0;
  EXPECT_EQ(update.finish(1, &drop, units), std::nullopt);
}

}  // namespace
}  // namespace terrane
