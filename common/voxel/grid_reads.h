// The grid's reads — a voxel, a box, a ray cast, an overlap test — over any
// map of chunks: Grid (row-packed chunks) and, in the consumers' benchmark
// (tests/bench/consumers_bench.cpp), the same content as plain 2-byte
// arrays, so both run exactly this code.
//
// A chunk map G has `const C* find_chunk(Vec3i chunk_pos) const` (null: all
// Air), and its chunks C have `Voxel get(Vec3i local) const`,
// `void read_box(Vec3i local_min, Box& out, Vec3i out_offset, Vec3i size) const`
// and `bool box_has_solid(Vec3i local_min, Vec3i local_max, std::uint8_t min_occupancy) const`
// (chunk.h). Stateless: thread-safety is the map's.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <optional>

#include "common/voxel/box.h"
#include "common/voxel/chunk.h"
#include "common/voxel/vec3.h"

namespace terrane {

struct RayHit {
  Vec3i voxel;      // the voxel hit
  Vec3i normal;     // outward normal of the face entered (zero if the ray starts inside)
  float distance;   // along the normalised direction, from the origin to the entry point
  Voxel value;
};

// An axis-aligned box in world units; voxel (x, y, z) spans [x, x+1) etc.
struct Aabb {
  Vec3f min;
  Vec3f max;
};

// Rays are capped at this length (voxels); each step is a voxel lookup.
inline constexpr float kMaxRayDistance = 1 << 16;

template <class G>
Voxel grid_get(const G& grid, Vec3i p) {
  const auto* c = grid.find_chunk(chunk_of(p));
  return c == nullptr ? Voxel{} : c->get(local_of(p));
}

// Reads the box [min, min + out.size()) into out (out keeps its size).
template <class G>
void grid_read_box(const G& grid, Vec3i min, Box& out) {
  const Region r = Region::from_min_size(min, out.size());
  for_each_chunk_in(r, [&](Vec3i cp) {
    const Region part = intersect(r, chunk_region(cp));
    const Vec3i out_offset = part.min - min;
    if (const auto* c = grid.find_chunk(cp)) {
      c->read_box(part.min - chunk_origin(cp), out, out_offset, part.size());
      return;
    }
    const Vec3i size = part.size();
    for (int y = 0; y < size.y; ++y)
      for (int z = 0; z < size.z; ++z)
        std::fill_n(out.write_row(out_offset.y + y, out_offset.z + z) + out_offset.x, size.x, Voxel{});
  });
}

// First voxel along the ray whose occupancy byte is >= min_occupancy (non-Air),
// within max_distance (capped at kMaxRayDistance). direction need not be
// normalised; a zero or non-finite direction or origin finds nothing.
template <class G>
std::optional<RayHit> grid_raycast(const G& grid, Vec3f origin, Vec3f dir, float max_distance,
                                   std::uint8_t min_occupancy) {
  const float len = std::sqrt(dir.x * dir.x + dir.y * dir.y + dir.z * dir.z);
  if (!(len > 0.0f) || !std::isfinite(len) || !(max_distance >= 0.0f)) return std::nullopt;
  if (!std::isfinite(origin.x) || !std::isfinite(origin.y) || !std::isfinite(origin.z)) return std::nullopt;
  max_distance = std::min(max_distance, kMaxRayDistance);
  dir = dir * (1.0f / len);
  // Amanatides & Woo: step voxel by voxel along the ray.
  const Vec3i cell{static_cast<int>(std::floor(origin.x)), static_cast<int>(std::floor(origin.y)),
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
  float t = 0.0f;
  Vec3i normal{0, 0, 0};
  // Bound the walk by the number of cells a segment of this length can cross.
  const int max_steps = static_cast<int>(3.0f * (max_distance + 2.0f));
  for (int i = 0; i <= max_steps && t <= max_distance; ++i) {
    const Vec3i p{c[0], c[1], c[2]};
    const Voxel v = grid_get(grid, p);
    if (solid_enough(v, min_occupancy)) return RayHit{p, normal, t, v};
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

// box_has_solid over a plain box: whether any voxel of [min, max) is
// solid_enough (voxel.h), row by row. (Chunk::box_has_solid is the
// row-packed one; a map of plain chunks answers with this.)
inline bool box_has_solid(const Box& box, Vec3i min, Vec3i max, std::uint8_t min_occupancy) {
  for (int y = min.y; y < max.y; ++y)
    for (int z = min.z; z < max.z; ++z)
      if (any_solid_enough(box.read_row(y, z), min.x, max.x, min_occupancy)) return true;
  return false;
}

// True if any non-Air voxel with occupancy >= min_occupancy overlaps the box
// (touching faces do not count). Asks each chunk the box crosses whether its
// part holds such a voxel (a row-packed chunk answers from its layers and
// records, without decoding them), and stops at the first.
template <class G>
bool grid_collides(const G& grid, const Aabb& box, std::uint8_t min_occupancy) {
  // Cells overlapping the open box: floor(min) .. ceil(max) - 1.
  const Vec3i lo{static_cast<int>(std::floor(box.min.x)), static_cast<int>(std::floor(box.min.y)),
                 static_cast<int>(std::floor(box.min.z))};
  const Vec3i hi{static_cast<int>(std::ceil(box.max.x)), static_cast<int>(std::ceil(box.max.y)),
                 static_cast<int>(std::ceil(box.max.z))};
  if (hi.x <= lo.x || hi.y <= lo.y || hi.z <= lo.z) return false;
  const Region cells{lo, hi};
  const Vec3i c0 = chunk_of(lo), c1 = chunk_of(hi - Vec3i{1, 1, 1});
  for (int cy = c0.y; cy <= c1.y; ++cy)
    for (int cz = c0.z; cz <= c1.z; ++cz)
      for (int cx = c0.x; cx <= c1.x; ++cx) {
        const Vec3i cp{cx, cy, cz};
        const auto* c = grid.find_chunk(cp);
        if (c == nullptr) continue;  // all Air
        const Vec3i origin = chunk_origin(cp);
        const Region part = intersect(cells, chunk_region(cp));
        if (c->box_has_solid(part.min - origin, part.max - origin, min_occupancy)) return true;
      }
  return false;
}

}  // namespace terrane
