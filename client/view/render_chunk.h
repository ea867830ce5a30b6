// Render chunks: the cubes the viewer meshes, growing with distance from
// 16^3 voxels near the camera to 256^3 far away (the smooth terrain
// article's rendering chunks), each meshed as 16 cells per axis from the
// replica's data at the matching mip level, or coarser where only a
// coarser mip has arrived (refined in place when finer data comes).
//
// A render chunk of level k is the cube [origin, origin + (16 << k))^3,
// origin a multiple of its size. Its samples are spaced s = 2^l voxels
// apart (l its sample level, >= k), one per s^3 cube of the chunk, plus one
// ring of samples of the neighbouring cubes: the ring makes neighbouring
// chunks overlap so that their closed surfaces leave no crack between them
// (client/view/mesher.h, client/view/VIEWER.md).
#pragma once

#include <algorithm>
#include <cstdint>
#include <vector>

#include "client/view/mesher.h"
#include "common/voxel/box.h"
#include "common/voxel/chunk.h"
#include "common/voxel/grid.h"
#include "common/voxel/vec3.h"

namespace terrane::view {

inline constexpr int kRenderChunkCells = 16;  // cells per axis at the chunk's own level
inline constexpr int kMaxRenderLevel = 4;     // 16 << 4 = 256 voxels

struct NodeKey {
  Vec3i origin;
  int level = 0;  // size 16 << level
  int size() const { return kRenderChunkCells << level; }
  Region region() const { return Region::from_min_size(origin, {size(), size(), size()}); }
  friend bool operator==(const NodeKey&, const NodeKey&) = default;
};
struct NodeKeyHash {
  std::size_t operator()(const NodeKey& k) const noexcept {
    return Vec3iHash{}(k.origin) ^ (static_cast<std::size_t>(k.level) * 0x9E3779B97F4A7C15ull);
  }
};

// What the mesher reads: per 32^3 chunk, the finest level held.
// Implementations: GridSource (a whole Grid at full resolution) and
// ReplicaSource (client/view/replica_source.h).
class VoxelSource {
 public:
  virtual ~VoxelSource() = default;
  // -1 nothing known (meshed as Air), 0 full resolution (or known Air),
  // 1..3 the mip level held.
  virtual int level(Vec3i chunk_pos) const = 0;
  // Changes whenever the chunk's voxels change (0 when not tracked).
  virtual std::uint64_t revision(Vec3i chunk_pos) const = 0;
  // Writes the chunk's voxels at a level L with level(chunk_pos) <= L <=
  // max(want, level(chunk_pos)) into out, resized to (32 >> L)^3, and
  // returns L (callers downsample further if L < want). want is in 0..3.
  // Precondition: level(chunk_pos) >= 0.
  virtual int read(Vec3i chunk_pos, int want, Box& out) const = 0;
  // A part of the chunk at level `want` (0..3): when the chunk is held at
  // level 0 (or known Air), writes the voxels of `part` (coordinates at
  // that level) into out, resized to part.size(), and returns want;
  // otherwise does read(chunk_pos, want, out) and returns what it returns.
  // A render chunk's sample ring needs one layer of its neighbours, not all
  // of them. By default: read() whole, then the part copied. Precondition:
  // level(chunk_pos) >= 0, part non-empty and inside the chunk at want.
  virtual int read_part(Vec3i chunk_pos, int want, const Region& part, Box& out) const;
};

// A Grid held wholly at full resolution; chunks outside `known` (chunk
// coordinates, half-open) are unknown.
class GridSource final : public VoxelSource {
 public:
  GridSource(const Grid& grid, Region known_chunks) : grid_(grid), known_(known_chunks) {}
  int level(Vec3i chunk_pos) const override { return known_.contains(chunk_pos) ? 0 : -1; }
  std::uint64_t revision(Vec3i) const override { return 0; }
  int read(Vec3i chunk_pos, int want, Box& out) const override;
  int read_part(Vec3i chunk_pos, int want, const Region& part, Box& out) const override;

 private:
  const Grid& grid_;
  Region known_;
};

// Writes the part (coordinates at `level`, 0..3) of a chunk held at full
// resolution into out, resized to part.size(). A part of level 1 short of
// the whole chunk is made from level 0 (read_box, then downsampled: the
// mip's own rule, so the same voxels) for less than decoding the whole mip
// unit; other levels read the mip. C is a Chunk or has its read_box and
// read_level.
template <class C>
void read_chunk_part(const C& chunk, int level, const Region& part, Box& out) {
  const Vec3i size = part.size();
  if (level == 0) {
    out.resize(size);
    chunk.read_box(part.min, out, Vec3i{0, 0, 0}, size);
    return;
  }
  const int n = kChunkSize >> level;
  if (part == Region{{0, 0, 0}, {n, n, n}}) {
    chunk.read_level(level, out);
    return;
  }
  out.resize(size);
  if (level == 1) {
    Box fine(size * 2);
    chunk.read_box(part.min * 2, fine, Vec3i{0, 0, 0}, size * 2);
    for (int y = 0; y < size.y; ++y)
      for (int z = 0; z < size.z; ++z) {
        const Voxel* r00 = fine.read_row(2 * y, 2 * z);
        const Voxel* r01 = fine.read_row(2 * y, 2 * z + 1);
        const Voxel* r10 = fine.read_row(2 * y + 1, 2 * z);
        const Voxel* r11 = fine.read_row(2 * y + 1, 2 * z + 1);
        Voxel* row = out.write_row(y, z);
        for (int x = 0; x < size.x; ++x) {
          const int fx = 2 * x;
          const Voxel children[8] = {r00[fx], r00[fx + 1], r01[fx], r01[fx + 1],
                                     r10[fx], r10[fx + 1], r11[fx], r11[fx + 1]};
          row[x] = downsample(children);
        }
      }
    return;
  }
  Box whole;
  chunk.read_level(level, whole);
  for (int y = 0; y < size.y; ++y)
    for (int z = 0; z < size.z; ++z)
      std::copy_n(whole.read_row(part.min.y + y, part.min.z + z) + part.min.x, size.x, out.write_row(y, z));
}

struct LodParams {
  float view_distance = 384;  // voxels; render chunks beyond are not drawn
  // A render chunk is split into 8 while the camera is nearer than
  // split_factor times its size: higher is finer (and more triangles).
  float split_factor = 2.5f;
  std::int32_t min_y = -128, max_y = 256;  // world vertical bounds
  // Never sample finer than this level (1: mips only, ignoring full data).
  int min_sample_level = 0;
  // Detail enhancement and snowflake lighting for render chunks sampled at
  // full resolution (client/view/enhanced_chunk.h).
  bool enhance = false;
};

// Distance from p to the nearest point of a region (0 inside).
float distance_to(Vec3f p, const Region& r);

// The render chunks for a camera position, nearest first: an octree from
// 256^3 roots, split by distance, within the view distance and bounds.
std::vector<NodeKey> select_render_chunks(Vec3f camera, const LodParams& params);

// What a render chunk's mesh depends on: its sample level (the chunk's own
// level, or coarser where the source holds only coarser data) and a hash of
// the level and revision of every source chunk its samples read. Equal
// plans give equal meshes.
struct ChunkPlan {
  int sample_level = 0;
  std::uint64_t signature = 0;
  bool any_known = false;
  bool enhanced = false;  // meshed with detail enhancement (LodParams::enhance at level 0)
};
ChunkPlan plan_render_chunk(const VoxelSource& source, const NodeKey& key, const LodParams& params);

// The samples of a render chunk at a sample level (see the header comment).
SampleGrid sample_render_chunk(const VoxelSource& source, const NodeKey& key, int sample_level);

// Meshes a render chunk's samples. Blocks with no sample below or none above the
// surface level give an empty mesh: a buried chunk adds no hull, its
// neighbours' overlapping hulls seal it.
void mesh_render_samples(const SampleGrid& samples, Mesh& out, const MesherOptions& options = {});
// sample_render_chunk + mesh_render_samples.
void build_render_chunk(const VoxelSource& source, const NodeKey& key, int sample_level, Mesh& out,
                        const MesherOptions& options = {});

}  // namespace terrane::view
