// Meshing throughput of the viewer: render chunks per second over the
// default world's generated terrain (256 x 192 x 256 voxels around the
// origin), at each render chunk level (16^3 at full resolution, 32^3 at
// 1/2, 64^3 at 1/4, 128^3 at 1/8): sampling from a Grid plus surface nets.
// Every render chunk of the box counts (buried and empty ones are cheap);
// surface chunks are those with triangles.
#include <benchmark/benchmark.h>

#include "client/view/render_chunk.h"
#include "common/world/terrain_generator.h"
#include "common/world/world.h"

namespace terrane::view {
namespace {

constexpr Region kBox{{-128, -32, -128}, {128, 160, 128}};

const Grid& terrain() {
  static Grid* grid = [] {
    auto* g = new Grid();
    auto gen = TerrainGenerator::from_metadata(default_world_meta().generator_params);
    Box b;
    gen->generate(kBox, b);
    g->write_box(kBox.min, b);
    return g;
  }();
  return *grid;
}

void BM_MeshRenderChunks(benchmark::State& state) {
  const int level = static_cast<int>(state.range(0));
  const Grid& g = terrain();
  GridSource src(g, {floor_div(kBox.min, 32), floor_div(kBox.max - Vec3i{1, 1, 1}, 32) + Vec3i{1, 1, 1}});
  std::vector<NodeKey> keys;
  const int size = kRenderChunkCells << level;
  for (int y = kBox.min.y; y < kBox.max.y; y += size)
    for (int z = kBox.min.z; z < kBox.max.z; z += size)
      for (int x = kBox.min.x; x < kBox.max.x; x += size) keys.push_back({{x, y, z}, level});
  Mesh mesh;
  std::int64_t chunks = 0, surface = 0, triangles = 0;
  for (auto _ : state) {
    for (const NodeKey& k : keys) {
      build_render_chunk(src, k, level, mesh);
      ++chunks;
      surface += mesh.empty() ? 0 : 1;
      triangles += static_cast<std::int64_t>(mesh.triangle_count());
    }
    benchmark::DoNotOptimize(mesh.indices.data());
  }
  state.counters["chunks/s"] = benchmark::Counter(static_cast<double>(chunks), benchmark::Counter::kIsRate);
  state.counters["surface_chunks/s"] = benchmark::Counter(static_cast<double>(surface), benchmark::Counter::kIsRate);
  state.counters["triangles/s"] = benchmark::Counter(static_cast<double>(triangles), benchmark::Counter::kIsRate);
  state.counters["surface_share"] = static_cast<double>(surface) / static_cast<double>(std::max<std::int64_t>(chunks, 1));
}
BENCHMARK(BM_MeshRenderChunks)->DenseRange(0, 3)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace terrane::view

BENCHMARK_MAIN();
