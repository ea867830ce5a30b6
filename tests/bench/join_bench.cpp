// Joining a world: an in-process terrane-server and one client over
// 127.0.0.1. Measures the time from connect to coarse coverage of the whole
// view and to full resolution inside the full-resolution radius, and the
// bytes received by then. "Cold" starts each join on a new world (chunks
// generated on demand); "Warm" joins a server that already holds them.
//
//   terrane-bench-join --benchmark_counters_tabular=true
#include <benchmark/benchmark.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <filesystem>

#include <spdlog/spdlog.h>

#include "client/client.h"
#include "server/server.h"

namespace terrane {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;
using namespace std::chrono_literals;

float dist_to_chunk(Vec3f p, Vec3i cp) {
  const Vec3i o = chunk_origin(cp);
  auto axis = [](float v, std::int32_t lo) {
    const float a = static_cast<float>(lo), b = static_cast<float>(lo + kChunkSize);
    return v < a ? a - v : (v > b ? v - b : 0.0f);
  };
  const float dx = axis(p.x, o.x), dy = axis(p.y, o.y), dz = axis(p.z, o.z);
  return std::sqrt(dx * dx + dy * dy + dz * dz);
}

std::vector<Vec3i> chunks_within(Vec3f p, float radius, const WelcomeMsg& w) {
  std::vector<Vec3i> out;
  const Vec3i v{static_cast<int>(std::floor(p.x)), static_cast<int>(std::floor(p.y)), static_cast<int>(std::floor(p.z))};
  const int r = static_cast<int>(radius) + 1;
  const Vec3i c0 = chunk_of(v - Vec3i{r, r, r}), c1 = chunk_of(v + Vec3i{r, r, r});
  for (int y = c0.y; y <= c1.y; ++y)
    for (int z = c0.z; z <= c1.z; ++z)
      for (int x = c0.x; x <= c1.x; ++x) {
        const Vec3i cp{x, y, z};
        if (cp.y * kChunkSize >= w.bounds_max_y || (cp.y + 1) * kChunkSize <= w.bounds_min_y) continue;
        if (dist_to_chunk(p, cp) <= radius) out.push_back(cp);
      }
  return out;
}

struct JoinResult {
  double coarse_s = 0, full_s = 0;
  std::uint64_t coarse_bytes = 0, full_bytes = 0;
  std::size_t view_chunks = 0, full_chunks = 0;
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
  const bool coarse = c.wait_until(
      [&](const ClientView& v) {
        for (const Vec3i cp : in_view)
          if (v.replica.coverage(cp) == nullptr) return v.closed;
        r.coarse_bytes = v.counters.bytes_in;
        return true;
      },
      600s);
  r.coarse_s = std::chrono::duration<double>(Clock::now() - t0).count();
  const bool done = c.wait_until(
      [&](const ClientView& v) {
        for (const Vec3i cp : near) {
          const ChunkCoverage* cov = v.replica.coverage(cp);
          if (cov == nullptr || cov->state == CoverageState::kMip) return v.closed;
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

BENCHMARK(BM_JoinCold)->Args({128, 64})->Args({256, 128})->Iterations(2)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_JoinWarm)->Args({128, 64})->Args({256, 128})->Iterations(3)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace terrane

BENCHMARK_MAIN();
