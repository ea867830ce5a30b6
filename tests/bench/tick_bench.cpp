// The cost of one tick on the server, split as the world strand and the
// replicators pay it, for 200 clients that all hold the edited chunks (the
// crowd scenario): apply (edits on copies of their chunks, new versions),
// encode (each version's update piece and mips, once, shared), commit (the
// stored blobs' encoding and one SQLite transaction, synchronous=FULL), world fan-out (interest lookups,
// one list per holder) and delivery (per client: one UpdateBatch frame of
// the pieces, TickUpdate, or a StreamBatch of mip refresh records, each a
// frame whose segments share the versions' bytes; owned_per_tick counts
// the bytes the frames hold copies of).
//   ./build/bin/terrane-bench-tick
// Times are per tick; "per_delivery" is the time per (changed chunk,
// holder) pair, in seconds with an SI suffix.
#include <benchmark/benchmark.h>
#include <unistd.h>

#include <filesystem>
#include <future>
#include <random>
#include <unordered_map>
#include <unordered_set>

#include "common/codec/update_batch.h"
#include "common/world/world.h"
#include "protocol/messages.h"
#include "protocol/stream_batch.h"
#include "server/storage/storage.h"
#include "server/base/chunk_version.h"
#include "server/replication/tick_update.h"
#include "server/world/edits.h"
#include "server/world/interest.h"

namespace terrane {
namespace {

constexpr int kClients = 200;
constexpr int kEditsPerTick = 5;  // 200 bots, one edit per 2 s each, 20 Hz ticks (3.3 at 30 Hz)

struct Scene {
  std::unique_ptr<World> world;
  std::vector<VersionPtr> versions;  // the edited area's chunks
  std::filesystem::path dir;
  Scene() {
    dir = std::filesystem::temp_directory_path() / ("terrane-bench-tick-" + std::to_string(::getpid()));
    std::filesystem::remove_all(dir);
    auto w = World::create(dir.string(), default_world_meta());
    world = std::move(*w);
    const int h = static_cast<int>(world->generator()->surface_height(0, 0));
    for (int z = -2; z < 2; ++z)
      for (int x = -2; x < 2; ++x) {
        const Vec3i cp{x, floor_div(h, kChunkSize), z};
        Chunk c = world->generate_chunk(cp);
        versions.push_back(std::make_shared<const ChunkVersion>(
            cp, 1, c.empty() ? nullptr : std::make_shared<const Chunk>(std::move(c))));
      }
  }
  ~Scene() {
    world.reset();
    std::filesystem::remove_all(dir);
  }
};

Scene& scene() {
  static Scene s;
  return s;
}

// One tick's edits applied to copies of their chunks; returns the new versions.
std::vector<VersionPtr> apply_tick(std::mt19937& rng, const std::vector<VersionPtr>& base, std::uint64_t rev) {
  std::unordered_map<Vec3i, VersionPtr, Vec3iHash> by_pos;
  for (const auto& v : base) by_pos[v->pos()] = v;
  Grid scratch;
  std::unordered_set<Vec3i, Vec3iHash> copied;
  ChangedUnits changed;
  std::uniform_int_distribution<int> xz(-60, 59);
  const Vec3i c0 = base.front()->pos();
  for (int e = 0; e < kEditsPerTick; ++e) {
    EditRequestMsg edit;
    edit.kind = e % 2 ? EditKind::kDig : EditKind::kFillSphere;
    edit.material = e % 2 ? kAir : materials::kBrick;
    edit.radius = 3;
    edit.center = {static_cast<float>(xz(rng)), static_cast<float>(c0.y * kChunkSize + 16), static_cast<float>(xz(rng))};
    const Region r = edit.reads();
    for_each_chunk_in(r, [&](Vec3i cp) {
      if (!copied.insert(cp).second) return;
      auto it = by_pos.find(cp);
      if (it != by_pos.end() && !it->second->empty()) scratch.put_chunk(cp, it->second->chunk()->clone());
    });
    apply_edit(scratch, edit, edit.bounds(), changed);
  }
  std::vector<VersionPtr> out;
  for (const auto& [cp, bits] : changed) {
    if (bits.none()) continue;
    std::shared_ptr<const Chunk> chunk;
    if (auto c = scratch.take_chunk(cp); c && !c->empty()) chunk = std::move(c);
    auto it = by_pos.find(cp);
    const Chunk* prev = it != by_pos.end() ? it->second->chunk() : nullptr;
    const auto d = levels_changed(prev, chunk.get());
    std::array<std::uint64_t, kMipLevels> since{};
    for (std::size_t l = 0; l < since.size(); ++l) since[l] = d[l] ? rev : 1;
    out.push_back(std::make_shared<const ChunkVersion>(cp, rev, std::move(chunk), bits, since));
  }
  return out;
}

void BM_TickApply(benchmark::State& state) {
  std::mt19937 rng(1);
  std::uint64_t rev = 2, versions = 0;
  for (auto _ : state) {
    auto v = apply_tick(rng, scene().versions, rev++);
    versions += v.size();
    benchmark::DoNotOptimize(v);
  }
  state.counters["versions_per_tick"] = static_cast<double>(versions) / static_cast<double>(state.iterations());
}
BENCHMARK(BM_TickApply)->Unit(benchmark::kMicrosecond);

void BM_TickEncode(benchmark::State& state) {
  std::mt19937 rng(2);
  std::uint64_t rev = 2;
  for (auto _ : state) {
    state.PauseTiming();
    auto vs = apply_tick(rng, scene().versions, rev++);
    state.ResumeTiming();
    for (const auto& v : vs) {
      if (v->changed_units().any()) benchmark::DoNotOptimize(v->update_piece().rest.data());
      for (int l = 1; l < kMipLevels; ++l) benchmark::DoNotOptimize(v->encoded(l).data());
    }
  }
}
BENCHMARK(BM_TickEncode)->Unit(benchmark::kMicrosecond);

void BM_TickCommit(benchmark::State& state) {
  auto storage = Storage::open(*scene().world, 1);
  std::mt19937 rng(3);
  std::uint64_t rev = 2;
  for (auto _ : state) {
    state.PauseTiming();
    auto vs = apply_tick(rng, scene().versions, rev++);
    state.ResumeTiming();
    std::promise<void> done;
    (*storage)->commit(vs, {}, [&](const FileStatus&) { done.set_value(); });
    done.get_future().wait();
  }
}
BENCHMARK(BM_TickCommit)->Unit(benchmark::kMicrosecond)->UseRealTime();

void BM_TickFanoutWorld(benchmark::State& state) {
  InterestIndex idx;
  for (const auto& v : scene().versions)
    for (ClientId id = 1; id <= kClients; ++id) idx.hold(v->pos(), id, id <= 20);
  std::mt19937 rng(4);
  auto vs = apply_tick(rng, scene().versions, 2);
  std::uint64_t deliveries = 0;
  for (auto _ : state) {
    std::unordered_map<ClientId, std::vector<VersionPtr>> news;
    for (const auto& v : vs)
      idx.for_each_holder(v->pos(), [&](InterestIndex::Holder h) {
        news[h.id()].push_back(v);
        ++deliveries;
      });
    benchmark::DoNotOptimize(news);
  }
  state.counters["per_delivery"] =
      benchmark::Counter(static_cast<double>(deliveries), benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}
BENCHMARK(BM_TickFanoutWorld)->Unit(benchmark::kMicrosecond);

void BM_TickDelivery(benchmark::State& state) {
  // Every client builds its frames from the shared pieces: 20 of them hold
  // the chunks at full resolution (one UpdateBatch), the rest a mip (one
  // refresh record per chunk in a StreamBatch).
  std::mt19937 rng(5);
  auto vs = apply_tick(rng, scene().versions, 2);
  for (const auto& v : vs) {
    (void)v->update_piece();
    (void)v->encoded(2);
  }
  std::uint64_t deliveries = 0, bytes = 0, copied = 0;
  for (auto _ : state) {
    for (int c = 0; c < kClients; ++c) {
      if (c < 20) {
        TickUpdate update;
        for (const auto& v : vs) update.add(v);
        std::size_t units = 0;
        const auto f = update.finish(2, nullptr, units);
        bytes += f->size();
        copied += f->size() - f->shared_bytes();
      } else {
        StreamBatchWriter w;
        for (const auto& v : vs) w.add(StreamRecordKind::kMip2, v->pos(), v->revision(), v->encoded(2), v);
        const OutFrame f = w.finish();
        bytes += f.size();
        copied += f.size() - f.shared_bytes();
      }
      deliveries += vs.size();
    }
  }
  state.counters["per_delivery"] = benchmark::Counter(static_cast<double>(deliveries),
                                                          benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
  state.counters["bytes_per_tick"] = static_cast<double>(bytes) / static_cast<double>(state.iterations());
  // The frames' own bytes (written by the frame builders; the rest are
  // the versions' shared bytes).
  state.counters["owned_per_tick"] = static_cast<double>(copied) / static_cast<double>(state.iterations());
}
BENCHMARK(BM_TickDelivery)->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace terrane

BENCHMARK_MAIN();
