// Terrain generation throughput: 32^3 chunks across the default world box
// (512 x 256 x 512 around the origin, y in [-64, 192)), plus the share of
// non-empty and partially occupied voxels it produces.
#include <benchmark/benchmark.h>

#include <cstdint>

#include "common/voxel/box.h"
#include "common/world/terrain_generator.h"

namespace terrane {
namespace {

constexpr int kChunk = 32;
constexpr Vec3i kBoxChunks{16, 8, 16};
constexpr Vec3i kBoxMin{-256, -64, -256};

Region chunk_region(std::int64_t i) {
  const int n = kBoxChunks.x * kBoxChunks.y * kBoxChunks.z;
  const int k = static_cast<int>(i % n);
  const Vec3i c{k % kBoxChunks.x, (k / kBoxChunks.x) % kBoxChunks.y, k / (kBoxChunks.x * kBoxChunks.y)};
  return Region::from_min_size(kBoxMin + c * kChunk, {kChunk, kChunk, kChunk});
}

// Cycles through the 2048 chunks of the default box, one per iteration.
void BM_GenerateDefaultBoxChunks(benchmark::State& state) {
  const TerrainGenerator gen(GeneratorParams{});
  Box box;
  std::int64_t i = 0, total = 0, non_empty = 0, partial = 0;
  for (auto _ : state) {
    gen.generate(chunk_region(i++), box);
    for (const Voxel v : box.voxels()) {
      non_empty += v.material != kAir;
      partial += v.material != kAir && v.occupancy != kFullOccupancy;
    }
    total += static_cast<std::int64_t>(box.voxel_count());
    benchmark::DoNotOptimize(box.voxels().data());
  }
  state.SetItemsProcessed(total);
  state.counters["voxels/s"] = benchmark::Counter(static_cast<double>(total), benchmark::Counter::kIsRate);
  state.counters["non_empty_%"] = 100.0 * static_cast<double>(non_empty) / static_cast<double>(total);
  state.counters["partial_%"] = 100.0 * static_cast<double>(partial) / static_cast<double>(total);
}
BENCHMARK(BM_GenerateDefaultBoxChunks)->Unit(benchmark::kMicrosecond)->Iterations(2048);

// The whole default box, chunk by chunk: seconds per 67M-voxel world.
void BM_GenerateWholeDefaultBox(benchmark::State& state) {
  const TerrainGenerator gen(GeneratorParams{});
  Box box;
  const int n = kBoxChunks.x * kBoxChunks.y * kBoxChunks.z;
  std::int64_t total = 0, non_empty = 0, partial = 0;
  for (auto _ : state) {
    for (int i = 0; i < n; ++i) {
      gen.generate(chunk_region(i), box);
      for (const Voxel v : box.voxels()) {
        non_empty += v.material != kAir;
        partial += v.material != kAir && v.occupancy != kFullOccupancy;
      }
      total += static_cast<std::int64_t>(box.voxel_count());
    }
    benchmark::DoNotOptimize(box.voxels().data());
  }
  state.SetItemsProcessed(total);
  state.counters["non_empty_%"] = 100.0 * static_cast<double>(non_empty) / static_cast<double>(total);
  state.counters["partial_%"] = 100.0 * static_cast<double>(partial) / static_cast<double>(total);
}
BENCHMARK(BM_GenerateWholeDefaultBox)->Unit(benchmark::kMillisecond)->Iterations(1);

// The scalar reference path, one voxel at a time near the surface.
void BM_VoxelAt(benchmark::State& state) {
  const TerrainGenerator gen(GeneratorParams{});
  std::int32_t i = 0;
  for (auto _ : state) {
    const Vec3i p{(i * 37) % 512 - 256, 20 + (i * 13) % 64, (i * 91) % 512 - 256};
    benchmark::DoNotOptimize(gen.voxel_at(p));
    ++i;
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_VoxelAt);

}  // namespace
}  // namespace terrane

BENCHMARK_MAIN();
