#include "common/world/world.h"

#include "common/world/sqlite_store.h"

#include <algorithm>
#include <map>

namespace terrane {

WorldMeta default_world_meta(std::uint64_t seed) {
  WorldMeta m;
  m.generator = GeneratorKind::kTerrain;
  GeneratorParams p;
  p.seed = seed;
  m.generator_params = TerrainGenerator(p).to_metadata();
  m.materials = default_material_names();
  return m;
}

World::World(std::unique_ptr<WorldStore> store) : store_(std::move(store)) {}

FileStatus World::init_generator() {
  if (meta().generator != GeneratorKind::kTerrain) return Ok{};
  std::string message;
  auto gen = TerrainGenerator::from_metadata(meta().generator_params, &message);
  if (!gen) return FileError{store_->where() + ": generator parameters: " + message, gen.error()};
  generator_.emplace(std::move(*gen));
  return Ok{};
}

FileResult<std::unique_ptr<World>> World::open(const std::string& dir) {
  auto store = SqliteStore::open(dir);
  if (!store) return store.error();
  return open(std::move(*store));
}

FileResult<std::unique_ptr<World>> World::open(std::unique_ptr<WorldStore> store) {
  std::unique_ptr<World> w(new World(std::move(store)));
  if (auto s = w->init_generator(); !s) return s.error();
  return w;
}

FileResult<std::unique_ptr<World>> World::create(const std::string& dir, const WorldMeta& meta) {
  if (meta.generator == GeneratorKind::kTerrain) {
    std::string message;
    if (!TerrainGenerator::from_metadata(meta.generator_params, &message))
      return FileError{"world " + dir + ": generator parameters: " + message, {}};
  }
  auto store = SqliteStore::create(dir, meta);
  if (!store) return store.error();
  std::unique_ptr<World> w(new World(std::move(*store)));
  if (auto s = w->init_generator(); !s) return s.error();
  return w;
}

void World::generate_chunk_box(Vec3i chunk_pos, Box& out) const {
  out.resize({kChunkSize, kChunkSize, kChunkSize});
  const Region full = chunk_region(chunk_pos);
  const Region inside = meta().bounds.clamp(full);
  if (!generator_ || inside.empty()) return;
  if (inside == full) {
    generator_->generate(full, out);
    return;
  }
  Box part;
  generator_->generate(inside, part);
  const Vec3i off = inside.min - full.min;
  const Vec3i s = inside.size();
  for (int y = 0; y < s.y; ++y)
    for (int z = 0; z < s.z; ++z)
      std::copy_n(part.read_row(y, z), s.x, out.write_row(off.y + y, off.z + z) + off.x);
}

bool World::generates_air(Vec3i chunk_pos) const {
  const Region inside = meta().bounds.clamp(chunk_region(chunk_pos));
  return !generator_ || inside.empty() || generator_->all_air(inside);
}

namespace {

// Estimates of chunks at side^3 voxels each (a divisor of 32), one
// coarse_sample per column stack; put(i, voxel index in Box order, voxel)
// for the i-th chunk. Cells outside the bounds are Air, as generate_chunk's
// voxels.
template <class Put>
void estimate_cells(const TerrainGenerator& generator, const WorldBounds& bounds, std::span<const Vec3i> chunks,
                    int side, Put&& put) {
  const int cell = kChunkSize / side;  // voxels a side per estimated voxel
  // Column stacks: the chunks of each (x, z), sampled in one call.
  std::map<std::pair<std::int32_t, std::int32_t>, std::vector<std::size_t>> stacks;
  for (std::size_t i = 0; i < chunks.size(); ++i) stacks[{chunks[i].x, chunks[i].z}].push_back(i);
  Box cells;
  for (const auto& [xz, members] : stacks) {
    std::int32_t lo = chunks[members.front()].y, hi = lo;
    for (const std::size_t i : members) {
      lo = std::min(lo, chunks[i].y);
      hi = std::max(hi, chunks[i].y);
    }
    generator.coarse_sample(Vec3i{xz.first, lo, xz.second} * kChunkSize, cell, Vec3i{side, side * (hi - lo + 1), side},
                            cells);
    for (const std::size_t i : members) {
      const int y0 = (chunks[i].y - lo) * side;
      const Vec3i base = chunks[i] * kChunkSize;
      for (int y = 0; y < side; ++y)
        for (int z = 0; z < side; ++z)
          for (int x = 0; x < side; ++x) {
            const Vec3i centre = base + Vec3i{x, y, z} * cell + Vec3i{cell / 2, cell / 2, cell / 2};
            put(i, static_cast<std::size_t>((y * side + z) * side + x),
                bounds.contains(centre) ? cells.get({x, y0 + y, z}) : Voxel{});
          }
    }
  }
}

}  // namespace

std::vector<CoarseVoxels> World::estimate_coarse(std::span<const Vec3i> chunks) const {
  std::vector<CoarseVoxels> out(chunks.size(), CoarseVoxels{});
  if (!generator_) return out;
  estimate_cells(*generator_, meta().bounds, chunks, kCoarseSide,
                 [&](std::size_t i, std::size_t at, Voxel v) { out[i][at] = v; });
  return out;
}

void World::estimate_horizon(std::span<const Vec3i> chunks, HorizonBuilder& out) const {
  if (!generator_ || chunks.empty()) return;
  // One coarse_sample over the box of the chunks' cells (a region's columns
  // share their slopes' neighbours): cells of 16 voxels at level 4, 32 at
  // level 5, 64 (a block of 2^3 chunks) at level 6. A cell whose centre is
  // outside the bounds is Air, as in generate_chunk; at level 6 a chunk's
  // own centre decides, as at level 5.
  const int cell = 1 << out.level();
  const int per = kChunkSize / cell;  // cells a side per chunk (0 at level 6: 2 chunks a cell)
  Vec3i lo = chunks.front(), hi = chunks.front();
  for (const Vec3i cp : chunks) {
    lo = Vec3i{std::min(lo.x, cp.x), std::min(lo.y, cp.y), std::min(lo.z, cp.z)};
    hi = Vec3i{std::max(hi.x, cp.x), std::max(hi.y, cp.y), std::max(hi.z, cp.z)};
  }
  const Vec3i origin = per > 0 ? lo * kChunkSize : floor_div(lo, 2) * (2 * kChunkSize);
  const Vec3i count = per > 0 ? (hi - lo + Vec3i{1, 1, 1}) * per : floor_div(hi, 2) - floor_div(lo, 2) + Vec3i{1, 1, 1};
  Box cells;
  generator_->coarse_sample(origin, cell, count, cells);
  const WorldBounds& bounds = meta().bounds;
  if (per == 0) {
    for (const Vec3i cp : chunks) {
      const Vec3i centre = cp * kChunkSize + Vec3i{kChunkSize / 2, kChunkSize / 2, kChunkSize / 2};
      const Voxel v = bounds.contains(centre) ? cells.get(floor_div(cp, 2) - floor_div(lo, 2)) : Voxel{};
      out.put(cp, std::span<const Voxel>(&v, 1));
    }
    return;
  }
  std::vector<Voxel> voxels(static_cast<std::size_t>(per) * per * per);
  for (const Vec3i cp : chunks) {
    const Vec3i at = (cp - lo) * per;
    for (int y = 0; y < per; ++y)
      for (int z = 0; z < per; ++z)
        for (int x = 0; x < per; ++x) {
          const Vec3i centre = cp * kChunkSize + Vec3i{x, y, z} * cell + Vec3i{cell / 2, cell / 2, cell / 2};
          voxels[static_cast<std::size_t>((y * per + z) * per + x)] =
              bounds.contains(centre) ? cells.get(at + Vec3i{x, y, z}) : Voxel{};
        }
    out.put(cp, voxels);
  }
}

Chunk World::generate_chunk(Vec3i chunk_pos) const {
  // Sky known from the columns alone: no voxel to evaluate.
  if (generates_air(chunk_pos)) return Chunk(kAir);
  Box box;
  generate_chunk_box(chunk_pos, box);
  // Sky (most chunks of a generated world): no rows to pack, no mips to build.
  if (all_air(box.voxels()))
    return Chunk(kAir);
  return Chunk::from_box(box);
}

FileResult<StoredChunk> World::load_chunk(Vec3i chunk_pos) {
  auto stored = store_->load_chunk(chunk_pos);
  if (!stored) return stored.error();
  if (stored->has_value()) return std::move(**stored);
  // Never stored, or quarantined: generated, with revisions continuing
  // above any quarantined row so they only grow.
  auto floor = store_->quarantined_revision(chunk_pos);
  if (!floor) return floor.error();
  return StoredChunk{floor->has_value() ? **floor + 1 : 0, generate_chunk(chunk_pos)};
}

FileStatus World::read_box(Vec3i min, Box& out) {
  const Region r = Region::from_min_size(min, out.size());
  FileStatus status = Ok{};
  for_each_chunk_in(r, [&](Vec3i cp) {
    if (!status) return;
    auto chunk = load_chunk(cp);
    if (!chunk) {
      status = chunk.error();
      return;
    }
    const Region part = intersect(r, chunk_region(cp));
    chunk->chunk.read_box(part.min - chunk_origin(cp), out, part.min - min, part.size());
  });
  return status;
}

FileStatus World::write_box(Vec3i min, const Box& src) {
  const Region target = meta().bounds.clamp(Region::from_min_size(min, src.size()));
  std::vector<ChunkWrite> writes;
  FileStatus status = Ok{};
  for_each_chunk_in(target, [&](Vec3i cp) {
    if (!status) return;
    auto chunk = load_chunk(cp);
    if (!chunk) {
      status = chunk.error();
      return;
    }
    const Vec3i origin = chunk_origin(cp);
    chunk->chunk.modify(Region{target.min - origin, target.max - origin},
                        [&](Vec3i l, Voxel) { return src.get(l + origin - min); });
    writes.push_back(
        ChunkWrite{cp, chunk->revision + 1, encode_chunk_blob(chunk->chunk), coarse_voxels(&chunk->chunk)});
  });
  if (!status || writes.empty()) return status;
  return store_->save_chunks(writes);
}

}  // namespace terrane
