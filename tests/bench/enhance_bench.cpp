// Voxel detail enhancement throughput: output fragments per second (all
// fragments of the box, skipped ones included) and surface fragments per
// second, for each method and expansion factor, on a 16^3 box of generated
// terrain crossing the surface; plus one-voxel updates and lighting.
#include <benchmark/benchmark.h>

#include <cstdint>

#include "common/enhance/enhance.h"
#include "common/enhance/lighting.h"
#include "common/voxel/box.h"
#include "common/world/terrain_generator.h"

namespace terrane {
namespace {

constexpr Vec3i kOrigin{0, 32, 0};  // about half solid, above sea level

const Box& terrain() {
  static const Box box = [] {
    Box b;
    TerrainGenerator(GeneratorParams{}).generate(Region::from_min_size(kOrigin, {16, 16, 16}), b);
    return b;
  }();
  return box;
}

void report(benchmark::State& state, std::uint64_t fragments, const Box& last, const EnhanceStats& stats) {
  const std::uint64_t surface = count_surface(last);
  const auto iters = static_cast<double>(state.iterations());
  state.counters["fragments/s"] = benchmark::Counter(static_cast<double>(fragments), benchmark::Counter::kIsRate);
  state.counters["surface_frag/s"] =
      benchmark::Counter(static_cast<double>(surface) * iters, benchmark::Counter::kIsRate);
  state.counters["surface_frags"] = static_cast<double>(surface);
  state.counters["evaluated/iter"] = static_cast<double>(stats.voxels_evaluated) / iters;
  state.counters["skipped/iter"] = static_cast<double>(stats.voxels_skipped) / iters;
}

// Arg: levels (factor 2^levels). Figure 1's thresholds: 1 below y 40, 3/4 above.
void BM_Subdivide(benchmark::State& state) {
  const SubdivisionParams params{static_cast<int>(state.range(0)), SubdivisionThreshold{1, 3, 4, 40}};
  EnhanceStats stats;
  Box fine;
  std::uint64_t fragments = 0;
  for (auto _ : state) {
    fine = subdivide(terrain(), kOrigin, params, &stats);
    fragments += fine.voxel_count();
    benchmark::DoNotOptimize(fine.voxels().data());
  }
  report(state, fragments, fine, stats);
}
BENCHMARK(BM_Subdivide)->DenseRange(1, 4)->Unit(benchmark::kMillisecond);

// Args: factor, probes. Spread 1.0 and threshold 25% as in Figure 2; the
// cache is cleared every iteration (cold), so every surface configuration
// is evaluated once per run.
void BM_Resample(benchmark::State& state) {
  Resampler r(ResampleParams{static_cast<int>(state.range(0)), static_cast<int>(state.range(1)), 1.0f, 0.25f, 1});
  EnhanceStats stats;
  Box fine;
  std::uint64_t fragments = 0;
  for (auto _ : state) {
    r.clear_cache();
    fine = r.resample(terrain(), kOrigin, &stats);
    fragments += fine.voxel_count();
    benchmark::DoNotOptimize(fine.voxels().data());
  }
  report(state, fragments, fine, stats);
  state.counters["cache_entries"] = static_cast<double>(r.cache_entries());
}
BENCHMARK(BM_Resample)
    ->Args({2, 64})
    ->Args({3, 64})
    ->Args({4, 64})
    ->Args({8, 64})
    ->Args({16, 64})
    ->Args({16, 4})
    ->Args({16, 512})
    ->Unit(benchmark::kMillisecond);

// The same with a warm cache: what an interactive session pays once the
// configurations around the player have been seen.
void BM_ResampleWarm(benchmark::State& state) {
  Resampler r(ResampleParams{static_cast<int>(state.range(0)), static_cast<int>(state.range(1)), 1.0f, 0.25f, 1});
  (void)r.resample(terrain(), kOrigin);
  EnhanceStats stats;
  Box fine;
  std::uint64_t fragments = 0;
  for (auto _ : state) {
    fine = r.resample(terrain(), kOrigin, &stats);
    fragments += fine.voxel_count();
    benchmark::DoNotOptimize(fine.voxels().data());
  }
  report(state, fragments, fine, stats);
}
BENCHMARK(BM_ResampleWarm)->Args({16, 64})->Args({16, 512})->Unit(benchmark::kMillisecond);

// Re-enhancing after a one-voxel edit at the centre of the box.
void BM_SubdivideUpdate(benchmark::State& state) {
  const SubdivisionParams params{static_cast<int>(state.range(0)), SubdivisionThreshold{1, 3, 4, 40}};
  Box coarse = terrain();
  Box fine = subdivide(coarse, kOrigin, params);
  const Vec3i p{8, 8, 8};
  std::int64_t rewritten = 0;
  for (auto _ : state) {
    const Voxel v = coarse.get(p);
    coarse.set(p, enhance_solid(v) ? Voxel{kAir, 0} : solid(materials::kRock));
    rewritten +=
        subdivide_update(coarse, kOrigin, params, Region::from_min_size(kOrigin + p, {1, 1, 1}), fine).volume();
  }
  state.counters["updates/s"] =
      benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
  state.counters["fragments/update"] = static_cast<double>(rewritten) / static_cast<double>(state.iterations());
}
BENCHMARK(BM_SubdivideUpdate)->DenseRange(1, 4)->Unit(benchmark::kMicrosecond);

void BM_ResampleUpdate(benchmark::State& state) {
  Resampler r(ResampleParams{static_cast<int>(state.range(0)), 64, 1.0f, 0.25f, 1});
  Box coarse = terrain();
  Box fine = r.resample(coarse, kOrigin);
  const Vec3i p{8, 8, 8};
  std::int64_t rewritten = 0;
  for (auto _ : state) {
    const Voxel v = coarse.get(p);
    coarse.set(p, enhance_solid(v) ? Voxel{kAir, 0} : solid(materials::kRock));
    rewritten += r.update(coarse, kOrigin, Region::from_min_size(kOrigin + p, {1, 1, 1}), fine).volume();
  }
  state.counters["updates/s"] =
      benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
  state.counters["fragments/update"] = static_cast<double>(rewritten) / static_cast<double>(state.iterations());
}
BENCHMARK(BM_ResampleUpdate)->Arg(4)->Arg(16)->Unit(benchmark::kMicrosecond);

// Snowflake tracing of a 4x subdivision (64^3 fragments), default params.
void BM_Lighting(benchmark::State& state) {
  const Box fine = subdivide(terrain(), kOrigin, SubdivisionParams{2, SubdivisionThreshold::constant(2)});
  const LightingParams params;
  std::uint64_t lit = 0;
  for (auto _ : state) {
    const LightMap map = compute_lighting(fine, kOrigin * 4, params);
    for (const std::uint8_t v : map.light) lit += v != 0;
  }
  const std::uint64_t surface = count_surface(fine);
  state.counters["surface_frags"] = static_cast<double>(surface);
  state.counters["lit/s"] = benchmark::Counter(static_cast<double>(lit), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_Lighting)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace terrane

BENCHMARK_MAIN();
