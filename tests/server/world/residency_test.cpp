// Residency on the world strand against a real SQLite Storage (its reads
// held at a gate where a test needs a load under way, or failing where a
// test needs a chunk unreadable) and a real FanOut: a chunk wanted while
// it loads is granted to every waiter once loaded, each at the resolution
// it asked for, and once only; chunks pinned by queued edits are never
// lightened, while they load or after, until every edit released them; an
// unreadable chunk is logged once, read again every retry, and served
// once read; a want of a loaded chunk is granted at once.
#include "server/world/residency.h"

#include <gtest/gtest.h>
#include <spdlog/sinks/base_sink.h>

#include <atomic>
#include <memory>
#include <mutex>
#include <string>

#include "server/base/log.h"
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
  WorldOptions options_;
  ServerCounters counters_;
  WorldClock clock_;
  FanOut fan_out_{options_, counters_};
  HorizonCache horizons_{w_.strand, *w_.storage, fan_out_};
  Residency residency_{w_.strand, *w_.storage, options_, counters_, clock_, fan_out_, horizons_};
};

const Vec3i kChunk{2, 0, 3};
const Region kInChunk{{2 * 32 + 1, 1, 3 * 32 + 1}, {2 * 32 + 3, 3, 3 * 32 + 3}};

class ResidencyGatedTest : public ResidencyTest {
 protected:
  ResidencyGatedTest() : ResidencyTest(std::make_shared<StoreGate>(std::unordered_set<Vec3i, Vec3iHash>{kChunk})) {}
};

// Nothing waits at the gate; reads of a chunk fail while a test says so.
class ResidencyFailingTest : public ResidencyTest {
 protected:
  ResidencyFailingTest() : ResidencyTest(std::make_shared<StoreGate>(std::unordered_set<Vec3i, Vec3iHash>{})) {}
};

// Counts the server log's lines that contain a text, while it lives.
class LogCounter {
 public:
  explicit LogCounter(std::string text) : sink_(std::make_shared<Sink>(std::move(text))) {
    server_log().sinks().push_back(sink_);
  }
  ~LogCounter() { std::erase(server_log().sinks(), sink_); }
  LogCounter(const LogCounter&) = delete;
  LogCounter& operator=(const LogCounter&) = delete;
  int count() const { return sink_->count.load(); }

 private:
  struct Sink : spdlog::sinks::base_sink<std::mutex> {
    explicit Sink(std::string t) : text(std::move(t)) {}
    void sink_it_(const spdlog::details::log_msg& msg) override {
      if (std::string_view(msg.payload.data(), msg.payload.size()).find(text) != std::string_view::npos) ++count;
    }
    void flush_() override {}
    std::string text;
    std::atomic<int> count{0};
  };
  std::shared_ptr<Sink> sink_;
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

TEST_F(ResidencyGatedTest, WaitersAreServedOnceByTheLoadThatLandsAndNotAgainByALaterLoad) {
  auto c = join(1);
  w_.on_strand([&] { residency_.want(1, {ChunkWant{kChunk, true, 0, false}}); });
  ASSERT_TRUE(testing_support::eventually([&] { return gate_->reached(); }));
  w_.on_strand([&] {
    // Loading, nothing held yet.
    EXPECT_TRUE(residency_.loading(kChunk));
    EXPECT_EQ(residency_.find(kChunk), nullptr);
    EXPECT_EQ(residency_.loaded_count(), 0u);
  });
  gate_->open();
  ASSERT_TRUE(c->wait([](RecordingClient& r) { return r.grants.size() == 1; }));
  // Read again (as a shared world's authority does when another server
  // wrote it): nobody waits for this load, so nobody is granted anything.
  w_.on_strand([&] {
    EXPECT_FALSE(residency_.loading(kChunk));
    residency_.load_unless_loading(kChunk, Storage::Priority::kUrgent);
    EXPECT_TRUE(residency_.loading(kChunk));
  });
  ASSERT_TRUE(w_.eventually_on_strand([&] { return !residency_.loading(kChunk); }));
  w_.on_strand([] {});  // grants handed over in a strand turn of their own
  {
    std::lock_guard lock(c->m);
    EXPECT_EQ(c->grants.size(), 1u);
  }
  w_.on_strand([&] {
    EXPECT_TRUE(residency_.loaded(kChunk));
    EXPECT_EQ(residency_.loaded_count(), 1u);
  });
}

TEST_F(ResidencyGatedTest, AChunkPinnedWhileItLoadsStaysUntilEveryEditReleasedIt) {
  options_.resident_chunks = 0;  // every chunk nobody holds at full resolution goes
  w_.on_strand([&] {
    residency_.reserve(kInChunk);
    residency_.reserve(kInChunk);  // two queued edits touch it
  });
  ASSERT_TRUE(testing_support::eventually([&] { return gate_->reached(); }));
  w_.on_strand([&] {
    EXPECT_TRUE(residency_.busy(kChunk));
    EXPECT_TRUE(residency_.loading(kChunk));
    EXPECT_FALSE(residency_.loaded(kChunk));
  });
  unload_passes(1);
  w_.on_strand([&] { EXPECT_TRUE(residency_.busy(kChunk)); });
  gate_->open();
  ASSERT_TRUE(w_.eventually_on_strand([&] { return residency_.loaded(kChunk); }));
  unload_passes(2);
  w_.on_strand([&] {
    EXPECT_TRUE(residency_.loaded(kChunk));
    residency_.unbusy(kInChunk);  // one edit done: still pinned by the other
    EXPECT_TRUE(residency_.busy(kChunk));
  });
  unload_passes(2);
  w_.on_strand([&] {
    EXPECT_TRUE(residency_.loaded(kChunk));
    residency_.unbusy(kInChunk);
    EXPECT_FALSE(residency_.busy(kChunk));
    residency_.unbusy(kInChunk);  // released more often than pinned: nothing happens
    EXPECT_FALSE(residency_.busy(kChunk));
  });
  unload_passes(2);
  w_.on_strand([&] {
    EXPECT_FALSE(residency_.loaded(kChunk));
    ASSERT_NE(residency_.find(kChunk), nullptr);
    EXPECT_FALSE(residency_.find(kChunk)->current->has_voxels());
  });
}

TEST_F(ResidencyFailingTest, AnUnreadableChunkIsLoggedOnceReadAgainEachRetryAndServedOnceRead) {
  LogCounter logged("chunk (2,0,3): ");
  gate_->fail(kChunk);
  auto first = join(1), second = join(2);
  w_.on_strand([&] { residency_.want(1, {ChunkWant{kChunk, true, 0, false}}); });
  ASSERT_TRUE(testing_support::eventually([&] { return logged.count() == 1; }));
  // Its waiters wait: the load stays under way until a retry reads it.
  w_.on_strand([&] {
    EXPECT_TRUE(residency_.loading(kChunk));
    EXPECT_FALSE(residency_.loaded(kChunk));
    residency_.want(2, {ChunkWant{kChunk, false, 1, false}});
  });
  for (int reads = 2; reads <= 3; ++reads) {
    w_.on_strand([&] { residency_.retry_unreadable(); });
    ASSERT_TRUE(testing_support::eventually([&] { return gate_->failed_reads() == reads; }));
  }
  {
    std::lock_guard lock(first->m);
    EXPECT_TRUE(first->grants.empty());
  }
  gate_->heal(kChunk);
  w_.on_strand([&] { residency_.retry_unreadable(); });
  ASSERT_TRUE(first->wait([](RecordingClient& r) { return r.grants.size() == 1; }));
  ASSERT_TRUE(second->wait([](RecordingClient& r) { return r.grants.size() == 1; }));
  w_.on_strand([&] {
    EXPECT_TRUE(residency_.loaded(kChunk));
    EXPECT_FALSE(residency_.loading(kChunk));
    // Read: nothing is retried any more.
    residency_.retry_unreadable();
    EXPECT_FALSE(residency_.loading(kChunk));
  });
  w_.quiesce();  // every failed read's result is in
  EXPECT_EQ(gate_->failed_reads(), 3);
  EXPECT_EQ(logged.count(), 1);
  std::lock_guard lock(first->m);
  EXPECT_EQ(first->grants.size(), 1u);
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
  const Region box = kInChunk;
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
