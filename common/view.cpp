#include "common/view.h"

#include <algorithm>
#include <tuple>

namespace terrane {

std::vector<Vec3i> chunks_in_view(Vec3f p, std::int32_t radius, std::int32_t min_y, std::int32_t max_y) {
  Vec3i lo, hi;
  chunk_range(p, radius, &lo, &hi);
  lo.y = std::max(lo.y, floor_div(min_y, kChunkSize));
  hi.y = std::min(hi.y, floor_div(max_y - 1, kChunkSize));
  std::vector<std::pair<double, Vec3i>> in;
  for (int y = lo.y; y <= hi.y; ++y)
    for (int z = lo.z; z <= hi.z; ++z)
      for (int x = lo.x; x <= hi.x; ++x) {
        const Vec3i cp{x, y, z};
        if (within(p, cp, radius)) in.emplace_back(chunk_center_dist2(p, cp), cp);
      }
  std::sort(in.begin(), in.end(), [](const auto& a, const auto& b) {
    if (a.first != b.first) return a.first < b.first;
    return std::tie(a.second.y, a.second.z, a.second.x) < std::tie(b.second.y, b.second.z, b.second.x);
  });
  std::vector<Vec3i> out;
  out.reserve(in.size());
  for (const auto& e : in) out.push_back(e.second);
  return out;
}

}  // namespace terrane
