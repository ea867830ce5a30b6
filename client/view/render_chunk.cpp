#include "client/view/render_chunk.h"

#include <algorithm>
#include <cmath>
#include <unordered_map>

#include "common/voxel/chunk.h"

namespace terrane::view {
namespace {

std::uint64_t mix(std::uint64_t h, std::uint64_t v) {
  h ^= v + 0x9E3779B97F4A7C15ull + (h << 6) + (h >> 2);
  return h * 0xBF58476D1CE4E5B9ull;
}

// Source chunks whose voxels the samples of `key` can read: the chunk's own
// cube grown by one voxel (the sample ring reaches at most one sample, of at
// most 32 voxels, beyond it, and origins are multiples of 16).
void for_each_source_chunk(const NodeKey& key, const auto& fn) {
  const Region r = key.region();
  for_each_chunk_in(Region{r.min - Vec3i{1, 1, 1}, r.max + Vec3i{1, 1, 1}}, fn);
}

}  // namespace

int GridSource::read(Vec3i chunk_pos, int want, Box& out) const {
  const int level = std::clamp(want, 0, kMipLevels - 1);
  if (const Chunk* c = grid_.find_chunk(chunk_pos)) {
    c->read_level(level, out);
  } else {
    const int n = kChunkSize >> level;
    out.resize({n, n, n});
  }
  return level;
}

int GridSource::read_part(Vec3i chunk_pos, int want, const Region& part, Box& out) const {
  if (const Chunk* c = grid_.find_chunk(chunk_pos)) {
    read_chunk_part(*c, want, part, out);
  } else {
    out.resize(part.size());
  }
  return want;
}

int VoxelSource::read_part(Vec3i chunk_pos, int want, const Region& part, Box& out) const {
  Box whole;
  const int level = read(chunk_pos, want, whole);
  if (level != want) {
    out = std::move(whole);
    return level;
  }
  out.resize(part.size());
  const Vec3i size = part.size();
  for (int y = 0; y < size.y; ++y)
    for (int z = 0; z < size.z; ++z)
      std::copy_n(whole.read_row(part.min.y + y, part.min.z + z) + part.min.x, size.x, out.write_row(y, z));
  return want;
}

float distance_to(Vec3f p, const Region& r) {
  auto axis = [](float v, std::int32_t lo, std::int32_t hi) {
    const float a = static_cast<float>(lo), b = static_cast<float>(hi);
    return v < a ? a - v : (v > b ? v - b : 0.0f);
  };
  const float dx = axis(p.x, r.min.x, r.max.x), dy = axis(p.y, r.min.y, r.max.y), dz = axis(p.z, r.min.z, r.max.z);
  return std::sqrt(dx * dx + dy * dy + dz * dz);
}

std::vector<NodeKey> select_render_chunks(Vec3f camera, const LodParams& params) {
  std::vector<std::pair<float, NodeKey>> out;
  const int root = kRenderChunkCells << kMaxRenderLevel;
  const auto vd = static_cast<std::int32_t>(std::ceil(params.view_distance));
  const auto fl = [](float v) { return static_cast<std::int32_t>(std::floor(v)); };
  const std::int32_t x0 = floor_div(fl(camera.x) - vd, root), x1 = floor_div(fl(camera.x) + vd, root);
  const std::int32_t z0 = floor_div(fl(camera.z) - vd, root), z1 = floor_div(fl(camera.z) + vd, root);
  const std::int32_t y0 = floor_div(std::max(fl(camera.y) - vd, params.min_y), root);
  const std::int32_t y1 = floor_div(std::min(fl(camera.y) + vd, params.max_y - 1), root);
  const auto visit = [&](const auto& self, const NodeKey& k) -> void {
    const Region r = k.region();
    if (r.max.y <= params.min_y || r.min.y >= params.max_y) return;
    const float d = distance_to(camera, r);
    if (d > params.view_distance) return;
    if (k.level > 0 && d < params.split_factor * static_cast<float>(k.size())) {
      const int h = k.size() / 2;
      for (int i = 0; i < 8; ++i)
        self(self, NodeKey{k.origin + Vec3i{(i & 1) * h, ((i >> 1) & 1) * h, ((i >> 2) & 1) * h}, k.level - 1});
      return;
    }
    out.emplace_back(d, k);
  };
  for (std::int32_t y = y0; y <= y1; ++y)
    for (std::int32_t z = z0; z <= z1; ++z)
      for (std::int32_t x = x0; x <= x1; ++x) visit(visit, NodeKey{Vec3i{x, y, z} * root, kMaxRenderLevel});
  std::stable_sort(out.begin(), out.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  std::vector<NodeKey> keys;
  keys.reserve(out.size());
  for (const auto& [d, k] : out) keys.push_back(k);
  return keys;
}

ChunkPlan plan_render_chunk(const VoxelSource& source, const NodeKey& key, const LodParams& params) {
  ChunkPlan plan;
  plan.sample_level = std::max(key.level, params.min_sample_level);
  std::uint64_t h = mix(0, static_cast<std::uint64_t>(params.min_sample_level));
  for_each_source_chunk(key, [&](Vec3i cp) {
    const int level = source.level(cp);
    if (level >= 0) {
      plan.any_known = true;
      plan.sample_level = std::max(plan.sample_level, level);
    }
    h = mix(h, static_cast<std::uint64_t>(level + 1));
    h = mix(h, source.revision(cp));
  });
  h = mix(h, static_cast<std::uint64_t>(plan.sample_level));
  plan.enhanced = params.enhance && plan.sample_level == 0;
  plan.signature = mix(h, plan.enhanced ? 1 : 0);
  return plan;
}

SampleGrid sample_render_chunk(const VoxelSource& source, const NodeKey& key, int sample_level) {
  const int s = 1 << sample_level;
  const int n = std::max(1, key.size() / s);
  const Vec3f origin{static_cast<float>(key.origin.x) - 0.5f * static_cast<float>(s),
                     static_cast<float>(key.origin.y) - 0.5f * static_cast<float>(s),
                     static_cast<float>(key.origin.z) - 0.5f * static_cast<float>(s)};
  SampleGrid grid({n + 2, n + 2, n + 2}, origin, static_cast<float>(s));

  // Each source chunk read once, brought to sample_level (or left at a
  // coarser level when that is all there is: nearest sampling then). Up to
  // the finest mip, only the part of the chunk the samples reach is read.
  struct Level {
    int level = -1;
    Box voxels;
    bool part = false;  // voxels hold the part from origin (at level), else the whole level
    Vec3i origin;
  };
  const int want = std::min(sample_level, kMipLevels - 1);
  // The voxels the samples reach: the render chunk and its ring (aligned to s).
  const Region reach{key.origin - Vec3i{s, s, s}, key.origin + Vec3i{n * s + s, n * s + s, n * s + s}};
  std::unordered_map<Vec3i, Level, Vec3iHash> cache;
  const auto level_of = [&](Vec3i cp) -> const Level& {
    auto [it, fresh] = cache.try_emplace(cp);
    if (!fresh) return it->second;
    Level& l = it->second;
    if (source.level(cp) < 0) return l;
    if (want == sample_level) {
      const Region r = intersect(reach, chunk_region(cp));
      const Region part{floor_div(r.min - chunk_origin(cp), s), floor_div(r.max - chunk_origin(cp), s)};
      l.level = source.read_part(cp, want, part, l.voxels);
      l.part = l.level == want;
      if (l.part) l.origin = part.min;
    } else {
      l.level = source.read(cp, want, l.voxels);
    }
    while (l.level < sample_level && l.voxels.size().x > 1) {
      l.voxels = downsample_box(l.voxels);
      ++l.level;
    }
    return l;
  };

  for (int k = 0; k < n + 2; ++k)
    for (int j = 0; j < n + 2; ++j)
      for (int i = 0; i < n + 2; ++i) {
        const Vec3i cube = key.origin + Vec3i{(i - 1) * s, (j - 1) * s, (k - 1) * s};
        const Vec3i cp = chunk_of(cube);
        const Level& l = level_of(cp);
        if (l.level < 0) continue;  // unknown: Air
        const Vec3i local = cube - chunk_origin(cp);
        const int side = l.voxels.size().x;
        const Vec3i at = l.part ? Vec3i{local.x >> l.level, local.y >> l.level, local.z >> l.level} - l.origin
                                : Vec3i{std::min(local.x >> l.level, side - 1), std::min(local.y >> l.level, side - 1),
                                        std::min(local.z >> l.level, side - 1)};
        const Voxel v = l.voxels.get(at);
        grid.set(i, j, k, occupancy_fraction(v), v.material);
      }
  return grid;
}

void mesh_render_samples(const SampleGrid& samples, Mesh& out, const MesherOptions& options) {
  const std::size_t solid = samples.solid_count();
  if (solid == 0 || solid == samples.occupancy.size()) {
    out.vertices.clear();
    out.indices.clear();
    return;
  }
  mesh_samples(samples, out, options);
}

void build_render_chunk(const VoxelSource& source, const NodeKey& key, int sample_level, Mesh& out,
                        const MesherOptions& options) {
  mesh_render_samples(sample_render_chunk(source, key, sample_level), out, options);
}

}  // namespace terrane::view
