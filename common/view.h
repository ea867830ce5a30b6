// The view policy: which chunks a client at a position is sent, and at which
// resolution. One rule, used by the server, the client library, the bots and
// the tests (PROTOCOL.md, "Streaming", states it with a worked example).
//
// Distance. A chunk is the closed cube [o, o + 32]^3 (o = chunk_pos * 32).
// With p the client's position, per axis
//     d_a = max(o_a - p_a, 0, p_a - (o_a + 32))
// computed in IEEE double from the float position (exact: every operand is a
// float or an integer below 2^31), and d2 = d_x^2 + d_y^2 + d_z^2 in double,
// summed x, y, z in that order without fused multiply-add. Every comparison
// is d2 <= r^2 with r converted to double: a chunk exactly at the radius is
// inside (ties are in).
//
// In view: d2 <= view^2 (and the chunk touches the world's bounds).
// Level (desired_level): 0 (full resolution) when d2 <= full^2; otherwise,
// with step = max(full, 32), mip 1 when d2 <= (2 step)^2, mip 2 when
// d2 <= (4 step)^2, else mip 3 (4^3 per chunk).
//
// Order (nearest first): by the distance from p to the chunk's centre
// (squared, in double), ties by y, then z, then x.
#pragma once

#include <cstdint>
#include <vector>

#include "common/chunk.h"
#include "common/vec3.h"

namespace terrane {

// Squared distance from p to the chunk's closed cube (0 inside).
inline double chunk_dist2(Vec3f p, Vec3i chunk_pos) {
  const Vec3i o = chunk_origin(chunk_pos);
  auto axis = [](float v, std::int32_t lo) {
    const double a = lo, b = static_cast<double>(lo) + kChunkSize, x = v;
    return x < a ? a - x : (x > b ? x - b : 0.0);
  };
  const double dx = axis(p.x, o.x), dy = axis(p.y, o.y), dz = axis(p.z, o.z);
  const double xx = dx * dx, yy = dy * dy, zz = dz * dz;
  return xx + yy + zz;
}

inline bool within(Vec3f p, Vec3i chunk_pos, std::int32_t radius) {
  const double r = radius;
  return chunk_dist2(p, chunk_pos) <= r * r;
}

// Squared distance from p to the chunk's centre: the streaming order.
inline double chunk_center_dist2(Vec3f p, Vec3i chunk_pos) {
  const Vec3i o = chunk_origin(chunk_pos);
  const double h = kChunkSize / 2.0;
  const double dx = o.x + h - p.x, dy = o.y + h - p.y, dz = o.z + h - p.z;
  const double xx = dx * dx, yy = dy * dy, zz = dz * dz;
  return xx + yy + zz;
}

// 0 for full resolution, 1..3 for a mip level (chunks in view only).
inline int desired_level(Vec3f p, Vec3i chunk_pos, std::int32_t full_res_radius) {
  const double d2 = chunk_dist2(p, chunk_pos);
  const double full = full_res_radius;
  if (d2 <= full * full) return 0;
  const double step = std::max<double>(full, kChunkSize);
  if (d2 <= 4.0 * step * step) return 1;
  if (d2 <= 16.0 * step * step) return 2;
  return 3;
}

// The chunk range that can hold chunks within radius of p (a cube one chunk
// wider than needed on each side, so ties at exact chunk faces are inside).
inline void chunk_range(Vec3f p, std::int32_t radius, Vec3i* lo, Vec3i* hi) {
  auto axis_lo = [&](float v) {
    return floor_div(static_cast<std::int32_t>(std::floor(static_cast<double>(v) - radius)), kChunkSize) - 1;
  };
  auto axis_hi = [&](float v) {
    return floor_div(static_cast<std::int32_t>(std::floor(static_cast<double>(v) + radius)), kChunkSize) + 1;
  };
  *lo = {axis_lo(p.x), axis_lo(p.y), axis_lo(p.z)};
  *hi = {axis_hi(p.x), axis_hi(p.y), axis_hi(p.z)};
}

// The chunks within radius of p whose y range overlaps [min_y, max_y),
// nearest first (the order above).
std::vector<Vec3i> chunks_in_view(Vec3f p, std::int32_t radius, std::int32_t min_y, std::int32_t max_y);

}  // namespace terrane
