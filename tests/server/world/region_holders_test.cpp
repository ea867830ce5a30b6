// IdTable (entries found by client id: scanned when few, indexed when many)
// and RegionHolders (a region's chunks' holders: a member per client, masks
// of what it holds).
#include "server/world/region_holders.h"

#include <gtest/gtest.h>

#include <map>
#include <random>
#include <utility>
#include <vector>

#include "server/world/id_table.h"

namespace terrane {
namespace {

struct Entry {
  ClientId client = 0;
  int value = 0;
  ClientId id() const { return client; }
};

std::map<ClientId, int> contents(const IdTable<Entry>& t) {
  std::map<ClientId, int> m;
  for (const Entry& e : t.entries()) EXPECT_TRUE(m.emplace(e.id(), e.value).second) << "id " << e.id() << " twice";
  return m;
}

TEST(ChunkHolder, KeepsTheIdAndTheFlagInEightBytes) {
  const ChunkHolder h((ClientId{1} << 62) + 5, true);
  EXPECT_EQ(h.id(), (ClientId{1} << 62) + 5);
  EXPECT_TRUE(h.full());
  EXPECT_FALSE(ChunkHolder(7, false).full());
  EXPECT_EQ(ChunkHolder(7, false).id(), 7u);
}

TEST(IdTable, IndexedPastTheScannedSizeAndScannedAgainWhenFew) {
  IdTable<Entry> t;
  std::uint64_t probes = 0;
  for (ClientId id = 1; id <= IdTable<Entry>::kScanAtMost; ++id) t.add({id, static_cast<int>(id)});
  EXPECT_EQ(t.index_size(), 0u);
  t.add({100, 100});
  EXPECT_GT(3 * t.index_size(), 4 * t.size());
  ASSERT_NE(t.find(100, probes), nullptr);
  t.find(100, probes)->value = 7;
  EXPECT_EQ(t.find(100, probes)->value, 7);
  for (ClientId id = 1; id <= IdTable<Entry>::kScanAtMost; ++id) EXPECT_TRUE(t.erase(id, probes));
  EXPECT_FALSE(t.erase(3, probes));  // twice: not there
  EXPECT_EQ(t.index_size(), 0u);
  EXPECT_EQ(contents(t), (std::map<ClientId, int>{{100, 7}}));
  EXPECT_TRUE(t.erase(100, probes));
  EXPECT_TRUE(t.empty());
  EXPECT_EQ(t.find(100, probes), nullptr);
  // No index; the vector keeps room for a few.
  EXPECT_LE(t.heap_bytes(), 2 * IdTable<Entry>::kScanAtMost * sizeof(Entry));
}

// Every entry is found after any sequence of changes (the index's
// positions follow the entries moved into gaps, and erasing by shifting
// back keeps every id reachable from its home); the index stays at most
// 3/4 full.
TEST(IdTable, EveryEntryFoundUnderRandomChanges) {
  IdTable<Entry> t;
  std::map<ClientId, int> ref;
  std::uint64_t probes = 0;
  std::mt19937 rng(3);
  std::uniform_int_distribution<ClientId> id_of(1, 3'000);
  std::uniform_int_distribution<int> coin(0, 9);
  for (int step = 0; step < 60'000; ++step) {
    const ClientId id = id_of(rng);
    const bool adding = (step / 6'000) % 2 == 0 ? coin(rng) < 8 : coin(rng) < 2;
    if (adding) {
      if (Entry* e = t.find(id, probes))
        e->value = step;
      else
        t.add({id, step});
      ref[id] = step;
    } else {
      EXPECT_EQ(t.erase(id, probes), ref.erase(id) == 1);
    }
    if (step % 211 != 0) continue;
    ASSERT_EQ(contents(t), ref) << "step " << step;
    for (const auto& [i, v] : ref) {
      const Entry* e = t.find(i, probes);
      ASSERT_NE(e, nullptr) << "step " << step << " id " << i;
      EXPECT_EQ(e->value, v);
    }
    if (t.index_size() != 0) {
      EXPECT_LE(4 * t.size(), 3 * t.index_size());
    }
    // Indexed past the scanned size; scanned again at half of it.
    if (t.size() > IdTable<Entry>::kScanAtMost) {
      EXPECT_NE(t.index_size(), 0u);
    }
    if (t.size() <= IdTable<Entry>::kScanAtMost / 2) {
      EXPECT_EQ(t.index_size(), 0u);
    }
  }
}

std::map<ClientId, bool> holders_of(const RegionHolders& r, int index) {
  std::map<ClientId, bool> m;
  r.for_each_holder(index, [&](ChunkHolder h) { EXPECT_TRUE(m.emplace(h.id(), h.full()).second); });
  return m;
}

TEST(RegionHolders, EachChunkHasItsOwnHoldersAndAMemberLeavesWithItsLastChunk) {
  RegionHolders r;
  std::uint64_t probes = 0;
  EXPECT_EQ(r.hold(0, 7, false, probes), RegionHolders::Held::kAdded);
  EXPECT_EQ(r.hold(511, 7, true, probes), RegionHolders::Held::kAdded);
  EXPECT_EQ(r.hold(0, 8, true, probes), RegionHolders::Held::kAdded);
  EXPECT_EQ(r.hold(0, 7, false, probes), RegionHolders::Held::kSame);
  EXPECT_EQ(r.members(), 2u);
  EXPECT_EQ(holders_of(r, 0), (std::map<ClientId, bool>{{7, false}, {8, true}}));
  EXPECT_EQ(holders_of(r, 511), (std::map<ClientId, bool>{{7, true}}));
  EXPECT_TRUE(holders_of(r, 1).empty());
  EXPECT_EQ(r.holders(0), 2u);
  EXPECT_EQ(r.full(0), 1u);
  EXPECT_EQ(r.hold(0, 7, true, probes), RegionHolders::Held::kChanged);
  EXPECT_EQ(r.full(0), 2u);
  EXPECT_EQ(r.hold(0, 8, false, probes), RegionHolders::Held::kChanged);
  EXPECT_EQ(r.full(0), 1u);
  EXPECT_TRUE(r.holds(511, 7, probes));
  EXPECT_FALSE(r.holds(511, 8, probes));
  EXPECT_FALSE(r.release(511, 8, probes));  // not held
  EXPECT_TRUE(r.release(0, 8, probes));
  EXPECT_EQ(r.members(), 1u);  // 8 held nothing else
  EXPECT_TRUE(r.release(0, 7, probes));
  EXPECT_EQ(r.members(), 1u);  // 7 still holds 511
  EXPECT_EQ(r.holders(0), 0u);
  EXPECT_EQ(r.full(0), 0u);
  EXPECT_TRUE(r.release(511, 7, probes));
  EXPECT_TRUE(r.empty());
  EXPECT_EQ(r.holders(511), 0u);
}

// Against a plain reference under random holds and releases of many
// clients over a few chunks: each chunk's holders and flags, the counts,
// holds().
TEST(RegionHolders, MatchesAReferenceUnderRandomChanges) {
  RegionHolders r;
  std::map<std::pair<int, ClientId>, bool> ref;  // (chunk, client) -> full
  std::uint64_t probes = 0;
  std::mt19937 rng(9);
  const std::vector<int> chunks{0, 1, 63, 64, 200, 511};
  std::uniform_int_distribution<std::size_t> chunk_of(0, chunks.size() - 1);
  std::uniform_int_distribution<ClientId> id_of(1, 40);
  std::uniform_int_distribution<int> coin(0, 9);
  for (int step = 0; step < 30'000; ++step) {
    const int chunk = chunks[chunk_of(rng)];
    const ClientId id = id_of(rng);
    const bool holding = (step / 3'000) % 2 == 0 ? coin(rng) < 7 : coin(rng) < 3;
    if (holding) {
      const bool full = coin(rng) < 4;
      r.hold(chunk, id, full, probes);
      ref[{chunk, id}] = full;
    } else {
      EXPECT_EQ(r.release(chunk, id, probes), ref.erase({chunk, id}) == 1);
    }
    if (step % 89 != 0) continue;
    std::map<ClientId, int> members;
    for (const int c : chunks) {
      std::map<ClientId, bool> want;
      std::uint32_t full = 0;
      for (const auto& [key, f] : ref)
        if (key.first == c) {
          want[key.second] = f;
          full += f ? 1 : 0;
          ++members[key.second];
        }
      ASSERT_EQ(holders_of(r, c), want) << "step " << step << " chunk " << c;
      EXPECT_EQ(r.holders(c), want.size());
      EXPECT_EQ(r.full(c), full);
      for (const auto& [h, f] : want) EXPECT_TRUE(r.holds(c, h, probes));
    }
    EXPECT_EQ(r.members(), members.size());
  }
}

}  // namespace
}  // namespace terrane
