// Storage benchmark: memory of the row-packed grid against the same content
// unpacked, read_row and box reads over packed versus unpacked chunks (the
// ratio is printed), writes (single voxel, box, repeated tiny writes), and
// making chunks: from their voxels (packing and mips) and from stored blobs
// of both codecs (common/world/WORLD_FORMAT.md).
//
// Memory counts every byte the grid holds: row headers, row data, mips,
// Chunk objects and the hash map (nodes and buckets, through a counting
// allocator). "Unpacked" is the article's Memory #1: each chunk as plain
// 2-byte-per-voxel arrays for level 0 and its three mips, plus the same
// map. Datasets: the real regions in tests/data (VXRAW) and "generated", a
// 512 × 256 × 512 box of the default world's terrain (seed 1) made in process.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cstdio>
#include <map>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "common/voxel/grid.h"
#include "common/world/terrain_generator.h"
#include "common/vxraw/vxraw.h"
#include "tests/bench/bench_datasets.h"
#include "common/world/sqlite_store.h"

namespace terrane {
namespace {

struct Dataset {
  std::string name;
  std::unique_ptr<Grid> grid;
  std::vector<Vec3i> chunk_positions;
  std::vector<Box> unpacked;  // level 0 of each chunk, same order
  std::int64_t voxels = 0;
  std::int64_t non_empty = 0;
};

Dataset& dataset(const std::string& name) {
  static std::map<std::string, Dataset> cache;
  auto it = cache.find(name);
  if (it != cache.end()) return it->second;
  Dataset d;
  d.name = name;
  d.grid = std::make_unique<Grid>();
  Vec3i origin;
  Box box;
  bench::load_dataset(name, "storage bench", box, origin);
  d.voxels = static_cast<std::int64_t>(box.voxel_count());
  for (const Voxel v : box.voxels()) d.non_empty += v.material != kAir;
  d.grid->write_box(origin, box);
  d.grid->compact();
  d.grid->for_each_chunk([&](Vec3i pos, const Chunk& c) {
    d.chunk_positions.push_back(pos);
    Box b;
    c.read_level(0, b);
    d.unpacked.push_back(std::move(b));
  });
  return cache.emplace(name, std::move(d)).first->second;
}

void print_memory(const std::string& name) {
  Dataset& d = dataset(name);
  const GridMemory m = d.grid->memory();
  constexpr std::size_t kUnpackedChunk = 2 * (32 * 32 * 32 + 16 * 16 * 16 + 8 * 8 * 8 + 4 * 4 * 4);
  const std::size_t unpacked = m.map_bytes + m.object_bytes + m.chunks * kUnpackedChunk;
  const double ne = static_cast<double>(d.non_empty);
  std::printf("%-8s voxels %lld, non-empty %lld, chunks %zu\n", name.c_str(),
              static_cast<long long>(d.voxels), static_cast<long long>(d.non_empty), m.chunks);
  std::printf("  memory unpacked   %10zu bytes  %.3f B/non-empty voxel\n", unpacked, static_cast<double>(unpacked) / ne);
  std::printf("  memory row-packed %10zu bytes  %.3f B/non-empty voxel  (map %zu, objects %zu, level0 %zu, mips %zu)\n",
              m.total(), static_cast<double>(m.total()) / ne, m.map_bytes, m.object_bytes, m.level0_bytes,
              m.mip_bytes);
  const RowPackedStats& s = m.level0_rows;  // level-0 row forms over all chunks
  const double rows = static_cast<double>(s.uniform_rows + s.raw_rows + s.index_rows + s.run_rows);
  const std::size_t headers = m.level0_bytes - s.data_bytes;
  std::printf("  level-0 rows: uniform %.1f%%, index records %.1f%%, run records %.1f%%, raw %.1f%%; "
              "with occupancy %.1f%%, shared %.1f%%\n",
              100.0 * static_cast<double>(s.uniform_rows) / rows, 100.0 * static_cast<double>(s.index_rows) / rows,
              100.0 * static_cast<double>(s.run_rows) / rows, 100.0 * static_cast<double>(s.raw_rows) / rows,
              100.0 * static_cast<double>(s.occupancy_rows) / rows, 100.0 * static_cast<double>(s.shared_rows) / rows);
  std::printf("  level-0 bytes: headers %zu (%.3f B/nev), palette tables %zu (%.3f), records %zu (%.3f); "
              "mip units %.3f B/nev\n",
              headers, static_cast<double>(headers) / ne, s.table_bytes, static_cast<double>(s.table_bytes) / ne,
              s.data_bytes - s.table_bytes, static_cast<double>(s.data_bytes - s.table_bytes) / ne,
              static_cast<double>(m.mip_bytes) / ne);
  std::printf("  level-0 records by kind: run %.3f, index %.3f, raw %.3f B/nev (inline palettes %.3f of them); "
              "layers with headers: narrow %zu, wide %zu\n",
              static_cast<double>(s.run_bytes) / ne, static_cast<double>(s.index_bytes) / ne,
              static_cast<double>(s.raw_bytes) / ne, static_cast<double>(s.inline_palette_bytes) / ne,
              s.narrow_layers, s.wide_layers);
  // Where the headers go: layers (one y, all 32 rows) whose rows are all
  // uniform with one material hold 64 bytes of headers that say one value.
  std::size_t owning = 0, alike_layers = 0;
  d.grid->for_each_chunk([&](Vec3i, const Chunk& c) {
    if (c.level0().is_uniform()) return;
    ++owning;
    for (int y = 0; y < 32; ++y) {
      bool alike = true;
      const Material first = c.get(0, y, 0).material;
      for (int z = 0; z < 32 && alike; ++z)
        alike = c.level0().record_tag(y, z) < 0 && c.get(0, y, z).material == first;
      alike_layers += alike ? 1 : 0;
    }
  });
  std::printf("  level-0 headers: %zu chunks own them; layers of one uniform material %.1f%% (%.3f B/nev of headers)\n",
              owning, 100.0 * static_cast<double>(alike_layers) / static_cast<double>(std::max<std::size_t>(owning * 32, 1)),
              static_cast<double>(alike_layers * 64) / ne);
}

// Consumes a row the way meshing or physics would: touches every voxel.
inline std::uint32_t consume(const Voxel* row) {
  std::uint32_t s = 0;
  for (int x = 0; x < 32; ++x) s += row[x].occupancy + row[x].material;
  return s;
}

void BM_ReadRowPacked(benchmark::State& state, const std::string& name) {
  Dataset& d = dataset(name);
  std::vector<const Chunk*> chunks;
  for (Vec3i p : d.chunk_positions) chunks.push_back(d.grid->find_chunk(p));
  Chunk::Level0::Row scratch;
  for (auto _ : state) {
    std::uint32_t sum = 0;
    for (const Chunk* c : chunks)
      for (int y = 0; y < 32; ++y)
        for (int z = 0; z < 32; ++z) sum += consume(c->read_row(y, z, scratch));
    benchmark::DoNotOptimize(sum);
  }
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(chunks.size()) * 32 * 32 * 32);
}

void BM_ReadRowUnpacked(benchmark::State& state, const std::string& name) {
  Dataset& d = dataset(name);
  for (auto _ : state) {
    std::uint32_t sum = 0;
    for (const Box& b : d.unpacked)
      for (int y = 0; y < 32; ++y)
        for (int z = 0; z < 32; ++z) sum += consume(b.read_row(y, z));
    benchmark::DoNotOptimize(sum);
  }
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(d.unpacked.size()) * 32 * 32 * 32);
}

// Whole-box read: a 48³ box at random places across chunk borders.
void BM_ReadBox(benchmark::State& state, const std::string& name) {
  Dataset& d = dataset(name);
  std::mt19937 rng(1);
  std::uniform_int_distribution<std::size_t> pick(0, d.chunk_positions.size() - 1);
  Box out({48, 48, 48});
  for (auto _ : state) {
    const Vec3i at = chunk_origin(d.chunk_positions[pick(rng)]) + Vec3i{7, 7, 7};
    d.grid->read_box(at, out);
    benchmark::DoNotOptimize(out.voxels().data());
  }
  state.SetItemsProcessed(state.iterations() * 48 * 48 * 48);
}

// Grid writes alone: the chunks' mips are updated but left unpacked (see
// BM_SphereEdits for a write with its mips encoded).
void BM_WriteSingleVoxel(benchmark::State& state) {
  Grid g;
  g.fill(Region{{0, 0, 0}, {64, 64, 64}}, solid(materials::kRock));
  std::mt19937 rng(2);
  std::uniform_int_distribution<int> c(0, 63), occ(0, 255);
  for (auto _ : state) {
    g.set({c(rng), c(rng), c(rng)}, make_voxel(materials::kMud, static_cast<std::uint8_t>(occ(rng))));
  }
  state.SetItemsProcessed(state.iterations());
}

// The article's pathological case: tiny writes that flip row classes,
// each of which would repack the chunk without the unpack fallback.
void BM_WriteRepeatedTiny(benchmark::State& state) {
  Chunk chunk(materials::kRock);
  std::mt19937 rng(3);
  std::uniform_int_distribution<int> c(0, 31);
  int i = 0;
  for (auto _ : state) {
    const Voxel v = (++i & 1) ? make_voxel(materials::kMud, 100) : solid(materials::kRock);
    chunk.set({c(rng), c(rng), c(rng)}, v);
  }
  state.SetItemsProcessed(state.iterations());
}

void BM_WriteBox(benchmark::State& state) {
  Grid g;
  const int n = static_cast<int>(state.range(0));
  Box src({n, n, n});
  std::mt19937 rng(4);
  std::uniform_int_distribution<int> occ(0, 255);
  for (auto& v : src.voxels()) v = make_voxel(materials::kSand, static_cast<std::uint8_t>(occ(rng)));
  int k = 0;
  for (auto _ : state) {
    g.write_box({(k * 13) % 64, 0, (k * 7) % 64}, src);
    ++k;
  }
  state.SetItemsProcessed(state.iterations() * n * n * n);
  state.SetBytesProcessed(state.iterations() * n * n * n * 2);
}

// What a chunk costs to make from its voxels: packing the rows and building
// the three mips (every load, generation and coarse view pays it).
void BM_ChunkFromBox(benchmark::State& state, const std::string& name) {
  Dataset& d = dataset(name);
  for (auto _ : state)
    for (const Box& b : d.unpacked) {
      Chunk c = Chunk::from_box(b);
      benchmark::DoNotOptimize(&c);
    }
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(d.unpacked.size()));
}

// A stored chunk's load: its blob decoded into a Chunk, in codec 1 (byte
// RLE + LZ4 of the voxels: packed and mips built on load) or codec 2 (the
// chunk image: copied and checked). bytes_per_chunk: the blobs' mean size.
void BM_DecodeChunkBlob(benchmark::State& state, const std::string& name, int codec) {
  Dataset& d = dataset(name);
  std::vector<std::vector<std::uint8_t>> blobs;
  std::size_t bytes = 0;
  for (const Box& b : d.unpacked) {
    blobs.push_back(codec == 1 ? encode_chunk_blob_byte_rle(b) : encode_chunk_blob(Chunk::from_box(b)));
    bytes += blobs.back().size();
  }
  for (auto _ : state)
    for (const auto& blob : blobs) {
      auto c = decode_chunk_blob(blob);
      benchmark::DoNotOptimize(&c);
    }
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(blobs.size()));
  state.counters["bytes_per_chunk"] = static_cast<double>(bytes) / static_cast<double>(blobs.size());
}

// Edit throughput: spheres of radius 1..3 (dig, or fill with sand) at random
// places in the dataset's chunks, each applied to the grid and its touched
// chunks' mips encoded again, as the world strand does for a tick with one
// edit. One item is one sphere.
void BM_SphereEdits(benchmark::State& state, const std::string& name) {
  Dataset& d = dataset(name);
  Grid g;
  for (std::size_t i = 0; i < d.chunk_positions.size(); ++i) g.put_chunk(d.chunk_positions[i], Chunk::from_box(d.unpacked[i]));
  std::mt19937 rng(5);
  std::uniform_int_distribution<std::size_t> pick(0, d.chunk_positions.size() - 1);
  std::uniform_int_distribution<int> c(0, 31), rad(1, 3), coin(0, 1);
  for (auto _ : state) {
    const Vec3i center = chunk_origin(d.chunk_positions[pick(rng)]) + Vec3i{c(rng), c(rng), c(rng)};
    const int r = rad(rng);
    const Voxel fill = coin(rng) ? Voxel{} : solid(materials::kSand);
    const Region box{center - Vec3i{r, r, r}, center + Vec3i{r + 1, r + 1, r + 1}};
    g.modify(box, [&](Vec3i p, Voxel old) {
      const Vec3i q = p - center;
      return q.x * q.x + q.y * q.y + q.z * q.z <= r * r ? fill : old;
    });
    for_each_chunk_in(box, [&](Vec3i cp) { g.pack_mips(cp); });
  }
  state.SetItemsProcessed(state.iterations());
}

// Prints each packed/unpacked pair's speed ratio after the normal report.
class RatioReporter : public benchmark::ConsoleReporter {
 public:
  void ReportRuns(const std::vector<Run>& runs) override {
    for (const Run& r : runs)
      if (!r.error_occurred) times_[r.benchmark_name()] = r.GetAdjustedRealTime();
    ConsoleReporter::ReportRuns(runs);
  }
  void Finalize() override {
    ConsoleReporter::Finalize();
    for (const char* name : {"mc-1.9", "mc-1.16", "generated"}) {
      const auto p = times_.find(std::string("BM_ReadRowPacked/") + name);
      const auto u = times_.find(std::string("BM_ReadRowUnpacked/") + name);
      if (p != times_.end() && u != times_.end())
        std::printf("read_row speed, packed / unpacked on %s: %.2fx\n", name, u->second / p->second);
    }
  }

 private:
  std::map<std::string, double> times_;
};

}  // namespace
}  // namespace terrane

int main(int argc, char** argv) {
  using namespace terrane;
  benchmark::Initialize(&argc, argv);
  std::printf("Grid memory on real regions (tests/data) and generated terrain:\n");
  for (const char* name : {"mc-1.9", "mc-1.16", "generated"}) print_memory(name);
  std::printf("\n");
  for (const char* name : {"mc-1.9", "mc-1.16", "generated"}) {
    benchmark::RegisterBenchmark((std::string("BM_ReadRowPacked/") + name).c_str(), BM_ReadRowPacked, std::string(name));
    benchmark::RegisterBenchmark((std::string("BM_ReadRowUnpacked/") + name).c_str(), BM_ReadRowUnpacked, std::string(name));
    benchmark::RegisterBenchmark((std::string("BM_ReadBox48/") + name).c_str(), BM_ReadBox, std::string(name));
    benchmark::RegisterBenchmark((std::string("BM_ChunkFromBox/") + name).c_str(), BM_ChunkFromBox, std::string(name));
    for (int codec : {1, 2})
      benchmark::RegisterBenchmark((std::string("BM_DecodeChunkBlob/codec") + std::to_string(codec) + "/" + name).c_str(),
                                   BM_DecodeChunkBlob, std::string(name), codec);
    benchmark::RegisterBenchmark((std::string("BM_SphereEdits/") + name).c_str(), BM_SphereEdits, std::string(name));
  }
  benchmark::RegisterBenchmark("BM_WriteSingleVoxel", BM_WriteSingleVoxel);
  benchmark::RegisterBenchmark("BM_WriteRepeatedTiny", BM_WriteRepeatedTiny);
  benchmark::RegisterBenchmark("BM_WriteBox", BM_WriteBox)->Arg(4)->Arg(16)->Arg(48);
  RatioReporter reporter;
  benchmark::RunSpecifiedBenchmarks(&reporter);
  benchmark::Shutdown();
  return 0;
}
