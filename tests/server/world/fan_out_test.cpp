// FanOut on its own (no strand, no storage): a committed version reaches
// the holders at full resolution at once and the coarser holders only when
// their mip news is due (or at once when they come to hold it at full
// resolution); clients that left hear nothing; presence goes out only when
// it changed.
#include "server/world/fan_out.h"

#include <gtest/gtest.h>

#include <chrono>
#include <memory>

#include "tests/support/world_strand.h"

namespace terrane {
namespace {

using namespace std::chrono_literals;
using testing_support::RecordingClient;

VersionPtr version(Vec3i cp, std::uint64_t revision) {
  return std::make_shared<const ChunkVersion>(cp, revision, std::shared_ptr<const Chunk>{});
}

class FanOutTest : public ::testing::Test {
 protected:
  FanOutTest() { options_.mip_refresh_ms = 250; }
  std::shared_ptr<RecordingClient> join(ClientId id) {
    auto c = std::make_shared<RecordingClient>();
    fan_out_.join(id, c);
    return c;
  }

  WorldOptions options_;
  ServerCounters counters_;
  FanOut fan_out_{options_, counters_};
  const Vec3i cp_{3, 0, 4};
  const std::chrono::steady_clock::time_point t0_ = std::chrono::steady_clock::now();
};

TEST_F(FanOutTest, ACommittedVersionReachesFullHoldersAtOnceAndCoarseHoldersOnlyAtMipDue) {
  auto near = join(1), far = join(2), other = join(3);
  fan_out_.hold(cp_, 1, true);
  fan_out_.hold(cp_, 2, false);
  const VersionPtr v1 = version(cp_, 1), v2 = version(cp_, 2);
  fan_out_.publish(7, {v1}, t0_);
  fan_out_.publish(8, {v2}, t0_ + 100ms);
  ASSERT_EQ(near->ticks.size(), 2u);
  EXPECT_EQ(near->ticks[0].first, 7u);
  EXPECT_EQ(near->ticks[0].second, std::vector<VersionPtr>{v1});
  EXPECT_EQ(near->ticks[1].first, 8u);
  EXPECT_TRUE(far->ticks.empty());
  EXPECT_TRUE(far->mip_news.empty());
  EXPECT_TRUE(other->ticks.empty());  // holds nothing

  fan_out_.deliver_mip_news(t0_ + 249ms);
  EXPECT_TRUE(far->mip_news.empty());
  // Due mip_refresh_ms after the first news: both ticks' versions at once,
  // oldest first, named by the newest tick.
  fan_out_.deliver_mip_news(t0_ + 250ms);
  ASSERT_EQ(far->mip_news.size(), 1u);
  EXPECT_EQ(far->mip_news[0].first, 8u);
  EXPECT_EQ(far->mip_news[0].second, (std::vector<VersionPtr>{v1, v2}));
  fan_out_.deliver_mip_news(t0_ + 10s);
  EXPECT_EQ(far->mip_news.size(), 1u);
  EXPECT_EQ(counters_.deliveries.load(), 4u);
}

TEST_F(FanOutTest, WithoutAMipRefreshEveryHolderHearsAtOnce) {
  options_.mip_refresh_ms = 0;
  auto far = join(2);
  fan_out_.hold(cp_, 2, false);
  fan_out_.publish(3, {version(cp_, 1)}, t0_);
  ASSERT_EQ(far->ticks.size(), 1u);
  EXPECT_TRUE(far->mip_news.empty());
}

TEST_F(FanOutTest, NewsGatheredForAChunkNowHeldAtFullResolutionGoesAtOnce) {
  auto c = join(2);
  const Vec3i other{9, 0, 9};
  fan_out_.hold(cp_, 2, false);
  fan_out_.hold(other, 2, false);
  fan_out_.publish(5, {version(cp_, 1), version(other, 1)}, t0_);
  EXPECT_TRUE(c->mip_news.empty());
  fan_out_.holds_full(2, {Vec3i{50, 0, 50}});  // not held: changes nothing
  EXPECT_TRUE(c->mip_news.empty());
  fan_out_.holds_full(2, {cp_});
  ASSERT_EQ(c->mip_news.size(), 1u);
  EXPECT_EQ(c->mip_news[0].second.size(), 2u);  // the rest with it
  EXPECT_TRUE(fan_out_.held_full(cp_));
  EXPECT_FALSE(fan_out_.held_full(other));
  // Its due entry is stale now: nothing more.
  fan_out_.deliver_mip_news(t0_ + 10s);
  EXPECT_EQ(c->mip_news.size(), 1u);
  // From now on it hears of cp_ every tick.
  fan_out_.publish(6, {version(cp_, 2)}, t0_ + 1s);
  EXPECT_EQ(c->ticks.size(), 1u);
}

TEST_F(FanOutTest, AClientThatLeftOrReleasedHearsNothing) {
  auto gone = join(1), released = join(2);
  fan_out_.hold(cp_, 1, true);
  fan_out_.hold(cp_, 2, true);
  fan_out_.release(2, {cp_});
  fan_out_.leave(1);
  EXPECT_FALSE(fan_out_.present(1));
  EXPECT_TRUE(fan_out_.present(2));
  // (The replicator releases before it leaves; a holder that did not is
  // skipped.)
  fan_out_.publish(4, {version(cp_, 1)}, t0_);
  EXPECT_TRUE(gone->ticks.empty());
  EXPECT_TRUE(released->ticks.empty());
  EXPECT_FALSE(fan_out_.answer(1, EditAcked{1, 1}));
  EXPECT_TRUE(fan_out_.answer(2, EditAcked{1, 1}));
  EXPECT_EQ(released->answered<EditAcked>(), (std::vector<EditAcked>{EditAcked{1, 1}}));
  EXPECT_TRUE(gone->answers.empty());
}

TEST_F(FanOutTest, TheFullResolutionRegionIsWhereTheClientLastMoved) {
  join(1);
  const Region box{{8, 0, 8}, {12, 4, 12}};
  EXPECT_FALSE(fan_out_.within_full_res(1, box));  // not placed yet
  fan_out_.moved(1, Vec3f{10, 10, 10}, 96, 32);
  EXPECT_TRUE(fan_out_.within_full_res(1, box));
  fan_out_.moved(1, Vec3f{5000, 10, 5000}, 96, 32);
  EXPECT_FALSE(fan_out_.within_full_res(1, box));
  EXPECT_FALSE(fan_out_.within_full_res(2, box));  // never joined
}

TEST_F(FanOutTest, PresenceIsSentOnlyWhenItChanged) {
  options_.tick_hz = 1;
  options_.presence_hz = 1;  // every client every tick
  auto a = join(1), b = join(2);
  fan_out_.moved(1, Vec3f{0, 10, 0}, 96, 32);
  fan_out_.moved(2, Vec3f{20, 10, 0}, 96, 32);
  fan_out_.send_presence(1);
  ASSERT_EQ(a->answers.size(), 1u);
  EXPECT_EQ(b->answers.size(), 1u);
  // Each hears of the other, where it is.
  const auto seen = a->answered<PresenceNearby>();
  ASSERT_EQ(seen.size(), 1u);
  ASSERT_EQ(seen[0].entries.size(), 1u);
  EXPECT_EQ(seen[0].entries[0].client_id, 2u);
  EXPECT_EQ(seen[0].entries[0].position.x, 20.0f);
  fan_out_.send_presence(2);  // nobody moved
  EXPECT_EQ(a->answers.size(), 1u);
  fan_out_.moved(2, Vec3f{30, 10, 0}, 96, 32);
  fan_out_.send_presence(3);
  ASSERT_EQ(a->answers.size(), 2u);  // b moved
  EXPECT_EQ(a->answered<PresenceNearby>()[1].entries[0].position.x, 30.0f);
  EXPECT_EQ(b->answers.size(), 1u);  // a did not
  EXPECT_EQ(counters_.presence_sent.load(), 3u);
}

// Each client has its turn once every tick_hz / presence_hz ticks, at the
// phase of its id; clients that join or leave keep the others' turns, and
// a new period (the options changed) gives every client its turn again.
TEST_F(FanOutTest, EachClientHasOnePresenceTurnAPeriod) {
  options_.tick_hz = 6;
  options_.presence_hz = 2;  // a turn every 3 ticks
  std::vector<std::shared_ptr<RecordingClient>> clients;
  for (ClientId id = 1; id <= 20; ++id) {
    clients.push_back(join(id));
    fan_out_.moved(id, Vec3f{static_cast<float>(id), 10, 0}, 96, 32);
  }
  auto late = join(40);  // before the turns are first laid out (the first send_presence); 41 joins after
  fan_out_.send_presence(0);  // the phase-0 clients: ids 3, 6, ... (id + 0) % 3 == 0
  for (ClientId id = 1; id <= 20; ++id)
    EXPECT_EQ(clients[id - 1]->answers.size(), id % 3 == 0 ? 1u : 0u) << "client " << id;
  fan_out_.moved(40, Vec3f{40, 10, 0}, 96, 32);
  fan_out_.leave(5);
  auto later = join(41);
  fan_out_.moved(41, Vec3f{41, 10, 0}, 96, 32);
  fan_out_.send_presence(1);  // (id + 1) % 3 == 0: 2, 8, 11, ..., 41
  fan_out_.send_presence(2);  // 1, 4, 7, 10, ..., 40 (5 left)
  for (ClientId id = 1; id <= 20; ++id)
    EXPECT_EQ(clients[id - 1]->answers.size(), id == 5 ? 0u : 1u) << "client " << id;
  EXPECT_EQ(late->answers.size(), 1u);
  EXPECT_EQ(later->answers.size(), 1u);
  // Every 2 ticks now: each (but 5) hears within the next 2, moved first.
  options_.presence_hz = 3;
  for (ClientId id = 1; id <= 20; ++id) fan_out_.moved(id, Vec3f{static_cast<float>(id), 11, 0}, 96, 32);
  fan_out_.send_presence(3);
  fan_out_.send_presence(4);
  for (ClientId id = 1; id <= 20; ++id)
    EXPECT_EQ(clients[id - 1]->answers.size(), id == 5 ? 0u : 2u) << "client " << id;
}

// Each entry names the client (its Hello's name), so a client can say who
// it sees; a client joined without a name is told without one.
TEST_F(FanOutTest, PresenceNamesTheClients) {
  options_.tick_hz = 1;
  options_.presence_hz = 1;
  auto a = join(1);
  auto b = std::make_shared<RecordingClient>();
  fan_out_.join(2, b, "builder");
  fan_out_.moved(1, Vec3f{0, 10, 0}, 96, 32);
  fan_out_.moved(2, Vec3f{20, 10, 0}, 96, 32);
  fan_out_.send_presence(1);
  const auto a_sees = a->answered<PresenceNearby>();
  ASSERT_EQ(a_sees.size(), 1u);
  ASSERT_EQ(a_sees[0].entries.size(), 1u);
  EXPECT_EQ(a_sees[0].entries[0].name, "builder");
  const auto b_sees = b->answered<PresenceNearby>();
  ASSERT_EQ(b_sees.size(), 1u);
  EXPECT_EQ(b_sees[0].entries[0].client_id, 1u);
  EXPECT_EQ(b_sees[0].entries[0].name, "");

  // The builder moves and stays in a's list: its entry comes again without
  // its name (a keeps the one told); once gone from the list and back, it
  // is named again.
  fan_out_.moved(2, Vec3f{24, 10, 0}, 96, 32);
  fan_out_.send_presence(2);
  auto later = a->answered<PresenceNearby>();
  ASSERT_EQ(later.size(), 2u);
  ASSERT_EQ(later[1].entries.size(), 1u);
  EXPECT_EQ(later[1].entries[0].client_id, 2u);
  EXPECT_EQ(later[1].entries[0].name, "") << "a name is told once, when its entry enters the list";
  fan_out_.moved(2, Vec3f{2000, 10, 0}, 96, 32);  // out of a's view
  fan_out_.send_presence(3);
  fan_out_.moved(2, Vec3f{30, 10, 0}, 96, 32);
  fan_out_.send_presence(4);
  later = a->answered<PresenceNearby>();
  ASSERT_EQ(later.size(), 4u);
  EXPECT_TRUE(later[2].entries.empty());
  ASSERT_EQ(later[3].entries.size(), 1u);
  EXPECT_EQ(later[3].entries[0].name, "builder");
}

// PresenceRecords: a client told what changed keeps, by applying them, the
// list a whole-list client is sent (positions in eighths); the near
// entries' moves come every turn, the far ones' on their turns, and an
// entry that stopped is told where it stopped within 8 turns.
TEST_F(FanOutTest, PresenceRecordsKeepTheListAWholeListClientIsSent) {
  options_.tick_hz = 1;
  options_.presence_hz = 1;  // every client every tick
  auto told = std::make_shared<RecordingClient>();
  auto whole = std::make_shared<RecordingClient>();
  fan_out_.join(1, told, "told", true);
  fan_out_.join(2, whole, "whole");
  fan_out_.moved(1, Vec3f{0, 10, 0}, 1000, 32);
  fan_out_.moved(2, Vec3f{0, 10, 0}, 1000, 32);
  // Others: near (within 64), middling (128..256) and far (over 256).
  const ClientId near = 10, mid = 11, far = 12;
  for (ClientId id : {near, mid, far}) fan_out_.join(id, std::make_shared<RecordingClient>(), "bot" + std::to_string(id));
  auto place = [&](float step) {
    fan_out_.moved(near, Vec3f{20 + step, 10, 0}, 64, 32);
    fan_out_.moved(mid, Vec3f{200 + step, 10, 0}, 64, 32);
    fan_out_.moved(far, Vec3f{600 + step, 10.3f, 0}, 64, 32);
  };
  PresenceList list;
  std::size_t applied = 0;
  auto apply = [&] {
    const auto got = told->answered<PresenceChanged>();
    for (; applied < got.size(); ++applied) ASSERT_TRUE(list.apply(got[applied].records).ok());
  };
  // The two see each other: the others, their ids and places (a whole
  // list names an entry only when it enters).
  auto others = [](std::vector<PresenceEntryMsg> e) {
    std::erase_if(e, [](const PresenceEntryMsg& x) { return x.client_id == 1 || x.client_id == 2; });
    for (auto& x : e) x.name.clear();
    return e;
  };
  auto expected = [&] {
    auto e = whole->answered<PresenceNearby>().back().entries;
    for (auto& x : e) x.position = presence_position(presence_eighths(x.position));
    return others(e);
  };
  std::uint64_t tick = 1;
  place(0);
  fan_out_.send_presence(tick++);
  apply();
  const auto first = told->answered<PresenceChanged>();
  ASSERT_EQ(first.size(), 1u);
  for (const PresenceRecord& r : first[0].records) {
    EXPECT_EQ(r.kind, PresenceRecordKind::kEntered);
    EXPECT_EQ(r.name, r.client_id == 2 ? "whole" : "bot" + std::to_string(r.client_id))
        << "the first records name every entry";
  }
  // On the move: the near one is told every turn, the far one on one turn in 8.
  std::size_t near_moves = 0, far_moves = 0;
  for (int turn = 0; turn < 16; ++turn) {
    place(static_cast<float>(turn + 1));
    const std::size_t before = told->answered<PresenceChanged>().size();
    fan_out_.send_presence(tick++);
    apply();
    const auto got = told->answered<PresenceChanged>();
    for (std::size_t i = before; i < got.size(); ++i)
      for (const PresenceRecord& r : got[i].records) {
        EXPECT_EQ(r.kind, PresenceRecordKind::kMoved);
        EXPECT_TRUE(r.name.empty());
        near_moves += r.client_id == near;
        far_moves += r.client_id == far;
      }
  }
  EXPECT_EQ(near_moves, 16u);
  EXPECT_EQ(far_moves, 2u);
  // They stop: within 8 turns the list is the whole list's, exactly.
  for (int turn = 0; turn < 8; ++turn) {
    fan_out_.send_presence(tick++);
    apply();
  }
  EXPECT_EQ(others(list.nearest_first(Vec3f{0, 10, 0})), expected());
  const std::size_t settled = told->answered<PresenceChanged>().size();
  fan_out_.send_presence(tick++);
  EXPECT_EQ(told->answered<PresenceChanged>().size(), settled) << "nothing changed, nothing sent";
  // One leaves the view: it is told at once, without waiting for a turn.
  fan_out_.moved(far, Vec3f{5000, 10, 0}, 64, 32);
  fan_out_.send_presence(tick++);
  apply();
  ASSERT_EQ(told->answered<PresenceChanged>().size(), settled + 1);
  const auto last = told->answered<PresenceChanged>().back().records;
  ASSERT_EQ(last.size(), 1u);
  EXPECT_EQ(last[0].kind, PresenceRecordKind::kLeft);
  EXPECT_EQ(last[0].client_id, far);
  EXPECT_EQ(others(list.nearest_first(Vec3f{0, 10, 0})), expected());
  EXPECT_TRUE(whole->answered<PresenceChanged>().empty()) << "a client that did not ask for records gets lists";
}

// A full list whose nearest changes: the one that left is told first, so
// the list never holds more than its maximum, even between two records.
TEST_F(FanOutTest, PresenceRecordsTellWhoLeftFirst) {
  options_.tick_hz = 1;
  options_.presence_hz = 1;
  options_.presence_max_entries = 1;
  auto told = std::make_shared<RecordingClient>();
  fan_out_.join(1, told, "told", true);
  fan_out_.join(2, std::make_shared<RecordingClient>(), "far");
  fan_out_.join(3, std::make_shared<RecordingClient>(), "near");
  fan_out_.moved(1, Vec3f{0, 10, 0}, 500, 32);
  fan_out_.moved(2, Vec3f{40, 10, 0}, 64, 32);
  fan_out_.send_presence(1);
  fan_out_.moved(3, Vec3f{10, 10, 0}, 64, 32);
  fan_out_.send_presence(2);
  const auto got = told->answered<PresenceChanged>();
  ASSERT_EQ(got.size(), 2u);
  ASSERT_EQ(got[1].records.size(), 2u);
  EXPECT_EQ(got[1].records[0].kind, PresenceRecordKind::kLeft);
  EXPECT_EQ(got[1].records[0].client_id, 2u);
  EXPECT_EQ(got[1].records[1].kind, PresenceRecordKind::kEntered);
  EXPECT_EQ(got[1].records[1].client_id, 3u);
  PresenceList list;
  for (const auto& g : got)
    for (const PresenceRecord& r : g.records) {
      ASSERT_TRUE(list.apply(std::span(&r, 1)).ok());
      EXPECT_LE(list.entries().size(), 1u);
    }
}

}  // namespace
}  // namespace terrane
