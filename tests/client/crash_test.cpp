// Crash test: the real terrane-server (a child process) is killed with
// SIGKILL at seeded random moments while a client's edits are in flight, and
// restarted on the same world, several times. Every edit the server
// acknowledged must be there afterwards, on disk and in a fresh client's
// replica, and that replica must agree with the server's chunk hashes.
//
// Each edit fills one voxel never edited before with a value that differs
// from what the voxel held, so a lost edit cannot hide behind another edit
// or behind the terrain.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <optional>
#include <random>
#include <set>
#include <string>
#include <tuple>
#include <unordered_map>
#include <vector>

#include <unistd.h>

#include "client/client.h"
#include "common/world/coarse_image.h"
#include "common/world/sqlite_store.h"
#include "common/world/world.h"
#include "tests/support/server_process.h"
#include "tests/support/view_chunks.h"

namespace terrane {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using testing_support::ServerProcess;

// Generous: sanitizer builds on a shared 2-core machine generate slowly.
constexpr auto kDeadline = 30s;
constexpr int kKills = 5;
constexpr std::uint32_t kSeed = 20261123;
// Kill this long after the client starts editing (uniform, ms).
constexpr int kMinKillDelayMs = 150, kMaxKillDelayMs = 1200;
// Unanswered edits at most: below the server's per-client queue (64), so
// no edit is rejected for flooding and many are in flight at each kill.
constexpr std::size_t kMaxInFlight = 32;
// The client's full-resolution radius; edits stay well inside it.
constexpr int kFullRadius = 32;
// The edited voxels: a 32 × 16 × 32 block centred on the spawn point, every
// voxel at most 24.1 voxels from it (inside kFullRadius).
constexpr int kPoolX = 32, kPoolY = 16, kPoolZ = 32;
constexpr std::size_t kPoolSize = static_cast<std::size_t>(kPoolX) * kPoolY * kPoolZ;

Vec3i pool_voxel(Vec3i centre, std::size_t i) {
  const int x = static_cast<int>(i % kPoolX), z = static_cast<int>((i / kPoolX) % kPoolZ),
            y = static_cast<int>(i / (kPoolX * kPoolZ));
  return centre + Vec3i{x - kPoolX / 2, y - kPoolY / 2, z - kPoolZ / 2};
}

// Material 1..12 (all in the default table), occupancy 1..255.
Voxel value_for(std::size_t i) {
  return make_voxel(static_cast<Material>(1 + i % 12), static_cast<std::uint8_t>(1 + (i * 37) % 255));
}

using testing_support::chunks_within;

bool all_full(const Replica& r, const std::vector<Vec3i>& chunks) {
  return std::all_of(chunks.begin(), chunks.end(), [&](Vec3i cp) {
    const Holding* c = r.holding(cp);
    return c != nullptr && c->full_resolution();
  });
}

struct Edit {
  Vec3i voxel;
  Voxel value;
};

class CrashTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("terrane-crash-" + std::to_string(::getpid()));
    fs::remove_all(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  // Connects a client to the server and waits until it holds every chunk
  // within kFullRadius of the spawn point at full resolution.
  static std::vector<Vec3i> join(Client& c, std::string* error) {
    if (!c.connect(error)) return {};
    if (!c.wait_until([](const ClientView& v) { return v.welcomed || v.closed; }, kDeadline) || !c.welcome()) {
      *error = "no Welcome: " + c.disconnect_reason();
      return {};
    }
    const WelcomeMsg w = *c.welcome();
    auto near = chunks_within(w.spawn, static_cast<float>(kFullRadius), w);
    if (!c.wait_until([&](const ClientView& v) { return v.closed || all_full(v.replica, near); }, kDeadline) ||
        c.closed()) {
      *error = "full resolution never arrived: " + c.disconnect_reason();
      return {};
    }
    return near;
  }
  ClientOptions options(std::uint16_t port) const {
    ClientOptions o;
    o.port = port;
    o.name = "crash";
    o.state.view_distance = kFullRadius + 8;
    o.state.full_res_radius = kFullRadius;
    return o;
  }

  fs::path dir_;
};

TEST_F(CrashTest, EveryAcknowledgedEditSurvivesSigkillAndReplicasResumeClean) {
  std::mt19937 rng(kSeed);
  std::uniform_int_distribution<int> kill_delay_ms(kMinKillDelayMs, kMaxKillDelayMs);
  std::vector<Edit> acked;
  std::size_t sent_total = 0, unanswered_total = 0, rejected_total = 0, next = 0;
  int kills = 0;
  std::optional<Vec3i> centre;
  const auto started = std::chrono::steady_clock::now();

  for (int life = 0; life < kKills; ++life) {
    ServerProcess server(dir_.string(), {"--hash-push-ms", "0", "--edits-per-second", "0"});
    ASSERT_NE(server.port(), 0) << server.output();
    Client c(options(server.port()));
    std::string error;
    ASSERT_FALSE(join(c, &error).empty()) << "life " << life << ": " << error << "\n" << server.output();
    const Vec3f spawn = c.welcome()->spawn;
    const Vec3i here{static_cast<int>(std::floor(spawn.x)), static_cast<int>(std::floor(spawn.y)),
                     static_cast<int>(std::floor(spawn.z))};
    if (!centre) centre = here;
    ASSERT_EQ(here, *centre) << "the spawn point moved; the edited block would leave the full-resolution region";

    // Edit until the kill time, keeping kMaxInFlight edits unanswered.
    std::unordered_map<std::uint32_t, Edit> sent;
    const auto kill_at = std::chrono::steady_clock::now() + std::chrono::milliseconds(kill_delay_ms(rng));
    while (std::chrono::steady_clock::now() < kill_at) {
      const bool room = c.wait_until(
          [&](const ClientView& v) { return v.closed || sent.size() - v.edits.size() < kMaxInFlight; }, 2ms);
      ASSERT_FALSE(c.closed()) << "life " << life << ": " << c.disconnect_reason();
      if (!room) continue;
      ASSERT_LT(next, kPoolSize) << "the voxel pool is used up; enlarge it";
      const std::size_t i = next++;
      const Vec3i p = pool_voxel(*centre, i);
      Voxel v = value_for(i);
      if (c.get(p) == v) v = make_voxel(v.material, static_cast<std::uint8_t>(v.occupancy == 255 ? 1 : v.occupancy + 1));
      const std::uint32_t id = c.fill_box(Region{p, p + Vec3i{1, 1, 1}}, v);
      ASSERT_NE(id, 0u);
      sent.emplace(id, Edit{p, v});
    }
    ASSERT_TRUE(server.kill_hard()) << "life " << life;
    ++kills;
    ASSERT_TRUE(c.wait_until([](const ClientView& v) { return v.closed; }, kDeadline));
    // The connection is gone: the outcomes the client has are all there will be.
    std::size_t acked_now = 0, unanswered = 0, rejected = 0;
    c.wait_until(
        [&](const ClientView& v) {
          for (const auto& [id, e] : sent) {
            auto it = v.edits.find(id);
            // Unanswered when the connection went: the client says so (unknown).
            if (it == v.edits.end() || it->second.reason == kEditOutcomeUnknown) {
              ++unanswered;
            } else if (it->second.accepted) {
              acked.push_back(e);
              ++acked_now;
            } else {
              ++rejected;
              ADD_FAILURE() << "edit " << id << " rejected: " << it->second.reason;
            }
          }
          return true;
        },
        0ms);
    c.disconnect();
    std::printf("crash test: life %d: %zu edits sent, %zu acknowledged, %zu unanswered at the SIGKILL\n", life,
                sent.size(), acked_now, unanswered);
    sent_total += sent.size();
    unanswered_total += unanswered;
    rejected_total += rejected;
  }

  // The last restart: a fresh client sees every acknowledged edit, and its
  // replica matches the server's chunk hashes.
  ServerProcess server(dir_.string(), {"--hash-push-ms", "0"});
  ASSERT_NE(server.port(), 0) << server.output();
  Client c(options(server.port()));
  std::string error;
  const auto near = join(c, &error);
  ASSERT_FALSE(near.empty()) << error << "\n" << server.output();
  std::size_t lost_replica = 0;
  for (const Edit& e : acked) lost_replica += c.get(e.voxel) != e.value;
  for (const Vec3i cp : near) ASSERT_TRUE(c.request_chunk_hash(cp));
  ASSERT_TRUE(c.wait_until(
      [&](const ClientView& v) {
        return v.closed || std::all_of(near.begin(), near.end(), [&](Vec3i cp) { return v.hash_checks.count(cp) != 0; });
      },
      kDeadline));
  const ClientCounters counters = c.counters();
  c.disconnect();
  EXPECT_EQ(server.stop(), 0) << server.output();

  // And on disk.
  auto world = World::open(dir_.string());
  ASSERT_TRUE(world.ok()) << world.error().message;
  std::size_t lost_disk = 0;
  Box one({1, 1, 1});
  for (const Edit& e : acked) {
    ASSERT_TRUE((*world)->read_box(e.voxel, one).ok());
    if (one.get(0, 0, 0) != e.value) {
      ++lost_disk;
      ADD_FAILURE() << "acknowledged edit lost at (" << e.voxel.x << ", " << e.voxel.y << ", " << e.voxel.z << ")";
    }
  }
  // What distant views are served from (the coarse images, read past
  // whatever the kills left behind: the server writes them after the
  // chunks) still matches every chunk after the kills.
  std::size_t coarse_wrong = 0, coarse_entries = 0;
  {
    std::map<std::tuple<int, int, int>, CoarseEntry> expected;
    std::set<std::tuple<int, int, int>> regions;
    ASSERT_TRUE((*world)->store().for_each_chunk([&](Vec3i p, std::uint64_t rev, std::span<const std::uint8_t> blob) {
      auto chunk = decode_chunk_blob(blob);
      ASSERT_TRUE(chunk.ok());
      expected[{p.x, p.y, p.z}] = CoarseEntry{p, rev, coarse_voxels(&*chunk)};
      const Vec3i r = coarse_region_of(p);
      regions.insert({r.x, r.y, r.z});
    }).ok());
    for (const auto& [rx, ry, rz] : regions) {
      auto entries = (*world)->store().load_coarse({rx, ry, rz});
      ASSERT_TRUE(entries.ok()) << entries.error().message;
      for (const CoarseEntry& e : *entries) {
        ++coarse_entries;
        auto it = expected.find({e.chunk_pos.x, e.chunk_pos.y, e.chunk_pos.z});
        if (it == expected.end() || !(it->second == e)) ++coarse_wrong;
        if (it != expected.end()) expected.erase(it);
      }
    }
    coarse_wrong += expected.size();
  }
  EXPECT_EQ(coarse_wrong, 0u) << "of " << coarse_entries << " coarse entries";
  EXPECT_GT(coarse_entries, 0u);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  std::printf(
      "crash test (seed %u): %d SIGKILLs, %zu edits sent, %zu acknowledged, %zu unanswered at the kills, %zu "
      "rejected; lost: %zu on disk, %zu in the restarted replica; chunk hashes after the last restart: %llu "
      "match, %llu mismatch (%zu chunks); %.1f s\n",
      kSeed, kills, sent_total, acked.size(), unanswered_total, rejected_total, lost_disk, lost_replica,
      static_cast<unsigned long long>(counters.hash_matches), static_cast<unsigned long long>(counters.hash_mismatches),
      near.size(), seconds);
  EXPECT_EQ(kills, kKills);
  EXPECT_GT(acked.size(), static_cast<std::size_t>(kKills) * 10) << "too few edits to mean anything";
  EXPECT_GT(unanswered_total, 0u) << "no edit was in flight at any kill";
  EXPECT_EQ(lost_disk, 0u);
  EXPECT_EQ(lost_replica, 0u);
  EXPECT_EQ(counters.hash_mismatches, 0u);
  EXPECT_EQ(counters.hash_matches, near.size());
}

}  // namespace
}  // namespace terrane
