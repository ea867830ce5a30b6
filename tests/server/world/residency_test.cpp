// Residency on the world strand against a real SQLite Storage (its reads
// held at a gate where a test needs a load under way) and a real FanOut:
// a chunk wanted while it loads is granted to every waiter once loaded,
// each at the resolution it asked for; chunks pinned by queued edits are
// never lightened, and are once released; a want of a loaded chunk is
// granted at once.
#include "server/world/residency.h"

#include <gtest/gtest.h>

#include <memory>

#include "tests/support/world_strand.h"

namespace terrane {
namespace {

using testing_support::RecordingClient;
using testing_support::StoreGate;
using testing_support::WorldStrand;

class ResidencyTest : public ::testing::Test {
 protected:
  explicit ResidencyTest(std::shared_ptr<StoreGate> gate = nullptr) : gate_(std::move(gate)), w_(gate_) {}
  ~ResidencyTest() override {
    if (gate_) gate_->open();  // a test that failed early leaves no read waiting
    w_.quiesce();
  }
  std::shared_ptr<RecordingClient> join(ClientId id) {
    auto c = std::make_shared<RecordingClient>();
    w_.on_strand([&] { fan_out_.join(id, c); });
    return c;
  }
  // Runs unload passes (a pass takes tick_hz ticks) with the lightening
  // after each, on the strand.
  void unload_passes(int passes) {
    w_.on_strand([&] {
      for (int i = 0; i < passes * static_cast<int>(options_.tick_hz + 1); ++i) {
        ++clock_.tick;
        residency_.unload_unwatched();
        residency_.lighten_some();
      }
    });
  }

  std::shared_ptr<StoreGate> gate_;  // null: no read waits
  WorldStrand w_;
  ServerOptions options_;
  ServerCounters counters_;
  WorldClock clock_;
  FanOut fan_out_{options_, counters_};
  HorizonCache horizons_{w_.strand, *w_.storage, fan_out_};
  Residency residency_{w_.strand, *w_.storage, options_, counters_, clock_, fan_out_, horizons_};
};

const Vec3i kChunk{2, 0, 3};

class ResidencyGatedTest : public ResidencyTest {
 protected:
  ResidencyGatedTest() : ResidencyTest(std::make_shared<StoreGate>(std::unordered_set<Vec3i, Vec3iHash>{kChunk})) {}
};

TEST_F(ResidencyGatedTest, AChunkWantedWhileItLoadsIsGrantedToEveryWaiterOnceLoaded) {
  auto near = join(1), far = join(2);
  w_.on_strand([&] { residency_.want(1, {ChunkWant{kChunk, true, 0, false}}); });
  ASSERT_TRUE(testing_support::eventually([&] { return gate_->reached(); }));
  w_.on_strand([&] { residency_.want(2, {ChunkWant{kChunk, false, 1, false}}); });
  w_.on_strand([&] {
    EXPECT_TRUE(residency_.loading(kChunk));
    EXPECT_FALSE(residency_.loaded(kChunk));
  });
  {
    std::lock_guard lock(near->m);
    EXPECT_TRUE(near->grants.empty());
  }
  gate_->open();
  ASSERT_TRUE(near->wait([](RecordingClient& c) { return c.grants.size() == 1; }));
  ASSERT_TRUE(far->wait([](RecordingClient& c) { return c.grants.size() == 1; }));
  EXPECT_EQ(near->grants[0]->pos(), kChunk);
  EXPECT_EQ(far->grants[0], near->grants[0]);  // one version for all
  w_.on_strand([&] {
    EXPECT_TRUE(residency_.loaded(kChunk));
    EXPECT_FALSE(residency_.loading(kChunk));
    EXPECT_EQ(residency_.loaded_count(), 1u);
    // Each waiter holds it as it asked: the near one at full resolution.
    EXPECT_TRUE(fan_out_.held_full(kChunk));
    fan_out_.release(1, {kChunk});
    EXPECT_FALSE(fan_out_.held_full(kChunk));
    EXPECT_TRUE(fan_out_.watched(kChunk));
  });
}

TEST_F(ResidencyTest, AWantOfAChunkHeldIsGrantedAtOnceInTheOrderAsked) {
  auto c = join(1);
  const std::vector<ChunkWant> wants = {{{0, 0, 0}, true}, {{1, 0, 0}, true}, {{0, 0, 1}, true}};
  w_.on_strand([&] { residency_.want(1, wants); });
  ASSERT_TRUE(c->wait([](RecordingClient& r) { return r.grants.size() == 3; }));
  auto again = join(2);
  w_.on_strand([&] {
    residency_.want(2, {wants[2], wants[0], wants[1]});
    // Granted within the call: nothing was loading.
    std::lock_guard lock(again->m);
    ASSERT_EQ(again->grants.size(), 3u);
    EXPECT_EQ(again->grants[0]->pos(), wants[2].chunk_pos);
    EXPECT_EQ(again->grants[1]->pos(), wants[0].chunk_pos);
    EXPECT_EQ(again->grants[2]->pos(), wants[1].chunk_pos);
  });
}

TEST_F(ResidencyTest, ChunksPinnedByQueuedEditsAreNeverLightenedAndAreOnceReleased) {
  options_.resident_chunks = 0;  // every chunk nobody holds at full resolution goes
  const Region box{{2 * 32 + 1, 1, 3 * 32 + 1}, {2 * 32 + 3, 3, 3 * 32 + 3}};  // in kChunk
  w_.on_strand([&] { residency_.reserve(box); });
  ASSERT_TRUE(w_.eventually_on_strand([&] { return residency_.loaded(kChunk); }));
  EXPECT_TRUE(residency_.busy(kChunk));
  unload_passes(2);
  w_.on_strand([&] { EXPECT_TRUE(residency_.loaded(kChunk)); });
  w_.on_strand([&] { residency_.unbusy(box); });
  EXPECT_FALSE(residency_.busy(kChunk));
  unload_passes(2);
  w_.on_strand([&] {
    // Kept as its mips only.
    EXPECT_FALSE(residency_.loaded(kChunk));
    ASSERT_NE(residency_.find(kChunk), nullptr);
    EXPECT_FALSE(residency_.find(kChunk)->current->has_voxels());
    EXPECT_EQ(residency_.loaded_count(), 0u);
  });
}

TEST_F(ResidencyTest, AVersionAdvancedIsWhatEditsBuildOnAndIsHandedOutOncePublished) {
  auto c = join(1);
  w_.on_strand([&] { residency_.want(1, {ChunkWant{kChunk, true, 0, false}}); });
  ASSERT_TRUE(c->wait([](RecordingClient& r) { return r.grants.size() == 1; }));
  const VersionPtr first = c->grants[0];
  auto chunk = std::make_unique<Chunk>(kAir);
  chunk->set({1, 1, 1}, solid(materials::kBrick));
  UnitBits bits;
  bits.set(0);
  const VersionPtr next = ChunkVersion::after(*first, std::move(chunk), bits);
  auto later = join(2);
  w_.on_strand([&] {
    residency_.advance(next);
    EXPECT_EQ(residency_.revision(kChunk), first->revision() + 1);
    EXPECT_EQ(residency_.get(Vec3i{2 * 32 + 1, 1, 3 * 32 + 1}), solid(materials::kBrick));
    // Not committed yet: a new reader is handed what was published.
    residency_.want(2, {ChunkWant{kChunk, true, 0, false}});
  });
  ASSERT_TRUE(later->wait([](RecordingClient& r) { return r.grants.size() == 1; }));
  EXPECT_EQ(later->grants[0], first);
  auto third = join(3);
  w_.on_strand([&] {
    residency_.publish({next});
    residency_.want(3, {ChunkWant{kChunk, true, 0, false}});
  });
  ASSERT_TRUE(third->wait([](RecordingClient& r) { return r.grants.size() == 1; }));
  EXPECT_EQ(third->grants[0], next);
}

}  // namespace
}  // namespace terrane
