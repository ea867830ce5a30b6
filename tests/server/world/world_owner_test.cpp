// WorldOwner on its own (real Storage, no sockets): edits become versions
// that are committed before anyone hears of them, changes reach holders
// only, once per holder per tick (holders coarser than full resolution
// every mip_refresh_ms), history steps apply on the strand, and
// streaming's requests, in their own queue, neither hold up a tick nor
// pass each other.
#include "server/world/world_owner.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <filesystem>
#include <future>
#include <mutex>
#include <optional>
#include <thread>
#include <variant>

#include "common/world/sqlite_store.h"
#include "tests/support/eventually.h"
#include "tests/support/gated_store.h"
#include "tests/support/scratch_dir.h"
#include "tests/support/world_strand.h"

namespace terrane {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

// A client that records what the world tells it (RecordingClient), and
// how many grants it had when the first EditAck came.
class Recorder : public testing_support::RecordingClient {
 public:
  void answer(WorldAnswer a) override {
    {
      std::lock_guard lock(m);
      if (grants_at_first_ack < 0 && std::holds_alternative<EditAcked>(a))
        grants_at_first_ack = static_cast<std::int64_t>(grants.size());
    }
    RecordingClient::answer(std::move(a));
  }
  // Waits (up to a minute) until p(*this) holds, under the lock.
  template <class Pred>
  bool wait(Pred p) {
    return RecordingClient::wait([&](RecordingClient&) { return p(*this); });
  }
  // The answers of type T received.
  template <class T>
  std::size_t count() const {
    return static_cast<std::size_t>(
        std::count_if(answers.begin(), answers.end(), [](const WorldAnswer& a) { return std::holds_alternative<T>(a); }));
  }

  // While held, a grant keeps the world strand until let go (held_now
  // says one does): requests queue up behind it.
  void granted(std::vector<VersionPtr> versions) override {
    RecordingClient::granted(std::move(versions));
    std::unique_lock lock(m);
    if (!hold_grants) return;
    held_now = true;
    cv.notify_all();
    cv.wait(lock, [&] { return !hold_grants; });
    held_now = false;
  }
  void let_go() {
    std::lock_guard lock(m);
    hold_grants = false;
    cv.notify_all();
  }

  std::int64_t grants_at_first_ack = -1;  // grants received when the first EditAck came
  bool hold_grants = false, held_now = false;
};

class WorldOwnerTest : public ::testing::Test {
 protected:
  explicit WorldOwnerTest(std::uint32_t mip_refresh_ms = WorldOptions{}.mip_refresh_ms) {
    options_.mip_refresh_ms = mip_refresh_ms;
  }
  void SetUp() override {
    dir_ = testing_support::scratch_dir("terrane-world-owner");
    auto store = SqliteStore::create(dir_.string(), default_world_meta());
    ASSERT_TRUE(store.ok()) << store.error().message;
    std::unique_ptr<WorldStore> inner = std::move(*store);
    if (gate_) inner = std::make_unique<testing_support::GatedStore>(std::move(inner), gate_);
    auto w = World::open(std::move(inner));
    ASSERT_TRUE(w.ok()) << w.error().message;
    world_ = std::move(*w);
    // Gated: loaders to spare for the chunks not waiting at the gate.
    auto s = Storage::open(*world_, gate_ ? 3 : 1);
    ASSERT_TRUE(s.ok());
    storage_ = std::move(*s);
    owner_ = std::make_unique<WorldOwner>(io_, *world_, *storage_, options_, counters_);
    owner_->on_request_wait([this](std::chrono::nanoseconds waited) {
      last_wait_ns_ = waited.count();
      if (waited.count() > max_wait_ns_) max_wait_ns_ = waited.count();
    });
    owner_->start();
    thread_ = std::thread([this] { io_.run(); });
  }
  void TearDown() override {
    owner_->stop();
    work_.reset();
    io_.stop();
    thread_.join();
    owner_.reset();
    storage_.reset();
    world_.reset();
    fs::remove_all(dir_);
  }
  std::shared_ptr<Recorder> client(ClientId id, Vec3f at) {
    auto r = std::make_shared<Recorder>();
    std::string name = "client ";
    name += std::to_string(id);
    owner_->join(id, name, r);
    owner_->moved(id, at, 96, 32);
    return r;
  }
  static EditRequestMsg fill(std::uint32_t id, Region box, Material m) {
    EditRequestMsg e;
    e.edit_id = id;
    e.kind = EditKind::kFillBox;
    e.box = box;
    e.material = m;
    e.occupancy = 255;
    return e;
  }

  std::shared_ptr<testing_support::StoreGate> gate_;  // set by a fixture before SetUp: reads of its chunks wait
  fs::path dir_;
  std::unique_ptr<World> world_;
  std::unique_ptr<Storage> storage_;
  WorldOptions options_;
  ServerCounters counters_;
  asio::io_context io_;
  asio::executor_work_guard<asio::io_context::executor_type> work_{asio::make_work_guard(io_)};
  std::unique_ptr<WorldOwner> owner_;
  std::thread thread_;
  // What the world reported of its streaming requests' waits (its strand).
  std::atomic<std::int64_t> last_wait_ns_{-1}, max_wait_ns_{0};
};

TEST_F(WorldOwnerTest, AnEditBecomesACommittedVersionThatReachesHoldersOnly) {
  const Vec3i a{31, 0, 31}, b{31, 0, 32}, far{-40, 0, 5};
  auto holder = client(1, {1000, 10, 1000});
  auto other = client(2, {-1280, 10, 160});
  owner_->want(1, {{a, true}, {b, true}});
  owner_->want(2, {{far, false}});
  ASSERT_TRUE(holder->wait([](Recorder& r) { return r.grants.size() == 2; }));
  ASSERT_TRUE(other->wait([](Recorder& r) { return r.grants.size() == 1; }));
  const std::uint64_t rev_a = holder->grants[0]->pos() == a ? holder->grants[0]->revision() : holder->grants[1]->revision();
  // One edit spanning both chunks: one tick, one call with both versions.
  owner_->edit(1, fill(5, Region{{1020, 0, 1020}, {1030, 4, 1030}}, materials::kBrick));
  ASSERT_TRUE(holder->wait([](Recorder& r) { return !r.ticks.empty() && r.count<EditAcked>() == 1; }));
  {
    std::lock_guard lock(holder->m);
    ASSERT_EQ(holder->ticks.size(), 1u);
    const auto& changed = holder->ticks.front().second;
    ASSERT_EQ(changed.size(), 2u);
    for (const VersionPtr& v : changed) {
      EXPECT_TRUE(v->pos() == a || v->pos() == b);
      EXPECT_TRUE(v->changed_units().any());
      if (v->pos() == a) {
        EXPECT_EQ(v->revision(), rev_a + 1);
      }
    }
    EXPECT_EQ(holder->count<EditAcked>(), 1u);
  }
  // Committed before anyone heard: the store has it.
  auto stored = world_->store().load_chunk(a);
  ASSERT_TRUE(stored.ok());
  ASSERT_TRUE(stored->has_value());
  EXPECT_EQ((*stored)->revision, rev_a + 1);
  EXPECT_EQ((*stored)->chunk.get({28, 1, 28}), solid(materials::kBrick));
  {
    std::lock_guard lock(other->m);
    EXPECT_TRUE(other->ticks.empty()) << "not a holder of the changed chunks";
  }
  EXPECT_EQ(counters_.deliveries.load(), 2u);
}

TEST_F(WorldOwnerTest, AReleasedChunkIsNoLongerTold) {
  const Vec3i a{31, 0, 31};
  auto c = client(1, {1000, 10, 1000});
  owner_->want(1, {{a, true}});
  ASSERT_TRUE(c->wait([](Recorder& r) { return r.grants.size() == 1; }));
  owner_->release(1, {a});
  owner_->edit(1, fill(1, Region{{1000, 0, 1000}, {1002, 2, 1002}}, materials::kRock));
  ASSERT_TRUE(c->wait([](Recorder& r) { return r.count<EditAcked>() == 1; }));
  std::lock_guard lock(c->m);
  EXPECT_TRUE(c->ticks.empty());
}

TEST_F(WorldOwnerTest, UndoAndRedoApplyOnTheStrand) {
  const Vec3i a{31, 0, 31};
  auto c = client(1, {1000, 10, 1000});
  owner_->want(1, {{a, true}});
  ASSERT_TRUE(c->wait([](Recorder& r) { return r.grants.size() == 1; }));
  const Vec3i p{1001, 1, 1001};
  Voxel before{};
  owner_->inspect([&](const WorldView& v) { before = v.get(p); });
  owner_->edit(1, fill(1, Region{p, p + Vec3i{1, 1, 1}}, materials::kSnow));
  EditRequestMsg undo;
  undo.edit_id = 2;
  undo.kind = EditKind::kUndo;
  owner_->edit(1, undo);
  ASSERT_TRUE(c->wait([](Recorder& r) { return r.count<EditAcked>() == 2; }));
  owner_->inspect([&](const WorldView& v) { EXPECT_EQ(v.get(p), before); });
  EditRequestMsg redo = undo;
  redo.edit_id = 3;
  redo.kind = EditKind::kRedo;
  owner_->edit(1, redo);
  ASSERT_TRUE(c->wait([](Recorder& r) { return r.count<EditAcked>() == 3; }));
  owner_->inspect([&](const WorldView& v) { EXPECT_EQ(v.get(p), solid(materials::kSnow)); });
  owner_->edit(1, redo);  // nothing left to redo
  ASSERT_TRUE(c->wait([](Recorder& r) { return r.count<EditRejectMsg>() == 1; }));
}

TEST_F(WorldOwnerTest, ATickRunsBetweenSlicesOfQueuedRequestsNotBehindThemAll) {
  const Vec3i a{31, 0, 31};
  auto c = client(1, {1000, 10, 1000});
  owner_->want(1, {{a, true}});
  ASSERT_TRUE(c->wait([](Recorder& r) { return r.grants.size() == 1; }));
  std::uint64_t before = 0;
  owner_->inspect([&](const WorldView& v) { before = v.revision(a); });
  // Far more streaming work queued than one slice (each request is granted
  // again), then an edit: were requests served first come first served,
  // its tick would wait for every one of them. Watched from the strand
  // itself (inspect runs between slices too): the grants made when the
  // edit is first seen applied. (Its acknowledgement follows the commit on
  // the writer thread, which a loaded machine may delay past the last
  // grant: no measure of the strand.)
  // The strand is held (in a grant) while they are queued, so none is
  // served before the edit is queued behind them all.
  constexpr std::size_t kRequests = 200000;
  {
    std::lock_guard lock(c->m);
    c->hold_grants = true;
  }
  struct LetGo {
    Recorder& r;
    ~LetGo() { r.let_go(); }  // also when an assertion ends the test early
  } let_go{*c};
  owner_->want(1, {{a, true}});
  ASSERT_TRUE(c->wait([](Recorder& r) { return r.held_now; }));
  for (std::size_t i = 1; i < kRequests; ++i) owner_->want(1, {{a, true}});
  owner_->edit(1, fill(1, Region{{1001, 1, 1001}, {1002, 2, 1002}}, materials::kBrick));
  c->let_go();
  std::optional<std::size_t> grants_when_applied;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  while (!grants_when_applied && std::chrono::steady_clock::now() < deadline)
    owner_->inspect([&](const WorldView& v) {
      if (v.revision(a) == before) return;
      std::lock_guard lock(c->m);
      grants_when_applied = c->grants.size();
    });
  ASSERT_TRUE(grants_when_applied.has_value()) << "the edit was never applied";
  EXPECT_LT(*grants_when_applied, kRequests + 1);
  ASSERT_TRUE(c->wait([](Recorder& r) { return r.grants.size() == kRequests + 1 && r.grants_at_first_ack >= 0; }));
  // Their waits were reported, and a queue drained says nothing waits (the
  // strand says so after the last grant left, which the client may read
  // first).
  EXPECT_GT(max_wait_ns_.load(), 0);
  EXPECT_TRUE(testing_support::eventually([&] { return last_wait_ns_.load() == 0; })) << last_wait_ns_.load();
}

TEST_F(WorldOwnerTest, RequestsAreServedInTheOrderMade) {
  const Vec3i a{31, 0, 31};
  auto c = client(1, {1000, 10, 1000});
  owner_->want(1, {{a, true}});
  ASSERT_TRUE(c->wait([](Recorder& r) { return r.grants.size() == 1; }));  // loaded
  // Release, want: the client ends a holder (a change reaches it);
  // release last: it does not.
  owner_->release(1, {a});
  owner_->want(1, {{a, true}});
  ASSERT_TRUE(c->wait([](Recorder& r) { return r.grants.size() == 2; }));
  owner_->edit(1, fill(1, Region{{1001, 1, 1001}, {1002, 2, 1002}}, materials::kBrick));
  ASSERT_TRUE(c->wait([](Recorder& r) { return r.count<EditAcked>() == 1 && !r.ticks.empty(); }));
  owner_->release(1, {a});
  owner_->edit(1, fill(2, Region{{1003, 1, 1003}, {1004, 2, 1004}}, materials::kSnow));
  ASSERT_TRUE(c->wait([](Recorder& r) { return r.count<EditAcked>() == 2; }));
  std::lock_guard lock(c->m);
  EXPECT_EQ(c->ticks.size(), 1u);
}

TEST_F(WorldOwnerTest, AClientsRequestsNeverPassItsJoin) {
  const Vec3i a{31, 0, 31};
  auto first = client(1, {1000, 10, 1000});
  owner_->want(1, {{a, true}});
  ASSERT_TRUE(first->wait([](Recorder& r) { return r.grants.size() == 1; }));
  // The strand held busy while one client's request is queued (its drain
  // posted), a second client joins and asks at once: its request must not
  // be served before its join, or it would be dropped as a stranger's.
  std::promise<void> go;
  std::shared_future<void> released = go.get_future().share();
  asio::post(io_, [released] { released.wait(); });
  owner_->want(1, {{a, true}});
  auto second = client(2, {1000, 10, 1000});
  owner_->want(2, {{a, true}});
  go.set_value();
  EXPECT_TRUE(second->wait([](Recorder& r) { return r.grants.size() == 1; }));
  EXPECT_TRUE(first->wait([](Recorder& r) { return r.grants.size() == 2; }));
}

// Reads of chunk (31, 0, 31) wait until the test opens the gate.
class WorldOwnerWaitingEditTest : public WorldOwnerTest {
 protected:
  WorldOwnerWaitingEditTest() {
    gate_ = std::make_shared<testing_support::StoreGate>(std::unordered_set<Vec3i, Vec3iHash>{{31, 0, 31}});
  }
};

TEST_F(WorldOwnerWaitingEditTest, AnEditWaitingForItsChunkHoldsUpOnlyItsPlayersEditsAndEditsOnThatChunk) {
  auto a = client(1, {1000, 10, 1000});
  auto b = client(2, {1000, 10, 1000});
  auto c = client(3, {1000, 10, 1000});
  // a's first edit needs chunk (31, 0, 31), whose read waits at the gate.
  owner_->edit(1, fill(1, Region{{1000, 0, 1000}, {1008, 4, 1008}}, materials::kBrick));
  ASSERT_TRUE(testing_support::eventually([&] { return gate_->reached(); }));
  // Behind it: a's next edit elsewhere, c's edit over a's (its chunk), b's
  // edit elsewhere.
  owner_->edit(1, fill(2, Region{{1060, 0, 1060}, {1062, 2, 1062}}, materials::kSnow));
  owner_->edit(3, fill(3, Region{{1004, 0, 1004}, {1012, 4, 1012}}, materials::kRock));
  owner_->edit(2, fill(4, Region{{1130, 0, 1130}, {1132, 2, 1132}}, materials::kSand));
  ASSERT_TRUE(b->wait([](Recorder& r) { return r.count<EditAcked>() == 1; }))
      << "an edit behind a waiting one, of another player and chunk, is not held up";
  // Acknowledgements of one tick go out in the order applied: a's and c's,
  // queued before b's, would have come first.
  {
    std::lock_guard lock(a->m);
    EXPECT_TRUE(a->acked().empty()) << "a's second edit waits for its first";
  }
  {
    std::lock_guard lock(c->m);
    EXPECT_TRUE(c->acked().empty()) << "an edit on the waiting edit's chunk waits for it";
  }
  gate_->open();
  ASSERT_TRUE(a->wait([](Recorder& r) { return r.acked().size() == 2; }));
  ASSERT_TRUE(c->wait([](Recorder& r) { return r.acked().size() == 1; }));
  {
    std::lock_guard lock(a->m);
    EXPECT_EQ(a->acked(), (std::vector<std::uint32_t>{1, 2}));
  }
  // c's edit applied after a's first, over it.
  owner_->inspect([&](const WorldView& v) {
    EXPECT_EQ(v.get({1002, 1, 1002}), solid(materials::kBrick));
    EXPECT_EQ(v.get({1006, 1, 1006}), solid(materials::kRock));
    EXPECT_EQ(v.get({1061, 1, 1061}), solid(materials::kSnow));
  });
}

// Changes of chunks held coarser than full resolution are gathered and
// handed over every mip_refresh_ms, not posted every tick.
class WorldOwnerMipNewsTest : public WorldOwnerTest {
 protected:
  WorldOwnerMipNewsTest() : WorldOwnerTest(2000) {}
};
// The same, with news gathered for longer than any test runs: whatever
// reaches a holder afar came another way.
class WorldOwnerMipNewsHeldTest : public WorldOwnerTest {
 protected:
  WorldOwnerMipNewsHeldTest() : WorldOwnerTest(600'000) {}
};

TEST_F(WorldOwnerMipNewsTest, AHolderAfarHearsOfSeveralTicksAtOnce) {
  const Vec3i a{31, 0, 31};
  auto near = client(1, {1000, 10, 1000});
  auto afar = client(2, {1000, 10, 1000});
  owner_->want(1, {{a, true, 0}});
  owner_->want(2, {{a, false, kMipLevels - 1}});
  ASSERT_TRUE(near->wait([](Recorder& r) { return r.grants.size() == 1; }));
  ASSERT_TRUE(afar->wait([](Recorder& r) { return r.grants.size() == 1; }));
  const std::uint64_t rev = near->grants[0]->revision();
  // Three edits, each in a tick of its own (each waits for the last's ack).
  for (std::uint32_t i = 1; i <= 3; ++i) {
    owner_->edit(1, fill(i, Region{{1000, 0, 1000}, {1002, static_cast<std::int32_t>(i), 1002}}, materials::kBrick));
    ASSERT_TRUE(near->wait([i](Recorder& r) { return r.count<EditAcked>() == i; }));
  }
  {
    std::lock_guard lock(near->m);
    EXPECT_EQ(near->ticks.size(), 3u) << "a holder at full resolution hears of every tick";
    EXPECT_TRUE(near->mip_news.empty());
  }
  ASSERT_TRUE(afar->wait([rev](Recorder& r) {
    return !r.mip_news.empty() && r.mip_news.back().second.back()->revision() == rev + 3;
  }));
  std::lock_guard lock(afar->m);
  EXPECT_TRUE(afar->ticks.empty()) << "a holder afar is not told every tick";
  EXPECT_LT(afar->mip_news.size(), 3u) << "the ticks' news gathered";
  std::size_t versions = 0;
  for (const auto& [tick, changed] : afar->mip_news) {
    for (const VersionPtr& v : changed) EXPECT_EQ(v->pos(), a);
    versions += changed.size();
  }
  EXPECT_EQ(versions, 3u);
  EXPECT_EQ(counters_.deliveries.load(), 6u);
}

TEST_F(WorldOwnerMipNewsHeldTest, AChunkNowHeldAtFullResolutionIsToldEveryTickAndItsGatheredNewsAtOnce) {
  const Vec3i a{31, 0, 31}, b{31, 0, 30};
  auto editor = client(1, {1000, 10, 1000});
  auto mover = client(2, {1000, 10, 1000});
  owner_->want(1, {{a, true, 0}, {b, true, 0}});
  owner_->want(2, {{a, false, kMipLevels - 1}, {b, false, kMipLevels - 1}});
  ASSERT_TRUE(editor->wait([](Recorder& r) { return r.grants.size() == 2; }));
  ASSERT_TRUE(mover->wait([](Recorder& r) { return r.grants.size() == 2; }));
  // A change of b, gathered for the mover (not due for ten minutes).
  owner_->edit(1, fill(1, Region{{1000, 0, 990}, {1002, 2, 992}}, materials::kBrick));
  ASSERT_TRUE(editor->wait([](Recorder& r) { return r.count<EditAcked>() == 1; }));
  owner_->inspect([](const WorldView&) {});  // the commit's news handed out
  {
    std::lock_guard lock(mover->m);
    EXPECT_TRUE(mover->ticks.empty());
    EXPECT_TRUE(mover->mip_news.empty());
  }
  // The mover now holds b at full resolution: its gathered news of b comes
  // at once, and a's, not changed yet, stays gathered until a is too.
  owner_->holds_full(2, {b});
  ASSERT_TRUE(mover->wait([](Recorder& r) { return r.mip_news.size() == 1; }));
  {
    std::lock_guard lock(mover->m);
    ASSERT_EQ(mover->mip_news[0].second.size(), 1u);
    EXPECT_EQ(mover->mip_news[0].second[0]->pos(), b);
  }
  // b's next change reaches it in its tick.
  owner_->edit(1, fill(2, Region{{1000, 0, 990}, {1002, 3, 992}}, materials::kSnow));
  ASSERT_TRUE(mover->wait([](Recorder& r) { return r.ticks.size() == 1; }));
  std::lock_guard lock(mover->m);
  ASSERT_EQ(mover->ticks[0].second.size(), 1u);
  EXPECT_EQ(mover->ticks[0].second[0]->pos(), b);
}

TEST_F(WorldOwnerMipNewsHeldTest, HoldsFullOfAChunkNotHeldChangesNothing) {
  const Vec3i a{31, 0, 31};
  auto editor = client(1, {1000, 10, 1000});
  auto other = client(2, {1000, 10, 1000});
  owner_->want(1, {{a, true, 0}});
  ASSERT_TRUE(editor->wait([](Recorder& r) { return r.grants.size() == 1; }));
  owner_->holds_full(2, {a});  // never asked for, or released: no holder made
  owner_->edit(1, fill(1, Region{{1000, 0, 1000}, {1002, 2, 1002}}, materials::kBrick));
  ASSERT_TRUE(editor->wait([](Recorder& r) { return r.count<EditAcked>() == 1 && !r.ticks.empty(); }));
  owner_->inspect([](const WorldView&) {});
  std::lock_guard lock(other->m);
  EXPECT_TRUE(other->ticks.empty());
  EXPECT_TRUE(other->mip_news.empty());
}

}  // namespace
}  // namespace terrane
