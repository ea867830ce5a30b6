#include "common/voxel/grid.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace terrane {

Voxel Grid::get(Vec3i p) const {
  const Chunk* c = find_chunk(chunk_of(p));
  if (c == nullptr) return Voxel{};
  const Vec3i l = local_of(p);
  return c->get(l);
}

void Grid::set(Vec3i p, Voxel v) { fill(Region{p, p + Vec3i{1, 1, 1}}, v); }

const Chunk* Grid::find_chunk(Vec3i chunk_pos) const {
  auto it = chunks_.find(chunk_pos);
  return it == chunks_.end() ? nullptr : it->second.get();
}

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

void Grid::read_box(Vec3i min, Box& out) const {
  const Region r = Region::from_min_size(min, out.size());
  for_each_chunk_in(r, [&](Vec3i cp) {
    const Region part = intersect(r, chunk_region(cp));
    const Vec3i out_offset = part.min - min;
    if (const Chunk* c = find_chunk(cp)) {
      c->read_box(part.min - chunk_origin(cp), out, out_offset, part.size());
      return;
    }
    const Vec3i size = part.size();
    for (int y = 0; y < size.y; ++y)
      for (int z = 0; z < size.z; ++z)
        std::fill_n(out.write_row(out_offset.y + y, out_offset.z + z) + out_offset.x, size.x, Voxel{});
  });
}

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
  const float len = std::sqrt(dir.x * dir.x + dir.y * dir.y + dir.z * dir.z);
  if (!(len > 0.0f) || !std::isfinite(len) || !(max_distance >= 0.0f)) return std::nullopt;
  if (!std::isfinite(origin.x) || !std::isfinite(origin.y) || !std::isfinite(origin.z)) return std::nullopt;
  max_distance = std::min(max_distance, kMaxRayDistance);
  dir = dir * (1.0f / len);
  // Amanatides & Woo: step voxel by voxel along the ray.
  Vec3i cell{static_cast<int>(std::floor(origin.x)), static_cast<int>(std::floor(origin.y)),
             static_cast<int>(std::floor(origin.z))};
  const float o[3] = {origin.x, origin.y, origin.z};
  const float d[3] = {dir.x, dir.y, dir.z};
  int c[3] = {cell.x, cell.y, cell.z};
  int step[3];
  float t_max[3], t_delta[3];
  constexpr float kInf = std::numeric_limits<float>::infinity();
  for (int a = 0; a < 3; ++a) {
    if (d[a] > 0) {
      step[a] = 1;
      t_max[a] = (static_cast<float>(c[a] + 1) - o[a]) / d[a];
      t_delta[a] = 1.0f / d[a];
    } else if (d[a] < 0) {
      step[a] = -1;
      t_max[a] = (static_cast<float>(c[a]) - o[a]) / d[a];
      t_delta[a] = -1.0f / d[a];
    } else {
      step[a] = 0;
      t_max[a] = kInf;
      t_delta[a] = kInf;
    }
  }
  auto solid_enough = [&](Voxel v) { return v.material != kAir && v.occupancy >= min_occupancy; };
  float t = 0.0f;
  Vec3i normal{0, 0, 0};
  // Bound the walk by the number of cells a segment of this length can cross.
  const int max_steps = static_cast<int>(3.0f * (max_distance + 2.0f));
  for (int i = 0; i <= max_steps && t <= max_distance; ++i) {
    const Vec3i p{c[0], c[1], c[2]};
    const Voxel v = get(p);
    if (solid_enough(v)) return RayHit{p, normal, t, v};
    int a = 0;
    if (t_max[1] < t_max[a]) a = 1;
    if (t_max[2] < t_max[a]) a = 2;
    t = t_max[a];
    t_max[a] += t_delta[a];
    c[a] += step[a];
    normal = Vec3i{0, 0, 0};
    (a == 0 ? normal.x : a == 1 ? normal.y : normal.z) = -step[a];
  }
  return std::nullopt;
}

bool Grid::collides(const Aabb& box, std::uint8_t min_occupancy) const {
  // Cells overlapping the open box: floor(min) .. ceil(max) - 1.
  const Vec3i lo{static_cast<int>(std::floor(box.min.x)), static_cast<int>(std::floor(box.min.y)),
                 static_cast<int>(std::floor(box.min.z))};
  const Vec3i hi{static_cast<int>(std::ceil(box.max.x)), static_cast<int>(std::ceil(box.max.y)),
                 static_cast<int>(std::ceil(box.max.z))};
  if (hi.x <= lo.x || hi.y <= lo.y || hi.z <= lo.z) return false;
  Box cells(hi - lo);
  read_box(lo, cells);
  for (const Voxel v : cells.voxels())
    if (v.material != kAir && v.occupancy >= min_occupancy) return true;
  return false;
}

}  // namespace terrane
