#include "common/world/view.h"

#include <algorithm>
#include <tuple>

namespace terrane {

std::vector<Vec3i> view_offsets(std::int32_t radius) {
  // 32 |o| - 16 <= radius  <=>  |o| <= (radius + 16) / 32.
  const std::int32_t n = (std::max(radius, 0) + kChunkSize / 2) / kChunkSize;
  std::vector<Vec3i> out;
  for (int y = -n; y <= n; ++y)
    for (int z = -n; z <= n; ++z)
      for (int x = -n; x <= n; ++x)
        if (offset_within({x, y, z}, radius)) out.push_back({x, y, z});
  std::sort(out.begin(), out.end(), [](Vec3i a, Vec3i b) {
    const std::int64_t da = offset_center_dist2(a), db = offset_center_dist2(b);
    if (da != db) return da < db;
    return std::tie(a.y, a.z, a.x) < std::tie(b.y, b.z, b.x);
  });
  return out;
}

std::vector<Vec3i> chunks_in_view(Vec3f position, std::int32_t radius, const WorldBounds& bounds) {
  const Vec3i c = view_chunk(position);
  std::vector<Vec3i> out;
  for (const Vec3i o : view_offsets(radius)) {
    const Vec3i cp = c + o;
    if (bounds.touches_chunk(cp)) out.push_back(cp);
  }
  return out;
}

}  // namespace terrane
