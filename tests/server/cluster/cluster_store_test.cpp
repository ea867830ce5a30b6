// ClusterStore against a real PostgreSQL started by the test (one per
// suite, a database per test), on 127.0.0.1: the region leases that keep
// one writer per region (claims, renewals, takeovers, the neighbours'
// rule), the servers' addresses and the map of writers, the regions'
// write sequences, forwarded edits taken once and only before their
// deadline, taken back, and relayed between inboxes. Chunks are
// written through the chunk store (PostgresStore) beside it.
#include "server/cluster/cluster_store.h"

#include <fmt/format.h>
#include <gtest/gtest.h>

#include <libpq-fe.h>

#include <algorithm>
#include <chrono>
#include <map>
#include <memory>
#include <span>
#include <string>
#include <future>
#include <thread>

#include "common/world/world.h"
#include "server/storage/postgres_store.h"
#include "tests/support/eventually.h"
#include "tests/support/postgres.h"
#include "tests/support/postgres_stores.h"

namespace terrane {
namespace {

using namespace std::chrono_literals;
using testing_support::eventually;

using testing_support::run_sql;
using testing_support::sql_value;

class ClusterStoreTest : public testing_support::PostgresStoresTest {};

TEST_F(ClusterStoreTest, ManyLeasesRenewInOneStatementAndStaleOnesAreLeftOut) {
  auto a = open();
  ASSERT_TRUE(a);
  std::vector<RegionLease> leases;
  for (int x = -2; x <= 2; ++x) {
    auto l = cl(a)->claim({x, 1, -x}, 1, 60s);
    ASSERT_TRUE(l.ok()) << l.error().message;
    leases.push_back(*l);
  }
  // Region (0,1,0) changes hands (its epoch moves on), (2,1,-2) runs out.
  auto newer = cl(a)->claim({0, 1, 0}, 1, 60s);
  ASSERT_TRUE(newer.ok());
  ASSERT_EQ(run_sql(url_, "UPDATE terrane_leases SET expires_at = clock_timestamp() WHERE rx = 2"), "");
  auto kept = cl(a)->renew(leases, 60s);
  ASSERT_TRUE(kept.ok()) << kept.error().message;
  std::vector<RegionLease> want{leases[0], leases[1], leases[3]};
  std::sort(kept->begin(), kept->end(), [](const RegionLease& p, const RegionLease& q) { return p.region.x < q.region.x; });
  EXPECT_EQ(*kept, want);
  auto none = cl(a)->renew({}, 60s);
  ASSERT_TRUE(none.ok());
  EXPECT_TRUE(none->empty());
}

TEST_F(ClusterStoreTest, ServersSayWhereClientsReachThemAndTheMapNamesEachRegionsWriter) {
  auto a = open(), b = open();
  ASSERT_TRUE(a && b);
  ASSERT_TRUE(cl(a)->claim({0, 0, 0}, 1, 60s).ok());
  ASSERT_TRUE(cl(b)->claim({1, 0, 0}, 2, 60s).ok());
  ASSERT_TRUE(cl(b)->claim({2, 0, 0}, 3, 60s).ok());
  ASSERT_TRUE(cl(a)->advertise(1, "127.0.0.1:7001").ok());
  ASSERT_TRUE(cl(b)->advertise(2, "[::1]:7002").ok());
  ASSERT_TRUE(cl(b)->advertise(2, "127.0.0.1:7002").ok());  // seen again, moved
  // A row that is not HOST:PORT (another program's, damage) is left out.
  ASSERT_EQ(run_sql(url_, "INSERT INTO terrane_servers VALUES (3, 'nowhere', clock_timestamp())"), "");
  auto c = cl(a)->cluster(60s);
  ASSERT_TRUE(c.ok()) << c.error().message;
  EXPECT_EQ(c->writers.size(), 3u);
  ASSERT_EQ(c->servers.size(), 2u);
  const ClusterMap map(c->writers, c->servers, std::chrono::steady_clock::now());
  ASSERT_NE(map.writer_of({0, 0, 0}), nullptr);
  EXPECT_EQ(map.writer_of({0, 0, 0})->text(), "127.0.0.1:7001");
  ASSERT_NE(map.writer_of({1, 0, 0}), nullptr);
  EXPECT_EQ(*map.writer_of({1, 0, 0}), (ServerAddress{2, "127.0.0.1", 7002}));
  EXPECT_EQ(map.writer_of({2, 0, 0}), nullptr);  // its writer has no address
  EXPECT_EQ(map.writer_of({3, 0, 0}), nullptr);  // nobody writes it
  // A server gone quiet (not seen within fresh) or withdrawn is no
  // address, nor is a lease that ran out a writer.
  ASSERT_EQ(run_sql(url_, "UPDATE terrane_servers SET seen_at = clock_timestamp() - interval '10 seconds' WHERE id = 1"),
            "");
  ASSERT_TRUE(cl(b)->withdraw(2).ok());
  ASSERT_EQ(run_sql(url_, "UPDATE terrane_leases SET expires_at = clock_timestamp() WHERE rx = 2"), "");
  auto later = cl(a)->cluster(5s);
  ASSERT_TRUE(later.ok());
  EXPECT_TRUE(later->servers.empty());
  EXPECT_EQ(later->writers.size(), 2u);
}

// A renewal locks its lease rows in the order a commit checks them (y, z,
// x), whatever order it is given them in: while a commit holds the first,
// the renewal holds none, so the commit takes the second and ends (a
// renewal that took the second first would deadlock with it, and
// PostgreSQL would abort one).
TEST_F(ClusterStoreTest, ARenewalLocksLeasesInTheOrderACommitDoes) {
  auto keeper = open();
  ASSERT_TRUE(keeper);
  const Vec3i first{0, 0, 0}, second{0, 1, 0};
  auto a = cl(keeper)->claim(first, 1, 60s), b = cl(keeper)->claim(second, 1, 60s);
  ASSERT_TRUE(a.ok() && b.ok());
  PGconn* commit = PQconnectdb(url_.c_str());
  ASSERT_EQ(PQstatus(commit), CONNECTION_OK) << PQerrorMessage(commit);
  const auto exec = [&](const char* sql) { return command(commit, sql); };
  ASSERT_EQ(exec("BEGIN"), "");
  ASSERT_EQ(exec("UPDATE terrane_leases SET seq = seq + 1 WHERE rx = 0 AND ry = 0 AND rz = 0"), "");
  const std::vector<RegionLease> given{*b, *a};  // the second first
  std::thread renewal([&] {
    auto kept = cl(keeper)->renew(given, 60s);
    ASSERT_TRUE(kept.ok()) << kept.error().message;
    EXPECT_EQ(kept->size(), 2u);
  });
  // The renewal waits for the first row's lock.
  EXPECT_TRUE(eventually([&] {
    return sql_value(url_, "SELECT count(*) FROM pg_stat_activity WHERE wait_event_type = 'Lock'") == "1";
  }));
  EXPECT_EQ(exec("UPDATE terrane_leases SET seq = seq + 1 WHERE rx = 0 AND ry = 1 AND rz = 0"), "")
      << "the commit takes the second row";
  EXPECT_EQ(exec("COMMIT"), "");
  renewal.join();
  PQfinish(commit);
}

TEST_F(ClusterStoreTest, EachWriteMovesItsRegionsSequenceOnAcrossChangesOfHands) {
  auto a = open(), b = open();
  ASSERT_TRUE(a && b);
  auto first = cl(a)->claim({0, 0, 0}, 1, 60s);
  ASSERT_TRUE(first.ok());
  const ChunkWrite w = chunk_write({1, 1, 1}, 1, materials::kBrick);
  ASSERT_TRUE(a->save_fenced(std::span(&*first, 1), std::span(&w, 1)).ok());
  ASSERT_TRUE(a->save_fenced(std::span(&*first, 1), std::span(&w, 1)).ok());
  ASSERT_TRUE(cl(a)->release(std::span(&*first, 1)).ok());
  auto second = cl(b)->claim({0, 0, 0}, 2, 60s);
  ASSERT_TRUE(second.ok());
  ASSERT_TRUE(b->save_fenced(std::span(&*second, 1), std::span(&w, 1)).ok());
  // A region only claimed has no writes.
  ASSERT_TRUE(cl(b)->claim({5, 0, 0}, 2, 60s).ok());
  auto seqs = cl(a)->region_seqs();
  ASSERT_TRUE(seqs.ok()) << seqs.error().message;
  EXPECT_EQ(*seqs, (std::vector<RegionSeq>{{{0, 0, 0}, 3}}));
  // A fenced write moves nothing.
  EXPECT_FALSE(a->save_fenced(std::span(&*first, 1), std::span(&w, 1)).ok());
  EXPECT_EQ(cl(a)->region_seqs()->front().seq, 3u);
}

TEST_F(ClusterStoreTest, ARegionHasOneWriterAtATime) {
  auto a = open(), b = open();
  ASSERT_TRUE(a && b);
  const Vec3i region{0, 0, 0};
  auto first = cl(a)->claim(region, 1, 60s);
  ASSERT_TRUE(first.ok()) << first.error().message;
  EXPECT_EQ(first->epoch, 1u);
  // Another server is refused, told who holds it.
  auto refused = cl(b)->claim(region, 2, 60s);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().kind, StoreError::Kind::kOwned);
  EXPECT_NE(refused.error().message.find("server 1"), std::string::npos) << refused.error().message;
  // Renewing keeps the epoch; claiming again (a restarted server) starts
  // the next one, which fences whatever the earlier incarnation writes.
  auto renewed = cl(a)->renew(std::span(&*first, 1), 60s);
  ASSERT_TRUE(renewed.ok());
  ASSERT_EQ(renewed->size(), 1u);
  EXPECT_EQ(renewed->front(), *first);
  auto again = cl(a)->claim(region, 1, 60s);
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(again->epoch, 2u);
  const ChunkWrite w = chunk_write(region * 8, 1, materials::kBrick);
  auto stale = a->save_fenced(std::span(&*first, 1), std::span(&w, 1));
  ASSERT_FALSE(stale.ok());
  EXPECT_EQ(stale.error().kind, StoreError::Kind::kFenced);
  auto who = cl(b)->holder(region);
  ASSERT_TRUE(who.ok());
  ASSERT_TRUE(who->has_value());
  EXPECT_EQ(**who, *again);
  // Other regions are free.
  auto other = cl(b)->claim({1, 0, 0}, 2, 60s);
  ASSERT_TRUE(other.ok());
  EXPECT_EQ(other->owner, 2u);
  // A stale lease gives nothing up; the current one, given up, goes to the
  // next claim, at a higher epoch.
  ASSERT_TRUE(cl(a)->release(std::span(&*first, 1)).ok());
  EXPECT_FALSE(cl(b)->claim(region, 2, 60s).ok());
  ASSERT_TRUE(cl(a)->release(std::span(&*again, 1)).ok());
  auto taken = cl(b)->claim(region, 2, 60s);
  ASSERT_TRUE(taken.ok()) << taken.error().message;
  EXPECT_EQ(taken->epoch, 3u);
  // Server ids are below 2^31 (the table's integer).
  auto too_big = cl(b)->claim({5, 5, 5}, 0x80000000u, 60s);
  ASSERT_FALSE(too_big.ok());
  EXPECT_NE(too_big.error().message.find("not below 2^31"), std::string::npos) << too_big.error().message;
}

TEST_F(ClusterStoreTest, AFreeRegionIsLeftToTheServerWritingItsNeighboursUnlessTheClaimantWritesOneToo) {
  auto a = open(), b = open();
  ASSERT_TRUE(a && b);
  const auto prefer = ClaimRule::kPreferNeighbours;
  // Nobody writes near: each server takes a region of its own.
  ASSERT_TRUE(cl(a)->claim({0, 0, 0}, 1, 60s, prefer).ok());
  ASSERT_TRUE(cl(b)->claim({10, 0, 10}, 2, 60s, prefer).ok());
  // A free region touching only server 1's (here by a corner) is left to
  // server 1, named; no lease changes.
  auto left = cl(b)->claim({1, 1, 1}, 2, 60s, prefer);
  ASSERT_FALSE(left.ok());
  EXPECT_EQ(left.error().kind, StoreError::Kind::kLeft);
  EXPECT_EQ(left.error().holder, std::optional<std::uint32_t>(1));
  EXPECT_NE(left.error().message.find("left to server 1"), std::string::npos) << left.error().message;
  auto free = cl(b)->holder({1, 1, 1});
  ASSERT_TRUE(free.ok());
  EXPECT_FALSE(free->has_value()) << "a preference changes no lease";
  // Without the rule (a tool, a forwarded edit) the claim takes it.
  ASSERT_TRUE(cl(b)->claim({1, 1, 1}, 2, 60s).ok());
  // Next to its own, a server takes a region whatever else touches it.
  ASSERT_TRUE(cl(b)->claim({1, 0, 0}, 2, 60s, prefer).ok());
  // Several neighbours' servers: the one writing most of them (server 2:
  // (1,1,1) and (1,0,0), against server 1's (0,0,0)).
  auto most = cl(a)->claim({1, 0, 1}, 3, 60s, prefer);
  ASSERT_FALSE(most.ok());
  EXPECT_EQ(most.error().holder, std::optional<std::uint32_t>(2)) << most.error().message;
  // A held region is refused as ever, naming its holder.
  auto held = cl(b)->claim({0, 0, 0}, 2, 60s, prefer);
  ASSERT_FALSE(held.ok());
  EXPECT_EQ(held.error().kind, StoreError::Kind::kOwned);
  // An expired lease counts for nothing: once server 3's region (at
  // 300 ms) has run out, a region next to it alone is server 4's to take
  // (were it counted, it would be left to server 3 for good).
  ASSERT_TRUE(cl(a)->claim({30, 0, 30}, 3, 300ms, prefer).ok());
  StoreResult<RegionLease> after = StoreError{};
  ASSERT_TRUE(eventually([&] { return (after = cl(b)->claim({31, 0, 30}, 4, 60s, prefer)).ok(); }, 30s))
      << after.error().message;
}

TEST_F(ClusterStoreTest, ALeaseThatRanOutIsTakenOverAndItsHolderIsFenced) {
  auto a = open(), b = open();
  ASSERT_TRUE(a && b);
  const Vec3i cp{5, 1, 5};
  const Vec3i region = lease_region_of(cp);
  auto mine = cl(a)->claim(region, 1, 300ms);
  ASSERT_TRUE(mine.ok());
  const ChunkWrite v1 = chunk_write(cp, 1, materials::kBrick);
  ASSERT_TRUE(a->save_fenced(std::span(&*mine, 1), std::span(&v1, 1)).ok());
  // Server 1 stops renewing (paused, say): once its lease has run out by
  // the database's clock, server 2's claim succeeds, one epoch up.
  StoreResult<RegionLease> theirs = StoreError{};
  ASSERT_TRUE(eventually([&] { return (theirs = cl(b)->claim(region, 2, 60s)).ok(); }, 30s))
      << theirs.error().message;
  EXPECT_EQ(theirs->epoch, mine->epoch + 1);
  // Server 1 comes back: its renewal finds the lease gone ...
  auto kept = cl(a)->renew(std::span(&*mine, 1), 300ms);
  ASSERT_TRUE(kept.ok());
  EXPECT_TRUE(kept->empty());
  // ... and its next write is fenced: nothing is written.
  const ChunkWrite stale = chunk_write(cp, 2, materials::kSand);
  auto fenced = a->save_fenced(std::span(&*mine, 1), std::span(&stale, 1));
  ASSERT_FALSE(fenced.ok());
  EXPECT_EQ(fenced.error().kind, StoreError::Kind::kFenced);
  EXPECT_NE(fenced.error().message.find("no longer current"), std::string::npos) << fenced.error().message;
  auto got = b->load_chunk(cp);
  ASSERT_TRUE(got.ok() && got->has_value());
  EXPECT_EQ((*got)->revision, 1u);
  EXPECT_EQ((*got)->chunk.get({0, 0, 0}).material, materials::kBrick);
  // The new holder writes.
  const ChunkWrite v2 = chunk_write(cp, 2, materials::kSnow);
  ASSERT_TRUE(b->save_fenced(std::span(&*theirs, 1), std::span(&v2, 1)).ok());
  got = a->load_chunk(cp);
  ASSERT_TRUE(got.ok() && got->has_value());
  EXPECT_EQ((*got)->revision, 2u);
  EXPECT_EQ((*got)->chunk.get({0, 0, 0}).material, materials::kSnow);
}

// A claim that waits for the lease row (locked by a transaction the
// previous holder left open: paused inside a commit) gets a whole lease
// from when it took the row, not from when it asked: a claim that waited a
// lease time would otherwise hold a lease already run out.
TEST_F(ClusterStoreTest, AClaimThatWaitedForTheLeaseRowGetsAWholeLease) {
  auto a = open(), b = open();
  ASSERT_TRUE(a && b);
  const Vec3i region{0, 0, 0};
  auto old = cl(a)->claim(region, 1, 1ms);  // runs out at once
  ASSERT_TRUE(old.ok());
  PGconn* stalled = PQconnectdb(url_.c_str());
  ASSERT_EQ(PQstatus(stalled), CONNECTION_OK);
  ASSERT_EQ(command(stalled, "BEGIN"), "");
  PGresult* locked = PQexec(stalled, "SELECT 1 FROM terrane_leases WHERE rx = 0 AND ry = 0 AND rz = 0 FOR UPDATE");
  ASSERT_EQ(PQresultStatus(locked), PGRES_TUPLES_OK);
  PQclear(locked);
  auto claim = std::async(std::launch::async, [&] { return cl(b)->claim(region, 2, 2000ms); });
  // The claim waits for the row ...
  ASSERT_TRUE(eventually([&] {
    return testing_support::sql_value(url_, "SELECT count(*) FROM pg_locks WHERE NOT granted") != "0";
  }));
  // ... and is let go at a time the database notes: the claim asked
  // before it, so a lease counted from the asking ends before this time
  // plus a lease, and one counted from taking the row ends after it.
  PGresult* at = PQexec(stalled, "SELECT clock_timestamp()::text");
  ASSERT_EQ(PQresultStatus(at), PGRES_TUPLES_OK);
  const std::string released = PQgetvalue(at, 0, 0);
  PQclear(at);
  ASSERT_EQ(command(stalled, "COMMIT"), "");
  PQfinish(stalled);
  auto theirs = claim.get();
  ASSERT_TRUE(theirs.ok()) << theirs.error().message;
  EXPECT_EQ(testing_support::sql_value(url_, "SELECT expires_at >= '" + released +
                                                 "'::timestamptz + interval '2000 milliseconds' FROM terrane_leases"
                                                 " WHERE rx = 0 AND ry = 0 AND rz = 0"),
            "t");
}

// A forwarded edit passed on: its row goes to the next server's inbox with
// its sender and deadline, so that server answers the sender directly and
// takes it only in time; the row is no longer the relaying server's
// (relayed once, never twice).
TEST_F(ClusterStoreTest, ARelayedEditKeepsItsSenderAndDeadlineAndLeavesTheRelaysInbox) {
  auto s = open();
  ASSERT_TRUE(s);
  const std::vector<std::uint8_t> edit{1, 2, 3};
  auto row = cl(s)->forward(1, 2, "ann", edit, testing_support::database_now_us(url_) + 20'000'000);
  ASSERT_TRUE(row.ok()) << row.error().message;
  auto taken = cl(s)->inbox(2, 0, 10);
  ASSERT_TRUE(taken.ok()) << taken.error().message;
  ASSERT_EQ(taken->size(), 1u);
  ASSERT_TRUE(cl(s)->relay(*row, 2, 3).ok());
  auto at_relay = cl(s)->inbox(2, 0, 10);
  ASSERT_TRUE(at_relay.ok());
  EXPECT_TRUE(at_relay->empty());
  const auto asked = std::chrono::steady_clock::now();
  auto at_next = cl(s)->inbox(3, 0, 10);
  ASSERT_TRUE(at_next.ok());
  ASSERT_EQ(at_next->size(), 1u);
  EXPECT_EQ(at_next->front().id, *row);
  EXPECT_EQ(at_next->front().from, 1u);
  EXPECT_EQ(at_next->front().player, "ann");
  EXPECT_EQ(at_next->front().edit, edit);
  // The deadline kept: at most 20 s from when it was first sent.
  EXPECT_LE(at_next->front().current_until, asked + 20s);
  EXPECT_GT(at_next->front().current_until, asked + 10s);
  auto again = cl(s)->relay(*row, 2, 3);
  ASSERT_FALSE(again.ok());
  EXPECT_NE(again.error().message.find("no longer server 2's"), std::string::npos) << again.error().message;
}

// A forwarded edit whose deadline has passed by the database's clock when
// its row lands (held up on the way) is never taken: its sender has told
// its player it was not applied. One in time is taken once.
TEST_F(ClusterStoreTest, AForwardedEditPastItsDeadlineIsNeverTakenAndOneInTimeIsTakenOnce) {
  auto s = open();
  ASSERT_TRUE(s);
  const std::vector<std::uint8_t> edit{4, 5, 6};
  auto late = cl(s)->forward(1, 2, "ann", edit, testing_support::database_now_us(url_) - 1000);
  ASSERT_TRUE(late.ok()) << late.error().message;
  auto in_time = cl(s)->forward(1, 2, "bob", edit, testing_support::database_now_us(url_) + 20'000'000);
  ASSERT_TRUE(in_time.ok()) << in_time.error().message;
  auto taken = cl(s)->inbox(2, 0, 10);
  ASSERT_TRUE(taken.ok()) << taken.error().message;
  ASSERT_EQ(taken->size(), 1u);
  EXPECT_EQ(taken->front().id, *in_time);
  EXPECT_EQ(taken->front().player, "bob");
  auto again = cl(s)->inbox(2, 0, 10);
  ASSERT_TRUE(again.ok()) << again.error().message;
  EXPECT_TRUE(again->empty()) << "taken twice";
  // The late one is still there, untaken: its sender takes it back.
  auto back = cl(s)->take_back(*late);
  ASSERT_TRUE(back.ok()) << back.error().message;
  EXPECT_TRUE(*back);
}

// A row's deadline is another server's word: one far off (years, or
// 'infinity') is taken as at most ten minutes away, and spoils no read.
TEST_F(ClusterStoreTest, AForwardedEditsDeadlineFarOffIsTakenAsTenMinutesAtMost) {
  auto s = open();
  ASSERT_TRUE(s);
  const std::vector<std::uint8_t> edit{1, 2, 3};
  auto years = cl(s)->forward(1, 2, "ann", edit, testing_support::database_now_us(url_) + 100 * 365 * 86'400'000'000LL);
  ASSERT_TRUE(years.ok()) << years.error().message;
  auto endless = cl(s)->forward(1, 2, "bob", edit, testing_support::database_now_us(url_) + 20'000'000);
  ASSERT_TRUE(endless.ok()) << endless.error().message;
  ASSERT_EQ(run_sql(url_, fmt::format("UPDATE terrane_inbox SET expires_at = 'infinity' WHERE id = {}", *endless)), "");
  const auto asked = std::chrono::steady_clock::now();
  auto taken = cl(s)->inbox(2, 0, 10);
  const auto answered = std::chrono::steady_clock::now();
  ASSERT_TRUE(taken.ok()) << taken.error().message;
  ASSERT_EQ(taken->size(), 2u);
  for (const InboxEdit& e : *taken) {
    EXPECT_GT(e.current_until, asked + 9min) << e.player;
    EXPECT_LE(e.current_until, answered + 10min) << e.player;
  }
}

// Taken and taken back exclude each other: a row its addressee took stays
// (its sender waits for the answer), and a row taken back is never taken.
TEST_F(ClusterStoreTest, ATakenEditCannotBeTakenBackAndOneTakenBackIsNeverTaken) {
  auto s = open();
  ASSERT_TRUE(s);
  const std::vector<std::uint8_t> edit{7, 8, 9};
  auto first = cl(s)->forward(1, 2, "ann", edit, testing_support::database_now_us(url_) + 20'000'000);
  ASSERT_TRUE(first.ok()) << first.error().message;
  auto taken = cl(s)->inbox(2, 0, 10);
  ASSERT_TRUE(taken.ok() && taken->size() == 1u);
  auto back = cl(s)->take_back(*first);
  ASSERT_TRUE(back.ok()) << back.error().message;
  EXPECT_FALSE(*back) << "taken back after its addressee took it";
  EXPECT_EQ(sql_value(url_, fmt::format("SELECT count(*) FROM terrane_inbox WHERE id = {}", *first)), "1");
  auto second = cl(s)->forward(1, 2, "ann", edit, testing_support::database_now_us(url_) + 20'000'000);
  ASSERT_TRUE(second.ok()) << second.error().message;
  back = cl(s)->take_back(*second);
  ASSERT_TRUE(back.ok()) << back.error().message;
  EXPECT_TRUE(*back);
  auto after = cl(s)->inbox(2, 0, 10);
  ASSERT_TRUE(after.ok()) << after.error().message;
  EXPECT_TRUE(after->empty()) << "a row taken back was taken";
  back = cl(s)->take_back(*second);
  ASSERT_TRUE(back.ok()) << back.error().message;
  EXPECT_FALSE(*back) << "taken back twice";
}

// Every renewal round reads the database's clock: a lower bound of it at
// any later local time.
TEST_F(ClusterStoreTest, ARenewalReadsALowerBoundOfTheDatabasesClock) {
  auto s = open();
  ASSERT_TRUE(s);
  auto lease = cl(s)->claim({0, 0, 0}, 1, 60s);
  ASSERT_TRUE(lease.ok()) << lease.error().message;
  for (const bool with_leases : {true, false}) {
    DatabaseClock clock;
    const std::int64_t before = testing_support::database_now_us(url_);
    auto kept = with_leases ? cl(s)->renew(std::span(&*lease, 1), 60s, &clock)
                            : cl(s)->renew(std::span<const RegionLease>{}, 60s, &clock);
    ASSERT_TRUE(kept.ok()) << kept.error().message;
    EXPECT_EQ(kept->size(), with_leases ? 1u : 0u);
    EXPECT_GE(clock.at_us, before);
    const auto local = std::chrono::steady_clock::now();  // then the database's clock, read later
    EXPECT_LE(clock.at_least_at(local), testing_support::database_now_us(url_));
  }
}

}  // namespace
}  // namespace terrane
