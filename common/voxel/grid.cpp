#include "common/voxel/grid.h"

#include <algorithm>

namespace terrane {

Voxel Grid::get(Vec3i p) const { return grid_get(*this, p); }

void Grid::set(Vec3i p, Voxel v) { fill(Region{p, p + Vec3i{1, 1, 1}}, v); }

void Grid::put_chunk(Vec3i chunk_pos, Chunk chunk) {
  if (chunk.empty()) {
    chunks_.erase(chunk_pos);
    return;
  }
  Slot& slot = chunks_[chunk_pos];
  slot.shared.reset();
  if (slot.own) {
    *slot.own = std::move(chunk);
  } else {
    slot.own = std::make_unique<Chunk>(std::move(chunk));
  }
}

void Grid::put_shared_chunk(Vec3i chunk_pos, std::shared_ptr<const Chunk> chunk) {
  if (chunk->empty()) {
    chunks_.erase(chunk_pos);
    return;
  }
  Slot& slot = chunks_[chunk_pos];
  slot.own.reset();
  slot.shared = std::move(chunk);
}

void Grid::read_box(Vec3i min, Box& out) const { grid_read_box(*this, min, out); }

void Grid::write_box(Vec3i min, const Box& src) {
  modify(Region::from_min_size(min, src.size()), [&](Vec3i p, Voxel) { return src.get(p - min); });
}

void Grid::pack_mips(Vec3i chunk_pos) {
  auto it = chunks_.find(chunk_pos);
  if (it != chunks_.end() && !it->second.get()->mips_packed()) it->second.writable().pack_mips();
}

void Grid::compact() {
  for (auto& [pos, slot] : chunks_) slot.writable().compact();
}

GridMemory Grid::memory() const {
  GridMemory m;
  m.chunks = chunks_.size();
  m.map_bytes = chunks_.table_bytes();
  for (const auto& [pos, slot] : chunks_) {
    const ChunkMemory cm = slot.get()->memory();
    // A shared chunk: its share (with its control block).
    const std::size_t holders = slot.shared ? static_cast<std::size_t>(std::max(1L, slot.shared.use_count())) : 1;
    if (slot.shared) ++m.shared_chunks;
    m.object_bytes += (cm.object_bytes + (slot.shared ? 2 * sizeof(long) : 0)) / holders;
    m.level0_bytes += cm.level0_bytes / holders;
    m.mip_bytes += cm.mip_bytes / holders;
    m.level0_rows += slot.get()->level0_stats();
  }
  return m;
}

std::optional<RayHit> Grid::raycast(Vec3f origin, Vec3f dir, float max_distance,
                                    std::uint8_t min_occupancy) const {
  return grid_raycast(*this, origin, dir, max_distance, min_occupancy);
}

bool Grid::collides(const Aabb& box, std::uint8_t min_occupancy) const {
  return grid_collides(*this, box, min_occupancy);
}

}  // namespace terrane
