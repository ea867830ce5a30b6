// The view policy: which chunks a client is sent, and at which resolution.
// One rule, used by the server, the client library, the bots and the tests
// (PROTOCOL.md, "Streaming", states it with a worked example).
//
// Everything is measured from the centre of the client's chunk, the chunk
// containing its position (c = floor(position / 32)), to the nearest point
// of the other chunk's closed cube, in whole voxels. With the chunk offset
// o = chunk_pos - c, per axis
//     g_a = max(32 |o_a| - 16, 0)
// and the squared distance is d2 = g_x^2 + g_y^2 + g_z^2 (an integer).
//   In view:      d2 <= view^2 (and the chunk touches the world's bounds).
//   Level:        0 (full resolution) when d2 <= full^2; otherwise, with
//                 step = max(full, 32): mip 1 when d2 <= (2 step)^2, mip 2
//                 when d2 <= (4 step)^2, else mip 3 (4^3 per chunk).
//   Order:        nearest first by the centre-to-centre distance
//                 (32 o)^2 summed, ties by o.y, then o.z, then o.x.
// Ties are inside (<=). Since the rule depends only on the offset, a server
// precomputes it once per radius (ViewTable) and a move into the next chunk
// changes only a thin shell of chunks.
#pragma once

#include <cstdint>
#include <cstdlib>
#include <vector>

#include "common/voxel/chunk.h"
#include "common/voxel/vec3.h"
#include "common/world/world_bounds.h"

namespace terrane {

// The chunk whose centre views are measured from.
inline Vec3i view_chunk(Vec3f position) {
  return chunk_of(Vec3i{static_cast<std::int32_t>(std::floor(position.x)),
                        static_cast<std::int32_t>(std::floor(position.y)),
                        static_cast<std::int32_t>(std::floor(position.z))});
}

inline std::int64_t offset_dist2(Vec3i o) {
  auto g = [](std::int32_t a) -> std::int64_t {
    const std::int64_t v = std::int64_t{kChunkSize} * std::abs(std::int64_t{a}) - kChunkSize / 2;
    return v > 0 ? v : 0;
  };
  const std::int64_t x = g(o.x), y = g(o.y), z = g(o.z);
  return x * x + y * y + z * z;
}

inline std::int64_t offset_center_dist2(Vec3i o) {
  const std::int64_t x = std::int64_t{kChunkSize} * o.x, y = std::int64_t{kChunkSize} * o.y,
                     z = std::int64_t{kChunkSize} * o.z;
  return x * x + y * y + z * z;
}

inline bool offset_within(Vec3i o, std::int32_t radius) {
  return offset_dist2(o) <= std::int64_t{radius} * radius;
}

inline int offset_level(Vec3i o, std::int32_t full_res_radius) {
  const std::int64_t d2 = offset_dist2(o);
  const std::int64_t full = full_res_radius;
  if (d2 <= full * full) return 0;
  const std::int64_t step = full > kChunkSize ? full : kChunkSize;
  if (d2 <= 4 * step * step) return 1;
  if (d2 <= 16 * step * step) return 2;
  return 3;
}

// The same, for a client at position.
inline bool within(Vec3f position, Vec3i chunk_pos, std::int32_t radius) {
  return offset_within(chunk_pos - view_chunk(position), radius);
}
inline int desired_level(Vec3f position, Vec3i chunk_pos, std::int32_t full_res_radius) {
  return offset_level(chunk_pos - view_chunk(position), full_res_radius);
}

// Every offset within radius, nearest first (the order above).
std::vector<Vec3i> view_offsets(std::int32_t radius);

// The chunks within radius of a client at position that hold any voxel of
// the world (WorldBounds::touches_chunk: its vertical range and, when it has
// one, its horizontal border), nearest first: what a complete view holds.
std::vector<Vec3i> chunks_in_view(Vec3f position, std::int32_t radius, const WorldBounds& bounds);

}  // namespace terrane
