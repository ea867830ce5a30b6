// Grid: the sparse, unbounded voxel grid — a hash map from signed chunk
// coordinates to 32³ row-packed chunks (the article's
// HashMap<Vector3int32, Chunk>). Voxel coordinates map to chunks by floor
// division, so negative coordinates work. A chunk absent from the map is all
// Air; a chunk that becomes all Air is freed.
//
// A chunk is the grid's own, or shared with other grids and caches
// (put_shared_chunk: the replicas of one process holding equal chunks);
// a shared chunk is never changed in place: the first write to it in a
// grid gives that grid a copy of its own (copy on write).
// Memory is counted exactly: the map's table (a flat Vec3iMap) and the
// chunks' own heap bytes (see memory(); a shared chunk counts as its
// share, bytes / holders).
// Thread-safety: const methods may run concurrently; writes need exclusion.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>

#include "common/voxel/box.h"
#include "common/voxel/chunk.h"
#include "common/voxel/grid_reads.h"
#include "common/voxel/vec3.h"
#include "common/voxel/vec3_map.h"

namespace terrane {

struct GridMemory {
  std::size_t chunks = 0;
  std::size_t map_bytes = 0;      // the hash map's table
  std::size_t object_bytes = 0;   // Chunk objects
  std::size_t level0_bytes = 0;   // 32³ headers and row data
  std::size_t mip_bytes = 0;      // mip headers and row data
  std::size_t shared_chunks = 0;  // of chunks, held shared (put_shared_chunk)
  RowPackedStats level0_rows;     // row classes over all chunks
  std::size_t total() const { return map_bytes + object_bytes + level0_bytes + mip_bytes; }
};

class Grid {
 public:
  Grid() = default;
  Grid(Grid&&) = default;
  Grid& operator=(Grid&&) = default;

  Voxel get(Vec3i p) const;
  void set(Vec3i p, Voxel v);

  // Reads the box [min, min + out.size()) into out (out keeps its size).
  void read_box(Vec3i min, Box& out) const;
  // Writes src at [min, min + src.size()).
  void write_box(Vec3i min, const Box& src);
  // Rewrites every voxel of region: fn(Vec3i world, Voxel old) -> Voxel new.
  // Chunks that do not exist are created only if fn produces non-Air in them;
  // chunks left all Air are freed. fn must not touch the grid.
  template <class VoxelFn>
  void modify(const Region& region, VoxelFn&& fn);
  // Fills region with one voxel.
  void fill(const Region& region, Voxel v) {
    modify(region, [v](Vec3i, Voxel) { return v; });
  }

  // Inline: every voxel read of grid_reads.h starts here.
  const Chunk* find_chunk(Vec3i chunk_pos) const {
    auto it = chunks_.find(chunk_pos);
    return it == chunks_.end() ? nullptr : it->second.get();
  }
  // Encodes the mips writes left unpacked in that chunk, if it is held.
  void pack_mips(Vec3i chunk_pos);
  // Inserts or replaces a whole chunk (mips must be current). An empty chunk
  // erases the entry.
  void put_chunk(Vec3i chunk_pos, Chunk chunk);
  // Inserts or replaces a whole chunk shared with its other holders: read
  // as it is, copied by the first write. Precondition: not null, mips
  // current. An empty chunk erases the entry.
  void put_shared_chunk(Vec3i chunk_pos, std::shared_ptr<const Chunk> chunk);
  // The chunk if it is held shared (as put_shared_chunk left it), else
  // null (absent, or the grid's own).
  std::shared_ptr<const Chunk> shared_chunk(Vec3i chunk_pos) const {
    auto it = chunks_.find(chunk_pos);
    return it == chunks_.end() ? nullptr : it->second.shared;
  }
  // Makes the grid's own chunk a shared one (moved, not copied) and
  // returns it; a shared one is returned as it is; null if absent.
  std::shared_ptr<const Chunk> share_chunk(Vec3i chunk_pos) {
    auto it = chunks_.find(chunk_pos);
    if (it == chunks_.end()) return nullptr;
    Slot& s = it->second;
    if (s.own) s.shared = std::shared_ptr<const Chunk>(std::move(s.own));
    return s.shared;
  }
  void erase_chunk(Vec3i chunk_pos) { chunks_.erase(chunk_pos); }
  // Removes the chunk from the grid and returns it (null if absent; a
  // copy if it was shared).
  std::unique_ptr<Chunk> take_chunk(Vec3i chunk_pos) {
    auto it = chunks_.find(chunk_pos);
    if (it == chunks_.end()) return nullptr;
    it->second.writable();
    std::unique_ptr<Chunk> c = std::move(it->second.own);
    chunks_.erase(it);
    return c;
  }
  std::size_t chunk_count() const { return chunks_.size(); }
  template <class F>
  void for_each_chunk(F&& f) const {
    for (const auto& [pos, slot] : chunks_) f(pos, *slot.get());
  }
  void clear() { chunks_.clear(); }

  // Repacks every chunk (after imports or write-heavy phases).
  void compact();
  GridMemory memory() const;

  // (The reads are grid_reads.h's, over this grid's chunks.)
  // First voxel along the ray (capped at kMaxRayDistance) whose occupancy byte is >= min_occupancy (non-Air),
  // within max_distance. direction need not be normalised (must be non-zero).
  std::optional<RayHit> raycast(Vec3f origin, Vec3f direction, float max_distance,
                                std::uint8_t min_occupancy = 0) const;
  // True if any non-Air voxel with occupancy >= min_occupancy overlaps the box
  // (touching faces do not count).
  bool collides(const Aabb& box, std::uint8_t min_occupancy = 0) const;

 private:
  // A chunk of the grid's own, or a shared one (exactly one is set).
  struct Slot {
    std::unique_ptr<Chunk> own;
    std::shared_ptr<const Chunk> shared;
    const Chunk* get() const { return own ? own.get() : shared.get(); }
    // The chunk to write: the grid's own, copied from the shared one first.
    Chunk& writable() {
      if (!own) {
        own = std::make_unique<Chunk>(shared->clone());
        shared.reset();
      }
      return *own;
    }
  };
  Vec3iMap<Slot> chunks_;
};

template <class VoxelFn>
void Grid::modify(const Region& region, VoxelFn&& fn) {
  for_each_chunk_in(region, [&](Vec3i cp) {
    const Vec3i origin = chunk_origin(cp);
    const Region local{region.min - origin, region.max - origin};
    auto shifted = [&](Vec3i l, Voxel old) { return fn(l + origin, old); };
    auto it = chunks_.find(cp);
    if (it == chunks_.end()) {
      // Only materialise a chunk if the edit puts something in it.
      auto chunk = std::make_unique<Chunk>();
      chunk->modify(local, shifted);
      if (!chunk->empty()) chunks_.emplace(cp, Slot{std::move(chunk), nullptr});
      return;
    }
    Chunk& chunk = it->second.writable();
    chunk.modify(local, shifted);
    if (chunk.empty()) chunks_.erase(it);
  });
}

}  // namespace terrane
