// Chunk: a 32³ block of the grid, row-packed, with its mip pyramid.
//
// Level 0 is the full-resolution 32³ content, row-packed; levels 1, 2, 3 are
// the 16³, 8³ and 4³ mips, kept as network-codec units (NET_CODEC.md; a
// chunk encodes them in format version 1, which decodes fastest; a chunk
// loaded from an image keeps the units it was stored with, of either
// version) back
// to back in one allocation: a bit-packed RLE is several times smaller than
// row-packed 16-voxel rows, and the mips are read whole (for LOD and
// replication, where the stored unit is the bytes sent). Writes update the
// mips at once, in plain boxes the chunk holds from its first write until
// pack_mips() or compact() encodes them again, so a run of writes pays one
// encoding (the world strand packs each tick's chunks before publishing). A mip voxel
// covers 2×2×2 voxels of the level below (its "children"):
//   - it is Air only if all its children are Air, so Air at any level means
//     Air in everything it covers (an all-Air 4³ level is an empty chunk);
//   - otherwise its material is the most common non-Air material among the
//     children (ties go to the lowest id) and its occupancy is the mean of
//     the children's occupancy fractions (Air counting 0), quantized to the
//     nearest byte and never below the smallest non-zero value: matter is
//     conserved up to quantization.
// Coordinates here are chunk-local, 0..31 at level 0.
#pragma once

#include <cmath>

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "common/voxel/box.h"
#include "common/voxel/row_packed_box.h"
#include "common/voxel/vec3.h"

namespace terrane {

inline constexpr int kChunkSize = 32;
inline constexpr int kChunkShift = 5;
inline constexpr int kMipLevels = 4;  // level 0 (32³) .. level 3 (4³)

// Voxel <-> chunk coordinates (floor division: negative coordinates work).
inline Vec3i chunk_of(Vec3i voxel) { return floor_div(voxel, kChunkSize); }
inline Vec3i local_of(Vec3i voxel) { return floor_mod(voxel, kChunkSize); }
inline Vec3i chunk_origin(Vec3i chunk_pos) { return chunk_pos * kChunkSize; }
inline Region chunk_region(Vec3i chunk_pos) {
  return Region::from_min_size(chunk_origin(chunk_pos), {kChunkSize, kChunkSize, kChunkSize});
}

// Calls fn(Vec3i chunk_pos) for every chunk overlapping a non-empty region,
// y outermost, then z, then x.
template <class F>
void for_each_chunk_in(const Region& r, F&& fn) {
  if (r.empty()) return;
  const Vec3i c0 = chunk_of(r.min), c1 = chunk_of(r.max - Vec3i{1, 1, 1});
  for (int y = c0.y; y <= c1.y; ++y)
    for (int z = c0.z; z <= c1.z; ++z)
      for (int x = c0.x; x <= c1.x; ++x) fn(Vec3i{x, y, z});
}

// Whether two non-empty regions overlap a chunk in common.
inline bool chunks_meet(const Region& a, const Region& b) {
  const auto cover = [](const Region& r) {
    return Region{chunk_origin(chunk_of(r.min)), chunk_origin(chunk_of(r.max - Vec3i{1, 1, 1}) + Vec3i{1, 1, 1})};
  };
  return !a.empty() && !b.empty() && !intersect(cover(a), cover(b)).empty();
}

// The downsampling rule above, for the 8 children of one mip voxel.
Voxel downsample(const Voxel children[8]);
// A box of even side n downsampled to side n / 2 by that rule (children in
// the order the chunk's mips take them: x fastest, then z, then y).
Box downsample_box(const Box& in);

struct ChunkMemory {
  std::size_t object_bytes = 0;  // sizeof(Chunk)
  std::size_t level0_bytes = 0;  // headers + row data of the 32³ level
  std::size_t mip_bytes = 0;     // the encoded units of levels 1..3
  std::size_t total() const { return object_bytes + level0_bytes + mip_bytes; }
};

class Chunk {
 public:
  using Level0 = RowPackedBox<32>;

  explicit Chunk(Material fill = kAir);
  // How a chunk holds its mips: kKept, as units (or dense boxes between
  // writes), made when level 0 changes; kDerived, none held: a read of a
  // mip level downsamples level 0 then (mip_get, read_level), and writes
  // pay nothing for mips. kDerived is for holders that rarely or never read
  // a full-resolution chunk's mips, such as a load test's replicas, whose
  // Full records would otherwise each pay a downsample and three encodings
  // and keep the units. clone() and moves keep the choice; write_image()
  // writes the mips either way.
  enum class Mips : std::uint8_t { kKept, kDerived };
  // A packed chunk from a 32³ box, its mips as asked. Precondition: box is 32³.
  static Chunk from_box(const Box& box, Mips mips = Mips::kKept);
  // A moved-from chunk is empty Air, usable as any other.
  Chunk(Chunk&& other) noexcept { *this = std::move(other); }
  Chunk& operator=(Chunk&& other) noexcept;
  Chunk clone() const;

  Voxel get(int x, int y, int z) const { return level0_.get(x, y, z); }
  Voxel get(Vec3i p) const { return get(p.x, p.y, p.z); }
  const Voxel* read_row(int y, int z, Level0::Row& scratch) const { return level0_.read_row(y, z, scratch); }
  // Whether any voxel of the chunk-local box [min, max) is solid_enough
  // (voxel.h), read in place (RowPackedBox::box_has_solid).
  // Precondition: the box lies inside the chunk.
  bool box_has_solid(Vec3i min, Vec3i max, std::uint8_t min_occupancy) const {
    return level0_.box_has_solid(min.x, max.x, min.y, max.y, min.z, max.z, min_occupancy);
  }
  const Level0& level0() const { return level0_; }

  // Voxel of mip level 0..3 at level-local coordinates (0 .. 32 >> level).
  // (Levels 1..3 decode their unit: read a level whole where speed matters.)
  Voxel mip_get(int level, int x, int y, int z) const;
  // Reads a whole level into a (32 >> level)³ box.
  void read_level(int level, Box& out) const;
  // The network-codec unit of mip level 1..3, as stored (empty for a uniform
  // chunk, whose levels are all its one material, while writes have left
  // the mips unpacked, and for derived mips).
  std::span<const std::uint8_t> mip_unit(int level) const;
  // Encodes mips left unpacked by writes into units (no-op otherwise).
  void pack_mips();
  bool mips_packed() const { return dense_ == nullptr; }
  Mips mips() const { return mips_derived_ ? Mips::kDerived : Mips::kKept; }

  // Copies the chunk-local region [min, min + out.size()) into out.
  // Precondition: the region lies inside the chunk.
  void read_box(Vec3i min, Box& out, Vec3i out_offset, Vec3i size) const;

  // Rewrites the chunk-local region: fn(Vec3i local, Voxel old) -> Voxel new.
  // fn must not touch this chunk. Mips are updated before returning.
  template <class VoxelFn>
  void modify(const Region& local, VoxelFn&& fn) {
    const Region r = intersect(local, Region{{0, 0, 0}, {kChunkSize, kChunkSize, kChunkSize}});
    if (r.empty()) return;
    level0_.modify_rows(r.min.y, r.max.y, r.min.z, r.max.z, [&](int y, int z, Voxel* row) {
      for (int x = r.min.x; x < r.max.x; ++x) row[x] = fn(Vec3i{x, y, z}, row[x]);
    });
    update_mips(r);
  }
  void set(Vec3i local, Voxel v) {
    modify(Region{local, local + Vec3i{1, 1, 1}}, [&](Vec3i, Voxel) { return v; });
  }
  void fill(Material m);

  // True when every voxel is Air (kept beside the mips).
  bool empty() const { return empty_; }
  // Uniform chunk: one material at default occupancy everywhere.
  bool uniform() const { return level0_.is_uniform(); }

  // Recomputes every mip level from level 0 (after bulk loads).
  void rebuild_mips();
  // Repacks level 0 (leaving unpacked mode) and packs the mips: call after
  // write-heavy phases.
  void compact();

  // The chunk as it is in memory (WORLD_FORMAT.md, "Chunk image"), appended
  // to out: level 0's image (RowPackedBox::write_image), then, unless level
  // 0 is uniform, the three mip units, each after its length (u16 LE).
  // Unpacked storage is packed in a copy first. False (out unchanged) for
  // the rare chunk whose rows stay unpacked when packed (records beyond
  // 15-bit offsets, RowPackedBox::compact), which has no image.
  bool write_image(std::vector<std::uint8_t>& out) const;
  // Reads an image from in at pos and advances pos past it: level 0 checked
  // as read_image checks it, each mip unit decoded once to check it, and
  // level 3 agreeing with level 0 on whether the chunk is empty. A damaged
  // image is an error, never a chunk that reads out of bounds. (The mips
  // are otherwise taken as stored: the blob's checksum guards them.)
  static Result<Chunk> read_image(std::span<const std::uint8_t> in, std::size_t& pos);

  ChunkMemory memory() const;
  RowPackedStats level0_stats() const { return level0_.stats(); }

 private:
  // Mips between writes and pack_mips(): levels 1, 2, 3 as plain boxes.
  struct DenseMips {
    Box levels[kMipLevels - 1];  // levels 1..3 at [0..2]
  };

  void update_mips(const Region& changed_level0);
  // The units of levels 1..3 of dense, back to back in units (cleared
  // first); end[l] is where level l's ends.
  static void encode_mip_units(const DenseMips& dense, std::vector<std::uint8_t>& units,
                               std::array<std::uint16_t, kMipLevels>& end);

  Level0 level0_;
  std::unique_ptr<DenseMips> dense_;          // unpacked mips (then mips_ is stale and null)
  std::unique_ptr<std::uint8_t[]> mips_;      // units of levels 1, 2, 3; null when level 0 is uniform
  std::array<std::uint16_t, kMipLevels> mip_end_{};  // end of level l's unit in mips_ (l = 1..3)
  Material mip_fill_ = kAir;  // without units: every mip voxel is this material (level 0's, when last uniform)
  bool empty_ = true;
  bool mips_derived_ = false;  // Mips::kDerived: dense_ and mips_ stay null, mip reads downsample level 0
};

}  // namespace terrane
