// Servers sharing one world in a real PostgreSQL started by the test (on
// 127.0.0.1, a database per test), with the real terrane-server binaries and
// the client library: what one server acknowledges survives it, a region has
// one writer, and a server that takes a region over reads what the previous
// owner wrote before writing there. Every wait is on an event with a
// deadline; nothing sleeps.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "client/client.h"
#include "tests/support/postgres.h"
#include "tests/support/server_process.h"
#include "tests/support/view_chunks.h"

namespace terrane {
namespace {

using namespace std::chrono_literals;
using testing_support::run_sql;
using testing_support::ServerProcess;

// Generous: sanitizer builds on a shared 2-core machine generate slowly.
constexpr auto kDeadline = 30s;

class ClusterTest : public testing_support::PostgresTest {
 protected:
  void TearDown() override {
    for (auto& s : servers_) {
      if (!s) continue;
      if (HasFailure()) std::fprintf(stderr, "--- server output ---\n%s", s->output().c_str());
      s->stop();
    }
  }
  // A server of the shared world; lease_ms short where a test waits for one
  // to run out.
  // Edits may be tried again at once while a region is another server's
  // (refused without waiting), so the edit rate is no bound here.
  ServerProcess& start(std::uint32_t id, int lease_ms = 5000) {
    servers_.push_back(std::make_unique<ServerProcess>(
        url_, std::vector<std::string>{"--server-id", std::to_string(id), "--lease-ms", std::to_string(lease_ms),
                                       "--hash-push-ms", "0", "--edits-per-second", "100000"}));
    EXPECT_NE(servers_.back()->port(), 0) << servers_.back()->output();
    return *servers_.back();
  }
  static ClientOptions options(const ServerProcess& s, const std::string& name) {
    ClientOptions o;
    o.port = s.port();
    o.name = name;
    o.state.view_distance = 64;
    o.state.full_res_radius = 32;
    return o;
  }
  // Servers 1 and 2, with ann joined on the first and bob on the second,
  // each holding the spawn's chunks at full resolution.
  struct Pair {
    ServerProcess* a = nullptr;
    ServerProcess* b = nullptr;
    std::unique_ptr<Client> ann, bob;
    std::vector<Vec3i> near;  // the chunks bob holds around the spawn
  };
  void start_pair(int lease_ms, Pair* p) {
    p->a = &start(1, lease_ms);
    ASSERT_NE(p->a->port(), 0);
    p->b = &start(2, lease_ms);
    ASSERT_NE(p->b->port(), 0);
    p->ann = std::make_unique<Client>(options(*p->a, "ann"));
    p->bob = std::make_unique<Client>(options(*p->b, "bob"));
    join(*p->ann);
    p->near = join(*p->bob);
  }
  // Connects and waits until the chunks around the spawn are held at full
  // resolution.
  static std::vector<Vec3i> join(Client& c) {
    std::string err;
    EXPECT_TRUE(c.connect(&err)) << err;
    EXPECT_TRUE(c.wait_until([](const ClientView& v) { return v.welcomed || v.closed; }, kDeadline));
    const auto w = c.welcome();
    if (!w) return {};
    auto near = testing_support::chunks_within(w->spawn, 20, *w);
    EXPECT_TRUE(c.wait_until(
        [&](const ClientView& v) {
          return v.closed || std::all_of(near.begin(), near.end(), [&](Vec3i cp) {
                   const ChunkCoverage* cov = v.replica.coverage(cp);
                   return cov != nullptr && cov->state != CoverageState::kMip;
                 });
        },
        kDeadline));
    return near;
  }
  // The edit's answer: "" if accepted, else the reason.
  static std::string outcome(Client& c, std::uint32_t id) {
    EXPECT_NE(id, 0u);
    std::string reason = "no answer";
    c.wait_until(
        [&](const ClientView& v) {
          auto it = v.edits.find(id);
          if (it == v.edits.end()) return v.closed;
          reason = it->second.accepted ? "" : it->second.reason;
          return true;
        },
        kDeadline);
    return reason;
  }
  // Tries the edit until it is accepted (a region is taken over once its
  // lease is given up or runs out): "" then, else the last refusal.
  static std::string until_accepted(Client& c, const Region& r, const std::vector<Voxel>& v) {
    std::string answer = "not tried";
    const auto deadline = std::chrono::steady_clock::now() + kDeadline;
    while (!answer.empty() && std::chrono::steady_clock::now() < deadline && !c.wait_until(
                                                                                 [](const ClientView& view) {
                                                                                   return view.closed;
                                                                                 },
                                                                                 0ms))
      answer = outcome(c, c.write_box(r, v));
    return answer;
  }
  // Every chunk of near the client holds agrees with its server's (region
  // hashes asked for and answered, none mismatched).
  static void expect_agrees_with_its_server(Client& c, const std::vector<Vec3i>& near) {
    for (const Vec3i cp : near) ASSERT_TRUE(c.request_region_hash(cp));
    ASSERT_TRUE(c.wait_until(
        [&](const ClientView& v) {
          return v.closed ||
                 std::all_of(near.begin(), near.end(), [&](Vec3i cp) { return v.hash_checks.count(cp) != 0; });
        },
        kDeadline));
    EXPECT_EQ(c.counters().hash_mismatches, 0u);
  }
  // A box beside the spawn, and a pattern to write there.
  static Region box_near(const Client& c, int dx) {
    const Vec3f s = c.welcome()->spawn;
    const Vec3i p{static_cast<int>(std::floor(s.x)) + dx, static_cast<int>(std::floor(s.y)) - 3,
                  static_cast<int>(std::floor(s.z)) + 2};
    return Region{p, p + Vec3i{3, 3, 3}};
  }
  static std::vector<Voxel> pattern(const Region& r, Material m) {
    std::vector<Voxel> out;
    for (std::int64_t i = 0; i < r.volume(); ++i)
      out.push_back(i % 3 == 0 ? Voxel{} : make_voxel(m, static_cast<std::uint8_t>(30 + i)));
    return out;
  }
  static bool shows(const Replica& replica, const Region& r, const std::vector<Voxel>& want) {
    Box got(r.size());
    replica.read_box(r.min, got);
    return std::equal(want.begin(), want.end(), got.voxels().begin());
  }
  static bool replica_shows(Client& c, const Region& r, const std::vector<Voxel>& want) {
    return c.with_replica([&](const Replica& replica) { return shows(replica, r, want); });
  }
  int current_leases() {
    PGconn* conn = PQconnectdb(url_.c_str());
    PGresult* r = PQexec(conn, "SELECT count(*) FROM terrane_leases WHERE expires_at > clock_timestamp()");
    const int n = PQresultStatus(r) == PGRES_TUPLES_OK ? std::atoi(PQgetvalue(r, 0, 0)) : -1;
    PQclear(r);
    PQfinish(conn);
    return n;
  }

  std::vector<std::unique_ptr<ServerProcess>> servers_;
};

TEST_F(ClusterTest, AServerOnPostgresqlKeepsWhatItAcknowledgedAcrossARestart) {
  ServerProcess& a = start(1);
  ASSERT_NE(a.port(), 0);
  Region box;
  std::vector<Voxel> want;
  {
    Client c(options(a, "ann"));
    join(c);
    box = box_near(c, 0);
    want = pattern(box, materials::kBrick);
    ASSERT_EQ(outcome(c, c.write_box(box, want)), "");
    c.disconnect();
  }
  ASSERT_EQ(a.stop(), 0) << a.output();
  // A clean stop gives its leases up at once.
  EXPECT_EQ(current_leases(), 0);
  ServerProcess& again = start(1);
  ASSERT_NE(again.port(), 0);
  Client c(options(again, "ann"));
  join(c);
  EXPECT_TRUE(replica_shows(c, box, want));
  c.disconnect();
}

TEST_F(ClusterTest, AnEditInAnotherServersRegionIsForwardedAndATakeoverReadsWhatTheOwnerWrote) {
  Pair p;
  ASSERT_NO_FATAL_FAILURE(start_pair(5000, &p));
  ServerProcess& a = *p.a;
  Client &ann = *p.ann, &bob = *p.bob;
  const std::vector<Vec3i>& near = p.near;
  const Region box = box_near(ann, 0);
  const auto anns = pattern(box, materials::kBrick);
  ASSERT_EQ(outcome(ann, ann.write_box(box, anns)), "");
  // The region is server 1's now: server 2 forwards bob's edit there to it,
  // and acknowledges it once server 1 stored it and bob's replica shows it.
  const Region beside = box_near(bob, 5);
  const auto bobs = pattern(beside, materials::kSnow);
  ASSERT_EQ(outcome(bob, bob.write_box(beside, bobs)), "");
  EXPECT_TRUE(replica_shows(bob, beside, bobs));
  EXPECT_TRUE(replica_shows(bob, box, anns));
  ASSERT_TRUE(ann.wait_until([&](const ClientView& v) { return v.closed || shows(v.replica, beside, bobs); }, kDeadline))
      << "ann never saw bob's forwarded edit";
  // Server 1 stops (giving its leases up): server 2 takes the region over,
  // reads what server 1 stored, then writes bob's next edit itself.
  ann.disconnect();
  ASSERT_EQ(a.stop(), 0) << a.output();
  const Region third = box_near(bob, -5);
  const auto more = pattern(third, materials::kSand);
  ASSERT_EQ(until_accepted(bob, third, more), "");
  EXPECT_TRUE(replica_shows(bob, third, more));
  // Every chunk bob holds agrees with server 2's.
  expect_agrees_with_its_server(bob, near);
  bob.disconnect();
  // And the database holds all three: a third server shows them.
  ServerProcess& c = start(3);
  ASSERT_NE(c.port(), 0);
  Client cy(options(c, "cy"));
  join(cy);
  EXPECT_TRUE(replica_shows(cy, box, anns));
  EXPECT_TRUE(replica_shows(cy, beside, bobs));
  EXPECT_TRUE(replica_shows(cy, third, more));
  cy.disconnect();
}

TEST_F(ClusterTest, AServerPausedPastItsLeaseCannotWriteAgain) {
  Pair p;
  ASSERT_NO_FATAL_FAILURE(start_pair(1000, &p));
  ServerProcess &a = *p.a, &b = *p.b;
  Client &ann = *p.ann, &bob = *p.bob;
  const Region box = box_near(ann, 0);
  ASSERT_EQ(outcome(ann, ann.write_box(box, pattern(box, materials::kBrick))), "");
  // Server 1 is paused: its lease runs out and server 2 takes the region.
  ASSERT_TRUE(a.pause());
  const Region beside = box_near(bob, 5);
  const auto bobs = pattern(beside, materials::kSnow);
  ASSERT_EQ(until_accepted(bob, beside, bobs), "");
  // Server 2 stops cleanly, giving the region up: free again when server 1
  // resumes. Server 1 must still not write there with what it held before
  // the pause: its next write is refused (the lease it knew is gone) or its
  // keeper finds the lease lost first; either way it stops, and an edit it
  // was sent meanwhile is never acknowledged.
  bob.disconnect();
  ASSERT_EQ(b.stop(), 0) << b.output();
  const std::uint32_t late = ann.write_box(box, pattern(box, materials::kSand));
  ASSERT_TRUE(a.resume());
  EXPECT_EQ(a.wait_exit(60s), 1) << a.output();
  EXPECT_NE(outcome(ann, late), "");
  // Server 2's write stands.
  ServerProcess& c = start(3);
  ASSERT_NE(c.port(), 0);
  Client cy(options(c, "cy"));
  join(cy);
  EXPECT_TRUE(replica_shows(cy, beside, bobs));
  cy.disconnect();
}

TEST_F(ClusterTest, AnEditOnOneServerReachesTheClientsOfAnother) {
  Pair p;
  ASSERT_NO_FATAL_FAILURE(start_pair(5000, &p));
  Client &ann = *p.ann, &bob = *p.bob;
  const std::vector<Vec3i>& near = p.near;
  const Region box = box_near(ann, 0);
  const auto anns = pattern(box, materials::kBrick);
  ASSERT_EQ(outcome(ann, ann.write_box(box, anns)), "");
  // Server 1's commit notifies server 2, which reads the chunks again and
  // sends them to bob.
  ASSERT_TRUE(bob.wait_until([&](const ClientView& v) { return v.closed || shows(v.replica, box, anns); }, kDeadline))
      << "bob never saw ann's edit";
  // A second edit of the same chunks follows the first.
  const auto again = pattern(box, materials::kSnow);
  ASSERT_EQ(outcome(ann, ann.write_box(box, again)), "");
  ASSERT_TRUE(bob.wait_until([&](const ClientView& v) { return v.closed || shows(v.replica, box, again); }, kDeadline));
  expect_agrees_with_its_server(bob, near);
  ann.disconnect();
  bob.disconnect();
}

TEST_F(ClusterTest, ARegionWhoseOwnerWasKilledIsTakenOverWithEveryAcknowledgedEdit) {
  Pair p;
  ASSERT_NO_FATAL_FAILURE(start_pair(1000, &p));
  ServerProcess& a = *p.a;
  Client &ann = *p.ann, &bob = *p.bob;
  // Edits acknowledged by server 1, then more sent as it is killed.
  std::vector<std::pair<Region, std::vector<Voxel>>> acknowledged;
  for (int i = 0; i < 4; ++i) {
    const Region r = box_near(ann, -8 + 4 * i);
    auto v = pattern(r, static_cast<Material>(materials::kBrick + i));
    ASSERT_EQ(outcome(ann, ann.write_box(r, v)), "");
    acknowledged.emplace_back(r, std::move(v));
  }
  std::vector<std::uint32_t> sand;
  for (int i = 0; i < 4; ++i) {
    const Region r = box_near(ann, -8 + 4 * i);
    sand.push_back(ann.write_box(r, pattern(r, materials::kSand)));
  }
  ASSERT_TRUE(a.kill_hard());
  std::vector<bool> sand_acknowledged(sand.size(), false);
  ann.wait_until(
      [&](const ClientView& v) {
        for (std::size_t i = 0; i < sand.size(); ++i) {
          auto it = v.edits.find(sand[i]);
          sand_acknowledged[i] = it != v.edits.end() && it->second.accepted;
        }
        return true;
      },
      0ms);
  // Server 2 takes the region over once the lease runs out, reads what
  // server 1 stored, and writes on top of it.
  const Region beside = box_near(bob, 9);
  const auto bobs = pattern(beside, materials::kSnow);
  ASSERT_EQ(until_accepted(bob, beside, bobs), "");
  ServerProcess& c = start(3);
  ASSERT_NE(c.port(), 0);
  Client cy(options(c, "cy"));
  join(cy);
  EXPECT_TRUE(replica_shows(cy, beside, bobs));
  // Every edit acknowledged is there: a sand edit acknowledged before the
  // kill, else the edit before it (or the sand edit, stored but not yet
  // acknowledged when server 1 died).
  for (std::size_t i = 0; i < acknowledged.size(); ++i) {
    const auto& [r, v] = acknowledged[i];
    const auto sand_box = pattern(r, materials::kSand);
    if (sand_acknowledged[i])
      EXPECT_TRUE(replica_shows(cy, r, sand_box)) << "acknowledged sand edit " << i << " lost";
    else
      EXPECT_TRUE(replica_shows(cy, r, v) || replica_shows(cy, r, sand_box)) << "acknowledged edit " << i << " lost";
  }
  cy.disconnect();
  bob.disconnect();
}

TEST_F(ClusterTest, APostgresqlRestartPausesAcknowledgementsAndLosesNone) {
  ServerProcess& a = start(1);
  ASSERT_NE(a.port(), 0);
  Client ann(options(a, "ann"));
  join(ann);
  const Region first = box_near(ann, 0), second = box_near(ann, 5), third = box_near(ann, -5);
  const auto v1 = pattern(first, materials::kBrick), v2 = pattern(second, materials::kSnow),
             v3 = pattern(third, materials::kSand);
  ASSERT_EQ(outcome(ann, ann.write_box(first, v1)), "");
  // The database restarts while an edit is under way: it is acknowledged
  // once stored, after the database is back; the server keeps running.
  bool restarted = false;
  std::thread restart([&] { restarted = pg_->restart(); });
  const std::uint32_t during = ann.write_box(second, v2);
  restart.join();
  ASSERT_TRUE(restarted) << pg_->why();
  EXPECT_EQ(outcome(ann, during), "");
  EXPECT_EQ(outcome(ann, ann.write_box(third, v3)), "");
  ann.disconnect();
  ASSERT_EQ(a.stop(), 0) << a.output();
  ServerProcess& b = start(2);
  ASSERT_NE(b.port(), 0);
  Client cy(options(b, "cy"));
  join(cy);
  EXPECT_TRUE(replica_shows(cy, first, v1));
  EXPECT_TRUE(replica_shows(cy, second, v2));
  EXPECT_TRUE(replica_shows(cy, third, v3));
  cy.disconnect();
}

TEST_F(ClusterTest, AnEditAcrossTwoServersRegionsIsAppliedByOneOfThem) {
  Pair p;
  ASSERT_NO_FATAL_FAILURE(start_pair(5000, &p));
  Client &ann = *p.ann, &bob = *p.bob;
  // The spawn lies on a region border (x = 0): ann's server takes the
  // region west of it, bob's the one east.
  const Region west = box_near(ann, -8), east = box_near(bob, 4);
  ASSERT_LT(west.max.x, 0);
  ASSERT_GE(east.min.x, 0);
  const auto wv = pattern(west, materials::kBrick), ev = pattern(east, materials::kSnow);
  ASSERT_EQ(outcome(ann, ann.write_box(west, wv)), "");
  ASSERT_EQ(outcome(bob, bob.write_box(east, ev)), "");
  // An edit across the border: bob's server hands its region over with the
  // edit to ann's, which then writes both sides.
  const Region across{{-2, west.min.y, west.min.z}, {2, west.max.y, west.max.z}};
  const auto av = pattern(across, materials::kSand);
  ASSERT_EQ(outcome(bob, bob.write_box(across, av)), "");
  EXPECT_TRUE(replica_shows(bob, across, av));
  ASSERT_TRUE(ann.wait_until([&](const ClientView& v) { return v.closed || shows(v.replica, across, av); }, kDeadline));
  // Bob's next edit east is forwarded there too, or his server takes the
  // region back: either way it is stored.
  const Region east2 = box_near(bob, 8);
  const auto ev2 = pattern(east2, materials::kGrass);
  ASSERT_EQ(until_accepted(bob, east2, ev2), "");
  ann.disconnect();
  bob.disconnect();
  ServerProcess& c = start(3);
  ASSERT_NE(c.port(), 0);
  Client cy(options(c, "cy"));
  join(cy);
  EXPECT_TRUE(replica_shows(cy, west, wv));
  EXPECT_TRUE(replica_shows(cy, east, ev));
  EXPECT_TRUE(replica_shows(cy, across, av));
  EXPECT_TRUE(replica_shows(cy, east2, ev2));
  cy.disconnect();
}

}  // namespace
}  // namespace terrane
