#include "client/view/enhanced_chunk.h"

#include <algorithm>

#include "common/voxel/chunk.h"

namespace terrane::view {
namespace {

int factor_of(const EnhanceViewParams& p) { return 1 << p.subdivision.levels; }

// Coarse voxels of margin around the chunk: the light window (steps
// fragments) plus the subdivision's reach (one coarse voxel low, two high),
// rounded up.
int margin_of(const EnhanceViewParams& p) {
  const int f = factor_of(p);
  return (p.lighting.steps + f - 1) / f + 3;
}

}  // namespace

EnhanceInput read_enhance_input(const VoxelSource& source, const NodeKey& key, const EnhanceViewParams& params) {
  const int m = margin_of(params);
  const Region r{key.origin - Vec3i{m, m, m}, key.origin + Vec3i{key.size() + m, key.size() + m, key.size() + m}};
  EnhanceInput in{r.min, Box(r.size())};
  Box chunk;
  for_each_chunk_in(r, [&](Vec3i cp) {
    if (source.level(cp) < 0) return;
    const int level = source.read(cp, 0, chunk);
    const Region part = intersect(r, chunk_region(cp));
    for (int y = part.min.y; y < part.max.y; ++y)
      for (int z = part.min.z; z < part.max.z; ++z)
        for (int x = part.min.x; x < part.max.x; ++x) {
          const Vec3i l = Vec3i{x, y, z} - chunk_origin(cp);
          in.coarse.set(Vec3i{x, y, z} - r.min, chunk.get(l.x >> level, l.y >> level, l.z >> level));
        }
  });
  return in;
}

SampleGrid enhance_samples(const EnhanceInput& in, const NodeKey& key, const EnhanceViewParams& params) {
  const int f = factor_of(params);
  const int steps = params.lighting.steps;
  // Fragments of the chunk plus one ring (the samples), and the lighting
  // box around them (steps more on every side).
  const Region samples{key.origin * f - Vec3i{1, 1, 1}, (key.origin + Vec3i{key.size(), key.size(), key.size()}) * f +
                                                           Vec3i{1, 1, 1}};
  const Region lit{samples.min - Vec3i{steps, steps, steps}, samples.max + Vec3i{steps, steps, steps}};
  Box fine;
  subdivide_region(in.coarse, in.origin, params.subdivision, lit, fine);
  LightMap light{samples, std::vector<std::uint8_t>(static_cast<std::size_t>(samples.volume()), 0)};
  light_region(fine, lit.min, params.lighting, samples, light);

  const float s = 1.0f / static_cast<float>(f);
  const Vec3i n = samples.size();
  SampleGrid g(n,
               {static_cast<float>(samples.min.x) * s + 0.5f * s, static_cast<float>(samples.min.y) * s + 0.5f * s,
                static_cast<float>(samples.min.z) * s + 0.5f * s},
               s);
  g.light.assign(g.occupancy.size(), 0);
  const Vec3i off = samples.min - lit.min;
  const auto lo = static_cast<std::uint8_t>(params.min_light * 255.0f);
  for (int z = 0; z < n.z; ++z)
    for (int y = 0; y < n.y; ++y)
      for (int x = 0; x < n.x; ++x) {
        const Voxel v = fine.get(x + off.x, y + off.y, z + off.z);
        if (!enhance_solid(v)) continue;
        g.set(x, y, z, 1.0f, v.material);
        if (!is_surface_fragment(fine, Vec3i{x, y, z} + off)) {
          g.light[g.index(x, y, z)] = 0;
          continue;
        }
        const std::uint8_t l = light.at(samples.min + Vec3i{x, y, z});
        g.light[g.index(x, y, z)] = static_cast<std::uint8_t>(lo + (255 - lo) * l / 255);
      }
  return g;
}

}  // namespace terrane::view
