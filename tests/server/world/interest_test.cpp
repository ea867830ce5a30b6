// InterestIndex and PresenceGrid: the world strand's indexes.
#include "server/world/interest.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <random>
#include <tuple>
#include <vector>

#include "server/world/presence.h"

namespace terrane {
namespace {

// The holders of a chunk, by id.
std::map<ClientId, bool> holders(const InterestIndex& idx, Vec3i chunk_pos) {
  std::map<ClientId, bool> m;
  idx.for_each_holder(chunk_pos, [&](InterestIndex::Holder h) { EXPECT_TRUE(m.emplace(h.id(), h.full()).second); });
  EXPECT_EQ(m.size(), idx.holder_count(chunk_pos));
  return m;
}

TEST(InterestIndex, HoldersAreExactlyThoseThatHoldAndNotReleased) {
  InterestIndex idx;
  const Vec3i a{1, 2, 3}, b{-4, 0, 9};
  idx.hold(a, 7, false);
  idx.hold(a, 8, true);
  idx.hold(b, 7, false);
  idx.hold(a, 7, false);  // again: still one entry
  EXPECT_EQ(holders(idx, a), (std::map<ClientId, bool>{{7, false}, {8, true}}));
  EXPECT_EQ(idx.entries(), 3u);
  EXPECT_TRUE(idx.held_full(a));
  EXPECT_FALSE(idx.held_full(b));
  idx.hold(b, 7, true);  // refined to full
  EXPECT_TRUE(idx.held_full(b));
  idx.release(a, 8);
  EXPECT_FALSE(idx.held_full(a));
  EXPECT_EQ(holders(idx, a), (std::map<ClientId, bool>{{7, false}}));
  idx.release(a, 7);
  idx.release(a, 7);  // twice: harmless
  EXPECT_FALSE(idx.watched(a));
  EXPECT_TRUE(holders(idx, a).empty());
  EXPECT_EQ(idx.chunks(), 1u);
  EXPECT_EQ(idx.entries(), 1u);
}

// The cost bound: with 10,000 holders on one chunk, holding, asking about
// and releasing one costs a few probes each, not a scan of the holders.
TEST(InterestIndex, OneHolderChangedCostsBoundedProbesWhateverTheCount) {
  InterestIndex idx;
  const Vec3i c{0, 0, 0};
  constexpr ClientId kHolders = 10'000;
  std::uint64_t before = idx.probes();
  for (ClientId id = 1; id <= kHolders; ++id) idx.hold(c, id, id % 3 == 0);
  // Adding: amortized a few probes each (rebuilds of the chunk's index
  // compare no ids).
  EXPECT_LT(idx.probes() - before, 4 * kHolders);
  ASSERT_EQ(idx.holder_count(c), kHolders);
  std::uint64_t worst = 0, total = 0;
  std::mt19937 rng(5);
  std::vector<ClientId> order;
  for (ClientId id = 1; id <= kHolders; ++id) order.push_back(id);
  std::shuffle(order.begin(), order.end(), rng);
  for (std::size_t i = 0; i < kHolders / 2; ++i) {
    before = idx.probes();
    EXPECT_TRUE(idx.holds(c, order[i]));
    idx.hold(c, order[i], true);   // refined: found, not added
    idx.release(c, order[i]);
    const std::uint64_t cost = idx.probes() - before;
    worst = std::max(worst, cost);
    total += cost;
  }
  // A scan would compare thousands of ids per call; the index a few.
  EXPECT_LE(worst, 64u);
  EXPECT_LT(total, 12 * (kHolders / 2));
  EXPECT_EQ(idx.holder_count(c), kHolders / 2);
  EXPECT_EQ(idx.entries(), kHolders / 2);
  // Asking about one that left costs no more.
  before = idx.probes();
  EXPECT_FALSE(idx.holds(c, order[0]));
  EXPECT_LE(idx.probes() - before, 64u);
}

// Invariants under a random sequence of holds and releases, checked
// against a plain reference: holders(), holds, held_full, watched,
// entries, chunks.
TEST(InterestIndex, MatchesAReferenceUnderRandomHoldsAndReleases) {
  InterestIndex idx;
  std::map<Vec3i, std::map<ClientId, bool>, bool (*)(const Vec3i&, const Vec3i&)> ref(
      [](const Vec3i& a, const Vec3i& b) { return std::tie(a.x, a.y, a.z) < std::tie(b.x, b.y, b.z); });
  std::mt19937 rng(11);
  // Few chunks and many clients, so some chunks' holders grow past the
  // scanned size and shrink back below it, again and again.
  // Chunks of a few regions, on both sides of zero.
  const std::vector<Vec3i> chunks{{0, 0, 0}, {1, 0, 0}, {7, 7, 7}, {8, 0, 0}, {-1, 0, 0}, {-9, 3, -17}};
  std::uniform_int_distribution<int> chunk(0, 5), client(1, 60), op(0, 9);
  for (int step = 0; step < 40'000; ++step) {
    const Vec3i cp = chunks[static_cast<std::size_t>(chunk(rng))];
    const ClientId id = static_cast<ClientId>(client(rng));
    // Phases that favour holding, then releasing, so the counts swing.
    const bool holding = (step / 4'000) % 2 == 0 ? op(rng) < 7 : op(rng) < 3;
    if (holding) {
      const bool full = op(rng) < 4;
      idx.hold(cp, id, full);
      ref[cp][id] = full;
    } else {
      idx.release(cp, id);
      if (auto it = ref.find(cp); it != ref.end()) {
        it->second.erase(id);
        if (it->second.empty()) ref.erase(it);
      }
    }
    if (step % 97 != 0) continue;
    std::size_t entries = 0;
    for (const auto& [pos, holders] : ref) {
      entries += holders.size();
      ASSERT_EQ(terrane::holders(idx, pos), holders) << "step " << step;
      bool any_full = false;
      for (const auto& [id2, full] : holders) any_full = any_full || full;
      EXPECT_EQ(idx.held_full(pos), any_full);
      EXPECT_TRUE(idx.watched(pos));
      EXPECT_TRUE(idx.holds(pos, holders.begin()->first));
    }
    EXPECT_EQ(idx.entries(), entries);
    EXPECT_EQ(idx.chunks(), ref.size());
  }
  for (const Vec3i cp : chunks)
    if (!ref.count(cp)) {
      EXPECT_FALSE(idx.watched(cp));
      EXPECT_TRUE(holders(idx, cp).empty());
    }
}

// Holders are kept per region: many clients each holding a view's worth of
// chunks (here 100 clients, 4,096 chunks each in 8 regions) cost about a
// byte per (chunk, holder) in all, where an entry per chunk and holder cost
// 8 bytes and its share of an index (about 20 bytes).
TEST(InterestIndex, ManyHoldersOfAViewsChunksCostAboutAByteEach) {
  InterestIndex idx;
  constexpr ClientId kClients = 100;
  for (ClientId id = 1; id <= kClients; ++id)
    for (int y = 0; y < 8; ++y)
      for (int z = -8; z < 8; ++z)
        for (int x = -16; x < 16; ++x) idx.hold({x, y, z}, id, y == 0 && z == 0 && x == 0);
  EXPECT_EQ(idx.entries(), kClients * 4'096);
  EXPECT_EQ(idx.chunks(), 4'096u);
  EXPECT_EQ(idx.regions(), 8u);
  EXPECT_EQ(idx.members(), kClients * 8);
  EXPECT_TRUE(idx.held_full({0, 0, 0}));
  EXPECT_FALSE(idx.held_full({1, 0, 0}));
  EXPECT_LT(idx.memory_bytes(), idx.entries());
  EXPECT_GT(idx.memory_bytes(), idx.members() * 2 * 64);  // each member's two masks at least
}

// The index's memory follows its holders: it grows as they come and
// falls back to the table's alone when they leave.
TEST(InterestIndex, MemoryFollowsTheHolders) {
  InterestIndex idx;
  const std::size_t empty = idx.memory_bytes();
  for (ClientId id = 1; id <= 1'000; ++id) idx.hold({1, 1, 1}, id, false);
  const std::size_t many = idx.memory_bytes();
  EXPECT_GE(many, empty + 1'000 * sizeof(InterestIndex::Holder));
  for (ClientId id = 1; id <= 1'000; ++id) idx.release({1, 1, 1}, id);
  EXPECT_EQ(idx.chunks(), 0u);
  EXPECT_EQ(idx.memory_bytes(), 0u);  // nothing held: the table went too
}

TEST(PresenceGrid, NearestFirstWithinTheRadiusAcrossCells) {
  PresenceGrid g;
  g.place(1, {0, 0, 0});
  g.place(2, {100, 0, 0});     // the same 128-voxel cell
  g.place(3, {-30, 0, 40});    // 50 away
  g.place(4, {400, 0, 0});     // beyond 300
  g.place(5, {0, 200, 0});     // above: distance is 3D
  auto near = g.nearest(1, {0, 0, 0}, 300, 10);
  ASSERT_EQ(near.size(), 3u);
  EXPECT_EQ(near[0].client_id, 3u);
  EXPECT_EQ(near[1].client_id, 2u);
  EXPECT_EQ(near[2].client_id, 5u);
  EXPECT_EQ(g.nearest(1, {0, 0, 0}, 300, 2).size(), 2u);
  // Moving across cells and leaving.
  g.place(4, {10, 0, 0});
  near = g.nearest(1, {0, 0, 0}, 300, 10);
  ASSERT_EQ(near.size(), 4u);
  EXPECT_EQ(near[0].client_id, 4u);
  g.remove(4);
  g.remove(3);
  near = g.nearest(1, {0, 0, 0}, 300, 10);
  ASSERT_EQ(near.size(), 2u);
  EXPECT_EQ(near[0].client_id, 2u);
  // A move within its cell: the entry's position follows.
  g.place(2, {110, 0, 0});
  near = g.nearest(1, {0, 0, 0}, 300, 10);
  ASSERT_EQ(near.size(), 2u);
  EXPECT_EQ(near[0].position, (Vec3f{110, 0, 0}));
}

}  // namespace
}  // namespace terrane
