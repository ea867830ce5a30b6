// Joining a world: an in-process terrane-server and one client over
// 127.0.0.1. Measures the time from connect to coarse coverage of the whole
// view and to full resolution inside the full-resolution radius, and the
// bytes received by then. "Cold" starts each join on a new world (chunks
// generated on demand); "Warm" joins a server that already holds them.
// "Imported" joins the real regions in tests/data imported as a world (view
// distance = full-resolution radius) and sets the bytes the client received
// against the network codec's own bytes for the same chunks and against
// Minecraft-style paletted sections + zlib-6 (tests/bench/paletted_section.h):
//   bytes_per_nev  all bytes received from connect until the full-resolution
//                  region is complete / its non-empty voxels
//   wire_over_codec  those bytes / the codec's bytes for the region's 16^3 units
//   paletted_per_nev paletted + zlib bytes of the same units / non-empty voxels
//
//   terrane-bench-join --benchmark_counters_tabular=true
#include <benchmark/benchmark.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <map>

#include <zlib.h>

#include <spdlog/spdlog.h>

#include "client/client.h"
#include "common/codec/net_codec.h"
#include "common/world/world.h"
#include "server/server.h"
#include "tests/bench/paletted_section.h"
#include "tests/support/view_chunks.h"

namespace terrane {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;
using namespace std::chrono_literals;

using testing_support::chunks_within;

struct JoinResult {
  double coarse_s = 0, full_s = 0;
  std::uint64_t coarse_bytes = 0, full_bytes = 0;
  std::size_t view_chunks = 0, full_chunks = 0;
  std::vector<Vec3i> full_set;
  bool ok = false;
};

JoinResult join_once(std::uint16_t port, int view, int full) {
  JoinResult r;
  ClientOptions o;
  o.port = port;
  o.name = "bench";
  o.state.view_distance = view;
  o.state.full_res_radius = full;
  Client c(o);
  std::string err;
  const auto t0 = Clock::now();
  if (!c.connect(&err)) return r;
  if (!c.wait_until([](const ClientView& v) { return v.welcomed || v.closed; }, 60s)) return r;
  const auto w = c.welcome();
  if (!w) return r;
  const auto in_view = chunks_within(w->spawn, static_cast<float>(view), *w);
  const auto near = chunks_within(w->spawn, static_cast<float>(full), *w);
  r.view_chunks = in_view.size();
  r.full_chunks = near.size();
  r.full_set = near;
  const bool coarse = c.wait_until(
      [&](const ClientView& v) {
        for (const Vec3i cp : in_view)
          if (v.replica.holding(cp) == nullptr) return v.closed;
        r.coarse_bytes = v.counters.bytes_in;
        return true;
      },
      600s);
  r.coarse_s = std::chrono::duration<double>(Clock::now() - t0).count();
  const bool done = c.wait_until(
      [&](const ClientView& v) {
        for (const Vec3i cp : near) {
          const Holding* cov = v.replica.holding(cp);
          if (cov == nullptr || !cov->full_resolution()) return v.closed;
        }
        r.full_bytes = v.counters.bytes_in;
        return true;
      },
      600s);
  r.full_s = std::chrono::duration<double>(Clock::now() - t0).count();
  r.ok = coarse && done && !c.closed();
  c.disconnect();
  return r;
}

void report(benchmark::State& state, const JoinResult& r, double n) {
  state.counters["coarse_ms"] += r.coarse_s * 1000 / n;
  state.counters["full_ms"] += r.full_s * 1000 / n;
  state.counters["coarse_KiB"] += static_cast<double>(r.coarse_bytes) / 1024 / n;
  state.counters["full_KiB"] += static_cast<double>(r.full_bytes) / 1024 / n;
  state.counters["view_chunks"] = static_cast<double>(r.view_chunks);
  state.counters["full_chunks"] = static_cast<double>(r.full_chunks);
}

std::unique_ptr<Server> start_server(const fs::path& dir) {
  fs::remove_all(dir);
  ServerOptions o;
  o.world_dir = dir.string();
  auto s = Server::create(o);
  if (!s) return nullptr;
  (*s)->start();
  return std::move(*s);
}

void BM_JoinCold(benchmark::State& state) {
  spdlog::set_level(spdlog::level::warn);
  const int view = static_cast<int>(state.range(0)), full = static_cast<int>(state.range(1));
  const fs::path dir = fs::temp_directory_path() / ("terrane-join-bench-" + std::to_string(::getpid()));
  for (auto _ : state) {
    state.PauseTiming();
    auto server = start_server(dir);
    if (!server) return state.SkipWithError("cannot start the server");
    state.ResumeTiming();
    const JoinResult r = join_once(server->port(), view, full);
    state.PauseTiming();
    server->stop();
    server.reset();
    fs::remove_all(dir);
    state.ResumeTiming();
    if (!r.ok) return state.SkipWithError("join did not complete");
    report(state, r, static_cast<double>(state.max_iterations));
  }
}

void BM_JoinWarm(benchmark::State& state) {
  spdlog::set_level(spdlog::level::warn);
  const int view = static_cast<int>(state.range(0)), full = static_cast<int>(state.range(1));
  const fs::path dir = fs::temp_directory_path() / ("terrane-join-bench-warm-" + std::to_string(::getpid()));
  auto server = start_server(dir);
  if (!server) return state.SkipWithError("cannot start the server");
  if (!join_once(server->port(), view, full).ok) return state.SkipWithError("warm-up join did not complete");
  for (auto _ : state) {
    const JoinResult r = join_once(server->port(), view, full);
    if (!r.ok) return state.SkipWithError("join did not complete");
    report(state, r, static_cast<double>(state.max_iterations));
  }
  server->stop();
  server.reset();
  fs::remove_all(dir);
}

// --- imported real terrain ----------------------------------------------------

struct Dataset {
  const char* name;
  const char* file;
};
constexpr Dataset kDatasets[] = {{"mc-1.9", "mc-1.9.vxraw.gz"}, {"mc-1.16", "mc-1.16.vxraw.gz"}};

fs::path bin_dir() { return fs::read_symlink("/proc/self/exe").parent_path(); }

// Imports a dataset once per process with the real terrane-world tool.
fs::path imported_world(int index) {
  static std::map<int, fs::path> done;
  if (auto it = done.find(index); it != done.end()) return it->second;
  const fs::path dir = fs::temp_directory_path() /
                       ("terrane-join-bench-" + std::string(kDatasets[index].name) + "-" + std::to_string(::getpid()));
  fs::remove_all(dir);
  const std::string cmd = (bin_dir() / "terrane-world").string() + " import --world " + dir.string() + " " +
                          TERRANE_TEST_DATA_DIR + "/" + kDatasets[index].file + " > /dev/null 2>&1";
  if (std::system(cmd.c_str()) != 0) return {};
  done[index] = dir;
  return dir;
}

struct RegionCost {
  std::uint64_t non_empty = 0, codec_bytes = 0, paletted_bytes = 0;
};

// What the chunks cost encoded unit by unit, outside the protocol.
RegionCost region_cost(const fs::path& world_dir, const std::vector<Vec3i>& chunks) {
  RegionCost c;
  auto world = World::open(world_dir.string());
  if (!world) return c;
  Box box({kFullRecordUnit, kFullRecordUnit, kFullRecordUnit});
  std::vector<std::uint8_t> bytes, section, z;
  for (const Vec3i cp : chunks) {
    auto stored = (*world)->load_chunk(cp);
    if (!stored || stored->chunk.empty()) continue;
    for (int i = 0; i < 8; ++i) {
      const Vec3i u{i & 1, (i >> 1) & 1, (i >> 2) & 1};
      stored->chunk.read_box(u * kFullRecordUnit, box, Vec3i{0, 0, 0},
                             Vec3i{kFullRecordUnit, kFullRecordUnit, kFullRecordUnit});
      for (const Voxel v : box.voxels()) c.non_empty += v.material != kAir;
      bytes.clear();
      net_codec_encode(kFullRecordUnit, box.voxels(), bytes);
      c.codec_bytes += bytes.size();
      paletted_section(box.voxels(), section);
      uLongf n = compressBound(static_cast<uLong>(section.size()));
      z.resize(n);
      compress2(z.data(), &n, section.data(), static_cast<uLong>(section.size()), 6);
      c.paletted_bytes += n;
    }
  }
  return c;
}

void BM_JoinImported(benchmark::State& state) {
  spdlog::set_level(spdlog::level::warn);
  const int index = static_cast<int>(state.range(0)), radius = static_cast<int>(state.range(1));
  state.SetLabel(kDatasets[index].name);
  const fs::path dir = imported_world(index);
  if (dir.empty()) return state.SkipWithError("cannot import the dataset (is terrane-world built?)");
  ServerOptions o;
  o.world_dir = dir.string();
  o.replication.hash_push_ms = 0;  // only streaming bytes in the figure
  o.world.presence_hz = 0;
  auto server = Server::create(o);
  if (!server) return state.SkipWithError("cannot start the server");
  (*server)->start();
  JoinResult r;
  for (auto _ : state) {
    r = join_once((*server)->port(), radius, radius);
    if (!r.ok) return state.SkipWithError("join did not complete");
    report(state, r, static_cast<double>(state.max_iterations));
  }
  (*server)->stop();
  const RegionCost cost = region_cost(dir, r.full_set);
  if (cost.non_empty == 0) return state.SkipWithError("no terrain in the full-resolution region");
  const double nev = static_cast<double>(cost.non_empty);
  state.counters["non_empty"] = nev;
  state.counters["bytes_per_nev"] = static_cast<double>(r.full_bytes) / nev;
  state.counters["codec_per_nev"] = static_cast<double>(cost.codec_bytes) / nev;
  state.counters["wire_over_codec"] = static_cast<double>(r.full_bytes) / static_cast<double>(cost.codec_bytes);
  state.counters["paletted_per_nev"] = static_cast<double>(cost.paletted_bytes) / nev;
}

BENCHMARK(BM_JoinImported)
    ->ArgsProduct({{0, 1}, {64, 128}})
    ->Iterations(2)
    ->Unit(benchmark::kMillisecond);

BENCHMARK(BM_JoinCold)->Args({128, 64})->Args({256, 128})->Iterations(2)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_JoinWarm)->Args({128, 64})->Args({256, 128})->Iterations(3)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace terrane

BENCHMARK_MAIN();
