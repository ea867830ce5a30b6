// HolderSet: one chunk's holders, scanned when few, indexed when many.
#include "server/world/holder_set.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <random>
#include <vector>

namespace terrane {
namespace {

std::map<ClientId, bool> contents(const HolderSet& s) {
  std::map<ClientId, bool> m;
  for (const ChunkHolder& h : s.holders()) m.emplace(h.id(), h.full());
  return m;
}

TEST(ChunkHolder, KeepsTheIdAndTheFlagInEightBytes) {
  ChunkHolder h((ClientId{1} << 62) + 5, true);
  EXPECT_EQ(h.id(), (ClientId{1} << 62) + 5);
  EXPECT_TRUE(h.full());
  h.set_full(false);
  EXPECT_FALSE(h.full());
  EXPECT_EQ(h.id(), (ClientId{1} << 62) + 5);
}

TEST(HolderSet, IndexedPastTheScannedSizeAndScannedAgainWhenFew) {
  HolderSet s;
  std::uint64_t probes = 0;
  for (ClientId id = 1; id <= HolderSet::kScanAtMost; ++id) EXPECT_EQ(s.hold(id, false, probes), HolderSet::Held::kAdded);
  EXPECT_EQ(s.index_size(), 0u);
  s.hold(100, true, probes);
  EXPECT_GT(3 * s.index_size(), 4 * s.size());
  EXPECT_EQ(s.hold(100, true, probes), HolderSet::Held::kSame);
  EXPECT_EQ(s.hold(100, false, probes), HolderSet::Held::kChanged);
  EXPECT_EQ(s.full(), 0u);
  for (ClientId id = 1; id <= HolderSet::kScanAtMost; ++id) EXPECT_TRUE(s.release(id, probes));
  EXPECT_FALSE(s.release(3, probes));  // twice: not there
  EXPECT_EQ(s.index_size(), 0u);
  EXPECT_EQ(contents(s), (std::map<ClientId, bool>{{100, false}}));
  EXPECT_TRUE(s.release(100, probes));
  EXPECT_TRUE(s.empty());
  // No index; the vector keeps room for a few (the index erases an empty set).
  EXPECT_LE(s.heap_bytes(), 2 * HolderSet::kScanAtMost * sizeof(ChunkHolder));
}

// Every holder is found after any sequence of changes (the index's
// positions follow the holders moved into gaps, and erasing by shifting
// back keeps every id reachable from its home); the index stays at most
// 3/4 full; the full count is right.
TEST(HolderSet, EveryHolderFoundUnderRandomChanges) {
  HolderSet s;
  std::map<ClientId, bool> ref;
  std::uint64_t probes = 0;
  std::mt19937 rng(3);
  std::uniform_int_distribution<ClientId> id_of(1, 3'000);
  std::uniform_int_distribution<int> coin(0, 9);
  for (int step = 0; step < 60'000; ++step) {
    const ClientId id = id_of(rng);
    const bool adding = (step / 6'000) % 2 == 0 ? coin(rng) < 8 : coin(rng) < 2;
    if (adding) {
      const bool full = coin(rng) < 5;
      s.hold(id, full, probes);
      ref[id] = full;
    } else {
      EXPECT_EQ(s.release(id, probes), ref.erase(id) == 1);
    }
    if (step % 211 != 0) continue;
    ASSERT_EQ(contents(s), ref) << "step " << step;
    std::size_t full = 0;
    for (const auto& [i, f] : ref) {
      full += f ? 1 : 0;
      ASSERT_TRUE(s.contains(i, probes)) << "step " << step << " id " << i;
    }
    EXPECT_EQ(s.full(), full);
    if (s.index_size() != 0) {
      EXPECT_LE(4 * s.size(), 3 * s.index_size());
    }
    // Indexed past the scanned size; scanned again at half of it.
    if (s.size() > HolderSet::kScanAtMost) {
      EXPECT_NE(s.index_size(), 0u);
    }
    if (s.size() <= HolderSet::kScanAtMost / 2) {
      EXPECT_EQ(s.index_size(), 0u);
    }
  }
}

}  // namespace
}  // namespace terrane
