#include "client/python/find.h"

#include <algorithm>
#include <cmath>
#include <tuple>
#include <utility>

#include "client/replica.h"
#include "common/voxel/box.h"
#include "common/voxel/chunk.h"

namespace terrane::python {

std::vector<Vec3i> find_voxels(const Client& c, Material m, Vec3f near, double within, std::size_t max) {
  const auto lo = [&](float v) { return static_cast<std::int32_t>(std::floor(v - within)); };
  const auto hi = [&](float v) { return static_cast<std::int32_t>(std::floor(v + within)) + 1; };
  const Region cube{{lo(near.x), lo(near.y), lo(near.z)}, {hi(near.x), hi(near.y), hi(near.z)}};
  const Vec3i c0 = chunk_of(cube.min), c1 = chunk_of(cube.max - Vec3i{1, 1, 1});
  std::vector<std::pair<double, Vec3i>> found;
  Box box;
  for (int cy = c0.y; cy <= c1.y; ++cy)
    for (int cz = c0.z; cz <= c1.z; ++cz)
      for (int cx = c0.x; cx <= c1.x; ++cx) {
        const Region part = intersect(chunk_region({cx, cy, cz}), cube);
        // One chunk under the lock at a time: the io side goes on between.
        const bool full = c.with_replica([&](const Replica& rep) {
          const Holding* h = rep.holding({cx, cy, cz});
          if (h == nullptr || !h->full_resolution()) return false;
          box = Box(part.size());
          rep.read_box(part.min, box);
          return true;
        });
        if (!full) continue;
        for (int y = 0; y < part.size().y; ++y)
          for (int z = 0; z < part.size().z; ++z)
            for (int x = 0; x < part.size().x; ++x) {
              if (box.get(x, y, z).material != m) continue;
              const Vec3i v = part.min + Vec3i{x, y, z};
              const double dx = v.x + 0.5 - near.x, dy = v.y + 0.5 - near.y, dz = v.z + 0.5 - near.z;
              const double d2 = dx * dx + dy * dy + dz * dz;
              if (d2 <= within * within) found.emplace_back(d2, v);
            }
      }
  const auto order = [](const auto& a, const auto& b) {
    if (a.first != b.first) return a.first < b.first;
    return std::tie(a.second.x, a.second.y, a.second.z) < std::tie(b.second.x, b.second.y, b.second.z);
  };
  const std::size_t n = std::min(max, found.size());
  std::partial_sort(found.begin(), found.begin() + static_cast<std::ptrdiff_t>(n), found.end(), order);
  std::vector<Vec3i> out;
  out.reserve(n);
  for (std::size_t i = 0; i < n; ++i) out.push_back(found[i].second);
  return out;
}

}  // namespace terrane::python
