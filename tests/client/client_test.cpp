// Loopback integration tests: the real terrane-server binary on 127.0.0.1
// (port 0) and the client library. Every wait is on an event with a
// deadline; nothing sleeps.
#include "client/client.h"

#include <gtest/gtest.h>
#include <poll.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <condition_variable>
#include <filesystem>
#include <fstream>
#include <future>
#include <mutex>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "common/world/world.h"
#include "tests/support/server_process.h"
#include "tests/support/view_chunks.h"

namespace terrane {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

// Only how long a test lets a condition take before it fails: generous,
// since the thread sanitizer's build streams a view of 320 in 5-9 s alone
// and took over 20 s beside another build on this 2-core machine.
constexpr auto kDeadline = 60s;

using testing_support::ServerProcess;

class ClientServerTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("terrane-client-" + std::to_string(::getpid()) + "-" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
  }
  void TearDown() override {
    if (server_) {
      // A clean exit also means no sanitizer report in the server.
      EXPECT_EQ(server_->stop(), 0);
      if (HasFailure()) std::fprintf(stderr, "--- server output ---\n%s", server_->output().c_str());
    }
    server_.reset();
    fs::remove_all(dir_);
  }
  void start_server(const std::vector<std::string>& extra = {}) {
    server_ = std::make_unique<ServerProcess>(dir_.string(), extra);
    ASSERT_NE(server_->port(), 0) << server_->output();
  }
  ClientOptions options(const std::string& name, int view = 64, int full = 32) const {
    ClientOptions o;
    o.port = server_->port();
    o.name = name;
    o.state.view_distance = view;
    o.state.full_res_radius = full;
    return o;
  }

  // A client that keeps its chunks in cache (ClientOptions::chunk_cache).
  ClientOptions options_cached(const std::string& name, int view, std::shared_ptr<ChunkCache> cache) const {
    ClientOptions o = options(name, view, 32);
    o.chunk_cache = std::move(cache);
    return o;
  }

  // A client that starts at position instead of the spawn.
  ClientOptions options_at(const std::string& name, Vec3f position, int view, int full) const {
    ClientOptions o = options(name, view, full);
    o.start_at_spawn = false;
    o.state.position = position;
    return o;
  }

  fs::path dir_;
  std::unique_ptr<ServerProcess> server_;
};

using testing_support::chunks_within;

bool all_full(const Replica& r, const std::vector<Vec3i>& chunks) {
  for (const Vec3i cp : chunks) {
    const Holding* c = r.holding(cp);
    if (c == nullptr || !c->full_resolution()) return false;
  }
  return true;
}

bool checked_all(const ClientView& v, const std::vector<Vec3i>& chunks) {
  return v.closed || std::all_of(chunks.begin(), chunks.end(), [&](Vec3i cp) { return v.hash_checks.count(cp) != 0; });
}

// Asks the server for the hash of each chunk and waits for every answer:
// the replica matches the server chunk for chunk.
void expect_verified(Client& c, const std::vector<Vec3i>& chunks) {
  for (const Vec3i cp : chunks) ASSERT_TRUE(c.request_chunk_hash(cp));
  ASSERT_TRUE(c.wait_until([&](const ClientView& v) { return v.closed || checked_all(v, chunks); }, kDeadline));
  EXPECT_EQ(c.counters().hash_mismatches, 0u);
}

bool all_covered(const Replica& r, const std::vector<Vec3i>& chunks) {
  for (const Vec3i cp : chunks)
    if (r.holding(cp) == nullptr) return false;
  return true;
}

// True when every chunk is held at the level the view rule promises at p
// (Empty counts as full resolution anywhere).
bool all_at_desired_level(const Replica& r, const std::vector<Vec3i>& chunks, Vec3f p, std::int32_t full_radius) {
  for (const Vec3i cp : chunks) {
    const Holding* c = r.holding(cp);
    if (c == nullptr) return false;
    if (!c->full_resolution() && c->level() != desired_level(p, cp, full_radius)) return false;
  }
  return true;
}

// Waits for the Welcome, then for full resolution inside the radius.
// Connects c and waits for its Welcome (nullopt, with the reason, when
// either fails).
std::optional<WelcomeMsg> join(Client& c) {
  std::string err;
  if (!c.connect(&err)) {
    ADD_FAILURE() << err;
    return std::nullopt;
  }
  if (!c.wait_until([](const ClientView& v) { return v.welcomed || v.closed; }, kDeadline) || !c.welcome()) {
    ADD_FAILURE() << "no Welcome: " << c.disconnect_reason();
    return std::nullopt;
  }
  return c.welcome();
}

std::vector<Vec3i> wait_full_res(Client& c, float full_radius) {
  EXPECT_TRUE(c.wait_until([](const ClientView& v) { return v.welcomed || v.closed; }, kDeadline));
  const auto w = c.welcome();
  if (!w) return {};
  auto near = chunks_within(w->spawn, full_radius, *w);
  EXPECT_TRUE(c.wait_until([&](const ClientView& v) { return v.closed || all_full(v.replica, near); }, kDeadline));
  return near;
}

// Compares the replica's full-resolution chunks with the world on disk.
void expect_replica_matches_world(Client& c, const std::vector<Vec3i>& chunks, const std::string& world_dir) {
  auto world = World::open(world_dir);
  ASSERT_TRUE(world.ok()) << world.error().message;
  Box mine({kChunkSize, kChunkSize, kChunkSize}), theirs({kChunkSize, kChunkSize, kChunkSize});
  std::size_t non_empty = 0;
  for (const Vec3i cp : chunks) {
    c.read_box(chunk_origin(cp), mine);
    auto stored = (*world)->load_chunk(cp);
    ASSERT_TRUE(stored.ok());
    stored->chunk.read_level(0, theirs);
    ASSERT_TRUE(mine == theirs) << "chunk " << cp.x << "," << cp.y << "," << cp.z;
    const auto rev = c.with_replica([&](const Replica& r) { return r.revision(cp); });
    ASSERT_TRUE(rev.has_value());
    EXPECT_EQ(*rev, stored->revision);
    if (!stored->chunk.empty()) ++non_empty;
  }
  EXPECT_GT(non_empty, 0u) << "the test should cover some terrain";
}

// Each keepalive Ping carries the client's clock: its Pong gives the round
// trip, in the counters and to the callback (the bots' round_trip_ms).
TEST_F(ClientServerTest, KeepalivePingsAreTimedByTheirPongs) {
  start_server({"--hash-push-ms", "0"});
  ClientOptions o = options("pinger");
  o.keepalive = std::chrono::milliseconds(20);
  std::mutex mu;
  std::vector<double> timed;
  ClientCallbacks cb;
  cb.on_round_trip = [&](double ms) {
    std::lock_guard lock(mu);
    timed.push_back(ms);
  };
  Client c(o, cb);
  EXPECT_LT(c.counters().last_round_trip_ms, 0) << "a round trip before any Ping";
  std::string err;
  ASSERT_TRUE(c.connect(&err)) << err;
  ASSERT_TRUE(c.wait_until(
      [](const ClientView& v) { return v.closed || (v.counters.pongs >= 3 && v.counters.last_round_trip_ms >= 0); },
      kDeadline));
  ASSERT_FALSE(c.closed()) << c.disconnect_reason();
  const double last = c.counters().last_round_trip_ms;
  EXPECT_GE(last, 0);
  EXPECT_LT(last, 30000);
  c.disconnect();
  std::lock_guard lock(mu);
  ASSERT_FALSE(timed.empty());
  for (const double ms : timed) {
    EXPECT_GE(ms, 0);
    EXPECT_LT(ms, 30000);
  }
}

TEST_F(ClientServerTest, FullResolutionReplicaEqualsServerWorld) {
  start_server({"--hash-push-ms", "0"});  // only the hashes asked for below
  Client c(options("viewer"));
  std::string err;
  ASSERT_TRUE(c.connect(&err)) << err;
  const auto near = wait_full_res(c, 32);
  ASSERT_FALSE(near.empty());
  ASSERT_FALSE(c.closed()) << c.disconnect_reason();
  // Chunk hashes agree too.
  for (const Vec3i cp : near) ASSERT_TRUE(c.request_chunk_hash(cp));
  ASSERT_TRUE(c.wait_until(
      [&](const ClientView& v) { return v.closed || v.hash_checks.size() == near.size(); }, kDeadline));
  EXPECT_EQ(c.counters().hash_matches, near.size());
  EXPECT_EQ(c.counters().hash_mismatches, 0u);
  c.disconnect();
  ASSERT_EQ(server_->stop(), 0) << server_->output();
  expect_replica_matches_world(c, near, dir_.string());
}

TEST_F(ClientServerTest, EstimatedMipsAreReplacedByTheChunksOwnOnlyWhereTheyDiffer) {
  // A world never generated: the coarsest mip of every chunk comes first as
  // an estimate, then (generated in the background) the chunk's own mip is
  // sent where it differs, immediately (no refresh batching).
  start_server({"--mip-refresh-ms", "0", "--max-speed", "0"});
  Client c(options("horizon", 192, 32));
  std::string err;
  ASSERT_TRUE(c.connect(&err)) << err;
  const auto near = wait_full_res(c, 32);
  ASSERT_FALSE(near.empty());
  const auto w = c.welcome();
  ASSERT_TRUE(w.has_value());
  const auto view = chunks_within(w->spawn, 192, *w);
  // Each chunk's exact coarsest mip, from the world's own generator.
  auto world = World::open(dir_.string());
  ASSERT_TRUE(world.ok()) << world.error().message;
  std::unordered_map<Vec3i, std::vector<Voxel>, Vec3iHash> exact;
  for (const Vec3i cp : view) {
    const Chunk chunk = (*world)->generate_chunk(cp);
    Box mip;
    chunk.read_level(kMipLevels - 1, mip);
    exact[cp].assign(mip.voxels().begin(), mip.voxels().end());
  }
  const auto replaced = [&](const Replica& r) {
    for (const Vec3i cp : view) {
      const Holding* cov = r.holding(cp);
      if (cov == nullptr) return false;
      if (cov->full_resolution() || cov->level() != kMipLevels - 1) continue;
      Box held;
      if (!r.read_mip(cp, held) ||
          !std::equal(held.voxels().begin(), held.voxels().end(), exact[cp].begin(), exact[cp].end()))
        return false;
    }
    return true;
  };
  ASSERT_TRUE(c.wait_until([&](const ClientView& v) { return v.closed || replaced(v.replica); }, 60s))
      << "the coarsest mips held never all became the chunks' own";
  ASSERT_FALSE(c.closed()) << c.disconnect_reason();
  const ClientCounters counters = c.counters();
  EXPECT_GT(counters.estimates, 0u) << "no estimate was sent: the test shows nothing";
  c.with_replica([&](const Replica& r) {
    // Some estimates differed and were corrected (those that were exact keep
    // their mark: nothing was sent for them) ...
    EXPECT_LT(r.estimate_count(), counters.estimates);
    // ... and no record brought a level again with the voxels held.
    EXPECT_EQ(r.redundant_mips(), 0u);
  });
  // Full resolution, where the client is and where it moves, passes the
  // chunk hashes (estimates never reach full resolution).
  const Vec3f far{w->spawn.x + 150.0f, w->spawn.y, w->spawn.z};
  ASSERT_TRUE(c.set_state(ClientStateMsg{far, 192, 32}));
  const auto there = chunks_within(far, 32, *w);
  ASSERT_TRUE(c.wait_until([&](const ClientView& v) { return v.closed || all_full(v.replica, there); }, 60s));
  std::vector<Vec3i> checked = near;
  checked.insert(checked.end(), there.begin(), there.end());
  for (const Vec3i cp : checked) ASSERT_TRUE(c.request_chunk_hash(cp));
  ASSERT_TRUE(c.wait_until([&](const ClientView& v) { return v.closed || checked_all(v, checked); }, kDeadline));
  EXPECT_EQ(c.counters().hash_mismatches, 0u);
  c.disconnect();
}

TEST_F(ClientServerTest, MipsArriveBeforeFullResolution) {
  // Without horizon images, the coarse view is every chunk's 4^3 mip (with
  // them, chunks within full resolution skip it).
  start_server({"--no-horizon-images"});
  struct Event {
    Vec3i chunk;
    std::optional<Holding> now;
  };
  std::mutex mu;
  std::vector<Event> events;
  ClientCallbacks cb;
  cb.on_holding = [&](Vec3i p, const Holding* now) {
    std::lock_guard lock(mu);
    events.push_back({p, now ? std::optional<Holding>(*now) : std::nullopt});
  };
  Client c(options("mips", 96, 32), cb);
  std::string err;
  ASSERT_TRUE(c.connect(&err)) << err;
  const auto near = wait_full_res(c, 32);
  const auto w = c.welcome();
  ASSERT_TRUE(w.has_value());
  const auto view = chunks_within(w->spawn, 96, *w);
  ASSERT_TRUE(c.wait_until([&](const ClientView& v) { return all_covered(v.replica, view); }, kDeadline));
  c.disconnect();

  std::lock_guard lock(mu);
  // Every chunk of the view got its coarse form before any chunk went Full.
  std::set<std::tuple<int, int, int>> coarse;
  std::size_t first_full = events.size();
  for (std::size_t i = 0; i < events.size(); ++i) {
    const Event& e = events[i];
    if (!e.now) continue;  // released
    if (e.now->form == HoldingForm::kFull) {
      first_full = std::min(first_full, i);
      continue;
    }
    const bool is_coarse = e.now->form == HoldingForm::kEmpty || e.now->level() == 3;
    // (A later coarse record is a refresh: an estimate corrected.)
    if (is_coarse && coarse.insert({e.chunk.x, e.chunk.y, e.chunk.z}).second) {
      EXPECT_LT(i, first_full) << "coarse coverage after the first full chunk";
    }
  }
  for (const Vec3i cp : view) EXPECT_EQ(coarse.count({cp.x, cp.y, cp.z}), 1u);
  EXPECT_GT(view.size(), near.size());
  EXPECT_LT(first_full, events.size()) << "some chunk reached full resolution";
  // Distant chunks hold a mip, never full resolution.
  c.with_replica([&](const Replica& r) {
    for (const Vec3i cp : view) {
      if (within(w->spawn, cp, 64)) continue;
      const Holding* cov = r.holding(cp);
      EXPECT_TRUE(cov != nullptr && cov->form != HoldingForm::kFull);
    }
    return 0;
  });
}

// Client::coverage() answers for the view the client asked for: nothing
// before the Welcome, then the view rule's chunks, complete once each is
// held at its distance's level.
TEST_F(ClientServerTest, CoverageOfTheViewIsCompleteOnceStreamingHasSettled) {
  start_server();
  Client c(options("coverage", 96, 32));
  EXPECT_FALSE(c.coverage().has_value());
  const auto w = join(c);
  ASSERT_TRUE(w.has_value());
  const auto view = chunks_within(w->spawn, 96, *w);
  ASSERT_TRUE(c.wait_until(
      [&](const ClientView& v) { return v.closed || all_at_desired_level(v.replica, view, w->spawn, 32); }, kDeadline));
  const std::optional<StreamedView> asked = c.streamed_view();
  ASSERT_TRUE(asked.has_value());
  EXPECT_EQ(asked->view_distance, 96);
  EXPECT_EQ(asked->full_res_radius, 32);
  const std::optional<ViewCoverage> cov = c.coverage();
  ASSERT_TRUE(cov.has_value());
  EXPECT_EQ(cov->in_view, view.size());
  EXPECT_EQ(cov->not_held, 0u);
  EXPECT_TRUE(cov->complete);
  EXPECT_TRUE(cov->full_region_held());
  EXPECT_EQ(cov->want_full, chunks_within(w->spawn, 32, *w).size());
  EXPECT_EQ(cov->full + cov->empty + cov->mip1 + cov->mip2 + cov->mip3 + cov->estimate + cov->horizon, view.size());
  EXPECT_EQ(cov->horizon, 0u) << "a settled view holds no horizon image";
  c.disconnect();
}

TEST_F(ClientServerTest, EveryEditKindReplicatesExactly) {
  start_server({"--hash-push-ms", "0"});  // only the hashes asked for below
  Client a(options("a")), b(options("b"));
  std::string err;
  ASSERT_TRUE(a.connect(&err)) << err;
  ASSERT_TRUE(b.connect(&err)) << err;
  wait_full_res(a, 32);
  wait_full_res(b, 32);
  const auto w = a.welcome();
  ASSERT_TRUE(w.has_value());
  const Vec3f s = w->spawn;
  const Vec3f below{s.x, s.y - 3.0f, s.z};
  std::vector<Voxel> pattern;
  const Region wb{{static_cast<int>(s.x) - 6, static_cast<int>(s.y) - 4, static_cast<int>(s.z) + 3},
                  {static_cast<int>(s.x) - 1, static_cast<int>(s.y) + 1, static_cast<int>(s.z) + 7}};
  for (std::int64_t i = 0; i < wb.volume(); ++i)
    pattern.push_back(i % 4 == 0 ? Voxel{} : make_voxel(materials::kBrick, static_cast<std::uint8_t>(40 + i)));
  const std::vector<std::uint32_t> ids = {
      a.fill_sphere(below, 4.0f, materials::kSand), a.dig({s.x + 3.0f, s.y - 2.0f, s.z}, 3.0f),
      a.paint(below, 3.0f, materials::kSnow),       a.smooth({s.x + 1.5f, s.y - 2.0f, s.z}, 4.0f, 0.8f),
      a.write_box(wb, pattern)};
  for (const std::uint32_t id : ids) ASSERT_NE(id, 0u);
  ASSERT_TRUE(a.wait_until(
      [&](const ClientView& v) {
        return std::all_of(ids.begin(), ids.end(), [&](std::uint32_t id) { return v.edits.count(id) != 0; });
      },
      kDeadline));
  a.wait_until(
      [&](const ClientView& v) {
        for (const std::uint32_t id : ids)
          EXPECT_TRUE(v.edits.at(id).accepted) << "edit " << id << ": " << v.edits.at(id).reason;
        return true;
      },
      0ms);
  // The paint left snow, the write box its exact pattern (b's replica).
  const Vec3i bc{static_cast<int>(std::floor(below.x)), static_cast<int>(std::floor(below.y)),
                 static_cast<int>(std::floor(below.z))};
  std::vector<Vec3i> touched;
  for_each_chunk_in(Region{bc - Vec3i{12, 12, 12}, bc + Vec3i{12, 12, 12}}, [&](Vec3i cp) { touched.push_back(cp); });
  for (Client* cl : {&a, &b}) {
    for (const Vec3i cp : touched) ASSERT_TRUE(cl->request_chunk_hash(cp));
    ASSERT_TRUE(cl->wait_until([&](const ClientView& v) { return checked_all(v, touched); }, kDeadline));
    EXPECT_EQ(cl->counters().hash_mismatches, 0u);
  }
  EXPECT_EQ(b.get(bc).material, materials::kSnow);
  Box got(wb.size());
  b.read_box(wb.min, got);
  EXPECT_TRUE(std::equal(pattern.begin(), pattern.end(), got.voxels().begin()));
  // ReadBox through the server agrees with the replica.
  const std::uint32_t rid = b.request_read_box(wb);
  ASSERT_NE(rid, 0u);
  ASSERT_TRUE(b.wait_until([&](const ClientView& v) { return v.read_results.count(rid) != 0; }, kDeadline));
  b.wait_until(
      [&](const ClientView& v) {
        const ReadBoxResultMsg& r = v.read_results.at(rid);
        EXPECT_TRUE(r.error.empty()) << r.error;
        EXPECT_TRUE(r.voxels.size() == pattern.size() && std::equal(pattern.begin(), pattern.end(), r.voxels.begin()));
        return true;
      },
      0ms);
  a.disconnect();
  b.disconnect();
}

// Both ways a server tells presence: PresenceRecords (the library's
// default: positions in eighths of a voxel) and whole Presence lists (to a
// client that does not ask for records, or from a server run with
// --no-presence-records).
TEST_F(ClientServerTest, PresenceShowsTheOtherClient) {
  for (const char* way : {"records", "lists", "server-off"}) {
    SCOPED_TRACE(way);
    const bool records = std::string(way) == "records";
    std::vector<std::string> flags{"--presence-hz", "10"};
    if (std::string(way) == "server-off") flags.push_back("--no-presence-records");
    start_server(flags);
    ClientOptions ao = options("a");
    if (std::string(way) == "lists") ao.features &= ~kFeaturePresenceRecords;
    auto as_told = [&](Vec3f p) { return records ? presence_position(presence_eighths(p)) : p; };
    Client a(ao), b(options("b"));
    std::string err;
    ASSERT_TRUE(a.connect(&err)) << err;
    ASSERT_TRUE(b.connect(&err)) << err;
    wait_full_res(b, 32);
    ASSERT_TRUE(a.wait_until([](const ClientView& v) { return v.presence.size() == 1 || v.closed; }, kDeadline));
    const auto w = b.welcome();
    ASSERT_TRUE(w.has_value());
    EXPECT_EQ(a.presence().at(0).position, as_told(w->spawn));
    EXPECT_EQ(a.presence().at(0).name, "b");
    // b moves: its entry comes again without its name (told once, when it
    // entered a's list), and a's presence keeps the name.
    ClientStateMsg st = *b.last_state();
    st.position.x += 3.3f;
    ASSERT_TRUE(b.set_state(st));
    ASSERT_TRUE(a.wait_until(
        [&](const ClientView& v) {
          return (v.presence.size() == 1 && v.presence[0].position == as_told(st.position)) || v.closed;
        },
        kDeadline));
    EXPECT_EQ(a.presence().at(0).name, "b");
    // b leaves: a's list empties.
    b.disconnect();
    ASSERT_TRUE(a.wait_until([](const ClientView& v) { return v.presence.empty() || v.closed; }, kDeadline));
    EXPECT_FALSE(a.closed());
    const auto& by_type = a.counters().by_message_type;
    EXPECT_EQ(by_type[static_cast<std::size_t>(wire::Body::PresenceRecords)].frames_in != 0, records);
    EXPECT_EQ(by_type[static_cast<std::size_t>(wire::Body::Presence)].frames_in != 0, !records);
    a.disconnect();
    server_.reset();
  }
}

TEST_F(ClientServerTest, EditByOneClientReachesTheOther) {
  start_server({"--hash-push-ms", "0"});  // only the hashes asked for below
  Client a(options("a")), b(options("b"));
  std::string err;
  ASSERT_TRUE(a.connect(&err)) << err;
  ASSERT_TRUE(b.connect(&err)) << err;
  const auto near_a = wait_full_res(a, 32);
  const auto near_b = wait_full_res(b, 32);
  const auto w = a.welcome();
  ASSERT_TRUE(w.has_value());
  // A brick sphere just below spawn, and a glass-clear box dug beside it.
  const Vec3f centre{w->spawn.x, w->spawn.y - 4.0f, w->spawn.z};
  const std::uint32_t s = a.fill_sphere(centre, 5.5f, materials::kBrick);
  const Vec3i corner{static_cast<int>(w->spawn.x) + 8, static_cast<int>(w->spawn.y) - 6, static_cast<int>(w->spawn.z)};
  const std::uint32_t d = a.fill_box(Region{corner, corner + Vec3i{4, 4, 4}}, Voxel{});
  ASSERT_NE(s, 0u);
  ASSERT_NE(d, 0u);
  ASSERT_TRUE(a.wait_until([&](const ClientView& v) { return v.edits.count(s) && v.edits.count(d); }, kDeadline));
  EXPECT_TRUE(a.wait_until([&](const ClientView& v) { return v.edits.at(s).accepted && v.edits.at(d).accepted; }, 0ms));
  const Vec3i c{static_cast<int>(std::floor(centre.x)), static_cast<int>(std::floor(centre.y)),
                static_cast<int>(std::floor(centre.z))};
  EXPECT_EQ(b.wait_until([&](const ClientView& v) { return v.replica.get(c).material == materials::kBrick; }, kDeadline),
            true);
  EXPECT_TRUE(b.wait_until([&](const ClientView& v) { return v.replica.get(corner).material == kAir; }, kDeadline));
  // Chunk hashes are answered after every update queued before them: once
  // both clients verified the touched chunks, both replicas are current.
  const Region area{c - Vec3i{8, 8, 8}, corner + Vec3i{8, 8, 8}};
  std::vector<Vec3i> touched;
  for_each_chunk_in(area, [&](Vec3i cp) { touched.push_back(cp); });
  for (Client* cl : {&a, &b}) {
    for (const Vec3i cp : touched) ASSERT_TRUE(cl->request_chunk_hash(cp));
    ASSERT_TRUE(cl->wait_until([&](const ClientView& v) { return checked_all(v, touched); }, kDeadline));
    EXPECT_EQ(cl->counters().hash_mismatches, 0u);
  }
  Box ra(area.size()), rb(area.size());
  a.read_box(area.min, ra);
  b.read_box(area.min, rb);
  EXPECT_TRUE(ra == rb);
  a.disconnect();
  b.disconnect();
  ASSERT_EQ(server_->stop(), 0) << server_->output();
  expect_replica_matches_world(a, near_a, dir_.string());
  expect_replica_matches_world(b, near_b, dir_.string());
}

bool fill_acknowledged(Client& c, const Region& box, Voxel v);

// on_chunks_loaded names each chunk as it first becomes held at full
// resolution: every chunk of the full-resolution region, once.
TEST_F(ClientServerTest, ChunksLoadedNamesEachChunkOnceAsItReachesFullResolution) {
  start_server();
  std::mutex mu;
  std::condition_variable cv;
  std::vector<Vec3i> loaded;
  ClientCallbacks cb;
  cb.on_chunks_loaded = [&](const std::vector<Vec3i>& chunks) {
    EXPECT_FALSE(chunks.empty());
    std::lock_guard lock(mu);
    loaded.insert(loaded.end(), chunks.begin(), chunks.end());
    cv.notify_all();
  };
  Client c(options("loaded"), cb);
  std::string err;
  ASSERT_TRUE(c.connect(&err)) << err;
  const auto near = wait_full_res(c, 32);
  ASSERT_FALSE(near.empty());
  std::unique_lock lock(mu);
  const auto has = [&](Vec3i cp) { return std::find(loaded.begin(), loaded.end(), cp) != loaded.end(); };
  ASSERT_TRUE(cv.wait_for(lock, kDeadline, [&] { return std::all_of(near.begin(), near.end(), has); }));
  std::set<std::tuple<int, int, int>> once;
  for (const Vec3i cp : loaded) EXPECT_TRUE(once.insert({cp.x, cp.y, cp.z}).second) << "a chunk loaded twice";
  const std::vector<Vec3i> all = loaded;
  lock.unlock();
  EXPECT_TRUE(c.with_replica([&](const Replica& r) { return all_full(r, all); }));
  c.disconnect();
}

// With capture_voxel_changes on, on_update carries each voxel an edit
// changed as the replica held it before and after; off, none.
TEST_F(ClientServerTest, UpdatesCarryTheVoxelsTheyChangedOnceAsked) {
  start_server();
  std::mutex mu;
  std::condition_variable cv;
  std::vector<UpdateInfo> updates;
  ClientCallbacks cb;
  cb.on_update = [&](const UpdateInfo& u) {
    std::lock_guard lock(mu);
    updates.push_back(u);
    cv.notify_all();
  };
  Client c(options("changes"), cb);
  std::string err;
  ASSERT_TRUE(c.connect(&err)) << err;
  wait_full_res(c, 32);
  const auto w = c.welcome();
  ASSERT_TRUE(w.has_value());
  // 2^3 voxels a little below spawn, inside one chunk.
  const Vec3i s{static_cast<int>(std::floor(w->spawn.x)), static_cast<int>(std::floor(w->spawn.y)) - 4,
                static_cast<int>(std::floor(w->spawn.z))};
  const Vec3i p = chunk_origin(chunk_of(s)) + Vec3i{8, 8, 8};
  const Region box{p, p + Vec3i{2, 2, 2}};
  Box before(box.size());
  c.read_box(box.min, before);
  const Voxel brick = solid(materials::kBrick);
  c.capture_voxel_changes(1000);
  ASSERT_TRUE(fill_acknowledged(c, box, brick));
  std::unique_lock lock(mu);
  const auto recorded = [&] {
    return std::find_if(updates.begin(), updates.end(), [](const UpdateInfo& u) { return !u.voxels.empty(); });
  };
  ASSERT_TRUE(cv.wait_for(lock, kDeadline, [&] { return recorded() != updates.end(); }));
  const UpdateInfo u = *recorded();
  EXPECT_TRUE(u.voxels_recorded);
  EXPECT_FALSE(u.voxels_truncated);
  std::size_t expected = 0;
  for (int y = 0; y < 2; ++y)
    for (int z = 0; z < 2; ++z)
      for (int x = 0; x < 2; ++x) expected += before.get(x, y, z) != brick;
  EXPECT_EQ(u.voxels.size(), expected);
  for (const VoxelChange& v : u.voxels) {
    const Vec3i l = v.voxel_pos - box.min;
    EXPECT_EQ(v.before, before.get(l.x, l.y, l.z));
    EXPECT_EQ(v.after, brick);
  }
  // Off again: the next update records nothing.
  lock.unlock();
  c.capture_voxel_changes(0);
  const std::size_t seen = [&] {
    std::lock_guard l(mu);
    return updates.size();
  }();
  ASSERT_TRUE(fill_acknowledged(c, box, solid(materials::kRock)));
  lock.lock();
  ASSERT_TRUE(cv.wait_for(lock, kDeadline, [&] { return updates.size() > seen; }));
  EXPECT_FALSE(updates.back().voxels_recorded);
  EXPECT_TRUE(updates.back().voxels.empty());
  lock.unlock();
  c.disconnect();
}

TEST_F(ClientServerTest, DroppedUpdateIsDetectedByChunkHash) {
  start_server({"--test-drop-updates", "1", "--hash-push-ms", "0"});
  Client a(options("a"));
  std::string err;
  ASSERT_TRUE(a.connect(&err)) << err;
  wait_full_res(a, 32);
  const auto w = a.welcome();
  ASSERT_TRUE(w.has_value());
  Vec3i p{static_cast<int>(w->spawn.x), static_cast<int>(w->spawn.y) - 3, static_cast<int>(w->spawn.z)};
  if (floor_mod(p.y, kChunkSize) == kChunkSize - 1) --p.y;  // keep the edit inside one chunk
  const std::uint32_t id = a.fill_box(Region{p, p + Vec3i{2, 2, 2}}, solid(materials::kSnow));
  ASSERT_TRUE(a.wait_until([&](const ClientView& v) { return v.edits.count(id) != 0; }, kDeadline));
  const Vec3i cp = chunk_of(p);
  ASSERT_TRUE(a.request_chunk_hash(cp));
  ASSERT_TRUE(a.wait_until([&](const ClientView& v) { return v.hash_checks.count(cp) != 0; }, kDeadline));
  EXPECT_EQ(a.counters().hash_mismatches, 1u);
  EXPECT_EQ(a.counters().update_batches, 0u);
}

// A paused server (SIGSTOP: its socket stays open, nothing comes back) is
// noticed by the silence timeout, not waited out; an edit sent to it ends
// with an unknown outcome when the connection closes.
TEST_F(ClientServerTest, ASilentServerIsNoticedAndItsUnansweredEditsEndUnknown) {
  start_server();
  ClientOptions o = options("patient");
  o.keepalive = 200ms;
  o.silence_timeout = 1000ms;
  Client c(o);
  ASSERT_TRUE(join(c).has_value());
  const auto near = wait_full_res(c, 32);
  ASSERT_FALSE(near.empty());
  ASSERT_FALSE(c.closed()) << c.disconnect_reason();
  const Vec3f spawn = c.welcome()->spawn;
  const Vec3i at{static_cast<std::int32_t>(std::floor(spawn.x)), static_cast<std::int32_t>(std::floor(spawn.y)),
                 static_cast<std::int32_t>(std::floor(spawn.z))};
  ASSERT_TRUE(server_->pause());
  const std::uint32_t id = c.fill_box(Region{at, at + Vec3i{1, 1, 1}}, solid(materials::kBrick));
  ASSERT_NE(id, 0u);
  const auto paused_at = std::chrono::steady_clock::now();
  EXPECT_TRUE(c.wait_until([](const ClientView& v) { return v.closed; }, kDeadline));
  const double waited = std::chrono::duration<double>(std::chrono::steady_clock::now() - paused_at).count();
  ASSERT_TRUE(server_->resume());
  EXPECT_NE(c.disconnect_reason().find("no answer from the server for"), std::string::npos) << c.disconnect_reason();
  EXPECT_LT(waited, 10.0) << "noticed only after " << waited << " s";
  std::optional<EditOutcome> outcome;
  c.wait_until(
      [&](const ClientView& v) {
        if (auto it = v.edits.find(id); it != v.edits.end()) outcome = it->second;
        return true;
      },
      0ms);
  ASSERT_TRUE(outcome.has_value()) << "the edit has no outcome after the close";
  EXPECT_FALSE(outcome->accepted);
  EXPECT_EQ(outcome->reason, kEditOutcomeUnknown);
}

TEST_F(ClientServerTest, MalformedFramesDisconnectOnlyTheirSender) {
  start_server();
  Client good(options("good")), garbage(options("garbage")), huge(options("huge"));
  ClientOptions oo = options("old");
  oo.protocol_version = kProtocolVersion + 1;
  Client wrong_version(oo);
  std::string err;
  for (Client* c : {&good, &garbage, &huge, &wrong_version}) ASSERT_TRUE(c->connect(&err)) << err;
  for (Client* c : {&good, &garbage, &huge})
    ASSERT_TRUE(c->wait_until([](const ClientView& v) { return v.welcomed; }, kDeadline));
  // A frame whose body is not a FlatBuffer Message.
  Frame junk;
  const std::uint8_t body[16] = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16};
  append_frame(body, junk);
  ASSERT_TRUE(garbage.send_raw(junk));
  // A length far over the maximum frame size.
  ASSERT_TRUE(huge.send_raw(Frame{0xff, 0xff, 0xff, 0x7f}));
  for (Client* c : {&garbage, &huge, &wrong_version})
    ASSERT_TRUE(c->wait_until([](const ClientView& v) { return v.closed; }, kDeadline));
  EXPECT_NE(garbage.disconnect_reason().find("protocol error"), std::string::npos) << garbage.disconnect_reason();
  EXPECT_NE(huge.disconnect_reason().find("protocol error"), std::string::npos) << huge.disconnect_reason();
  EXPECT_NE(wrong_version.disconnect_reason().find("is not supported: this server speaks version 2"), std::string::npos)
      << wrong_version.disconnect_reason();
  // The good client is still served.
  ASSERT_TRUE(good.ping(7));
  EXPECT_TRUE(good.wait_until([](const ClientView& v) { return v.counters.pongs == 1 || v.closed; }, kDeadline));
  EXPECT_FALSE(good.closed());
}

TEST_F(ClientServerTest, ClientThatStopsReadingIsDroppedWithoutStallingOthers) {
  start_server({"--write-timeout-ms", "1000", "--socket-send-buffer", "16384"});
  // A raw connection that handshakes, asks for a large view, then reads nothing.
  asio::io_context io;
  asio::ip::tcp::socket slow(io);
  slow.open(asio::ip::tcp::v4());
  slow.set_option(asio::socket_base::receive_buffer_size(4096));
  slow.connect({asio::ip::make_address("127.0.0.1"), server_->port()});
  Frame hello = build_hello(HelloMsg{kProtocolVersion, "slow", "", {}});
  Frame state = build_client_state(ClientStateMsg{{0.5f, 40.0f, 0.5f}, 256, 128});
  asio::write(slow, asio::buffer(hello));
  asio::write(slow, asio::buffer(state));

  Client good(options("good"));
  std::string err;
  ASSERT_TRUE(good.connect(&err)) << err;
  wait_full_res(good, 32);
  ASSERT_FALSE(good.closed());
  ASSERT_TRUE(server_->wait_for_output("too slow", kDeadline)) << "the stalled client was never dropped";

  // Now read: whatever was in flight, then (if it made it) the reason, then the end.
  FrameReader reader;
  std::string reason;
  std::vector<std::uint8_t> buf(64 * 1024);
  asio::error_code ec;
  while (!ec) {
    const std::size_t n = slow.read_some(asio::buffer(buf), ec);
    const auto st = reader.feed(std::span<const std::uint8_t>(buf.data(), n), [&](std::span<const std::uint8_t> body) {
      auto m = verify_message(body);
      ASSERT_TRUE(m.ok());
      if ((*m)->body_type() == wire::Body::Disconnect) reason = parse_disconnect(*(*m)->body_as_Disconnect()).value();
    });
    ASSERT_TRUE(st.ok());
  }
  if (!reason.empty()) {
    EXPECT_NE(reason.find("too slow"), std::string::npos) << reason;
  }
  // The other client is still served.
  ASSERT_TRUE(good.ping(1));
  EXPECT_TRUE(good.wait_until([](const ClientView& v) { return v.counters.pongs == 1 || v.closed; }, kDeadline));
  EXPECT_FALSE(good.closed());
}

TEST_F(ClientServerTest, CorruptedUpdateIsDetectedByChunkHash) {
  start_server({"--test-corrupt-updates", "1", "--hash-push-ms", "0"});
  Client a(options("a"));
  std::string err;
  ASSERT_TRUE(a.connect(&err)) << err;
  wait_full_res(a, 32);
  const auto w = a.welcome();
  ASSERT_TRUE(w.has_value());
  Vec3i p{static_cast<int>(w->spawn.x), static_cast<int>(w->spawn.y) - 3, static_cast<int>(w->spawn.z)};
  if (floor_mod(p.y, kChunkSize) == kChunkSize - 1) --p.y;  // keep the edit inside one chunk
  const std::uint32_t id = a.fill_box(Region{p, p + Vec3i{2, 2, 2}}, solid(materials::kSnow));
  ASSERT_TRUE(a.wait_until([&](const ClientView& v) { return v.edits.count(id) != 0; }, kDeadline));
  const Vec3i cp = chunk_of(p);
  ASSERT_TRUE(a.request_chunk_hash(cp));
  ASSERT_TRUE(a.wait_until([&](const ClientView& v) { return v.hash_checks.count(cp) != 0; }, kDeadline));
  EXPECT_EQ(a.counters().update_batches, 1u);  // the batch arrived and decoded fine
  EXPECT_EQ(a.counters().hash_mismatches, 1u);
}

TEST_F(ClientServerTest, PushedChunkHashesCatchACorruptedUpdateUnasked) {
  start_server({"--test-corrupt-updates", "1", "--hash-push-ms", "50"});
  std::vector<Vec3i> bad;
  std::mutex m;
  ClientCallbacks cb;
  cb.on_hash_checked = [&](Vec3i cp, bool match) {
    std::lock_guard lock(m);
    if (!match) bad.push_back(cp);
  };
  Client a(options("a", 64, 32), cb);
  std::string err;
  ASSERT_TRUE(a.connect(&err)) << err;
  wait_full_res(a, 32);
  const auto w = a.welcome();
  ASSERT_TRUE(w.has_value());
  Vec3i p{static_cast<int>(w->spawn.x), static_cast<int>(w->spawn.y) - 3, static_cast<int>(w->spawn.z)};
  if (floor_mod(p.y, kChunkSize) == kChunkSize - 1) --p.y;
  const std::uint32_t id = a.fill_box(Region{p, p + Vec3i{2, 2, 2}}, solid(materials::kSnow));
  ASSERT_TRUE(a.wait_until([&](const ClientView& v) { return v.edits.count(id) != 0; }, kDeadline));
  // The server cycles through the client's full-resolution chunks; the
  // corrupted one is named within one cycle.
  ASSERT_TRUE(a.wait_until(
      [&](const ClientView& v) {
        std::lock_guard lock(m);  // the callback runs without the client's lock
        return !bad.empty() || v.closed;
      },
      kDeadline));
  std::lock_guard lock(m);
  ASSERT_FALSE(bad.empty());
  EXPECT_EQ(bad.front(), chunk_of(p));
}

TEST_F(ClientServerTest, ClientReconnectsAfterARestartAndResumesItsReplica) {
  start_server();
  const std::uint16_t port = server_->port();
  ClientOptions o = options("phoenix", 96, 32);
  o.reconnect = true;
  o.reconnect_min = 50ms;
  std::atomic<int> lost{0}, back{0};
  ClientCallbacks cb;
  cb.on_connection_lost = [&](const std::string&) { ++lost; };
  cb.on_reconnected = [&] { ++back; };
  Client c(o, cb);
  std::string err;
  ASSERT_TRUE(c.connect(&err)) << err;
  const auto near = wait_full_res(c, 32);
  // Everything in view streamed: what a fresh join costs.
  const auto w = c.welcome();
  ASSERT_TRUE(w.has_value());
  const auto in_view = chunks_within(w->spawn, 96, *w);
  // ... and refined: every chunk at the level the view rule promises.
  ASSERT_TRUE(c.wait_until(
      [&](const ClientView& v) { return v.closed || all_at_desired_level(v.replica, in_view, w->spawn, 32); },
      kDeadline));
  const std::uint64_t first_bytes = c.counters().bytes_in;

  // The server goes away and comes back on the same port and world.
  ASSERT_EQ(server_->stop(), 0);
  server_ = std::make_unique<ServerProcess>(dir_.string(), std::vector<std::string>{"--port", std::to_string(port)});
  ASSERT_EQ(server_->port(), port) << server_->output();
  ASSERT_TRUE(c.wait_until([&](const ClientView& v) { return v.counters.reconnects == 1 || v.closed; }, kDeadline));
  ASSERT_FALSE(c.closed()) << c.disconnect_reason();
  // Verified after the restart: every full-resolution chunk matches.
  ASSERT_TRUE(c.wait_until([&](const ClientView&) { return back.load() == 1; }, kDeadline));
  expect_verified(c, near);
  // Nothing was streamed again: the second connection cost a small
  // fraction of the first.
  const std::uint64_t resumed_bytes = c.counters().bytes_in - first_bytes;
  EXPECT_LT(resumed_bytes * 10, first_bytes) << resumed_bytes << " bytes after the reconnect vs " << first_bytes;
  EXPECT_EQ(lost.load(), 1);
  // And edits work on the new connection.
  const Vec3i p{static_cast<int>(w->spawn.x), static_cast<int>(w->spawn.y) - 2, static_cast<int>(w->spawn.z)};
  const std::uint32_t id = c.fill_box(Region{p, p + Vec3i{1, 1, 1}}, solid(materials::kBrick));
  ASSERT_TRUE(c.wait_until([&](const ClientView& v) { return v.edits.count(id) != 0 || v.closed; }, kDeadline));
  c.disconnect();
}

// A client in a new process joins from its chunk cache: the world's id
// finds the chunks kept, they are claimed region by region, and the server
// sends only what changed since (an edited chunk again, at its new
// revision); the replica then matches the server chunk for chunk.
TEST_F(ClientServerTest, ARejoinFromTheChunkCacheIsSentOnlyWhatChanged) {
  start_server({"--hash-push-ms", "0"});
  const fs::path cache_dir = dir_.string() + "-cache";
  fs::remove_all(cache_dir);
  auto cache = ChunkCache::open(cache_dir.string(), 64u << 20);
  ASSERT_TRUE(cache.ok());
  std::optional<WelcomeMsg> w;
  std::uint64_t cold_bytes = 0;
  std::vector<Vec3i> in_view;
  {
    Client c(options_cached("first", 128, *cache));
    w = join(c);
    ASSERT_TRUE(w.has_value());
    ASSERT_NE(w->world_id, 0u);
    in_view = chunks_within(w->spawn, 128, *w);
    ASSERT_TRUE(c.wait_until(
        [&](const ClientView& v) { return v.closed || all_at_desired_level(v.replica, in_view, w->spawn, 32); },
        kDeadline));
    cold_bytes = c.counters().bytes_in;
    c.disconnect();
    EXPECT_GE(c.counters().cache_chunks_saved, in_view.size());
  }
  // Another client changes a chunk near the spawn meanwhile.
  const Vec3i p{static_cast<int>(w->spawn.x), static_cast<int>(w->spawn.y) - 2, static_cast<int>(w->spawn.z)};
  const Vec3i edited = chunk_of(p);
  std::uint64_t edited_revision = 0;
  {
    Client e(options("editor", 32, 32));
    ASSERT_TRUE(join(e).has_value());
    wait_full_res(e, 32);
    const std::uint32_t id = e.fill_box(Region{p, p + Vec3i{2, 2, 2}}, solid(materials::kBrick));
    ASSERT_TRUE(e.wait_until([&](const ClientView& v) { return v.edits.count(id) != 0 || v.closed; }, kDeadline));
    ASSERT_TRUE(e.wait_until([&](const ClientView& v) { return v.replica.get(p) == solid(materials::kBrick) || v.closed; }, kDeadline));
    edited_revision = *e.with_replica([&](const Replica& r) { return r.revision(edited); });
    e.disconnect();
  }
  {
    Client c(options_cached("again", 128, *cache));
    ASSERT_TRUE(join(c).has_value());
    // A position set while the cache loads waits for its claims: sent
    // before them, it would have the server stream the whole view (the
    // bytes below).
    ASSERT_TRUE(c.set_state(ClientStateMsg{w->spawn, 128, 32}));
    // Loaded on the cache's threads, then claimed.
    ASSERT_TRUE(c.wait_until([&](const ClientView& v) { return v.closed || v.counters.cache_chunks_loaded > 0; }, kDeadline));
    EXPECT_GE(c.counters().cache_chunks_loaded, in_view.size());
    ASSERT_TRUE(c.wait_until(
        [&](const ClientView& v) {
          return v.closed || (all_at_desired_level(v.replica, in_view, w->spawn, 32) && v.replica.get(p) == solid(materials::kBrick));
        },
        kDeadline));
    EXPECT_EQ(*c.with_replica([&](const Replica& r) { return r.revision(edited); }), edited_revision);
    const auto near = chunks_within(w->spawn, 32, *w);
    expect_verified(c, near);
    // The claims' answer is a small part of a cold join.
    EXPECT_LT(c.counters().bytes_in * 10, cold_bytes) << c.counters().bytes_in << " bytes rejoining vs " << cold_bytes;
    c.disconnect();
  }
  fs::remove_all(cache_dir);
}

// The cache is keyed by the world's id: another world (a server on a new
// directory) takes nothing from it, and a file that does not read back is
// a miss, streamed again.
TEST_F(ClientServerTest, AChunkCacheIsUsedOnlyForItsOwnWorldAndWhole) {
  start_server();
  const fs::path cache_dir = dir_.string() + "-cache";
  fs::remove_all(cache_dir);
  auto cache = ChunkCache::open(cache_dir.string(), 64u << 20);
  ASSERT_TRUE(cache.ok());
  std::uint64_t first_id = 0;
  {
    Client c(options_cached("first", 96, *cache));
    const auto w = join(c);
    ASSERT_TRUE(w.has_value());
    first_id = w->world_id;
    const auto in_view = chunks_within(w->spawn, 96, *w);
    ASSERT_TRUE(c.wait_until(
        [&](const ClientView& v) { return v.closed || all_at_desired_level(v.replica, in_view, w->spawn, 32); },
        kDeadline));
    c.disconnect();
  }
  // The same world again after a restart: the same id. One file damaged.
  ASSERT_EQ(server_->stop(), 0);
  server_ = std::make_unique<ServerProcess>(dir_.string(), std::vector<std::string>{});
  std::vector<fs::path> files;
  for (const auto& e : fs::recursive_directory_iterator(cache_dir))
    if (e.path().extension() == ".region") files.push_back(e.path());
  ASSERT_GE(files.size(), 2u);
  {
    std::fstream f(files.front(), std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(static_cast<std::streamoff>(ChunkCache::kHeaderBytes + 5));
    f.put('\x5a');
  }
  {
    Client c(options_cached("again", 96, *cache));
    const auto w = join(c);
    ASSERT_TRUE(w.has_value());
    EXPECT_EQ(w->world_id, first_id);
    ASSERT_TRUE(c.wait_until([&](const ClientView& v) { return v.closed || v.counters.cache_chunks_loaded > 0; }, kDeadline));
    EXPECT_EQ((*cache)->counters().regions_damaged, 1u);
    const auto near = chunks_within(w->spawn, 32, *w);
    ASSERT_TRUE(c.wait_until([&](const ClientView& v) { return v.closed || all_full(v.replica, near); }, kDeadline));
    expect_verified(c, near);
    c.disconnect();
  }
  // Another world: a new id, nothing loaded.
  ASSERT_EQ(server_->stop(), 0);
  server_ = std::make_unique<ServerProcess>(dir_.string() + "-other", std::vector<std::string>{});
  {
    Client c(options_cached("elsewhere", 96, *cache));
    const auto w = join(c);
    ASSERT_TRUE(w.has_value());
    EXPECT_NE(w->world_id, first_id);
    // The position goes once the load is done: chunks streamed mean it is.
    const auto near = chunks_within(w->spawn, 32, *w);
    ASSERT_TRUE(c.wait_until([&](const ClientView& v) { return v.closed || all_full(v.replica, near); }, kDeadline));
    EXPECT_EQ(c.counters().cache_chunks_loaded, 0u);
    c.disconnect();
  }
  ASSERT_EQ(server_->stop(), 0);
  server_.reset();
  fs::remove_all(dir_.string() + "-other");
  fs::remove_all(cache_dir);
}

// A client that reconnects to another world on the same address (the
// operator swapped it) has chunks of the old one: its claims name the old
// world's id, which the new server ignores, and the client drops them on the
// new Welcome. Here both worlds hold the chunk at the spawn at one revision
// with different voxels: taken as held, the old voxels would stay.
TEST_F(ClientServerTest, AReconnectToAnotherWorldDropsTheOldWorldsChunks) {
  const std::string world_b = dir_.string() + "-b";
  fs::remove_all(world_b);
  Vec3i p;
  auto edit = [&](const std::string& world, Voxel v) {
    server_ = std::make_unique<ServerProcess>(world, std::vector<std::string>{});
    ASSERT_NE(server_->port(), 0);
    Client e(options("editor", 32, 32));
    const auto w = join(e);
    ASSERT_TRUE(w.has_value());
    p = Vec3i{static_cast<int>(w->spawn.x), static_cast<int>(w->spawn.y) - 2, static_cast<int>(w->spawn.z)};
    wait_full_res(e, 32);
    const std::uint32_t id = e.fill_box(Region{p, p + Vec3i{1, 1, 1}}, v);
    ASSERT_TRUE(e.wait_until([&](const ClientView& cv) { return cv.edits.count(id) != 0 || cv.closed; }, kDeadline));
    e.disconnect();
    ASSERT_EQ(server_->stop(), 0);
  };
  edit(dir_.string(), solid(materials::kBrick));
  edit(world_b, solid(materials::kSnow));
  server_ = std::make_unique<ServerProcess>(dir_.string(), std::vector<std::string>{});
  const std::uint16_t port = server_->port();
  ClientOptions o = options("traveller", 64, 32);
  o.reconnect = true;
  o.reconnect_min = 50ms;
  Client c(o);
  const auto w = join(c);
  ASSERT_TRUE(w.has_value());
  const auto near = wait_full_res(c, 32);
  ASSERT_TRUE(c.wait_until([&](const ClientView& v) { return v.closed || v.replica.get(p) == solid(materials::kBrick); }, kDeadline));
  const auto old_revision = c.with_replica([&](const Replica& r) { return r.revision(chunk_of(p)); });

  ASSERT_EQ(server_->stop(), 0);
  server_ = std::make_unique<ServerProcess>(world_b, std::vector<std::string>{"--port", std::to_string(port)});
  ASSERT_EQ(server_->port(), port) << server_->output();
  ASSERT_TRUE(c.wait_until([&](const ClientView& v) { return v.counters.reconnects == 1 || v.closed; }, kDeadline));
  ASSERT_TRUE(c.wait_until([&](const ClientView& v) { return v.closed || (v.sessions == 2 && v.replica.get(p) == solid(materials::kSnow)); }, kDeadline))
      << "the old world's voxel stayed";
  EXPECT_EQ(c.with_replica([&](const Replica& r) { return r.revision(chunk_of(p)); }), old_revision);
  ASSERT_TRUE(c.wait_until([&](const ClientView& v) { return v.closed || all_full(v.replica, near); }, kDeadline));
  expect_verified(c, near);
  c.disconnect();
  ASSERT_EQ(server_->stop(), 0);
  server_.reset();
  fs::remove_all(world_b);
}

TEST_F(ClientServerTest, MovingReleasesOldChunksAndStreamsNewOnes) {
  start_server({"--max-speed", "0"});  // it jumps
  Client c(options("walker"));
  std::string err;
  ASSERT_TRUE(c.connect(&err)) << err;
  const auto old_near = wait_full_res(c, 32);
  const auto w = c.welcome();
  ASSERT_TRUE(w.has_value());
  const Vec3f there{w->spawn.x + 256.0f, w->spawn.y, w->spawn.z};
  ASSERT_TRUE(c.set_state(ClientStateMsg{there, 64, 32}));
  const auto new_near = chunks_within(there, 32, *w);
  ASSERT_TRUE(c.wait_until(
      [&](const ClientView& v) {
        for (const Vec3i cp : old_near)
          if (v.replica.holding(cp) != nullptr) return v.closed;
        return v.closed || all_full(v.replica, new_near);
      },
      kDeadline));
  EXPECT_FALSE(c.closed()) << c.disconnect_reason();
  EXPECT_GT(c.counters().released, 0u);
  EXPECT_EQ(c.resolution_at(chunk_origin(old_near.front())), kNoResolution);
}

// The chunk wholly 32 to 64 voxels above the spawn, sky in the default
// world; waits until c (near the spawn, full resolution beyond 64) holds it
// as Empty. nullopt if it never does.
std::optional<Vec3i> sky_above_spawn(Client& c) {
  if (!c.wait_until([](const ClientView& v) { return v.welcomed || v.closed; }, kDeadline)) return std::nullopt;
  const auto w = c.welcome();
  if (!w) return std::nullopt;
  const Vec3i target = view_chunk(w->spawn) + Vec3i{0, 2, 0};
  const bool sky = c.wait_until(
      [&](const ClientView& v) {
        const Holding* cov = v.replica.holding(target);
        return v.closed || (cov != nullptr && cov->form == HoldingForm::kEmpty);
      },
      kDeadline);
  if (!sky || c.closed()) return std::nullopt;
  return target;
}

// Waits until c holds the chunk as Empty (exact, not an estimate); its
// revision then, or nullopt.
std::optional<std::uint64_t> held_empty_revision(Client& c, Vec3i chunk_pos) {
  std::uint64_t revision = 0;
  const bool held = c.wait_until(
      [&](const ClientView& v) {
        const Holding* cov = v.replica.holding(chunk_pos);
        if (cov == nullptr || cov->form != HoldingForm::kEmpty) return v.closed;
        revision = cov->revision;
        return true;
      },
      kDeadline);
  if (!held || c.closed()) return std::nullopt;
  return revision;
}

// Fills box with v through c; true once the edit is acknowledged.
bool fill_acknowledged(Client& c, const Region& box, Voxel v) {
  const std::uint32_t id = c.fill_box(box, v);
  bool accepted = false;
  const bool answered = c.wait_until(
      [&](const ClientView& view) {
        auto it = view.edits.find(id);
        if (it == view.edits.end()) return view.closed;
        accepted = it->second.accepted;
        return true;
      },
      kDeadline);
  return answered && accepted;
}

TEST_F(ClientServerTest, ChunksThatLeaveTheViewAndComeBackBeforeTheyAreSentAreStillSent) {
  // Streaming held back (16 KiB/s), so chunks granted to the client wait
  // to be sent: the client jumps away and straight back, and every chunk
  // of its view must still arrive at its level (none is passed over as
  // already asked for, none kept registered with the world unsent).
  start_server({"--max-speed", "0", "--outbound-bytes-per-second", "16384"});
  Client c(options("jumper", 48, 16));
  const auto w = join(c);
  ASSERT_TRUE(w.has_value());
  // Refinement under way: some chunk is at full resolution already.
  ASSERT_TRUE(c.wait_until(
      [](const ClientView& v) { return v.closed || v.replica.chunk_count(HoldingForm::kFull) > 0; }, kDeadline));
  const Vec3f away{w->spawn.x + 1024.0f, w->spawn.y, w->spawn.z};
  ASSERT_TRUE(c.set_state(ClientStateMsg{away, 48, 16}));
  ASSERT_TRUE(c.set_state(ClientStateMsg{w->spawn, 48, 16}));
  const auto view = chunks_within(w->spawn, 48, *w);
  EXPECT_TRUE(c.wait_until(
      [&](const ClientView& v) { return v.closed || all_at_desired_level(v.replica, view, w->spawn, 16); }, kDeadline));
  EXPECT_FALSE(c.closed()) << c.disconnect_reason();
  std::size_t missing = 0;
  c.with_replica([&](const Replica& r) {
    for (const Vec3i cp : view) missing += r.holding(cp) == nullptr ? 1 : 0;
  });
  EXPECT_EQ(missing, 0u) << "chunks of the view never sent";
}

// Chunks the replica has only from a horizon image.
std::size_t horizon_only(const Replica& r) {
  std::size_t n = 0;
  r.for_each_holding([&](Vec3i, const Holding& c) { n += c.horizon(); });
  return n;
}

TEST_F(ClientServerTest, TheWholeViewArrivesAsHorizonImagesBeforeAnyChunkOfItsOwn) {
  start_server();
  std::mutex mu;
  std::vector<std::pair<Vec3i, int>> events;  // (chunk, level: 0 Full or Empty, 1..5 a mip)
  std::size_t released = 0;
  ClientCallbacks cb;
  cb.on_holding = [&](Vec3i p, const Holding* now) {
    std::lock_guard lock(mu);
    if (now == nullptr)
      ++released;
    else
      events.emplace_back(p, now->level());
  };
  // The same changes told once a batch, after on_holding's.
  std::vector<std::pair<Vec3i, int>> batched;
  std::size_t batched_released = 0, batches = 0, largest = 0;
  cb.on_holdings = [&](std::span<const HoldingChange> changes) {
    std::lock_guard lock(mu);
    ++batches;
    largest = std::max(largest, changes.size());
    for (const HoldingChange& c : changes) {
      if (c.now)
        batched.emplace_back(c.chunk_pos, c.now->level());
      else
        ++batched_released;
    }
    EXPECT_EQ(batched.size(), events.size()) << "on_holdings before on_holding told the batch";
  };
  // View 320 / 32: regions at 2^3 per chunk within 80 voxels, 1 voxel per
  // chunk beyond.
  Client c(options("horizon", 320, 32), cb);
  const auto w = join(c);
  ASSERT_TRUE(w.has_value());
  const auto view = chunks_within(w->spawn, 320, *w);
  ASSERT_TRUE(c.wait_until(
      [&](const ClientView& v) { return v.closed || all_at_desired_level(v.replica, view, w->spawn, 32); }, kDeadline));
  EXPECT_FALSE(c.closed()) << c.disconnect_reason();
  // Every chunk of the view came first as part of a horizon image, at the
  // level its distance gives, before any chunk's own record.
  std::lock_guard lock(mu);
  std::set<std::tuple<int, int, int>> seen;
  std::size_t horizon = 0;
  for (; horizon < events.size() && events[horizon].second > 3; ++horizon) {
    const auto [cp, level] = events[horizon];
    EXPECT_TRUE(seen.insert({cp.x, cp.y, cp.z}).second) << "a chunk covered twice by horizon images";
    EXPECT_TRUE(within(w->spawn, cp, 320)) << "a horizon image covered a chunk outside the view";
  }
  EXPECT_EQ(horizon, view.size()) << "the horizon images cover the whole view";
  // on_holdings told the same changes in the same order, many at once (a
  // horizon image alone covers up to 512 chunks).
  EXPECT_TRUE(batched == events);
  EXPECT_EQ(batched_released, released);
  EXPECT_LT(batches, events.size());
  EXPECT_GE(largest, 64u) << batches << " batches for " << events.size() << " changes";
  for (std::size_t i = horizon; i < events.size(); ++i) EXPECT_LE(events[i].second, 3) << "a horizon image after a chunk's own record";
  // Chunks within full resolution get it at once, not their 4^3 mip first.
  std::set<std::tuple<int, int, int>> first_own;
  for (std::size_t i = horizon; i < events.size(); ++i) {
    const auto [cp, level] = events[i];
    if (first_own.insert({cp.x, cp.y, cp.z}).second && within(w->spawn, cp, 32)) {
      EXPECT_EQ(level, 0) << "chunk (" << cp.x << "," << cp.y << "," << cp.z << ") within full resolution";
    }
  }
  const std::set<int> levels = [&] {
    std::set<int> l;
    for (std::size_t i = 0; i < horizon; ++i) l.insert(events[i].second);
    return l;
  }();
  EXPECT_EQ(levels, (std::set<int>{4, 5})) << "near regions at 2^3 per chunk, far ones at 1 voxel per chunk";
  // Then every chunk got its own data: nothing is left of the images.
  EXPECT_EQ(c.with_replica([](const Replica& r) { return horizon_only(r); }), 0u);
  EXPECT_EQ(c.counters().horizon_chunks, view.size());
}

TEST_F(ClientServerTest, ChunksSeenOnlyThroughAHorizonImageAreReleasedWhenTheyLeaveTheView) {
  // Streaming held back (4 KiB/s): most of the view is still known only
  // from its horizon images when the client jumps away; what it had of the
  // old view is released (none of it is in the new view), images included.
  start_server({"--max-speed", "0", "--outbound-bytes-per-second", "4096"});
  Client c(options("leaver", 320, 32));
  const auto w = join(c);
  ASSERT_TRUE(w.has_value());
  const auto view = chunks_within(w->spawn, 320, *w);
  ASSERT_TRUE(c.wait_until([&](const ClientView& v) { return v.closed || all_covered(v.replica, view); }, kDeadline));
  ASSERT_GT(c.with_replica([](const Replica& r) { return horizon_only(r); }), view.size() / 2)
      << "the premise: most of the view known only from horizon images";
  const Vec3f away{w->spawn.x + 4096.0f, w->spawn.y, w->spawn.z};
  ASSERT_TRUE(c.set_state(ClientStateMsg{away, 320, 32}));
  const auto outside = [&](const Replica& r) {
    std::size_t n = 0;
    r.for_each_holding([&](Vec3i cp, const Holding&) { n += within(away, cp, 320) ? 0 : 1; });
    return n;
  };
  EXPECT_TRUE(c.wait_until([&](const ClientView& v) { return v.closed || outside(v.replica) == 0; }, kDeadline))
      << c.with_replica(outside) << " chunks of the old view still held";
  EXPECT_FALSE(c.closed()) << c.disconnect_reason();
}

TEST_F(ClientServerTest, AFarHolderOfAnEmptyChunkLearnsItsNewRevisionWhenItIsEmptiedAgain) {
  // A chunk of sky that a far client holds as Empty is filled and emptied
  // again within one flush of mips: what the far client is sent still
  // carries the new revision.
  start_server();
  Client a(options("near", 192, 96));
  std::string err;
  ASSERT_TRUE(a.connect(&err)) << err;
  const auto target = sky_above_spawn(a);
  ASSERT_TRUE(target.has_value()) << "the premise: the chunk is sky";
  const auto welcome = a.welcome();
  Client b(options_at("far", Vec3f{welcome->spawn.x + 112.0f, welcome->spawn.y, welcome->spawn.z}, 192, 16));
  ASSERT_TRUE(b.connect(&err)) << err;
  const auto held = held_empty_revision(b, *target);
  ASSERT_TRUE(held.has_value()) << "the far client holds it as Empty";
  const std::uint64_t before = *held;
  const Vec3i o = chunk_origin(*target);
  const Region box{o + Vec3i{10, 10, 10}, o + Vec3i{14, 14, 14}};
  // Two ticks, well within one flush of mips (500 ms by default).
  const auto edit = [&](Voxel v) { return fill_acknowledged(a, box, v); };
  ASSERT_TRUE(edit(solid(materials::kBasalt)));
  ASSERT_TRUE(edit(Voxel{}));
  // Each edit, in a tick of its own, made a revision; the near client sees
  // both (its ack may come before the update: it is a control frame).
  const std::uint64_t server_revision = before + 2;
  ASSERT_TRUE(a.wait_until(
      [&](const ClientView& v) {
        const Holding* cov = v.replica.holding(*target);
        return cov != nullptr && cov->revision == server_revision;
      },
      kDeadline));
  EXPECT_TRUE(b.wait_until(
      [&](const ClientView& v) {
        const Holding* cov = v.replica.holding(*target);
        return cov != nullptr && cov->form == HoldingForm::kEmpty && cov->revision == server_revision;
      },
      kDeadline))
      << "the far client's revision stays behind the server's " << server_revision;
}

TEST_F(ClientServerTest, AnEmptyChunkThatChangedWhileFarIsSentWholeWhenItComesNear) {
  // A far client holds a chunk of sky as Empty. It is filled (the far
  // client's refresh waits for the next flush of mips, a minute here), and
  // the client comes near: the chunk is sent whole at once, so the client
  // may edit there and the next tick's units apply to what it holds. (Sent
  // the second fill's units alone, it lost the first fill for good.)
  start_server({"--max-speed", "0", "--mip-refresh-ms", "60000"});
  Client a(options("near", 192, 96));
  std::string err;
  ASSERT_TRUE(a.connect(&err)) << err;
  const auto sky = sky_above_spawn(a);
  ASSERT_TRUE(sky.has_value()) << "the premise: the chunk is sky";
  const Vec3i target = *sky;
  const auto welcome = a.welcome();
  Client b(options_at("far", Vec3f{welcome->spawn.x + 160.0f, welcome->spawn.y, welcome->spawn.z}, 256, 64));
  ASSERT_TRUE(b.connect(&err)) << err;
  const auto held = held_empty_revision(b, target);
  ASSERT_TRUE(held.has_value()) << "the far client holds it as Empty";
  const std::uint64_t before = *held;
  const auto edit = [&](const Region& box, Voxel v) { return fill_acknowledged(a, box, v); };
  const Vec3i o = chunk_origin(target);
  const Region first{o + Vec3i{2, 2, 2}, o + Vec3i{6, 6, 6}};
  const Region second{o + Vec3i{20, 20, 20}, o + Vec3i{24, 24, 24}};
  ASSERT_TRUE(edit(first, solid(materials::kBasalt)));
  // The client comes to the spawn, where the chunk is within its full
  // resolution; the chunks around the spawn reaching full resolution say
  // the server has its new position.
  ASSERT_TRUE(b.set_state(ClientStateMsg{welcome->spawn, 256, 64}));
  std::vector<Vec3i> near_spawn;
  for (const Vec3i cp : chunks_within(welcome->spawn, 32, *welcome))
    if (cp != target) near_spawn.push_back(cp);
  ASSERT_TRUE(b.wait_until([&](const ClientView& v) { return v.closed || all_full(v.replica, near_spawn); }, kDeadline));
  ASSERT_FALSE(b.closed()) << b.disconnect_reason();
  ASSERT_TRUE(b.wait_until(
      [&](const ClientView& v) {
        const Holding* cov = v.replica.holding(target);
        return v.closed || (cov != nullptr && cov->form == HoldingForm::kFull && cov->revision == before + 1);
      },
      kDeadline))
      << "the first fill did not reach the client that came near before the next flush of mips";
  EXPECT_EQ(b.with_replica([&](const Replica& r) { return r.get(o + Vec3i{3, 3, 3}); }).material, materials::kBasalt);
  ASSERT_TRUE(edit(second, solid(materials::kBrick)));
  ASSERT_TRUE(b.wait_until(
      [&](const ClientView& v) {
        const Holding* cov = v.replica.holding(target);
        return v.closed || (cov != nullptr && cov->form == HoldingForm::kFull && cov->revision == before + 2);
      },
      kDeadline));
  ASSERT_FALSE(b.closed()) << b.disconnect_reason();
  EXPECT_EQ(b.with_replica([&](const Replica& r) { return r.get(o + Vec3i{3, 3, 3}); }).material, materials::kBasalt)
      << "the first fill is missing from the far client's replica";
  EXPECT_EQ(b.with_replica([&](const Replica& r) { return r.get(o + Vec3i{21, 21, 21}); }).material, materials::kBrick);
  ASSERT_TRUE(b.request_chunk_hash(target));
  ASSERT_TRUE(b.wait_until([&](const ClientView& v) { return checked_all(v, {target}); }, kDeadline));
  EXPECT_EQ(b.counters().hash_mismatches, 0u);
}

TEST_F(ClientServerTest, MipHoldersGetTheRefreshedMipWholeOrAsAPatch) {
  start_server();
  Client a(options("near"));
  std::string err;
  ASSERT_TRUE(a.connect(&err)) << err;
  wait_full_res(a, 32);
  const auto w = a.welcome();
  ASSERT_TRUE(w.has_value());
  // B and C never stand near the edit: they hold the edited chunk as a mip.
  // B takes Mip patches (the library's default), C does not (Hello.features 0).
  ClientOptions ob = options("far", 192, 16);
  ob.start_at_spawn = false;
  ob.state.position = Vec3f{w->spawn.x + 112.0f, w->spawn.y, w->spawn.z};
  ClientOptions oc = ob;
  oc.name = "far-whole";
  oc.features = 0;
  Client b(ob), c(oc);
  ASSERT_TRUE(b.connect(&err)) << err;
  ASSERT_TRUE(c.connect(&err)) << err;
  const Vec3f centre{w->spawn.x, w->spawn.y - 3.0f, w->spawn.z};
  const Vec3i target = chunk_of(Vec3i{static_cast<int>(std::floor(centre.x)), static_cast<int>(std::floor(centre.y)),
                                      static_cast<int>(std::floor(centre.z))});
  std::uint64_t before = 0;
  int level = 0;
  for (Client* far : {&b, &c})
    ASSERT_TRUE(far->wait_until(
        [&](const ClientView& v) {
          const Holding* cov = v.replica.holding(target);
          // At its level already: the edit's news then come as a refresh,
          // not with a refinement.
          if (cov == nullptr || cov->full_resolution() || !all_at_desired_level(v.replica, {target}, ob.state.position, 16))
            return false;
          before = std::max(before, cov->revision);
          level = cov->level();
          return true;
        },
        kDeadline));
  ASSERT_TRUE(level == 1 || level == 2) << "a level a patch can refresh";
  const ClientCounters b_before = b.counters();
  const std::uint32_t id = a.fill_sphere(centre, 4.0f, materials::kBasalt);
  ASSERT_TRUE(a.wait_until([&](const ClientView& v) { return v.edits.count(id) != 0; }, kDeadline));
  std::uint64_t now = 0;
  ASSERT_TRUE(a.wait_until(
      [&](const ClientView& v) {
        const Holding* h = v.replica.holding(target);
        if (h == nullptr || h->revision <= before) return false;
        now = h->revision;
        return true;
      },
      kDeadline));
  for (Client* far : {&b, &c})
    ASSERT_TRUE(far->wait_until(
        [&](const ClientView& v) {
          const Holding* cov = v.replica.holding(target);
          return cov != nullptr && !cov->full_resolution() && cov->revision >= now;
        },
        kDeadline));
  // The mip each holds is the edited chunk's, made from A's full resolution.
  const int n = kChunkSize >> level;
  Box want({n, n, n});
  a.with_replica([&](const Replica& r) { r.grid().find_chunk(target)->read_level(level, want); });
  for (Client* far : {&b, &c}) {
    Box got;
    ASSERT_TRUE(far->with_replica([&](const Replica& r) { return r.read_mip(target, got); }));
    EXPECT_EQ(got, want) << (far == &b ? "patched" : "whole");
    EXPECT_EQ(far->counters().update_batches, 0u);  // a mip holder gets mips, not units
  }
  EXPECT_GE(b.counters().mip_patches, 1u);
  EXPECT_EQ(c.counters().mip_patches, 0u);
  // The byte budget: the refresh is counted as one, the editor's units as
  // updates, and each client's causes add up to every byte it received.
  const auto refresh = static_cast<std::size_t>(ByteCause::kRefresh);
  const auto update = static_cast<std::size_t>(ByteCause::kUpdate);
  EXPECT_GT(b.counters().bytes_in_by_cause[refresh], b_before.bytes_in_by_cause[refresh]);
  EXPECT_EQ(b.counters().bytes_in_by_cause[update], 0u);
  EXPECT_TRUE(a.wait_until([&](const ClientView& v) { return v.counters.bytes_in_by_cause[update] > 0; }, kDeadline));
  for (Client* k : {&a, &b, &c}) {
    const ClientCounters got = k->counters();
    std::uint64_t by_type = 0, by_cause = 0;
    for (const auto& t : got.by_message_type) by_type += t.bytes_in;
    for (const std::uint64_t x : got.bytes_in_by_cause) by_cause += x;
    EXPECT_EQ(by_cause, by_type);
    EXPECT_GT(got.bytes_in_by_cause[static_cast<std::size_t>(ByteCause::kStream)], 0u);
  }
}

}  // namespace
}  // namespace terrane

namespace terrane {
namespace {

// Shared mode: many clients on one io_context run by a small pool.
class SharedIoPool {
 public:
  explicit SharedIoPool(int threads) : work_(asio::make_work_guard(io_)) {
    for (int i = 0; i < threads; ++i) threads_.emplace_back([this] { io_.run(); });
  }
  ~SharedIoPool() {
    work_.reset();
    for (auto& t : threads_) t.join();
  }
  asio::io_context& io() { return io_; }

 private:
  asio::io_context io_;
  asio::executor_work_guard<asio::io_context::executor_type> work_;
  std::vector<std::thread> threads_;
};

TEST_F(ClientServerTest, SharedIoContextServesManyClientsAndReportsUpdateBatches) {
  start_server();
  SharedIoPool pool(2);
  constexpr int kClients = 6;
  std::mutex mu;
  std::vector<std::pair<int, std::uint64_t>> batches;  // (client, tick)
  std::vector<std::unique_ptr<Client>> clients;
  for (int i = 0; i < kClients; ++i) {
    ClientOptions o = options("shared" + std::to_string(i));
    o.io_context = &pool.io();
    ClientCallbacks cb;
    cb.on_update_batch = [&, i](std::uint64_t tick, const std::vector<ChunkRevisionMsg>& revs) {
      EXPECT_FALSE(revs.empty());
      std::lock_guard lock(mu);
      batches.emplace_back(i, tick);
    };
    clients.push_back(std::make_unique<Client>(o, cb));
    std::string err;
    ASSERT_TRUE(clients.back()->connect(&err)) << err;
  }
  for (auto& c : clients) wait_full_res(*c, 32);
  const auto w = clients[0]->welcome();
  ASSERT_TRUE(w.has_value());
  const std::uint32_t id = clients[0]->fill_sphere({w->spawn.x, w->spawn.y - 3.0f, w->spawn.z}, 3.0f, materials::kBrick);
  ASSERT_NE(id, 0u);
  ASSERT_TRUE(clients[0]->wait_until([&](const ClientView& v) { return v.edits.count(id) != 0; }, kDeadline));
  const auto outcome = clients[0]->wait_until([&](const ClientView& v) { return v.edits.at(id).accepted; }, 0ms);
  ASSERT_TRUE(outcome);
  std::uint64_t tick = 0;
  clients[0]->wait_until([&](const ClientView& v) { return (tick = v.edits.at(id).tick), true; }, 0ms);
  // Every client holds the edit at full resolution: each hears of it, at the ack's tick.
  for (int i = 0; i < kClients; ++i)
    ASSERT_TRUE(clients[static_cast<std::size_t>(i)]->wait_until(
        [&](const ClientView&) {
          std::lock_guard lock(mu);
          return std::count(batches.begin(), batches.end(), std::make_pair(i, tick)) > 0;
        },
        kDeadline))
        << "client " << i;
  for (auto& c : clients) {
    const ClientCounters k = c->counters();
    // Chunks stream in StreamBatch frames, eight 16^3 units per full chunk.
    const auto& stream = k.by_message_type[static_cast<std::size_t>(wire::Body::StreamBatch)];
    EXPECT_GT(stream.frames_in, 0u);
    EXPECT_EQ(k.chunk_units, 8 * k.full_records);
    EXPECT_EQ(k.by_message_type[static_cast<std::size_t>(wire::Body::Hello)].frames_out, 1u);
    std::uint64_t in = 0, out = 0;
    for (const auto& t : k.by_message_type) in += t.bytes_in, out += t.bytes_out;
    EXPECT_LE(in, k.bytes_in);
    EXPECT_GT(in, k.bytes_in / 2);
    EXPECT_EQ(out, k.bytes_out);
    EXPECT_FALSE(c->closed()) << c->disconnect_reason();
  }
  EXPECT_STREQ(message_type_name(static_cast<std::size_t>(wire::Body::UpdateBatch)), "UpdateBatch");
  for (auto& c : clients) c->disconnect();
  for (auto& c : clients) EXPECT_TRUE(c->closed());
}

TEST_F(ClientServerTest, SharedModeConnectFailureIsReported) {
  SharedIoPool pool(1);
  // A port nothing listens on: bind one, then close it.
  asio::io_context io;
  asio::ip::tcp::acceptor a(io, {asio::ip::make_address("127.0.0.1"), 0});
  const std::uint16_t port = a.local_endpoint().port();
  a.close();
  ClientOptions o;
  o.port = port;
  o.io_context = &pool.io();
  Client c(o);
  std::string err;
  EXPECT_FALSE(c.connect(&err));
  EXPECT_NE(err.find("cannot connect to 127.0.0.1:" + std::to_string(port)), std::string::npos) << err;
}

TEST_F(ClientServerTest, EmulatedLatencyDelaysEveryFrame) {
  start_server();
  ClientOptions o = options("laggy");
  o.emulation.latency = 300ms;
  Client c(o);
  std::string err;
  ASSERT_TRUE(c.connect(&err)) << err;
  ASSERT_TRUE(c.wait_until([](const ClientView& v) { return v.welcomed || v.closed; }, kDeadline));
  const auto sent = std::chrono::steady_clock::now();
  ASSERT_TRUE(c.ping(42));
  ASSERT_TRUE(c.wait_until([](const ClientView& v) { return v.counters.pongs >= 1 || v.closed; }, kDeadline));
  EXPECT_GE(std::chrono::steady_clock::now() - sent, 300ms);
  EXPECT_FALSE(c.closed());
}

TEST_F(ClientServerTest, EmulatedBandwidthCapsDeliveryRate) {
  start_server();
  ClientOptions o = options("thin", 96, 32);
  constexpr std::uint64_t kRate = 24 * 1024;
  o.emulation.bandwidth_bytes_per_s = kRate;
  o.emulation.latency = 20ms;
  Client c(o);
  std::string err;
  const auto start = std::chrono::steady_clock::now();
  ASSERT_TRUE(c.connect(&err)) << err;
  wait_full_res(c, 32);
  const double elapsed_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const ClientCounters k = c.counters();
  std::uint64_t delivered = 0;
  for (const auto& t : k.by_message_type) delivered += t.bytes_in;
  ASSERT_GT(delivered, 2 * kRate) << "the test needs more than a few reads of data";
  // Delivered bytes never outrun the link (plus one read in flight).
  EXPECT_LE(static_cast<double>(delivered), static_cast<double>(kRate) * elapsed_s + 64 * 1024);
  EXPECT_FALSE(c.closed()) << c.disconnect_reason();
}

}  // namespace
}  // namespace terrane
