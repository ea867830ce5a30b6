// Render chunks: selection by distance, plans that change only with the
// data read, parts of chunks read as their levels, crack-freedom across
// resolutions, and the worker remeshing only what changed.
#include "client/view/render_chunk.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <random>
#include <thread>
#include <unordered_map>

#include "client/view/mesh_scheduler.h"
#include "common/world/terrain_generator.h"
#include "common/world/world.h"

namespace terrane::view {
namespace {

// The default world's generator over a box, in a Grid.
struct TerrainFixture {
  Grid grid;
  Region box{{-160, -32, -160}, {160, 160, 160}};
  TerrainFixture() {
    auto gen = TerrainGenerator::from_metadata(default_world_meta().generator_params);
    EXPECT_TRUE(static_cast<bool>(gen));
    Box b;
    gen->generate(box, b);
    grid.write_box(box.min, b);
  }
  Region known_chunks() const { return {floor_div(box.min, 32), floor_div(box.max - Vec3i{1, 1, 1}, 32) + Vec3i{1, 1, 1}}; }
  // y just above the highest solid (occupancy >= 0.5) voxel of a column.
  int top(int x, int z) const {
    for (int y = box.max.y - 1; y >= box.min.y; --y)
      if (occupancy_fraction(grid.get({x, y, z})) >= 0.5f) return y + 1;
    return box.min.y;
  }
};

TEST(RenderChunks, GrowWithDistanceAndTileTheView) {
  LodParams p;
  p.view_distance = 1000;
  const Vec3f cam{10, 40, -20};
  const auto keys = select_render_chunks(cam, p);
  ASSERT_FALSE(keys.empty());
  float last = -1;
  std::int64_t volume = 0;
  std::unordered_map<int, int> per_level;
  for (const NodeKey& k : keys) {
    const float d = distance_to(cam, k.region());
    EXPECT_GE(d, last) << "nearest first";
    last = d;
    // Split while nearer than split_factor * size: a leaf above level 0 is
    // at least that far.
    if (k.level > 0) {
      EXPECT_GE(d, p.split_factor * static_cast<float>(k.size()));
    }
    EXPECT_EQ(floor_mod(k.origin, k.size()), Vec3i{}) << "aligned";
    volume += k.region().volume();
    ++per_level[k.level];
  }
  EXPECT_EQ(per_level.size(), 5u) << "16^3 up to 256^3";
  EXPECT_EQ(keys.front().level, 0);
  // Disjoint: the volumes add up to no more than the roots' cubes.
  std::unordered_map<NodeKey, int, NodeKeyHash> seen;
  for (const NodeKey& k : keys) EXPECT_TRUE(seen.emplace(k, 0).second);
  for (std::size_t i = 0; i < keys.size(); i += 37)
    for (std::size_t j = 0; j < keys.size(); ++j)
      if (i != j) {
        ASSERT_TRUE(intersect(keys[i].region(), keys[j].region()).empty());
      }
  EXPECT_GT(volume, 0);
}

class FakeSource final : public VoxelSource {
 public:
  explicit FakeSource(const Grid& g) : inner_(g, {{-100, -100, -100}, {100, 100, 100}}) {}
  int level(Vec3i cp) const override {
    auto it = levels_.find(cp);
    return it == levels_.end() ? inner_.level(cp) : it->second;
  }
  std::uint64_t revision(Vec3i cp) const override {
    auto it = revisions_.find(cp);
    return it == revisions_.end() ? 0 : it->second;
  }
  int read(Vec3i cp, int want, Box& out) const override { return inner_.read(cp, std::max(want, level(cp)), out); }
  std::unordered_map<Vec3i, int, Vec3iHash> levels_;
  std::unordered_map<Vec3i, std::uint64_t, Vec3iHash> revisions_;

 private:
  GridSource inner_;
};

TEST(RenderChunks, PlanFollowsTheDataRead) {
  Grid g;
  g.fill(Region{{0, 0, 0}, {64, 20, 64}}, solid(materials::kRock));
  FakeSource src(g);
  LodParams p;
  const NodeKey k{{16, 0, 16}, 0};
  const ChunkPlan a = plan_render_chunk(src, k, p);
  EXPECT_EQ(a.sample_level, 0);
  EXPECT_EQ(plan_render_chunk(src, k, p).signature, a.signature);
  // A revision in a chunk the samples read changes the plan ...
  src.revisions_[{0, 0, 0}] = 5;
  const ChunkPlan b = plan_render_chunk(src, k, p);
  EXPECT_NE(b.signature, a.signature);
  // ... one in a chunk out of reach does not.
  src.revisions_[{3, 0, 3}] = 9;
  EXPECT_EQ(plan_render_chunk(src, k, p).signature, b.signature);
  // Only a mip held: sampled at that level; finer data refines it.
  src.levels_[{0, 0, 0}] = 2;
  const ChunkPlan c = plan_render_chunk(src, k, p);
  EXPECT_EQ(c.sample_level, 2);
  EXPECT_NE(c.signature, b.signature);
  Mesh m;
  build_render_chunk(src, k, c.sample_level, m);
  EXPECT_FALSE(m.empty());
}

// A source that only reads whole chunks: VoxelSource's own read_part.
class WholeChunkSource final : public VoxelSource {
 public:
  explicit WholeChunkSource(const Grid& g) : inner_(g, {{-100, -100, -100}, {100, 100, 100}}) {}
  int level(Vec3i cp) const override { return inner_.level(cp); }
  std::uint64_t revision(Vec3i) const override { return 0; }
  int read(Vec3i cp, int want, Box& out) const override { return inner_.read(cp, want, out); }

 private:
  GridSource inner_;
};

TEST(RenderChunks, PartsOfAChunkAreTheVoxelsOfItsLevels) {
  Grid g;
  std::mt19937 rng(8);
  std::uniform_int_distribution<int> m(1, 5), occ(1, 255), coin(0, 5);
  g.modify(Region{{0, 0, 0}, {32, 32, 32}}, [&](Vec3i p, Voxel) {
    if (p.y > 20 + p.x % 5) return Voxel{};
    if (coin(rng) == 0) return make_voxel(static_cast<Material>(m(rng)), static_cast<std::uint8_t>(occ(rng)));
    return solid(p.y < 8 ? materials::kRock : static_cast<Material>(m(rng)));
  });
  g.compact();
  const Chunk& c = *g.find_chunk({0, 0, 0});
  const GridSource grid_source(g, {{-1, -1, -1}, {2, 2, 2}});
  const WholeChunkSource whole_source(g);
  std::uniform_int_distribution<int> any(0, 31);
  for (int level = 0; level < kMipLevels; ++level) {
    const int n = kChunkSize >> level;
    Box whole;
    c.read_level(level, whole);
    for (int i = 0; i < 40; ++i) {
      Vec3i a{any(rng) % n, any(rng) % n, any(rng) % n}, b{any(rng) % n, any(rng) % n, any(rng) % n};
      Region part{min3(a, b), max3(a, b) + Vec3i{1, 1, 1}};
      if (i == 0) part = Region{{0, 0, 0}, {n, n, n}};
      if (i == 1) part = Region{{0, 0, 0}, {1, n, n}};  // a face, as the sample ring reads
      Box got, by_grid, by_default;
      read_chunk_part(c, level, part, got);
      ASSERT_EQ(got.size(), part.size());
      for (int y = 0; y < part.size().y; ++y)
        for (int z = 0; z < part.size().z; ++z)
          for (int x = 0; x < part.size().x; ++x)
            ASSERT_EQ(got.get(x, y, z), whole.get(part.min + Vec3i{x, y, z})) << "level " << level;
      EXPECT_EQ(grid_source.read_part({0, 0, 0}, level, part, by_grid), level);
      EXPECT_EQ(whole_source.read_part({0, 0, 0}, level, part, by_default), level);
      EXPECT_EQ(by_grid, got);
      EXPECT_EQ(by_default, got);
    }
  }
  // Meshes from parts equal meshes from whole chunks, at every sample level.
  for (int level = 0; level <= 2; ++level) {
    Mesh a, b;
    const NodeKey k{{0, 0, 0}, level};
    build_render_chunk(grid_source, k, level, a);
    build_render_chunk(whole_source, k, level, b);
    EXPECT_FALSE(a.empty());
    EXPECT_EQ(a.indices, b.indices);
    EXPECT_EQ(a.triangle_count(), b.triangle_count());
  }
}

// Möller–Trumbore; the distance along the ray or a negative value.
float ray_triangle(const float o[3], const float d[3], const float* a, const float* b, const float* c) {
  const float e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
  const float p[3] = {d[1] * e2[2] - d[2] * e2[1], d[2] * e2[0] - d[0] * e2[2], d[0] * e2[1] - d[1] * e2[0]};
  const float det = e1[0] * p[0] + e1[1] * p[1] + e1[2] * p[2];
  if (std::fabs(det) < 1e-9f) return -1;
  const float inv = 1 / det;
  const float t[3] = {o[0] - a[0], o[1] - a[1], o[2] - a[2]};
  const float u = (t[0] * p[0] + t[1] * p[1] + t[2] * p[2]) * inv;
  if (u < 0 || u > 1) return -1;
  const float q[3] = {t[1] * e1[2] - t[2] * e1[1], t[2] * e1[0] - t[0] * e1[2], t[0] * e1[1] - t[1] * e1[0]};
  const float v = (d[0] * q[0] + d[1] * q[1] + d[2] * q[2]) * inv;
  if (v < 0 || u + v > 1) return -1;
  return (e2[0] * q[0] + e2[1] * q[1] + e2[2] * q[2]) * inv;
}

TEST(RenderChunks, NoCracksAcrossResolutions) {
  // Every render chunk of a camera's plan meshed at its own level (16^3 at
  // full resolution near the camera up to 128^3 at 1/8 far away): a
  // vertical ray from the sky must stop near the true ground everywhere.
  // Through a crack it would fall to the bottom of the box.
  TerrainFixture t;
  GridSource src(t.grid, t.known_chunks());
  LodParams p;
  p.view_distance = 400;
  p.split_factor = 1.0f;  // many resolution borders in a small box
  const Vec3f cam{3, 60, -5};
  std::vector<Mesh> meshes;
  std::unordered_map<int, int> levels;
  for (const NodeKey& k : select_render_chunks(cam, p)) {
    if (!intersect(k.region(), t.box).volume()) continue;
    const ChunkPlan plan = plan_render_chunk(src, k, p);
    if (!plan.any_known) continue;
    ++levels[plan.sample_level];
    meshes.emplace_back();
    build_render_chunk(src, k, plan.sample_level, meshes.back());
  }
  ASSERT_GE(levels.size(), 4u) << "several resolutions meet";
  // Columns of triangles by their x-z bounding boxes.
  const int lo = -120, hi = 120, side = hi - lo;
  std::vector<std::vector<const float*>> bins(static_cast<std::size_t>(side * side));
  for (const Mesh& m : meshes)
    for (std::size_t i = 0; i < m.indices.size(); i += 3) {
      const float* a = m.vertices[m.indices[i]].pos;
      const float* b = m.vertices[m.indices[i + 1]].pos;
      const float* c = m.vertices[m.indices[i + 2]].pos;
      const int x0 = std::max(lo, static_cast<int>(std::floor(std::min({a[0], b[0], c[0]}))));
      const int x1 = std::min(hi - 1, static_cast<int>(std::floor(std::max({a[0], b[0], c[0]}))));
      const int z0 = std::max(lo, static_cast<int>(std::floor(std::min({a[2], b[2], c[2]}))));
      const int z1 = std::min(hi - 1, static_cast<int>(std::floor(std::max({a[2], b[2], c[2]}))));
      for (int z = z0; z <= z1; ++z)
        for (int x = x0; x <= x1; ++x) {
          auto& bin = bins[static_cast<std::size_t>((z - lo) * side + (x - lo))];
          bin.push_back(a);
          bin.push_back(b);
          bin.push_back(c);
        }
    }
  // Voxels within Chebyshev distance 8 of Air (separable dilation of the
  // Air set). A ray's first hit must be there: one that slipped through a
  // crack stops deep inside the ground, on a hidden cap.
  constexpr int kNear = 8;
  const Vec3i n = t.box.size();
  std::vector<std::uint8_t> near(static_cast<std::size_t>(n.x) * n.y * n.z);
  const auto at = [&](int x, int y, int z) { return (static_cast<std::size_t>(z) * n.y + y) * n.x + x; };
  for (int z = 0; z < n.z; ++z)
    for (int y = 0; y < n.y; ++y)
      for (int x = 0; x < n.x; ++x)
        near[at(x, y, z)] = occupancy_fraction(t.grid.get(t.box.min + Vec3i{x, y, z})) < 0.5f ? 1 : 0;
  const auto dilate = [&](int axis) {
    const int len = axis == 0 ? n.x : axis == 1 ? n.y : n.z;
    std::vector<int> prefix(static_cast<std::size_t>(len) + 1);
    const int o1 = axis == 0 ? n.y : n.x, o2 = axis == 2 ? n.y : n.z;
    for (int b = 0; b < o2; ++b)
      for (int a = 0; a < o1; ++a) {
        const auto idx = [&](int i) {
          return axis == 0 ? at(i, a, b) : axis == 1 ? at(a, i, b) : at(a, b, i);
        };
        for (int i = 0; i < len; ++i) prefix[static_cast<std::size_t>(i) + 1] = prefix[static_cast<std::size_t>(i)] + near[idx(i)];
        for (int i = 0; i < len; ++i) {
          const int lo_i = std::max(0, i - kNear), hi_i = std::min(len, i + kNear + 1);
          near[idx(i)] = prefix[static_cast<std::size_t>(hi_i)] - prefix[static_cast<std::size_t>(lo_i)] > 0 ? 1 : 0;
        }
      }
  };
  dilate(0);
  dilate(1);
  dilate(2);
  int misses = 0, deep = 0;
  for (int z = lo; z < hi; ++z)
    for (int x = lo; x < hi; ++x) {
      const float o[3] = {static_cast<float>(x) + 0.37f, 400, static_cast<float>(z) + 0.61f}, d[3] = {0, -1, 0};
      float best = 1e9f;
      const auto& bin = bins[static_cast<std::size_t>((z - lo) * side + (x - lo))];
      for (std::size_t i = 0; i < bin.size(); i += 3) {
        const float h = ray_triangle(o, d, bin[i], bin[i + 1], bin[i + 2]);
        if (h >= 0) best = std::min(best, h);
      }
      if (best > 1e8f) {
        ++misses;
        continue;
      }
      const int y = static_cast<int>(std::floor(o[1] - best)) - t.box.min.y;
      if (y >= n.y - 1) continue;  // a peak cut by the top of the box
      if (y < 0 || !near[at(x - t.box.min.x, y, z - t.box.min.z)]) {
        if (++deep < 5) std::printf("deep hit: x %d z %d y %d (top %d)\n", x, z, y + t.box.min.y, t.top(x, z));
      }
    }
  EXPECT_EQ(misses, 0);
  EXPECT_EQ(deep, 0) << "rays that went through the surface";
}

TEST(MeshScheduler, RemeshesOnlyWhatChanged) {
  TerrainFixture t;
  FakeSource src(t.grid);
  std::mutex m;
  LodParams p;
  p.view_distance = 120;
  MeshScheduler s(
      [&](const std::function<void(const VoxelSource&)>& fn) {
        std::lock_guard lock(m);
        fn(src);
      },
      p);
  s.set_view({0, 50, 0});
  const auto settle = [&] {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    while (std::chrono::steady_clock::now() < deadline) {
      s.take_results();
      if (s.idle()) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    return false;
  };
  ASSERT_TRUE(settle());
  const std::uint64_t first = s.stats().chunks_meshed;
  const std::size_t planned = s.plan().chunks.size();
  EXPECT_EQ(first, planned);
  // Nothing changed: nothing remeshed.
  s.mark_dirty();
  ASSERT_TRUE(settle());
  EXPECT_EQ(s.stats().chunks_meshed, first);
  // One chunk's revision changes: only the render chunks reading it.
  const Vec3i changed{0, 1, 0};
  std::size_t readers = 0;
  for (const NodeKey& k : s.plan().chunks) {
    const Region r = k.region();
    if (!intersect(Region{r.min - Vec3i{1, 1, 1}, r.max + Vec3i{1, 1, 1}}, chunk_region(changed)).empty()) ++readers;
  }
  {
    std::lock_guard lock(m);
    src.revisions_[changed] = 1;
  }
  s.mark_dirty();
  ASSERT_TRUE(settle());
  EXPECT_EQ(s.stats().chunks_meshed - first, readers);
  EXPECT_GT(readers, 0u);
  EXPECT_LT(readers, planned / 4);
}

}  // namespace
}  // namespace terrane::view
