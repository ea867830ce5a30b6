// Tick on the world strand with a fake Authority (whose boxes a test makes
// wait, as a claim under way would) over a real Residency, FanOut and
// SQLite Storage: a player's edits keep their order while an earlier one
// waits, another player's edits go on meanwhile; an edit is acknowledged
// once committed, after its holders heard of it; a flush waits for the
// commit in flight; a forwarded edit its sender wins goes back to it
// unasked, and this server's own edit back goes ahead of those waiting; a
// forwarded edit past its time is refused.
#include "server/world/tick.h"

#include <gtest/gtest.h>

#include <atomic>
#include <memory>
#include <mutex>
#include <unordered_set>

#include "tests/support/world_strand.h"

namespace terrane {
namespace {

using namespace std::chrono_literals;

using testing_support::RecordingClient;
using testing_support::WorldStrand;

// Writable except where a test holds chunks (kWaiting there: a claim
// under way). On the strand.
class FakeAuthority final : public Authority {
 public:
  void start() override {}
  Writable writable(const Region& r, std::string*, std::optional<std::uint32_t>*, ClaimRule) override {
    bool held = false;
    for_each_chunk_in(r, [&](Vec3i cp) { held = held || waiting.count(cp) != 0; });
    ++asked;
    return held ? Writable::kWaiting : Writable::kYes;
  }
  bool claiming(const Region&) const override { return false; }
  bool writes_region(Vec3i) const override { return true; }
  bool forward_pending(ClientId, const Region&) const override { return false; }
  void forward(ClientId, const EditRequestMsg&, const std::string&, const Region&, std::uint32_t) override {}
  void relay(Forwarded f, const Region&, std::uint32_t to) override { relays.emplace_back(f, to); }
  bool passes_back_to(std::uint32_t) const override { return false; }
  void settle() override { ++settled; }
  void changed_elsewhere(std::vector<ChunkChange>) override {}
  void read_again_elsewhere(std::vector<Vec3i>) override {}
  void inbox_has_edits() override {}
  void answered(ForwardAnswer) override {}
  bool stale(Vec3i) const override { return false; }
  void landed(Vec3i) override {}

  std::unordered_set<Vec3i, Vec3iHash> waiting;
  int asked = 0;
  int settled = 0;
  std::vector<std::pair<Forwarded, std::uint32_t>> relays;  // and where to
};

EditRequestMsg fill(std::uint32_t id, Region box, Material m) {
  EditRequestMsg e;
  e.edit_id = id;
  e.kind = EditKind::kFillBox;
  e.box = box;
  e.material = m;
  e.occupancy = 255;
  return e;
}

class TickTest : public ::testing::Test {
 protected:
  TickTest() {
    options_.tick_hz = 100;
    w_.on_strand([&] { tick_.start(); });
  }
  ~TickTest() override {
    tick_.stop();
    w_.quiesce();
  }
  std::shared_ptr<RecordingClient> join(ClientId id, Vec3f at) {
    auto c = std::make_shared<RecordingClient>();
    w_.on_strand([&] {
      tick_.join(id, "player " + std::to_string(id));
      fan_out_.join(id, c);
      fan_out_.moved(id, at, 96, 32);
    });
    return c;
  }
  void edit(ClientId id, EditRequestMsg e) {
    w_.on_strand([&] { tick_.edit(id, std::move(e), std::chrono::steady_clock::now()); });
  }

  // Open: nothing waits; a test may make the saves fail.
  std::shared_ptr<testing_support::StoreGate> gate_ =
      std::make_shared<testing_support::StoreGate>(std::unordered_set<Vec3i, Vec3iHash>{});
  WorldStrand w_{gate_};
  WorldOptions options_;
  ServerCounters counters_;
  WorldClock clock_;
  FanOut fan_out_{options_, counters_};
  HorizonCache horizons_{w_.strand, *w_.storage, fan_out_};
  Residency residency_{w_.strand, *w_.storage, options_, counters_, clock_, fan_out_, horizons_};
  FakeAuthority authority_;
  Tick tick_{w_.strand, *w_.world, *w_.storage, options_, counters_, clock_, residency_, fan_out_, authority_};
};

TEST_F(TickTest, APlayersEditsKeepTheirOrderWhileAnEarlierOneWaitsAndOthersGoOn) {
  const Region a{{4, 1, 4}, {6, 3, 6}};        // chunk (0,0,0): waits
  const Region b{{40, 1, 4}, {42, 3, 6}};      // chunk (1,0,0): writable
  const Region c{{4, 1, 40}, {6, 3, 42}};      // chunk (0,0,1): writable
  w_.on_strand([&] { authority_.waiting.insert(Vec3i{0, 0, 0}); });
  auto one = join(1, {10, 10, 10});
  auto two = join(2, {10, 10, 10});
  edit(1, fill(11, a, materials::kBrick));
  edit(1, fill(12, b, materials::kBrick));  // its own box is writable: waits behind 11
  edit(2, fill(21, c, materials::kSand));   // another player's: goes on
  ASSERT_TRUE(two->wait([](RecordingClient& r) { return r.acked().size() == 1; }));
  {
    std::lock_guard lock(one->m);
    EXPECT_TRUE(one->acked().empty());
  }
  w_.on_strand([&] {
    EXPECT_NE(residency_.get(Vec3i{41, 2, 5}), solid(materials::kBrick));  // 12 not applied
    EXPECT_EQ(residency_.get(Vec3i{5, 2, 41}), solid(materials::kSand));
    authority_.waiting.clear();
  });
  ASSERT_TRUE(one->wait([](RecordingClient& r) { return r.acked().size() == 2; }));
  EXPECT_EQ(one->acked(), (std::vector<std::uint32_t>{11, 12}));
  w_.on_strand([&] {
    EXPECT_EQ(residency_.get(Vec3i{5, 2, 5}), solid(materials::kBrick));
    EXPECT_EQ(residency_.get(Vec3i{41, 2, 5}), solid(materials::kBrick));
    EXPECT_GT(authority_.settled, 0);
  });
}

// An edit another server forwarded is applied only while its deadline has
// surely not passed by the database's clock (Forwarded::current_until):
// later, its sender may have told its player it was not applied, or that
// its outcome is unknown, and the player gone on to edit there elsewhere.
TEST_F(TickTest, AForwardedEditWhoseDeadlineMayHavePassedIsRefusedNotApplied) {
  const Region late{{4, 1, 4}, {6, 3, 6}};       // chunk (0,0,0)
  const Region in_time{{4, 1, 40}, {6, 3, 42}};  // chunk (0,0,1)
  const auto now = std::chrono::steady_clock::now();
  w_.on_strand([&] {
    residency_.reserve(late);
    residency_.reserve(in_time);
    tick_.queue_forwarded(fill(1, late, materials::kBrick), "bob", Forwarded{1, 2, false, false, now - 1ms});
    tick_.queue_forwarded(fill(2, in_time, materials::kSand), "cy", Forwarded{2, 2, false, false, now + 600s});
  });
  ASSERT_TRUE(testing_support::eventually([&] {
    bool applied = false;
    w_.on_strand([&] { applied = residency_.get(Vec3i{5, 2, 41}) == solid(materials::kSand); });
    return applied;
  }));
  // The late one came first in the queue: refused by now, never applied.
  w_.on_strand([&] { EXPECT_NE(residency_.get(Vec3i{5, 2, 5}), solid(materials::kBrick)); });
}

TEST_F(TickTest, AnEditIsAcknowledgedAfterItsCommitAndAfterItsHoldersHeard) {
  const Region box{{4, 1, 4}, {6, 3, 6}};
  auto holder = join(1, {10, 10, 10});
  w_.on_strand([&] { residency_.want(1, {ChunkWant{{0, 0, 0}, true, 0, false}}); });
  ASSERT_TRUE(holder->wait([](RecordingClient& r) { return r.grants.size() == 1; }));
  const std::uint64_t before = holder->grants[0]->revision();
  edit(1, fill(7, box, materials::kBrick));
  ASSERT_TRUE(holder->wait([](RecordingClient& r) { return r.acked().size() == 1; }));
  {
    std::lock_guard lock(holder->m);
    ASSERT_EQ(holder->ticks.size(), 1u);  // heard before the ack was sent
    EXPECT_EQ(holder->ticks[0].second.at(0)->revision(), before + 1);
  }
  // Stored before it was acknowledged.
  auto stored = w_.world->store().load_chunk(Vec3i{0, 0, 0});
  ASSERT_TRUE(stored.ok() && stored->has_value());
  EXPECT_EQ((*stored)->revision, before + 1);
  EXPECT_EQ((*stored)->chunk.get({5, 2, 5}), solid(materials::kBrick));
}

TEST_F(TickTest, AFlushWaitsForTheTickAppliedAndAnUndoRestores) {
  const Region box{{4, 1, 4}, {6, 3, 6}};
  auto c = join(1, {10, 10, 10});
  edit(1, fill(1, box, materials::kBrick));
  std::atomic<bool> flushed{false};
  ASSERT_TRUE(c->wait([](RecordingClient& r) { return r.acked().size() == 1; }));
  w_.on_strand([&] {
    tick_.flush([&](std::uint64_t, bool stored) { flushed = stored; });
  });
  ASSERT_TRUE(testing_support::eventually([&] { return flushed.load(); }));
  EditRequestMsg undo;
  undo.edit_id = 2;
  undo.kind = EditKind::kUndo;
  edit(1, undo);
  ASSERT_TRUE(c->wait([](RecordingClient& r) { return r.acked().size() == 2; }));
  w_.on_strand([&] { EXPECT_NE(residency_.get(Vec3i{5, 2, 5}), solid(materials::kBrick)); });
}

// Two servers asked each other for regions at once and the sender wins:
// its edit goes back to it, and nothing is asked of the authority for it.
TEST_F(TickTest, AForwardedEditItsSenderWinsGoesBackToItUnasked) {
  const Region box{{4, 1, 4}, {6, 3, 6}};
  w_.on_strand([&] {
    residency_.reserve(box);  // as the inbox read does
    tick_.queue_forwarded(fill(1, box, materials::kBrick), "ann", Forwarded{5, 1, /*back=*/true, /*own=*/false});
  });
  ASSERT_TRUE(testing_support::eventually([&] {
    std::size_t n = 0;
    w_.on_strand([&] { n = authority_.relays.size(); });
    return n == 1;
  }));
  w_.on_strand([&] {
    EXPECT_EQ(authority_.relays[0].first.inbox_id, 5);
    EXPECT_EQ(authority_.relays[0].second, 1u);
    EXPECT_EQ(authority_.asked, 0);
    EXPECT_NE(residency_.get(Vec3i{5, 2, 5}), solid(materials::kBrick));
  });
}

// This server's own client's edit, passed back to it, goes ahead of the
// edits waiting (its player's later edits wait for its answer): the later
// edit, queued first, is applied after it.
TEST_F(TickTest, ThisServersOwnEditPassedBackGoesAheadOfTheEditsWaiting) {
  const Region box{{4, 1, 4}, {6, 3, 6}};
  auto c = join(1, {10, 10, 10});
  w_.on_strand([&] { authority_.waiting.insert(Vec3i{0, 0, 0}); });
  edit(1, fill(12, box, materials::kBrick));  // later, and waiting
  ASSERT_TRUE(testing_support::eventually([&] {
    int asked = 0;
    w_.on_strand([&] { asked = authority_.asked; });
    return asked > 0;
  }));
  w_.on_strand([&] {
    residency_.reserve(box);
    tick_.queue_forwarded(fill(11, box, materials::kSand), "player 1", Forwarded{6, 9, /*back=*/false, /*own=*/true});
    authority_.waiting.clear();
  });
  ASSERT_TRUE(testing_support::eventually([&] { return counters_.edits_applied.load() == 2; }));
  ASSERT_TRUE(c->wait([](RecordingClient& r) { return r.acked().size() == 1; }));
  w_.on_strand([&] { EXPECT_EQ(residency_.get(Vec3i{5, 2, 5}), solid(materials::kBrick)); });
}

TEST_F(TickTest, ACommitThatMayHaveBeenStoredIsNeitherAcknowledgedNorRefused) {
  // A commit whose answer was lost and that could not find out since
  // whether it was stored: its edits are rejected saying the outcome is
  // unknown (the edit may be in the world), and the server stops.
  FileError unknown{"postgresql: commit chunks: server closed the connection unexpectedly; the commit may have been "
                    "stored",
                    std::nullopt};
  unknown.outcome_unknown = true;
  gate_->fail_saves(unknown);
  auto editor = join(1, {10, 10, 10});
  edit(1, fill(5, Region{{4, 1, 4}, {6, 3, 6}}, materials::kBrick));
  ASSERT_TRUE(editor->wait([](RecordingClient& r) { return !r.closed.empty(); }));
  std::lock_guard lock(editor->m);
  EXPECT_TRUE(editor->acked().empty());
  const auto rejected = editor->answered<EditRejectMsg>();
  ASSERT_EQ(rejected.size(), 1u);
  EXPECT_EQ(rejected[0].edit_id, 5u);
  EXPECT_EQ(rejected[0].reason, "storage failure: outcome unknown (the edit may have been saved)");
  EXPECT_TRUE(rejected[0].outcome_unknown);
  EXPECT_TRUE(rejected[0].box.empty()) << "nothing of the world is shown: the tick is not known to be stored";
  EXPECT_EQ(editor->closed, "server storage failure");
}

}  // namespace
}  // namespace terrane
