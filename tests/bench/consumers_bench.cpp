// The consumers' benchmark: the subsystems that read voxels, each doing the
// same work on the row-packed grid and on the same content unpacked (every
// chunk's level 0 and mips as plain 2-byte-per-voxel arrays, the storage
// benchmark's "unpacked", in the same kind of map), on every dataset of
// tests/data and "generated" (the default world's terrain, seed 1, as in
// terrane-bench-storage), in one run. After the normal report it prints a
// table "consumer / dataset / packed ns / unpacked ns / ratio", the ratio
// being packed speed over unpacked speed (unpacked time / packed time; the
// goal is >= 0.9x), each time the CPU time of the fastest repetition (the
// machine may be shared: run with --benchmark_repetitions and
// --benchmark_enable_random_interleaving=true).
//
// Both sides run the product's own code, written once over a voxel source:
//   encode 16^3   encode_full_units (common/codec/chunk_units.h), what
//                 ChunkVersion::encoded(0) sends as a Full record
//   update 4^3    read_update_units + net_codec_encode_update_piece, what
//                 ChunkVersion::update_piece makes of a tick's changed units
//                 (here the 27 units of a 3^3 block of units in each chunk)
//   chunk hash    chunk_hash_of (protocol/chunk_hash.h), the replica checks'
//   ray cast      grid_raycast (common/voxel/grid_reads.h), Grid::raycast:
//                 rays of up to 64 voxels from random points
//   sweep         grid_collides, Grid::collides: a 0.6 x 1.8 x 0.6 box moved
//                 in 0.25-voxel steps along random 16-voxel paths
//   mesh L0, L1   the viewer's build_render_chunk over a VoxelSource: the
//                 8 level-0 render chunks (16^3) and the level-1 one (32^3)
//                 of every 8th chunk sampled
//   read_box 48   grid_read_box, Grid::read_box: 48^3 boxes across chunks
// Each consumer checks that both sides give the same answer before timing.
// The work runs over up to 256 of each dataset's chunks (every k-th, in the
// grid's order), the same on both sides.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "client/view/render_chunk.h"
#include "common/codec/chunk_units.h"
#include "common/voxel/grid.h"
#include "common/voxel/grid_reads.h"
#include "common/voxel/vec3_map.h"
#include "common/vxraw/vxraw.h"
#include "tests/bench/bench_datasets.h"
#include "common/world/terrain_generator.h"
#include "protocol/chunk_hash.h"

namespace terrane {
namespace {

// A chunk unpacked: level 0 and the three mips as plain boxes, with the
// reads of Chunk that the consumers use.
class UnpackedChunk {
 public:
  explicit UnpackedChunk(const Chunk& c) {
    for (int level = 0; level < kMipLevels; ++level) c.read_level(level, levels_[level]);
  }
  Voxel get(Vec3i p) const { return levels_[0].get(p); }
  const Voxel* read_row(int y, int z, Chunk::Level0::Row&) const { return levels_[0].read_row(y, z); }
  bool box_has_solid(Vec3i min, Vec3i max, std::uint8_t min_occupancy) const {
    return terrane::box_has_solid(levels_[0], min, max, min_occupancy);
  }
  void read_box(Vec3i min, Box& out, Vec3i out_offset, Vec3i size) const {
    for (int y = 0; y < size.y; ++y)
      for (int z = 0; z < size.z; ++z)
        std::copy_n(levels_[0].read_row(min.y + y, min.z + z) + min.x, size.x,
                    out.write_row(out_offset.y + y, out_offset.z + z) + out_offset.x);
  }
  void read_level(int level, Box& out) const { out = levels_[level]; }

 private:
  Box levels_[kMipLevels];
};

// The grid unpacked: the same map from chunk coordinates to owned chunks.
class UnpackedGrid {
 public:
  void put(Vec3i pos, const Chunk& c) { chunks_.emplace(pos, std::make_unique<UnpackedChunk>(c)); }
  const UnpackedChunk* find_chunk(Vec3i pos) const {
    auto it = chunks_.find(pos);
    return it == chunks_.end() ? nullptr : it->second.get();
  }

 private:
  Vec3iMap<std::unique_ptr<UnpackedChunk>> chunks_;
};

// The viewer's source over either grid, every chunk known at full resolution
// (GridSource's read and read_part, generic).
template <class G>
class Source final : public view::VoxelSource {
 public:
  explicit Source(const G& grid) : grid_(grid) {}
  int level(Vec3i) const override { return 0; }
  std::uint64_t revision(Vec3i) const override { return 0; }
  int read(Vec3i chunk_pos, int want, Box& out) const override {
    const int level = std::clamp(want, 0, kMipLevels - 1);
    if (const auto* c = grid_.find_chunk(chunk_pos)) {
      c->read_level(level, out);
    } else {
      const int n = kChunkSize >> level;
      out.resize({n, n, n});
    }
    return level;
  }
  int read_part(Vec3i chunk_pos, int want, const Region& part, Box& out) const override {
    if (const auto* c = grid_.find_chunk(chunk_pos)) {
      view::read_chunk_part(*c, want, part, out);
    } else {
      out.resize(part.size());
    }
    return want;
  }

 private:
  const G& grid_;
};

struct Dataset {
  std::string name;
  Grid packed;
  UnpackedGrid unpacked;
  Region bounds;                  // voxels
  std::vector<Vec3i> sample;      // chunk positions the work runs over
  std::vector<Vec3f> ray_origins, ray_dirs;
  std::vector<Vec3i> box_mins;    // read_box 48
  std::vector<Vec3f> sweep_from;  // sweep starts; each moves along sweep_dir
  std::vector<Vec3f> sweep_dir;
  std::vector<std::vector<std::uint16_t>> units;  // per sampled chunk
};

constexpr std::size_t kMaxSample = 256;
// Meshing is slow: it runs over every 8th chunk of the sample.
constexpr std::size_t kMeshStride = 8;

Dataset& dataset(const std::string& name) {
  static std::map<std::string, std::unique_ptr<Dataset>> cache;
  auto it = cache.find(name);
  if (it != cache.end()) return *it->second;
  auto d = std::make_unique<Dataset>();
  d->name = name;
  Box box;
  Vec3i origin;
  bench::load_dataset(name, "consumers bench", box, origin);
  d->bounds = Region::from_min_size(origin, box.size());
  d->packed.write_box(origin, box);
  d->packed.compact();
  std::vector<Vec3i> all;
  d->packed.for_each_chunk([&](Vec3i pos, const Chunk& c) {
    all.push_back(pos);
    d->unpacked.put(pos, c);
  });
  const std::size_t stride = std::max<std::size_t>(1, (all.size() + kMaxSample - 1) / kMaxSample);
  for (std::size_t i = 0; i < all.size(); i += stride) d->sample.push_back(all[i]);

  std::mt19937 rng(7);
  std::uniform_real_distribution<float> unit(-1.0f, 1.0f), in32(0.0f, 32.0f);
  std::uniform_int_distribution<std::size_t> pick(0, d->sample.size() - 1);
  std::uniform_int_distribution<int> block(0, 5);
  const auto random_dir = [&] {
    for (;;) {
      const Vec3f v{unit(rng), unit(rng), unit(rng)};
      if (v.x * v.x + v.y * v.y + v.z * v.z > 0.01f) return v;
    }
  };
  const auto random_point = [&] {
    const Vec3i o = chunk_origin(d->sample[pick(rng)]);
    return Vec3f{static_cast<float>(o.x) + in32(rng), static_cast<float>(o.y) + in32(rng),
                 static_cast<float>(o.z) + in32(rng)};
  };
  for (int i = 0; i < 2048; ++i) {
    d->ray_origins.push_back(random_point());
    d->ray_dirs.push_back(random_dir());
  }
  for (int i = 0; i < 512; ++i) {
    d->sweep_from.push_back(random_point());
    const Vec3f dir = random_dir();
    const float len = std::sqrt(dir.x * dir.x + dir.y * dir.y + dir.z * dir.z);
    d->sweep_dir.push_back(dir * (0.25f / len));  // one step
  }
  for (int i = 0; i < 64; ++i) d->box_mins.push_back(chunk_origin(d->sample[pick(rng)]) + Vec3i{7, 7, 7});
  for (std::size_t i = 0; i < d->sample.size(); ++i) {
    const int ux = block(rng), uy = block(rng), uz = block(rng);
    std::vector<std::uint16_t> u;
    for (int y = uy; y < uy + 3; ++y)
      for (int z = uz; z < uz + 3; ++z)
        for (int x = ux; x < ux + 3; ++x) u.push_back(static_cast<std::uint16_t>((y * 8 + z) * 8 + x));
    d->units.push_back(std::move(u));
  }
  return *cache.emplace(name, std::move(d)).first->second;
}

// --- the work, over either grid ------------------------------------------------

template <class G>
std::size_t encode_full(const G& g, const Dataset& d) {
  thread_local std::vector<std::uint8_t> out;
  std::size_t bytes = 0;
  for (const Vec3i p : d.sample) {
    out.clear();
    encode_full_units(g.find_chunk(p), out);
    bytes += out.size();
  }
  return bytes;
}

template <class G>
std::size_t update_units(const G& g, const Dataset& d) {
  std::vector<UnitUpdate> units;
  std::size_t bytes = 0;
  for (std::size_t i = 0; i < d.sample.size(); ++i) {
    units.clear();
    const auto* c = g.find_chunk(d.sample[i]);
    for (const std::uint16_t index : d.units[i]) {
      UnitUpdate u;
      u.chunk_pos = d.sample[i];
      u.unit_index = index;
      units.push_back(u);
    }
    read_update_units(c, std::span<UnitUpdate>(units));
    const UpdatePiece piece = net_codec_encode_update_piece(units);
    bytes += piece.rest.size();
  }
  return bytes;
}

template <class G>
std::uint64_t hashes(const G& g, const Dataset& d) {
  std::uint64_t h = 0;
  for (const Vec3i p : d.sample) h += chunk_hash_of(g.find_chunk(p), 1);
  return h;
}

template <class G>
std::uint64_t rays(const G& g, const Dataset& d) {
  std::uint64_t sum = 0;
  for (std::size_t i = 0; i < d.ray_origins.size(); ++i)
    if (const auto hit = grid_raycast(g, d.ray_origins[i], d.ray_dirs[i], 64.0f, 0))
      sum += static_cast<std::uint64_t>(hit->voxel.x * 7 + hit->voxel.y * 13 + hit->voxel.z) + 1000;
  return sum;
}

template <class G>
std::uint64_t sweeps(const G& g, const Dataset& d) {
  std::uint64_t hits = 0;
  for (std::size_t i = 0; i < d.sweep_from.size(); ++i) {
    Vec3f at = d.sweep_from[i];
    for (int s = 0; s < 64; ++s) {
      const Aabb box{at - Vec3f{0.3f, 0.9f, 0.3f}, at + Vec3f{0.3f, 0.9f, 0.3f}};
      hits += grid_collides(g, box, 0) ? 1 : 0;
      at = at + d.sweep_dir[i];
    }
  }
  return hits;
}

template <class G>
std::uint64_t mesh(const G& g, const Dataset& d, int level) {
  const Source<G> src(g);
  thread_local view::Mesh m;
  std::uint64_t triangles = 0;
  const int size = view::kRenderChunkCells << level;
  for (std::size_t i = 0; i < d.sample.size(); i += kMeshStride) {
    const Vec3i o = chunk_origin(d.sample[i]);
    for (int y = 0; y < kChunkSize; y += size)
      for (int z = 0; z < kChunkSize; z += size)
        for (int x = 0; x < kChunkSize; x += size) {
          view::build_render_chunk(src, view::NodeKey{o + Vec3i{x, y, z}, level}, level, m);
          triangles += m.triangle_count();
        }
  }
  return triangles;
}

template <class G>
std::uint64_t read_boxes(const G& g, const Dataset& d) {
  thread_local Box out({48, 48, 48});
  std::uint64_t sum = 0;
  for (const Vec3i at : d.box_mins) {
    grid_read_box(g, at, out);
    sum += out.voxels()[12345].material;
  }
  return sum;
}

// --- registration -----------------------------------------------------------------

struct Consumer {
  const char* name;
  std::uint64_t (*packed)(const Dataset&);
  std::uint64_t (*unpacked)(const Dataset&);
};

template <class Fn>
Consumer consumer(const char* name, Fn) {
  return {name, [](const Dataset& d) { return static_cast<std::uint64_t>(Fn{}(d.packed, d)); },
          [](const Dataset& d) { return static_cast<std::uint64_t>(Fn{}(d.unpacked, d)); }};
}

const std::vector<Consumer>& consumers() {
  static const std::vector<Consumer> all = {
      consumer("encode 16^3", [](const auto& g, const Dataset& d) { return encode_full(g, d); }),
      consumer("update 4^3", [](const auto& g, const Dataset& d) { return update_units(g, d); }),
      consumer("chunk hash", [](const auto& g, const Dataset& d) { return hashes(g, d); }),
      consumer("ray cast", [](const auto& g, const Dataset& d) { return rays(g, d); }),
      consumer("sweep", [](const auto& g, const Dataset& d) { return sweeps(g, d); }),
      consumer("mesh L0", [](const auto& g, const Dataset& d) { return mesh(g, d, 0); }),
      consumer("mesh L1", [](const auto& g, const Dataset& d) { return mesh(g, d, 1); }),
      consumer("read_box 48", [](const auto& g, const Dataset& d) { return read_boxes(g, d); }),
  };
  return all;
}

const char* const kDatasets[] = {"mc-1.9", "mc-1.16", "generated"};

std::string bench_name(const Consumer& c, const char* dataset, bool packed) {
  std::string n = c.name;
  std::replace(n.begin(), n.end(), ' ', '_');
  return n + "/" + dataset + (packed ? "/packed" : "/unpacked");
}

// Prints the table after the normal report: per consumer and dataset, the
// fastest repetition of each side and their ratio.
class TableReporter : public benchmark::ConsoleReporter {
 public:
  void ReportRuns(const std::vector<Run>& runs) override {
    for (const Run& r : runs) {
      if (r.error_occurred || r.run_type != Run::RT_Iteration) continue;
      const double t = r.GetAdjustedCPUTime();
      auto [it, fresh] = best_.try_emplace(r.benchmark_name(), t);
      if (!fresh) it->second = std::min(it->second, t);
    }
    ConsoleReporter::ReportRuns(runs);
  }
  void Finalize() override {
    ConsoleReporter::Finalize();
    std::printf("\n%-12s %-10s %14s %14s %7s\n", "consumer", "dataset", "packed ns", "unpacked ns", "ratio");
    std::vector<std::string> below;
    for (const Consumer& c : consumers())
      for (const char* d : kDatasets) {
        const auto p = best_.find(bench_name(c, d, true)), u = best_.find(bench_name(c, d, false));
        if (p == best_.end() || u == best_.end()) continue;
        const double ratio = u->second / p->second;
        std::printf("%-12s %-10s %14.0f %14.0f %6.2fx\n", c.name, d, p->second, u->second, ratio);
        if (ratio < 0.9) below.push_back(std::string(c.name) + " on " + d);
      }
    std::printf("below 0.9x: %s\n", below.empty() ? "none" : "");
    for (const auto& b : below) std::printf("  %s\n", b.c_str());
  }

 private:
  std::map<std::string, double> best_;
};

}  // namespace
}  // namespace terrane

int main(int argc, char** argv) {
  using namespace terrane;
  benchmark::Initialize(&argc, argv);
  for (const char* name : kDatasets) {
    Dataset& d = dataset(name);
    std::printf("%-10s chunks sampled %zu\n", name, d.sample.size());
    for (const Consumer& c : consumers()) {
      // Same work, same answer: the unpacked side is the packed side's content.
      if (c.packed(d) != c.unpacked(d)) {
        std::fprintf(stderr, "consumers bench: %s on %s differs between packed and unpacked\n", c.name, name);
        return 1;
      }
      for (const bool packed : {true, false}) {
        const auto fn = packed ? c.packed : c.unpacked;
        benchmark::RegisterBenchmark(bench_name(c, name, packed).c_str(),
                                     [fn, &d](benchmark::State& state) {
                                       for (auto _ : state) benchmark::DoNotOptimize(fn(d));
                                     });
      }
    }
  }
  TableReporter reporter;
  benchmark::RunSpecifiedBenchmarks(&reporter);
  benchmark::Shutdown();
  return 0;
}
