// Servers sharing one world in a real PostgreSQL started by the test (on
// 127.0.0.1, a database per test), with the real terrane-server binaries and
// the client library: what one server acknowledges survives it, a region has
// one writer, and a server that takes a region over reads what the previous
// owner wrote before writing there. Every wait is on an event with a
// deadline; nothing sleeps. (Built into the client library's test binary,
// which links the client: tests/CMakeLists.txt.)
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <mutex>
#include <set>
#include <unordered_map>
#include <chrono>
#include <cmath>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <httplib.h>

#include "client/bots/server_watch.h"
#include "client/client.h"
#include "common/world/coarse_image.h"
#include "tests/support/eventually.h"
#include "tests/support/postgres.h"
#include "tests/support/server_process.h"
#include "tests/support/view_chunks.h"

namespace terrane {
namespace {

using namespace std::chrono_literals;
using testing_support::run_sql;
using testing_support::ServerProcess;
using testing_support::sql_value;

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
  ServerProcess& start(std::uint32_t id, int lease_ms = 5000, int edits_per_second = 100000,
                       std::vector<std::string> more = {}, bool expect_start = true) {
    std::vector<std::string> flags{"--server-id", std::to_string(id), "--lease-ms", std::to_string(lease_ms),
                                   "--hash-push-ms", "0", "--edits-per-second", std::to_string(edits_per_second)};
    flags.insert(flags.end(), more.begin(), more.end());
    servers_.push_back(std::make_unique<ServerProcess>(url_, flags));
    if (expect_start) {
      EXPECT_NE(servers_.back()->port(), 0) << servers_.back()->output();
    }
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
  // Connects and waits until the chunks around the spawn (plus the
  // client's spawn offset) are held at full resolution.
  static std::vector<Vec3i> join(Client& c, Vec3f offset = {}) {
    std::string err;
    EXPECT_TRUE(c.connect(&err)) << err;
    EXPECT_TRUE(c.wait_until([](const ClientView& v) { return v.welcomed || v.closed; }, kDeadline));
    const auto w = c.welcome();
    if (!w) return {};
    auto near = testing_support::chunks_within(w->spawn + offset, 20, *w);
    EXPECT_TRUE(wait_full_resolution(c, near));
    return near;
  }
  // Waits until c holds every chunk of near at full resolution (or closes).
  static bool wait_full_resolution(Client& c, const std::vector<Vec3i>& near) {
    return c.wait_until(
        [&](const ClientView& v) {
          return v.closed || std::all_of(near.begin(), near.end(), [&](Vec3i cp) {
                   const Holding* cov = v.replica.holding(cp);
                   return cov != nullptr && cov->full_resolution();
                 });
        },
        kDeadline);
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
  // Writes v into r once c holds every chunk of r at full resolution (join
  // waits for the spawn's chunk and its six neighbours only; a box across a
  // corner of chunks reaches beyond them), and waits for the answer: "" if
  // accepted, else the reason.
  static std::string write(Client& c, const Region& r, const std::vector<Voxel>& v) {
    if (!wait_full_resolution(c, r)) return "never held at full resolution";
    return outcome(c, c.write_box(r, v));
  }
  static bool wait_full_resolution(Client& c, const Region& r) {
    std::vector<Vec3i> chunks;
    for_each_chunk_in(r, [&](Vec3i cp) { chunks.push_back(cp); });
    return wait_full_resolution(c, chunks);
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
      answer = write(c, r, v);
    return answer;
  }
  // Every chunk of near the client holds agrees with its server's (region
  // hashes asked for and answered, none mismatched).
  static void expect_agrees_with_its_server(Client& c, const std::vector<Vec3i>& near) {
    // Counted, not looked up: a chunk asked for earlier already has an
    // answer (these servers push no hashes, so every answer was asked for).
    const ClientCounters before = c.counters();
    const std::uint64_t want = before.hash_matches + before.hash_mismatches + near.size();
    for (const Vec3i cp : near) ASSERT_TRUE(c.request_chunk_hash(cp));
    ASSERT_TRUE(c.wait_until(
        [&](const ClientView& v) { return v.closed || v.counters.hash_matches + v.counters.hash_mismatches >= want; },
        kDeadline));
    ASSERT_FALSE(c.closed()) << c.disconnect_reason();
    EXPECT_EQ(c.counters().hash_mismatches, before.hash_mismatches);
  }
  // Where the redirect tests' second player stands: 48 voxels east and
  // south of the spawn, which lies by the corner x = 0, z = 0 of four
  // regions, so inside another region by more than the margin.
  static constexpr Vec3f kBeyond{48, 0, 48};
  // Moves c from `from` by `by` in three steps, each within the speed limit.
  static void walk(Client& c, Vec3f from, Vec3f by) {
    for (int step = 1; step <= 3; ++step) {
      ClientStateMsg st = *c.last_state();
      const float f = static_cast<float>(step) / 3.0f;
      st.position = from + Vec3f{by.x * f, by.y * f, by.z * f};
      ASSERT_TRUE(c.set_state(st));
    }
  }
  static Vec3i voxel_of(Vec3f p) {
    return {static_cast<int>(std::floor(p.x)), static_cast<int>(std::floor(p.y)), static_cast<int>(std::floor(p.z))};
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
  // Whether c's replica comes to show want in r (or, given, or_else), waited
  // for: an EditAck is a control frame and may arrive before the update
  // showing its edit (PROTOCOL.md, "Edits and updates").
  static bool replica_shows(Client& c, const Region& r, const std::vector<Voxel>& want,
                            const std::vector<Voxel>* or_else = nullptr) {
    const auto either = [&](const Replica& replica) {
      return shows(replica, r, want) || (or_else != nullptr && shows(replica, r, *or_else));
    };
    c.wait_until([&](const ClientView& v) { return v.closed || either(v.replica); }, kDeadline);
    return c.with_replica(either);
  }
  // The server writing region now (a current lease), or -1.
  int lease_owner(Vec3i region) {
    PGconn* conn = PQconnectdb(url_.c_str());
    const std::string q = fmt::format(
        "SELECT owner FROM terrane_leases WHERE rx = {} AND ry = {} AND rz = {} AND expires_at > clock_timestamp()",
        region.x, region.y, region.z);
    PGresult* r = PQexec(conn, q.c_str());
    const int n = PQresultStatus(r) == PGRES_TUPLES_OK && PQntuples(r) == 1 ? std::atoi(PQgetvalue(r, 0, 0)) : -1;
    PQclear(r);
    PQfinish(conn);
    return n;
  }
  int current_leases() {
    PGconn* conn = PQconnectdb(url_.c_str());
    PGresult* r = PQexec(conn, "SELECT count(*) FROM terrane_leases WHERE expires_at > clock_timestamp()");
    const int n = PQresultStatus(r) == PGRES_TUPLES_OK ? std::atoi(PQgetvalue(r, 0, 0)) : -1;
    PQclear(r);
    PQfinish(conn);
    return n;
  }

  // One sample of a server's metrics (started with --metrics 127.0.0.1:0),
  // or -1 when it cannot be read or is not there.
  static double metric(ServerProcess& s, const std::string& name) {
    httplib::Client http("127.0.0.1", s.metrics_port());
    http.set_connection_timeout(10, 0);
    http.set_read_timeout(30, 0);
    auto res = http.Get("/metrics");
    if (!res || res->status != 200) return -1;
    const bots::Scrape scrape = bots::parse_exposition(res->body);
    auto it = scrape.find(name);
    return it == scrape.end() ? -1 : it->second;
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
    ASSERT_EQ(write(c, box, want), "");
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
  ASSERT_EQ(write(ann, box, anns), "");
  // The region is server 1's now: server 2 forwards bob's edit there to it,
  // and acknowledges it once server 1 stored it and bob's replica shows it.
  const Region beside = box_near(bob, 5);
  const auto bobs = pattern(beside, materials::kSnow);
  ASSERT_EQ(write(bob, beside, bobs), "");
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

TEST_F(ClusterTest, AFreeRegionBesideAnotherServersIsLeftToItAndTheEditForwarded) {
  Pair p;
  ASSERT_NO_FATAL_FAILURE(start_pair(5000, &p));
  Client &ann = *p.ann, &bob = *p.bob;
  const auto region_of = [](const Region& r) { return coarse_region_of(chunk_of(r.min)); };
  // The spawn lies by the corner x = 0, z = 0 of four regions: boxes a few
  // voxels from it, in two of them.
  const Vec3i s = voxel_of(ann.welcome()->spawn);
  ASSERT_LT(std::abs(s.x) + std::abs(s.z), 4) << "the spawn is not by the region corner";
  const Vec3i corner{0, s.y - 3, 0};
  const Region anns{corner + Vec3i{4, 0, 4}, corner + Vec3i{7, 3, 7}};
  const Region beside{corner + Vec3i{-8, 0, 4}, corner + Vec3i{-5, 3, 7}};
  // Server 1 writes the region of ann's edit.
  ASSERT_EQ(write(ann, anns, pattern(anns, materials::kBrick)), "");
  ASSERT_EQ(lease_owner(region_of(anns)), 1);
  // Bob (on server 2, which writes nothing) edits the free region beside
  // it: the region is left to server 1, so the edit is forwarded there,
  // server 1 claims and writes it, and bob's replica comes to show it.
  const auto bobs = pattern(beside, materials::kSnow);
  ASSERT_EQ(write(bob, beside, bobs), "");
  EXPECT_EQ(lease_owner(region_of(beside)), 1) << "server 2 took a region beside server 1's";
  EXPECT_TRUE(replica_shows(bob, beside, bobs));
  ASSERT_TRUE(ann.wait_until([&](const ClientView& v) { return v.closed || shows(v.replica, beside, bobs); }, kDeadline))
      << "ann never saw bob's edit";
}

TEST_F(ClusterTest, AServerPausedPastItsLeaseCannotWriteAgain) {
  Pair p;
  ASSERT_NO_FATAL_FAILURE(start_pair(1000, &p));
  ServerProcess &a = *p.a, &b = *p.b;
  Client &ann = *p.ann, &bob = *p.bob;
  const Region box = box_near(ann, 0);
  ASSERT_EQ(write(ann, box, pattern(box, materials::kBrick)), "");
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
  ASSERT_EQ(write(ann, box, anns), "");
  // Server 1's commit notifies server 2, which reads the chunks again and
  // sends them to bob.
  ASSERT_TRUE(bob.wait_until([&](const ClientView& v) { return v.closed || shows(v.replica, box, anns); }, kDeadline))
      << "bob never saw ann's edit";
  // A second edit of the same chunks follows the first.
  const auto again = pattern(box, materials::kSnow);
  ASSERT_EQ(write(ann, box, again), "");
  ASSERT_TRUE(bob.wait_until([&](const ClientView& v) { return v.closed || shows(v.replica, box, again); }, kDeadline));
  expect_agrees_with_its_server(bob, near);
  ann.disconnect();
  bob.disconnect();
}

TEST_F(ClusterTest, AChunkAnotherServerChangedReachesAClientHereAsItsChangedUnitsNotReadAgain) {
  ServerProcess& one = start(1);
  ServerProcess& two = start(2, 5000, 100000, {"--metrics", "127.0.0.1:0"});
  ASSERT_NE(two.metrics_port(), 0) << two.output();
  Client ann(options(one, "ann"));
  join(ann);
  // The ticks of the UpdateBatches bob receives.
  std::mutex ticks_m;
  std::set<std::uint64_t> bobs_ticks;
  ClientCallbacks callbacks;
  callbacks.on_update_batch = [&](std::uint64_t tick, const std::vector<ChunkRevisionMsg>&) {
    std::lock_guard lock(ticks_m);
    bobs_ticks.insert(tick);
  };
  Client bob(options(two, "bob"), callbacks);
  const auto near = join(bob);
  auto units_updated = [&] {
    std::uint64_t n = 0;
    bob.wait_until([&](const ClientView& v) {
      n = v.counters.units_updated;
      return true;
    }, 0ms);
    return n;
  };
  const std::uint64_t units_before = units_updated();
  // The tick an acknowledged edit of c's names, and whether an UpdateBatch
  // of that tick comes to bob.
  auto acked_tick = [](Client& c, std::uint32_t id) {
    std::uint64_t tick = 0;
    c.wait_until([&](const ClientView& view) {
      tick = view.edits.at(id).tick;
      return true;
    }, 0ms);
    return tick;
  };
  auto bob_hears = [&](std::uint64_t tick) {
    return testing_support::eventually([&] {
      std::lock_guard lock(ticks_m);
      return bobs_ticks.count(tick) != 0;
    });
  };
  // Server 1's notices carry each chunk's changed units; server 2 holds the
  // chunks at the revision before, applies them and sends bob the units,
  // in an UpdateBatch of the tick server 1 acknowledged ann's edit with.
  const Region box = box_near(ann, 0);
  for (const Material m : {materials::kBrick, materials::kSnow}) {
    const auto v = pattern(box, m);
    ASSERT_TRUE(wait_full_resolution(ann, box));
    const std::uint32_t id = ann.write_box(box, v);
    ASSERT_EQ(outcome(ann, id), "");
    const std::uint64_t tick = acked_tick(ann, id);
    ASSERT_TRUE(bob.wait_until([&](const ClientView& view) { return view.closed || shows(view.replica, box, v); },
                               kDeadline))
        << "bob never saw ann's edit";
    EXPECT_TRUE(bob_hears(tick)) << "no UpdateBatch of tick " << tick << " reached bob";
    ASSERT_TRUE(replica_shows(ann, box, v));
  }
  // An edit of bob's there is forwarded to server 1; its ack names server
  // 1's tick, and so does the UpdateBatch bringing bob its units.
  {
    const auto v = pattern(box, materials::kSand);
    ASSERT_TRUE(wait_full_resolution(bob, box));
    const std::uint32_t id = bob.write_box(box, v);
    ASSERT_EQ(outcome(bob, id), "");
    const std::uint64_t tick = acked_tick(bob, id);
    EXPECT_TRUE(replica_shows(bob, box, v));
    EXPECT_TRUE(bob_hears(tick)) << "bob's forwarded edit was acknowledged with tick " << tick << ", which no UpdateBatch named";
    ASSERT_TRUE(replica_shows(ann, box, v));
  }
  // What server 2 made of the units is what server 1 wrote: the chunks
  // around the box agree voxel for voxel in the two clients' replicas.
  const Vec3i k{kChunkSize, kChunkSize, kChunkSize};
  const Region chunks{chunk_origin(chunk_of(box.min)), chunk_origin(chunk_of(box.max - Vec3i{1, 1, 1})) + k};
  Box anns(chunks.size()), bobs(chunks.size());
  ann.with_replica([&](const Replica& r) { r.read_box(chunks.min, anns); });
  bob.with_replica([&](const Replica& r) { r.read_box(chunks.min, bobs); });
  EXPECT_TRUE(std::equal(anns.voxels().begin(), anns.voxels().end(), bobs.voxels().begin()));
  const double changed = metric(two, "terrane_chunks_changed_elsewhere_total");
  EXPECT_GE(changed, 3);  // the box's chunks, three times
  EXPECT_EQ(metric(two, "terrane_chunks_updated_elsewhere_total"), changed) << "some were read again";
  EXPECT_GE(units_updated() - units_before, 3u);
  expect_agrees_with_its_server(bob, near);
  ann.disconnect();
  bob.disconnect();
}

TEST_F(ClusterTest, ChunksAnotherServerChangedThatNoClientHereHoldsAreForgottenNotReadAgain) {
  ServerProcess& one = start(1);
  ServerProcess& two = start(2, 5000, 100000, {"--metrics", "127.0.0.1:0"});
  ASSERT_NE(two.metrics_port(), 0) << two.output();
  Client ann(options(one, "ann"));
  join(ann);
  {
    // Server 2 loads the chunks around the spawn for bob, who leaves.
    Client bob(options(two, "bob"));
    join(bob);
    bob.disconnect();
  }
  ASSERT_TRUE(testing_support::eventually([&] { return metric(two, "terrane_clients") == 0; }));
  const Region box = box_near(ann, 0);
  const auto anns = pattern(box, materials::kBrick);
  ASSERT_EQ(write(ann, box, anns), "");
  // Server 1's commit notifies server 2, which holds the chunks for nobody:
  // forgotten, not read again.
  ASSERT_TRUE(testing_support::eventually(
      [&] { return metric(two, "terrane_chunks_forgotten_elsewhere_total") >= 1; }))
      << "server 2 forgot none of the chunks server 1 changed";
  EXPECT_EQ(metric(two, "terrane_chunks_forgotten_elsewhere_total"),
            metric(two, "terrane_chunks_changed_elsewhere_total"));
  // And read from the store when next wanted: a new client there sees the edit.
  Client carl(options(two, "carl"));
  const auto near = join(carl);
  EXPECT_TRUE(replica_shows(carl, box, anns)) << "carl never saw ann's edit";
  expect_agrees_with_its_server(carl, near);
  ann.disconnect();
  carl.disconnect();
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
    ASSERT_EQ(write(ann, r, v), "");
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
      EXPECT_TRUE(replica_shows(cy, r, v, &sand_box)) << "acknowledged edit " << i << " lost";
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
  ASSERT_EQ(write(ann, first, v1), "");
  ASSERT_TRUE(wait_full_resolution(ann, second));
  // The database restarts while an edit is under way: it is acknowledged
  // once stored, after the database is back; the server keeps running.
  bool restarted = false;
  std::thread restart([&] { restarted = pg_->restart(); });
  const std::uint32_t during = ann.write_box(second, v2);
  restart.join();
  ASSERT_TRUE(restarted) << pg_->why();
  EXPECT_EQ(outcome(ann, during), "");
  EXPECT_EQ(write(ann, third, v3), "");
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

// /health says whether the server can store: 503 with the reason while its
// database is down (a commit tried again meanwhile shows as retrying), 200
// again once the database is back and the commit stored.
TEST_F(ClusterTest, HealthIsUnavailableWhileTheDatabaseIsDownAndOkOnceItIsBack) {
  // A lease far longer than the outage: the server keeps its region.
  ServerProcess& a = start(1, 30000, 100000, {"--metrics", "127.0.0.1:0"});
  ASSERT_NE(a.port(), 0);
  ASSERT_NE(a.metrics_port(), 0) << a.output();
  const auto health = [&a](std::string* body = nullptr) {
    httplib::Client http("127.0.0.1", a.metrics_port());
    http.set_connection_timeout(10, 0);
    http.set_read_timeout(30, 0);
    auto res = http.Get("/health");
    if (body != nullptr) *body = res ? res->body : "";
    return res ? res->status : -1;
  };
  Client ann(options(a, "ann"));
  join(ann);
  const Region first = box_near(ann, 0), second = box_near(ann, 5);
  const auto v1 = pattern(first, materials::kBrick), v2 = pattern(second, materials::kSnow);
  ASSERT_EQ(write(ann, first, v1), "");  // the region claimed
  ASSERT_TRUE(wait_full_resolution(ann, second));
  std::string body;
  ASSERT_TRUE(testing_support::eventually([&] { return health(&body) == 200; }, kDeadline)) << body;
  EXPECT_EQ(body, "ready\n");
  // Started again however the test ends: the suite's later tests use it.
  struct Again {
    testing_support::ScratchPostgres& pg;
    bool down = false;
    ~Again() {
      if (down) (void)pg.start_again();
    }
  } again{*pg_};
  ASSERT_TRUE(pg_->stop()) << pg_->why();
  again.down = true;
  EXPECT_TRUE(testing_support::eventually([&] { return health(&body) == 503; }, 10s))
      << "/health still says " << body << " with the database down";
  EXPECT_NE(body.find("database"), std::string::npos) << body;
  // An edit now is applied, and its commit waits for the database.
  const std::uint32_t during = ann.write_box(second, v2);
  ASSERT_NE(during, 0u);
  EXPECT_TRUE(testing_support::eventually([&] { return metric(a, "terrane_storage_retrying") == 1; }, 10s))
      << "the commit is not being tried again";
  EXPECT_EQ(health(&body), 503);
  EXPECT_NE(body.find("storage retrying"), std::string::npos) << body;
  ASSERT_TRUE(pg_->start_again()) << pg_->why();
  again.down = false;
  EXPECT_EQ(outcome(ann, during), "");
  EXPECT_TRUE(testing_support::eventually([&] { return health(&body) == 200; }, 10s))
      << "/health still says " << body << " with the database back";
  EXPECT_EQ(metric(a, "terrane_storage_retrying"), 0);
  EXPECT_GE(metric(a, "terrane_storage_retries_total"), 1);
  EXPECT_EQ(metric(a, "terrane_database_listener_down"), 0);
  ann.disconnect();
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
  ASSERT_EQ(write(ann, west, wv), "");
  ASSERT_EQ(write(bob, east, ev), "");
  // An edit across the border: bob's server hands its region over with the
  // edit to ann's, which then writes both sides.
  const Region across{{-2, west.min.y, west.min.z}, {2, west.max.y, west.max.z}};
  const auto av = pattern(across, materials::kSand);
  ASSERT_EQ(write(bob, across, av), "");
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

// Edits across the border of two servers' regions sent through both servers
// at the same moment: each server asks the other for its region (hands its
// own over with its client's edit), and each gets the other's edit. The
// server with the lower id wins: the other claims nothing for that edit
// and passes it back with what it holds of it, so both edits are applied
// (by server 1) and none is refused. Each round then puts the border back
// (an edit of each player across a border with a region its server keeps
// hands the region it won over), so every round is such a duel.
TEST_F(ClusterTest, EditsAcrossABorderSentThroughBothServersAtOnceAreAllApplied) {
  for (std::uint32_t id = 1; id <= 2; ++id) ASSERT_NE(start(id).port(), 0);
  Client ann(options(*servers_[0], "ann")), bob(options(*servers_[1], "bob"));
  join(ann);
  join(bob);
  const Vec3f sp = ann.welcome()->spawn;
  const int y = static_cast<int>(std::floor(sp.y)) - 3;
  const auto region_y = [](int v) { return v >= 0 ? v / 256 : (v - 255) / 256; };
  const int ry = region_y(y);
  ASSERT_EQ(ry, region_y(y + 3)) << "the boxes cross a region border in y";
  // The four regions by the corner x = 0, z = 0 near the spawn: server 1
  // the two west of x = 0, server 2 the two east (set in the table: a
  // server claims a region leased to its own id as its own; a free region
  // beside server 1's would be left to server 1).
  const Vec3i nw{-1, ry, 0}, ne{0, ry, 0}, sw{-1, ry, -1}, se{0, ry, -1};
  for (const auto& [r, owner] : {std::pair{nw, 1}, std::pair{sw, 1}, std::pair{ne, 2}, std::pair{se, 2}})
    ASSERT_EQ(run_sql(url_, fmt::format("INSERT INTO terrane_leases (rx, ry, rz, owner, epoch, expires_at)"
                                        " VALUES ({}, {}, {}, {}, 1, clock_timestamp() + interval '1 hour')",
                                        r.x, r.y, r.z, owner)),
              "");
  const Region in_nw{{-8, y, 2}, {-5, y + 3, 5}}, in_sw{{-8, y, -6}, {-5, y + 3, -3}};
  const Region in_ne{{4, y, 2}, {7, y + 3, 5}}, in_se{{4, y, -6}, {7, y + 3, -3}};
  ASSERT_EQ(write(ann, in_nw, pattern(in_nw, materials::kBrick)), "");
  ASSERT_EQ(write(ann, in_sw, pattern(in_sw, materials::kBrick)), "");
  ASSERT_EQ(write(bob, in_ne, pattern(in_ne, materials::kSnow)), "");
  ASSERT_EQ(write(bob, in_se, pattern(in_se, materials::kSnow)), "");
  for (const auto& [r, owner] : {std::pair{nw, 1}, std::pair{sw, 1}, std::pair{ne, 2}, std::pair{se, 2}})
    ASSERT_EQ(lease_owner(r), owner);
  // The duel: one edit of each across x = 0 (north of z = 0) at once, each
  // player waiting for its answer. Then the border is put back: ann's edit
  // across z = 0 east of x = 0 hands north-east to server 2 if server 1
  // holds it, bob's west of x = 0 hands north-west to server 1.
  const Region anns{{-2, y, 6}, {2, y + 3, 9}}, bobs{{-2, y, 10}, {2, y + 3, 13}};
  const Region ann_back{{8, y, -2}, {11, y + 3, 2}}, bob_back{{-11, y, -2}, {-8, y + 3, 2}};
  for (const Region& r : {anns, bobs, ann_back, bob_back}) {
    ASSERT_TRUE(wait_full_resolution(ann, r));
    ASSERT_TRUE(wait_full_resolution(bob, r));
  }
  constexpr int kRounds = 20;
  std::vector<std::string> refused;
  std::vector<Voxel> last_ann, last_bob;
  for (int round = 0; round < kRounds; ++round) {
    const auto av = pattern(anns, static_cast<Material>(materials::kGrass + round % 8));
    const auto bv = pattern(bobs, static_cast<Material>(materials::kSnow + round % 4));
    const std::uint32_t a = ann.write_box(anns, av);
    const std::uint32_t b = bob.write_box(bobs, bv);
    if (const std::string o = outcome(ann, a); o.empty())
      last_ann = av;
    else
      refused.push_back(fmt::format("round {}, ann: {}", round, o));
    if (const std::string o = outcome(bob, b); o.empty())
      last_bob = bv;
    else
      refused.push_back(fmt::format("round {}, bob: {}", round, o));
    const auto back = pattern(ann_back, static_cast<Material>(materials::kSand + round % 2));
    if (const std::string o = write(ann, ann_back, back); !o.empty())
      refused.push_back(fmt::format("round {}, ann putting the border back: {}", round, o));
    if (const std::string o = write(bob, bob_back, back); !o.empty())
      refused.push_back(fmt::format("round {}, bob putting the border back: {}", round, o));
  }
  EXPECT_TRUE(refused.empty()) << refused.size() << " of " << 4 * kRounds << " refused:\n"
                               << fmt::format("{}", fmt::join(refused, "\n"));
  ASSERT_FALSE(last_ann.empty());
  ASSERT_FALSE(last_bob.empty());
  for (const auto& [r, owner] : {std::pair{nw, 1}, std::pair{sw, 1}, std::pair{ne, 2}, std::pair{se, 2}})
    EXPECT_EQ(lease_owner(r), owner) << "the border was not put back";
  // Both replicas show the last edits and agree with their servers.
  for (Client* c : {&ann, &bob}) {
    EXPECT_TRUE(replica_shows(*c, anns, last_ann));
    EXPECT_TRUE(replica_shows(*c, bobs, last_bob));
    std::vector<Vec3i> chunks;
    for_each_chunk_in(Region{{-11, y, -6}, {11, y + 3, 13}}, [&](Vec3i cp) { chunks.push_back(cp); });
    expect_agrees_with_its_server(*c, chunks);
  }
  ann.disconnect();
  bob.disconnect();
  // And the database holds them: a third server shows them.
  ServerProcess& c = start(3);
  ASSERT_NE(c.port(), 0);
  Client cy(options(c, "cy"));
  join(cy);
  EXPECT_TRUE(replica_shows(cy, anns, last_ann));
  EXPECT_TRUE(replica_shows(cy, bobs, last_bob));
  cy.disconnect();
}

// Three servers at once on one world: each writes the region its first
// editor claimed, every edit reaches the clients of the other two (by
// notice, or forwarded to its region's server), and every replica agrees
// with its own server.
TEST_F(ClusterTest, ThreeServersAtOnceEachWriteTheirRegionsAndEveryClientSeesEveryEdit) {
  std::vector<ServerProcess*> s;
  for (std::uint32_t id = 1; id <= 3; ++id) {
    s.push_back(&start(id));
    ASSERT_NE(s.back()->port(), 0);
  }
  std::vector<std::unique_ptr<Client>> c;
  std::vector<std::vector<Vec3i>> near;
  for (int i = 0; i < 3; ++i) {
    c.push_back(std::make_unique<Client>(options(*s[static_cast<std::size_t>(i)], "player-" + std::to_string(i))));
    near.push_back(join(*c.back()));
  }
  // Each claims a region of its own first: west of the spawn (x < 0), east
  // and north of it (x >= 0, z >= 0), east and south (x >= 0, z < 0).
  const Vec3f sp = c[0]->welcome()->spawn;
  const int y = static_cast<int>(std::floor(sp.y)) - 3;
  const Region own[3] = {{{-8, y, 2}, {-5, y + 3, 5}}, {{4, y, 2}, {7, y + 3, 5}}, {{4, y, -6}, {7, y + 3, -3}}};
  for (int i = 0; i < 3; ++i)
    ASSERT_EQ(until_accepted(*c[static_cast<std::size_t>(i)], own[i], pattern(own[i], materials::kBrick)), "") << i;
  // Then each edits the next one's region: forwarded there, acknowledged,
  // and seen by all three.
  std::vector<std::pair<Region, std::vector<Voxel>>> edits;
  for (int i = 0; i < 3; ++i) {
    const Region r = own[(i + 1) % 3];
    auto v = pattern(r, static_cast<Material>(materials::kSnow + i));
    ASSERT_EQ(until_accepted(*c[static_cast<std::size_t>(i)], r, v), "") << i;
    edits.emplace_back(r, std::move(v));
  }
  for (int i = 0; i < 3; ++i)
    for (const auto& edit : edits)
      EXPECT_TRUE(c[static_cast<std::size_t>(i)]->wait_until(
          [&](const ClientView& view) { return view.closed || shows(view.replica, edit.first, edit.second); },
          kDeadline))
          << "player " << i << " never saw an edit";
  for (int i = 0; i < 3; ++i) {
    expect_agrees_with_its_server(*c[static_cast<std::size_t>(i)], near[static_cast<std::size_t>(i)]);
    c[static_cast<std::size_t>(i)]->disconnect();
  }
}

// An edit across the corner of three servers' regions (leases set in the
// table: a server claims a region leased to its own id as its own). Sent
// to server 1, which holds one of them: it hands that over to the holder
// of another, which relays the edit, with its own regions, to the third;
// the third applies it, and the answer comes back the way the edit went.
TEST_F(ClusterTest, AnEditAcrossTheCornerOfThreeServersRegionsIsRelayedAndApplied) {
  for (std::uint32_t id = 1; id <= 3; ++id) ASSERT_NE(start(id, 5000, 100000, {"--metrics", "127.0.0.1:0"}).port(), 0);
  Client ann(options(*servers_[0], "ann"));
  join(ann);
  const Vec3f sp = ann.welcome()->spawn;
  const int y = static_cast<int>(std::floor(sp.y)) - 3;
  const int ry = y >= 0 ? y / 256 : (y - 255) / 256;
  // By the spawn lies the corner x = 0, z = 0 of four regions.
  const std::pair<Vec3i, int> leased[] = {
      {{-1, ry, 0}, 1}, {{0, ry, 0}, 2}, {{0, ry, -1}, 3}, {{-1, ry, -1}, 3}};
  for (const auto& [r, owner] : leased)
    ASSERT_EQ(run_sql(url_, fmt::format("INSERT INTO terrane_leases (rx, ry, rz, owner, epoch, expires_at)"
                                        " VALUES ({}, {}, {}, {}, 1, clock_timestamp() + interval '1 hour')",
                                        r.x, r.y, r.z, owner)),
              "");
  const Region corner{{-2, y, -2}, {2, y + 3, 2}};
  const auto v = pattern(corner, materials::kSand);
  ASSERT_EQ(write(ann, corner, v), "") << "accepted at the first try";
  EXPECT_TRUE(replica_shows(ann, corner, v));
  // One server writes all four regions now, and not server 1.
  const int writer = lease_owner(leased[0].first);
  EXPECT_NE(writer, 1);
  for (const auto& [r, owner] : leased) EXPECT_EQ(lease_owner(r), writer) << r.x << "," << r.z;
  // Server 1 forwarded it, and one of the others relayed it on.
  EXPECT_EQ(metric(*servers_[0], "terrane_edits_forwarded_total"), 1);
  EXPECT_EQ(metric(*servers_[1], "terrane_edits_forwarded_total") + metric(*servers_[2], "terrane_edits_forwarded_total"), 1);
  ann.disconnect();
}

// A forwarded edit whose region moved on before its addressee read it (the
// addressee holds none of its regions now) is relayed to the region's
// server, not refused. The region is leased to server 2 in the table;
// ann's edit on server 1 is forwarded there while server 2 is stopped,
// the lease passes to server 3, and server 2, resumed, relays the edit.
TEST_F(ClusterTest, AForwardedEditWhoseRegionMovedOnIsRelayedToItsNewServer) {
  // Long leases: server 1 waits a lease time for the answer, and the relay
  // (server 2 woken, claims, server 3's chunks made) may be slow here.
  for (std::uint32_t id = 1; id <= 3; ++id) ASSERT_NE(start(id, 20000, 100000, {"--metrics", "127.0.0.1:0"}).port(), 0);
  ServerProcess &a = *servers_[0], &b = *servers_[1], &c = *servers_[2];
  Client ann(options(a, "ann"));
  join(ann);
  // East and north of the corner x = 0, z = 0 by the spawn: in one region.
  const Vec3f sp = ann.welcome()->spawn;
  const int y = static_cast<int>(std::floor(sp.y)) - 3;
  const Region box{{4, y, 4}, {7, y + 3, 7}};
  const Vec3i region = coarse_region_of(chunk_of(box.min));
  ASSERT_EQ(region, coarse_region_of(chunk_of(box.max - Vec3i{1, 1, 1})));
  ASSERT_EQ(run_sql(url_, fmt::format("INSERT INTO terrane_leases (rx, ry, rz, owner, epoch, expires_at)"
                                      " VALUES ({}, {}, {}, 2, 1, clock_timestamp() + interval '1 hour')",
                                      region.x, region.y, region.z)),
            "");
  ASSERT_TRUE(wait_full_resolution(ann, box));
  ASSERT_TRUE(b.pause());
  const auto v = pattern(box, materials::kSand);
  const std::uint32_t id = ann.write_box(box, v);
  // In server 2's inbox: the lease goes to server 3 before server 2 reads it.
  const bool in_inbox = testing_support::eventually(
      [&] { return sql_value(url_, "SELECT count(*) FROM terrane_inbox WHERE to_server = 2") == "1"; }, kDeadline);
  const std::string moved = run_sql(url_, fmt::format("UPDATE terrane_leases SET owner = 3 WHERE rx = {} AND ry = {} AND rz = {}",
                                                      region.x, region.y, region.z));
  ASSERT_TRUE(b.resume());
  ASSERT_TRUE(in_inbox) << "server 1 never forwarded the edit to server 2";
  ASSERT_EQ(moved, "");
  EXPECT_EQ(outcome(ann, id), "");
  EXPECT_TRUE(replica_shows(ann, box, v));
  EXPECT_EQ(lease_owner(region), 3);
  EXPECT_EQ(metric(a, "terrane_edits_forwarded_total"), 1);
  EXPECT_EQ(metric(b, "terrane_edits_forwarded_total"), 1) << "server 2 relayed it";
  EXPECT_EQ(metric(c, "terrane_forwarded_edits_received_total"), 1);
  ann.disconnect();
}

// A border is the whole world's: a server is refused a new one while
// another runs on the world (which would go on without it); once alone it
// sets it, and every server started after applies it.
TEST_F(ClusterTest, ABorderIsSetOnlyWhileNoOtherServerRunsAndEveryServerAfterAppliesIt) {
  ServerProcess& a = start(1);
  ASSERT_NE(a.port(), 0);
  // Server 1 has said where it runs once its keeper's first round is done.
  ASSERT_TRUE(testing_support::eventually(
      [&] { return sql_value(url_, "SELECT count(*) FROM terrane_servers") == "1"; }, kDeadline));
  const std::vector<std::string> border{"--border", "-512,-512,512,512"};
  ServerProcess& refused = start(2, 5000, 100000, border, false);
  EXPECT_EQ(refused.wait_exit(60s), 1) << refused.output();
  EXPECT_NE(refused.output().find("--border: server 1 is running"), std::string::npos)
      << refused.output();
  // The border the world has already is no change: allowed.
  ServerProcess& same = start(2, 5000, 100000, {"--border", "none"});
  ASSERT_NE(same.port(), 0);
  ASSERT_EQ(same.stop(), 0) << same.output();
  ASSERT_EQ(a.stop(), 0) << a.output();
  ServerProcess& b = start(2, 5000, 100000, border);
  ASSERT_NE(b.port(), 0);
  ServerProcess& again = start(1);
  ASSERT_NE(again.port(), 0);
  Client c(options(again, "cy"));
  join(c);
  const auto w = c.welcome();
  ASSERT_TRUE(w);
  EXPECT_TRUE(w->bounded_xz);
  EXPECT_EQ(w->bounds_min_x, -512);
  EXPECT_EQ(w->bounds_max_z, 512);
  c.disconnect();
}

// A player's edits forwarded to a region's server are held to the edit rate
// there, whatever server they come through: its own server allows more.
TEST_F(ClusterTest, ForwardedEditsAreHeldToThePlayersEditRateAtTheRegionsServer) {
  ServerProcess& a = start(1, 5000, 1);  // 1 edit a second, a burst of 2
  ASSERT_NE(a.port(), 0);
  ServerProcess& b = start(2);
  ASSERT_NE(b.port(), 0);
  ClientOptions ao = options(a, "ann");
  Client ann(ao);
  join(ann);
  const Region box = box_near(ann, 0);
  ASSERT_EQ(write(ann, box, pattern(box, materials::kBrick)), "");
  // Server 1 writes the region now; bob, on server 2, edits there at once
  // ten times: forwarded, the first few applied, the rest refused.
  Client bob(options(b, "bob"));
  join(bob);
  std::vector<std::uint32_t> ids;
  ASSERT_TRUE(wait_full_resolution(bob, box));
  for (int i = 0; i < 10; ++i) ids.push_back(bob.write_box(box, pattern(box, static_cast<Material>(materials::kBrick + i % 4))));
  int accepted = 0, limited = 0;
  for (const std::uint32_t id : ids) {
    const std::string why = outcome(bob, id);
    if (why.empty())
      ++accepted;
    else if (why.find("edit rate limit") != std::string::npos)
      ++limited;
    else
      ADD_FAILURE() << "refused otherwise: " << why;
  }
  // The burst, and what refilled while they were forwarded one by one.
  EXPECT_GE(accepted, 1);
  EXPECT_GE(limited, 1);
  EXPECT_EQ(accepted + limited, 10);
  EXPECT_FALSE(bob.closed()) << bob.disconnect_reason();
  ann.disconnect();
  bob.disconnect();
}

// A client that walks well inside a region another server writes is sent
// there and keeps its replica: the new server streams only what the client
// did not hold (chunks entering the view, finer levels), never a chunk again.
TEST_F(ClusterTest, AClientWalkingIntoAnotherServersRegionIsRedirectedAndNoChunkIsSentTwice) {
  ServerProcess& a = start(1);
  ASSERT_NE(a.port(), 0);
  ServerProcess& b = start(2);
  ASSERT_NE(b.port(), 0);
  // What ann holds when it leaves server 1, and the records it gets after.
  struct Seen {
    std::mutex m;
    std::unordered_map<Vec3i, Holding, Vec3iHash> held;
    bool redirected = false;
    std::vector<std::string> resent;
    std::size_t records = 0;
    std::uint64_t stream_bytes_before = 0;
    std::atomic<std::uint32_t> now_on{0};  // the server of the latest Welcome
  };
  auto seen = std::make_shared<Seen>();
  Client* ann_ptr = nullptr;
  ClientCallbacks cb;
  cb.on_welcome = [seen](const WelcomeMsg& w) { seen->now_on = w.server_id; };
  cb.on_redirected = [&ann_ptr, seen](const RedirectMsg&) {
    std::unordered_map<Vec3i, Holding, Vec3iHash> held;
    ann_ptr->with_replica([&](const Replica& r) {
      r.for_each_holding([&](Vec3i cp, const Holding& c) { held[cp] = c; });
    });
    const auto before = ann_ptr->counters().by_message_type[static_cast<std::size_t>(wire::Body::StreamBatch)].bytes_in;
    std::lock_guard lock(seen->m);
    seen->held = std::move(held);
    seen->stream_bytes_before = before;
    seen->redirected = true;
  };
  cb.on_reconnected = [&ann_ptr, seen] { seen->now_on = ann_ptr->welcome()->server_id; };
  cb.on_holding = [seen](Vec3i cp, const Holding* now) {
    std::lock_guard lock(seen->m);
    if (!seen->redirected || now == nullptr) return;
    ++seen->records;
    auto it = seen->held.find(cp);
    if (it == seen->held.end() || !claimable(it->second.form)) return;
    const Holding& had = it->second;
    const bool again = (now->form == HoldingForm::kFull && had.form == HoldingForm::kFull) ||
                       (now->form == HoldingForm::kEmpty && had.form == HoldingForm::kEmpty) ||
                       (!now->full_resolution() && (had.full_resolution() || had.level() <= now->level()));
    if (again)
      seen->resent.push_back(fmt::format("({},{},{}) {}", cp.x, cp.y, cp.z, form_name(now->form)));
  };
  Client ann(options(a, "ann"), cb);
  ann_ptr = &ann;
  // Bob stands where ann walks to: 48 voxels east and south of the spawn,
  // which lies by the corner x = 0, z = 0 of four regions.
  ClientOptions bobs = options(b, "bob");
  bobs.spawn_offset = kBeyond;
  Client bob(bobs);
  join(ann);
  join(bob, bobs.spawn_offset);
  ASSERT_EQ(seen->now_on.load(), 1u);
  const WelcomeMsg w = *ann.welcome();
  const Vec3f spawn = w.spawn;
  const Vec3f there = spawn + kBeyond;
  const Vec3i region = coarse_region_of(view_chunk(there));
  std::printf("spawn (%.1f, %.1f, %.1f), region (%d,%d,%d)\n", spawn.x, spawn.y, spawn.z, region.x, region.y, region.z);
  ASSERT_EQ(region, coarse_region_of(view_chunk(spawn + Vec3f{1, 0, 1}))) << "the spawn is not by the region's corner";
  // Bob's server writes that region (its first edit there claims it), ann's
  // the one west of the spawn.
  const Vec3i at = voxel_of(there);
  const Region east{at + Vec3i{-1, 4, -1}, at + Vec3i{1, 6, 1}};
  ASSERT_EQ(coarse_region_of(chunk_of(east.min)), region);
  ASSERT_EQ(write(bob, east, pattern(east, materials::kSnow)), "");
  const Region west = box_near(ann, -8);
  ASSERT_EQ(write(ann, west, pattern(west, materials::kBrick)), "");
  // Ann's whole view first, each chunk with a record of its own (not only a
  // horizon image or an estimate), so that anything sent again would show.
  auto whole_view = [](const std::vector<Vec3i>& chunks) {
    return [&chunks](const ClientView& v) {
      return v.closed || std::all_of(chunks.begin(), chunks.end(), [&](Vec3i cp) {
               const Holding* c = v.replica.holding(cp);
               return c != nullptr && claimable(c->form);
             });
    };
  };
  const auto view = testing_support::chunks_within(spawn, 64, w);
  ASSERT_TRUE(ann.wait_until(whole_view(view), kDeadline));
  // On the border (within the margin of bob's region) ann stays; then it
  // walks there in steps within the speed limit.
  walk(ann, spawn, kBeyond);
  ASSERT_TRUE(ann.wait_until([&](const ClientView& v) { return v.closed || seen->now_on == 2; }, kDeadline))
      << "never redirected";
  EXPECT_EQ(ann.counters().redirects, 1u);
  // Every chunk ann held that is still in its view is asked for its hash:
  // the new server answers a claimed chunk only once it kept it (or sent
  // it again), so once all are answered every claim is settled.
  std::vector<Vec3i> kept;
  {
    std::lock_guard lock(seen->m);
    for (const Vec3i cp : testing_support::chunks_within(there, 64, w))
      if (auto it = seen->held.find(cp); it != seen->held.end() && claimable(it->second.form))
        kept.push_back(cp);
  }
  ASSERT_FALSE(kept.empty());
  for (const Vec3i cp : kept) ASSERT_TRUE(ann.request_chunk_hash(cp));
  ASSERT_TRUE(ann.wait_until(
      [&](const ClientView& v) {
        return v.closed || std::all_of(kept.begin(), kept.end(), [&](Vec3i cp) { return v.hash_checks.count(cp) != 0; });
      },
      kDeadline));
  EXPECT_FALSE(ann.closed()) << ann.disconnect_reason();
  {
    std::lock_guard lock(seen->m);
    // Those ann holds at full resolution are server 2's chunks exactly (a
    // mip holder's check never matches: it has no voxels to hash).
    std::size_t full = 0;
    for (const Vec3i cp : kept)
      if (seen->held.at(cp).full_resolution()) {
        ++full;
        EXPECT_TRUE(ann.wait_until([&](const ClientView& v) { return v.hash_checks.at(cp); }, 0ms))
            << "chunk (" << cp.x << "," << cp.y << "," << cp.z << ") differs from server 2's";
      }
    EXPECT_GT(full, 0u);
    EXPECT_TRUE(seen->resent.empty()) << seen->resent.size() << " chunks sent again, the first "
                                      << (seen->resent.empty() ? std::string() : seen->resent.front());
    const auto c = ann.counters();
    std::printf("redirect: %zu chunks kept, %zu records after it (chunks new to the view, or finer), stream bytes "
                "%llu before it and %llu after\n",
                kept.size(), seen->records, static_cast<unsigned long long>(seen->stream_bytes_before),
                static_cast<unsigned long long>(
                    c.by_message_type[static_cast<std::size_t>(wire::Body::StreamBatch)].bytes_in -
                    seen->stream_bytes_before));
  }
  // The whole new view arrives, and what ann holds there at full
  // resolution agrees with server 2.
  const auto near = testing_support::chunks_within(there, 20, w);
  ASSERT_TRUE(ann.wait_until(whole_view(testing_support::chunks_within(there, 64, w)), kDeadline));
  ASSERT_TRUE(wait_full_resolution(ann, near));
  expect_agrees_with_its_server(ann, near);
  // Ann's edits there are server 2's to write, and bob sees them.
  const Region more{at + Vec3i{3, 4, 3}, at + Vec3i{5, 6, 5}};
  const auto mv = pattern(more, materials::kSand);
  EXPECT_EQ(write(ann, more, mv), "");
  EXPECT_TRUE(replica_shows(ann, more, mv));
  ASSERT_TRUE(bob.wait_until([&](const ClientView& v) { return v.closed || shows(v.replica, more, mv); }, kDeadline));
  ann.disconnect();
  bob.disconnect();
}

// A Redirect to an address the client cannot reach: it goes back to the
// server that sent it, keeps what it holds, and is served there on.
// A border between two regions of one server is no border: a client near
// it, well away from any other server's region, is redirected there.
TEST_F(ClusterTest, AClientByABorderBetweenTwoRegionsOfAnotherServerIsRedirectedThere) {
  ServerProcess& a = start(1);
  ASSERT_NE(a.port(), 0);
  ServerProcess& b = start(2);
  ASSERT_NE(b.port(), 0);
  // Bob and cy (server 2) stand on either side of the face z = 0 east of
  // the spawn (which lies by the corner x = 0, z = 0 of four regions), and
  // each edits there: server 2 writes both regions.
  ClientOptions bobs = options(b, "bob"), cys = options(b, "cy");
  bobs.spawn_offset = kBeyond;
  cys.spawn_offset = Vec3f{kBeyond.x, 0, -kBeyond.z};
  // Where ann is redirected to, and whether it resumed there (set on the
  // client's thread).
  auto redirected_to = std::make_shared<std::atomic<std::uint32_t>>(0);
  ClientCallbacks cb;
  cb.on_redirected = [redirected_to](const RedirectMsg& r) { redirected_to->store(r.server_id); };
  auto resumed = std::make_shared<std::atomic<bool>>(false);
  cb.on_reconnected = [resumed] { resumed->store(true); };
  Client ann(options(a, "ann"), cb), bob(bobs), cy(cys);
  join(ann);
  join(bob, bobs.spawn_offset);
  join(cy, cys.spawn_offset);
  const Vec3f spawn = ann.welcome()->spawn;
  for (auto [c, offset] : {std::pair<Client*, Vec3f>{&bob, bobs.spawn_offset}, {&cy, cys.spawn_offset}}) {
    const Vec3i at = voxel_of(spawn + offset);
    const Region box{at + Vec3i{-1, 4, -1}, at + Vec3i{1, 6, 1}};
    ASSERT_EQ(write(*c, box, pattern(box, materials::kSnow)), "");
  }
  const Vec3i north = coarse_region_of(view_chunk(spawn + cys.spawn_offset));
  const Vec3i south = coarse_region_of(view_chunk(spawn + bobs.spawn_offset));
  ASSERT_EQ((north + Vec3i{0, 0, 1}), south) << "the two regions are not either side of one face";
  ASSERT_EQ(lease_owner(north), 2);
  ASSERT_EQ(lease_owner(south), 2);
  // Ann walks to 5 voxels from that face, deep in x: within the margin of
  // the face, but both sides are server 2's.
  const Vec3f by{kBeyond.x, 0, 5};
  walk(ann, spawn, by);
  ASSERT_TRUE(ann.wait_until([&](const ClientView& v) { return v.closed || redirected_to->load() != 0; }, kDeadline))
      << "never redirected";
  EXPECT_EQ(redirected_to->load(), 2u);
  ASSERT_TRUE(ann.wait_until([&](const ClientView& v) { return v.closed || resumed->load(); }, kDeadline))
      << "never resumed after the redirect";
  ASSERT_TRUE(ann.welcome().has_value());
  EXPECT_EQ(ann.welcome()->server_id, 2u);
  EXPECT_FALSE(ann.closed()) << ann.disconnect_reason();
}

TEST_F(ClusterTest, AClientThatCannotReachTheServerItIsRedirectedToGoesBackAndIsServedOn) {
  ServerProcess& a = start(1);
  ASSERT_NE(a.port(), 0);
  // Server 2 tells the others an address where nothing listens.
  ServerProcess& b = start(2, 5000, 100000, {"--advertise", "127.0.0.1:1"});
  ASSERT_NE(b.port(), 0);
  auto on = std::make_shared<std::atomic<std::uint32_t>>(0);
  Client* ann_ptr = nullptr;
  ClientCallbacks cb;
  cb.on_welcome = [on](const WelcomeMsg& w) { *on = w.server_id; };
  cb.on_reconnected = [on, &ann_ptr] { *on = ann_ptr->welcome()->server_id + 100; };  // 100 + id: a new session
  Client ann(options(a, "ann"), cb);
  ann_ptr = &ann;
  ClientOptions bobs = options(b, "bob");
  bobs.spawn_offset = kBeyond;
  Client bob(bobs);
  join(ann);
  join(bob, bobs.spawn_offset);
  const WelcomeMsg w = *ann.welcome();
  const Vec3f there = w.spawn + kBeyond;
  const Vec3i at = voxel_of(there);
  const Region east{at + Vec3i{-1, 4, -1}, at + Vec3i{1, 6, 1}};
  ASSERT_EQ(write(bob, east, pattern(east, materials::kSnow)), "");
  walk(ann, w.spawn, kBeyond);
  // Sent to 127.0.0.1:1, refused there, back on server 1 in a new session.
  ASSERT_TRUE(ann.wait_until([&](const ClientView& v) { return v.closed || *on == 101; }, kDeadline))
      << "never went back to server 1";
  EXPECT_EQ(ann.counters().redirects, 1u);
  // Served there: its new view arrives whole and agrees with server 1, and
  // its edits are forwarded to server 2.
  ASSERT_TRUE(ann.wait_until(
      [&](const ClientView& v) {
        const auto view = testing_support::chunks_within(there, 20, w);
        return v.closed || std::all_of(view.begin(), view.end(), [&](Vec3i cp) {
                 const Holding* c = v.replica.holding(cp);
                 return c != nullptr && c->full_resolution();
               });
      },
      kDeadline));
  expect_agrees_with_its_server(ann, testing_support::chunks_within(there, 20, w));
  const Region more{at + Vec3i{3, 4, 3}, at + Vec3i{5, 6, 5}};
  const auto mv = pattern(more, materials::kSand);
  EXPECT_EQ(write(ann, more, mv), "");
  EXPECT_TRUE(replica_shows(ann, more, mv));
  EXPECT_FALSE(ann.closed()) << ann.disconnect_reason();
  ann.disconnect();
  bob.disconnect();
}

}  // namespace
}  // namespace terrane
