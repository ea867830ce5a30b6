// ChunkSlot and ChunkSlots: one record of what a replicator knows of a
// chunk for its client, its rules (what holding a chunk keeps and forgets,
// what leaving the view drops, keeps and cancels, which grant and which
// change win), and the slots' counts and erasure of a slot left empty.
#include "server/replication/chunk_slot.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <memory>
#include <random>
#include <tuple>

#include "common/world/horizon.h"

namespace terrane {
namespace {

constexpr Vec3i kPos{3, -1, 7};

VersionPtr solid_version(std::uint64_t revision) {
  return std::make_shared<ChunkVersion>(kPos, revision, std::make_shared<Chunk>(materials::kRock));
}
VersionPtr air_version(std::uint64_t revision) { return std::make_shared<ChunkVersion>(kPos, revision, nullptr); }

// --- ChunkSlot ---------------------------------------------------------------------

TEST(ChunkSlot, ANewSlotHasNothingAndIsEmpty) {
  const ChunkSlot s;
  EXPECT_TRUE(s.empty());
  EXPECT_FALSE(s.held());
  EXPECT_FALSE(s.image());
  EXPECT_FALSE(s.known());
  EXPECT_FALSE(s.request());
  EXPECT_FALSE(s.ready());
  EXPECT_FALSE(s.claim());
  EXPECT_FALSE(s.mip_pending());
  EXPECT_FALSE(s.full());
}

TEST(ChunkSlot, AChunkSeenThroughAnImageIsKnownButNotHeld) {
  ChunkSlot s;
  s.see_image(kHorizonNearLevel);
  EXPECT_TRUE(s.image());
  EXPECT_TRUE(s.known());
  EXPECT_FALSE(s.held());
  EXPECT_FALSE(s.empty());
}

TEST(ChunkSlot, HoldingAChunkForgetsItsImage) {
  ChunkSlot s;
  s.see_image(kHorizonFarLevel);
  s.hold(Holding{HoldingForm::kMip3, 4}, solid_version(4));
  EXPECT_FALSE(s.image());
  ASSERT_TRUE(s.held());
  EXPECT_EQ(*s.held(), (Holding{HoldingForm::kMip3, 4}));
}

TEST(ChunkSlot, AChunkHeldFullKeepsItsVersionForHashesAndSaysWhenItIsNew) {
  ChunkSlot s;
  const VersionPtr v4 = solid_version(4), v5 = solid_version(5);
  EXPECT_TRUE(s.hold(Holding{HoldingForm::kFull, 4}, v4));
  EXPECT_EQ(s.full(), v4);
  // A newer version of a chunk held Full replaces it: not new.
  EXPECT_FALSE(s.hold(Holding{HoldingForm::kFull, 5}, v5));
  EXPECT_EQ(s.full(), v5);
}

TEST(ChunkSlot, AChunkHeldCoarserOrAllAirKeepsNoVersion) {
  ChunkSlot s;
  s.hold(Holding{HoldingForm::kFull, 4}, solid_version(4));
  EXPECT_FALSE(s.hold(Holding{HoldingForm::kMip1, 5}, solid_version(5)));
  EXPECT_FALSE(s.full());
  // Full at a revision whose voxels are all Air (a tick's units emptied it).
  EXPECT_FALSE(s.hold(Holding{HoldingForm::kFull, 6}, air_version(6)));
  EXPECT_FALSE(s.full());
  EXPECT_FALSE(s.hold(Holding{HoldingForm::kEmpty, 7}, air_version(7)));
  EXPECT_FALSE(s.full());
  EXPECT_EQ(*s.held(), (Holding{HoldingForm::kEmpty, 7}));
}

TEST(ChunkSlot, AnOutstandingRequestIsKeptWhenAskedAgain) {
  ChunkSlot s;
  EXPECT_TRUE(s.ask(ChunkRequest{ChunkIntent::kCoarse, 3}));
  EXPECT_FALSE(s.ask(ChunkRequest{ChunkIntent::kRefine, 0}));
  EXPECT_EQ(*s.request(), (ChunkRequest{ChunkIntent::kCoarse, 3}));
  EXPECT_EQ(s.take_request(), (ChunkRequest{ChunkIntent::kCoarse, 3}));
  EXPECT_FALSE(s.request());
  EXPECT_TRUE(s.empty());
}

TEST(ChunkSlot, TheFirstGrantWaitsAndAChangeMakesItNewer) {
  ChunkSlot s;
  EXPECT_FALSE(s.refresh_ready(solid_version(9)));  // nothing granted: not taken
  EXPECT_FALSE(s.ready());
  const VersionPtr v4 = solid_version(4);
  EXPECT_TRUE(s.set_ready(v4));
  EXPECT_FALSE(s.set_ready(solid_version(5)));
  EXPECT_EQ(s.ready(), v4);
  const VersionPtr v6 = solid_version(6);
  EXPECT_TRUE(s.refresh_ready(v6));
  EXPECT_EQ(s.ready(), v6);
  EXPECT_TRUE(s.refresh_ready(solid_version(5)));  // older: taken, not kept
  EXPECT_EQ(s.ready(), v6);
  EXPECT_EQ(s.take_ready(), v6);
  EXPECT_TRUE(s.empty());
}

TEST(ChunkSlot, TheNewestChangeWaitsForTheRefreshOfMips) {
  ChunkSlot s;
  const VersionPtr v5 = solid_version(5);
  EXPECT_TRUE(s.park_mip(v5));
  EXPECT_FALSE(s.park_mip(solid_version(4)));
  EXPECT_EQ(s.mip_pending(), v5);
  const VersionPtr v7 = solid_version(7);
  EXPECT_FALSE(s.park_mip(v7));  // not the first: already listed
  EXPECT_EQ(s.mip_pending(), v7);
  EXPECT_EQ(s.take_mip(), v7);
  EXPECT_TRUE(s.empty());
}

TEST(ChunkSlot, AClaimIsReplacedAndTakenOnce) {
  ChunkSlot s;
  s.set_claim(Holding{HoldingForm::kMip2, 3});
  s.set_claim(Holding{HoldingForm::kFull, 8});
  EXPECT_TRUE(s.known());
  EXPECT_FALSE(s.held());
  EXPECT_EQ(s.take_claim(), (Holding{HoldingForm::kFull, 8}));
  EXPECT_FALSE(s.take_claim());
  EXPECT_TRUE(s.empty());
}

TEST(ChunkSlot, LeavingReleasesTheClaimThenTheHoldingAndTellsTheWorld) {
  ChunkSlot s;
  s.set_claim(Holding{HoldingForm::kEmpty, 2});
  s.hold(Holding{HoldingForm::kFull, 9}, solid_version(9));
  const ChunkSlot::Left left = s.leave();
  EXPECT_EQ(left.claim, 2u);
  EXPECT_EQ(left.had, 9u);
  EXPECT_TRUE(left.registered);
  EXPECT_FALSE(s.held());
  EXPECT_FALSE(s.full());
  EXPECT_TRUE(s.empty());
}

TEST(ChunkSlot, LeavingReleasesAnImageAtRevisionZeroWithoutTellingTheWorld) {
  ChunkSlot s;
  s.see_image(kHorizonFarLevel);
  const ChunkSlot::Left left = s.leave();
  EXPECT_FALSE(left.claim);
  EXPECT_EQ(left.had, 0u);
  EXPECT_FALSE(left.registered);
  EXPECT_TRUE(s.empty());
}

TEST(ChunkSlot, LeavingDropsAGrantNotSentWithItsRequestAndTellsTheWorld) {
  ChunkSlot s;
  s.ask(ChunkRequest{ChunkIntent::kCoarse, 3});
  s.set_ready(solid_version(4));
  const ChunkSlot::Left left = s.leave();
  EXPECT_FALSE(left.had);
  EXPECT_TRUE(left.registered);
  EXPECT_FALSE(s.ready());
  EXPECT_FALSE(s.request());
  EXPECT_TRUE(s.empty());
}

TEST(ChunkSlot, LeavingCancelsARequestStillOnItsWay) {
  ChunkSlot s;
  s.hold(Holding{HoldingForm::kMip3, 4}, solid_version(4));
  s.ask(ChunkRequest{ChunkIntent::kRefine, 1});
  const ChunkSlot::Left left = s.leave();
  EXPECT_EQ(left.had, 4u);
  EXPECT_TRUE(left.registered);
  ASSERT_TRUE(s.request());
  EXPECT_TRUE(s.request()->cancelled);
  EXPECT_FALSE(s.empty());  // until its grant comes
}

TEST(ChunkSlot, LeavingKeepsAChangeWaitingForTheRefreshOfMips) {
  ChunkSlot s;
  s.hold(Holding{HoldingForm::kMip2, 4}, solid_version(4));
  const VersionPtr v5 = solid_version(5);
  s.park_mip(v5);
  s.leave();
  EXPECT_FALSE(s.held());
  EXPECT_EQ(s.mip_pending(), v5);
  EXPECT_FALSE(s.empty());
}

TEST(ChunkSlot, LeavingASlotWithNothingToLeaveChangesNothing) {
  ChunkSlot s;
  s.park_mip(solid_version(5));
  const ChunkSlot::Left left = s.leave();
  EXPECT_FALSE(left.claim);
  EXPECT_FALSE(left.had);
  EXPECT_FALSE(left.registered);
  EXPECT_TRUE(s.mip_pending());
}

// --- ChunkSlots --------------------------------------------------------------------

TEST(ChunkSlots, ASlotLeftWithNothingIsErased) {
  ChunkSlots slots;
  slots.change(kPos, [](ChunkSlot& s) { s.ask(ChunkRequest{ChunkIntent::kCoarse, 3}); });
  ASSERT_NE(slots.find(kPos), nullptr);
  EXPECT_EQ(slots.size(), 1u);
  slots.change(kPos, [](ChunkSlot& s) { s.take_request(); });
  EXPECT_EQ(slots.find(kPos), nullptr);
  EXPECT_EQ(slots.size(), 0u);
}

TEST(ChunkSlots, AChangeThatLeavesNothingMakesNoSlot) {
  ChunkSlots slots;
  slots.change(kPos, [](ChunkSlot&) {});
  EXPECT_EQ(slots.size(), 0u);
}

TEST(ChunkSlots, ChangeIfLeavesAChunkWithoutASlotAlone) {
  ChunkSlots slots;
  bool called = false;
  EXPECT_FALSE(slots.change_if(kPos, [&](ChunkSlot&) { called = true; }));
  EXPECT_FALSE(called);
  EXPECT_EQ(slots.size(), 0u);
  slots.change(kPos, [](ChunkSlot& s) { s.see_image(kHorizonNearLevel); });
  EXPECT_TRUE(slots.change_if(kPos, [&](ChunkSlot&) { called = true; }));
  EXPECT_TRUE(called);
}

TEST(ChunkSlots, HoldsIsARecordOfItsOwnAndKnownAlsoAnImageOrAClaim) {
  ChunkSlots slots;
  const Vec3i a{0, 0, 0}, b{1, 0, 0}, c{2, 0, 0}, d{3, 0, 0};
  slots.change(a, [](ChunkSlot& s) { s.hold(Holding{HoldingForm::kMip3, 1}, nullptr); });
  slots.change(b, [](ChunkSlot& s) { s.see_image(kHorizonFarLevel); });
  slots.change(c, [](ChunkSlot& s) { s.set_claim(Holding{HoldingForm::kEmpty, 1}); });
  slots.change(d, [](ChunkSlot& s) { s.ask(ChunkRequest{ChunkIntent::kCoarse, 3}); });
  EXPECT_TRUE(slots.holds(a));
  EXPECT_FALSE(slots.holds(b));
  EXPECT_FALSE(slots.holds(c));
  EXPECT_FALSE(slots.holds(d));
  EXPECT_TRUE(slots.known(a));
  EXPECT_TRUE(slots.known(b));
  EXPECT_TRUE(slots.known(c));
  EXPECT_FALSE(slots.known(d));  // asked for: nothing of it yet
  EXPECT_FALSE(slots.known({9, 9, 9}));
}

TEST(ChunkSlots, CountsFollowRequestsClaimsAndPendingMipsThroughEveryChange) {
  ChunkSlots slots;
  const Vec3i a{0, 0, 0}, b{1, 0, 0}, c{2, 0, 0};
  slots.change(a, [](ChunkSlot& s) { s.ask(ChunkRequest{ChunkIntent::kCoarse, 3}); });
  slots.change(b, [](ChunkSlot& s) {
    s.hold(Holding{HoldingForm::kMip3, 4}, nullptr);
    s.ask(ChunkRequest{ChunkIntent::kRefine, 1});
    s.park_mip(solid_version(5));
  });
  slots.change(c, [](ChunkSlot& s) {
    s.set_claim(Holding{HoldingForm::kMip2, 2});
    s.ask(ChunkRequest{ChunkIntent::kClaim, 2});
  });
  EXPECT_EQ(slots.requests(), 3u);
  EXPECT_EQ(slots.coarse_pass_requests(), 2u);  // the refinement is not the coarse pass's
  EXPECT_EQ(slots.claims(), 1u);
  EXPECT_EQ(slots.mips_pending(), 1u);

  // A cancelled request still counts until its grant comes.
  slots.change_if(a, [](ChunkSlot& s) { s.leave(); });
  EXPECT_EQ(slots.requests(), 3u);
  EXPECT_EQ(slots.coarse_pass_requests(), 2u);

  slots.change_if(c, [](ChunkSlot& s) {
    s.take_request();
    s.take_claim();
  });
  EXPECT_EQ(slots.requests(), 2u);
  EXPECT_EQ(slots.coarse_pass_requests(), 1u);
  EXPECT_EQ(slots.claims(), 0u);
  EXPECT_EQ(slots.find(c), nullptr);

  slots.change_if(b, [](ChunkSlot& s) {
    s.take_mip();
    s.take_request();
  });
  EXPECT_EQ(slots.requests(), 1u);
  EXPECT_EQ(slots.coarse_pass_requests(), 1u);
  EXPECT_EQ(slots.mips_pending(), 0u);
  EXPECT_NE(slots.find(b), nullptr);  // still held

  slots.clear();
  EXPECT_EQ(slots.size(), 0u);
  EXPECT_EQ(slots.requests(), 0u);
  EXPECT_EQ(slots.coarse_pass_requests(), 0u);
}

// Slots are kept in blocks of 4^3 chunks: every chunk (negative
// coordinates too) keeps its own slot however they are made and erased,
// and iteration visits each once with its coordinates.
TEST(ChunkSlots, EveryChunkKeepsItsOwnSlotAcrossBlocks) {
  ChunkSlots slots;
  auto less = [](const Vec3i& a, const Vec3i& b) { return std::tie(a.x, a.y, a.z) < std::tie(b.x, b.y, b.z); };
  std::map<Vec3i, std::uint64_t, decltype(less)> ref(less);
  std::mt19937 rng(7);
  std::uniform_int_distribution<int> coord(-9, 9), coin(0, 2);
  for (int step = 0; step < 20'000; ++step) {
    const Vec3i cp{coord(rng), coord(rng) / 3, coord(rng)};
    if (coin(rng) != 0) {
      const auto revision = static_cast<std::uint64_t>(step + 1);
      slots.change(cp, [&](ChunkSlot& s) { s.hold(Holding{HoldingForm::kMip3, revision}, nullptr); });
      ref[cp] = revision;
    } else {
      slots.change_if(cp, [](ChunkSlot& s) { s.leave(); });
      ref.erase(cp);
    }
  }
  ASSERT_EQ(slots.size(), ref.size());
  std::size_t seen = 0;
  for (const auto& [cp, s] : slots) {
    ++seen;
    auto it = ref.find(cp);
    ASSERT_NE(it, ref.end()) << cp.x << "," << cp.y << "," << cp.z;
    ASSERT_TRUE(s.held());
    EXPECT_EQ(s.held()->revision, it->second);
  }
  EXPECT_EQ(seen, ref.size());
  for (const auto& [cp, revision] : ref) {
    ASSERT_TRUE(slots.holds(cp));
    EXPECT_EQ(slots.find(cp)->held()->revision, revision);
  }
}

// The slots' memory is counted where the replicator says (the server's
// memory by part): it grows with the slots and all of it is taken back
// when they go.
// see_images marks a region's chunks in a mask at once: the same slots,
// counts and memory as marking each chunk by change, known chunks left as
// they are and taken out of the mask.
TEST(ChunkSlots, SeeImagesMarksTheMasksUnknownChunksAsChangeWould) {
  std::mt19937 rng(11);
  for (int round = 0; round < 20; ++round) {
    const Vec3i region{round % 3 - 1, round % 2 - 1, 2};
    std::atomic<std::int64_t> counted_a{0}, counted_b{0};
    ChunkSlots a(&counted_a), b(&counted_b);
    // Some chunks of the region (and one outside it) held, claimed or
    // asked for already, in both.
    for (int k = 0; k < round * 7; ++k) {
      const Vec3i cp = region * 8 + Vec3i{static_cast<int>(rng() % 8), static_cast<int>(rng() % 8),
                                          static_cast<int>(rng() % 8)};
      const int what = static_cast<int>(rng() % 3);
      const auto f = [&](ChunkSlot& s) {
        if (what == 0) s.hold(Holding{HoldingForm::kMip3, 1}, nullptr);
        if (what == 1) s.set_claim(Holding{HoldingForm::kFull, 2});
        if (what == 2) s.ask(ChunkRequest{ChunkIntent::kCoarse, 3});
      };
      a.change(cp, f);
      b.change(cp, f);
    }
    a.change(region * 8 + Vec3i{8, 0, 0}, [](ChunkSlot& s) { s.hold(Holding{HoldingForm::kEmpty, 1}, nullptr); });
    b.change(region * 8 + Vec3i{8, 0, 0}, [](ChunkSlot& s) { s.hold(Holding{HoldingForm::kEmpty, 1}, nullptr); });
    HorizonMask mask{};
    for (int i = 0; i < kHorizonRegionSlots; ++i)
      if (rng() % 4 != 0) horizon_mask_set(mask, i);
    // b: chunk by chunk, as before see_images.
    HorizonMask want{};
    std::size_t want_seen = 0;
    for_each_region_chunk(region, [&](Vec3i cp) {
      if (!horizon_mask_has(mask, coarse_index(cp)) || b.known(cp)) return;
      b.change(cp, [](ChunkSlot& s) { s.see_image(kHorizonFarLevel); });
      horizon_mask_set(want, coarse_index(cp));
      ++want_seen;
    });
    HorizonMask got = mask;
    EXPECT_EQ(a.see_images(region, got, kHorizonFarLevel), want_seen) << "round " << round;
    EXPECT_EQ(got, want) << "round " << round;
    EXPECT_EQ(a.size(), b.size());
    EXPECT_EQ(a.requests(), b.requests());
    EXPECT_EQ(a.claims(), b.claims());
    std::vector<std::tuple<int, int, int, bool, bool, int>> sa, sb;
    for (const auto& [cp, s] : a) sa.emplace_back(cp.x, cp.y, cp.z, s.image(), s.known(), s.held() ? static_cast<int>(s.held()->form) : (s.claim() ? 100 : -1));
    for (const auto& [cp, s] : b) sb.emplace_back(cp.x, cp.y, cp.z, s.image(), s.known(), s.held() ? static_cast<int>(s.held()->form) : (s.claim() ? 100 : -1));
    std::sort(sa.begin(), sa.end());
    std::sort(sb.begin(), sb.end());
    EXPECT_EQ(sa, sb) << "round " << round;
    EXPECT_EQ(counted_a.load(), static_cast<std::int64_t>(a.memory_bytes()));
  }
}

TEST(ChunkSlots, MemoryIsCountedAndTakenBack) {
  std::atomic<std::int64_t> counted{0};
  {
    ChunkSlots slots(&counted);
    for (int x = 0; x < 40; ++x)
      for (int z = 0; z < 40; ++z)
        slots.change({x, 0, z}, [](ChunkSlot& s) { s.hold(Holding{HoldingForm::kMip3, 1}, nullptr); });
    EXPECT_EQ(counted.load(), static_cast<std::int64_t>(slots.memory_bytes()));
    // Each slot's own bytes, and less than a flat map's 65 or so a chunk.
    EXPECT_GE(slots.memory_bytes(), 1'600 * sizeof(ChunkSlot));
    EXPECT_LT(slots.memory_bytes(), 1'600 * 40);
    const std::size_t before = slots.memory_bytes();
    slots.change({0, 0, 0}, [](ChunkSlot& s) { s.ask(ChunkRequest{ChunkIntent::kRefine, 0}); });
    EXPECT_EQ(slots.memory_bytes(), before + ChunkSlot::kMoreBytes);  // out of line
    EXPECT_EQ(counted.load(), static_cast<std::int64_t>(slots.memory_bytes()));
    slots.clear();
    EXPECT_EQ(counted.load(), 0);
    slots.change({1, 2, 3}, [](ChunkSlot& s) { s.see_image(kHorizonNearLevel); });
    EXPECT_GT(counted.load(), 0);
  }
  EXPECT_EQ(counted.load(), 0);
}

}  // namespace
}  // namespace terrane
