// Coarse images: the coarsest mip (4^3 voxels) of every stored chunk of a
// 256^3 region (8^3 chunks), with each chunk's revision, in one blob. The
// world store keeps one per region beside the chunks, written with them or
// after them (never newer; a reader reads past an image that is behind), so
// a distant view reads a few rows instead of decoding thousands of chunks
// (common/world/WORLD_FORMAT.md, "coarse").
//
// Blob (version 1): [version u8 = 1][codec u8 = 1: LZ4][LZ4 block of:
//   count u16 LE, then count entries in increasing index order:
//     index u16 LE     (y * 8 + z) * 8 + x of the chunk in its region
//     revision u64 LE
//     64 voxels        material u8, occupancy u8 each, Box order (x fastest)]
// In an image as read (past any lag), a chunk without an entry was never
// stored (the generator makes it) or its row is damaged.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "common/codec/decode_error.h"
#include "common/voxel/chunk.h"

namespace terrane {

inline constexpr int kCoarseRegionChunks = 8;
inline constexpr int kCoarseSide = kChunkSize >> (kMipLevels - 1);  // 4
inline constexpr int kCoarseVoxels = kCoarseSide * kCoarseSide * kCoarseSide;
using CoarseVoxels = std::array<Voxel, kCoarseVoxels>;

struct CoarseEntry {
  Vec3i chunk_pos;
  std::uint64_t revision = 0;
  CoarseVoxels voxels{};
  friend bool operator==(const CoarseEntry&, const CoarseEntry&) = default;
};

inline Vec3i coarse_region_of(Vec3i chunk_pos) { return floor_div(chunk_pos, kCoarseRegionChunks); }
inline int coarse_index(Vec3i chunk_pos) {
  const Vec3i l = floor_mod(chunk_pos, kCoarseRegionChunks);
  return (l.y * kCoarseRegionChunks + l.z) * kCoarseRegionChunks + l.x;
}

// Every chunk of region, in index order (coarse_index 0, 1, ...).
template <class F>
void for_each_region_chunk(Vec3i region, F&& fn) {
  const Vec3i base = region * kCoarseRegionChunks;
  for (int y = 0; y < kCoarseRegionChunks; ++y)
    for (int z = 0; z < kCoarseRegionChunks; ++z)
      for (int x = 0; x < kCoarseRegionChunks; ++x) fn(base + Vec3i{x, y, z});
}

// The chunk's coarsest mip (null: all Air).
CoarseVoxels coarse_voxels(const Chunk* chunk);
// The same from a chunk's 32^3 voxels (precondition: box is 32^3), by the
// same downsampling rule, without packing a chunk.
CoarseVoxels coarse_voxels(const Box& box);

// entries: of one region, any order (precondition: distinct chunks of it).
std::vector<std::uint8_t> encode_coarse_image(Vec3i region, std::vector<CoarseEntry> entries);
// Every error is a DecodeError (truncated, bad version, out-of-order or
// repeated index, material >= 64, Air with occupancy); nothing is trusted.
Result<std::vector<CoarseEntry>> decode_coarse_image(Vec3i region, std::span<const std::uint8_t> blob);

}  // namespace terrane
