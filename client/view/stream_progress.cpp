#include "client/view/stream_progress.h"

#include <algorithm>
#include <cmath>

#include "client/view/render_chunk.h"
#include "common/chunk.h"

namespace terrane::view {

int desired_stream_level(Vec3f position, Vec3i chunk_pos, std::int32_t full_res_radius) {
  const float d = distance_to(position, chunk_region(chunk_pos));
  const float full = static_cast<float>(full_res_radius);
  if (d <= full) return 0;
  const float step = std::max(full, static_cast<float>(kChunkSize));
  if (d <= 2 * step) return 1;
  if (d <= 4 * step) return 2;
  return 3;
}

StreamProgress stream_progress(const Replica& replica, Vec3f p, std::int32_t vd, std::int32_t full,
                               std::int32_t min_y, std::int32_t max_y) {
  StreamProgress out;
  const Vec3i v{static_cast<std::int32_t>(std::floor(p.x)), static_cast<std::int32_t>(std::floor(p.y)),
                static_cast<std::int32_t>(std::floor(p.z))};
  Vec3i c0 = chunk_of(v - Vec3i{vd, vd, vd}), c1 = chunk_of(v + Vec3i{vd, vd, vd});
  c0.y = std::max(c0.y, floor_div(min_y, kChunkSize));
  c1.y = std::min(c1.y, floor_div(max_y - 1, kChunkSize));
  for (int y = c0.y; y <= c1.y; ++y)
    for (int z = c0.z; z <= c1.z; ++z)
      for (int x = c0.x; x <= c1.x; ++x) {
        const Vec3i cp{x, y, z};
        if (distance_to(p, chunk_region(cp)) > static_cast<float>(vd)) continue;
        ++out.in_view;
        const ChunkCoverage* c = replica.coverage(cp);
        if (c == nullptr) continue;
        ++out.covered;
        const int level = c->state == CoverageState::kMip ? c->level : 0;
        if (level <= desired_stream_level(p, cp, full)) ++out.settled;
      }
  return out;
}

}  // namespace terrane::view
