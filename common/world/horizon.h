// Horizon images: a whole 256^3 region (8^3 chunks) at 2^3 or 1^3 voxels
// per chunk, or one voxel per 2^3 chunks, in one network codec unit (16^3,
// 8^3 or 4^3 voxels). A new view's
// first pass sends one per region, so the whole horizon arrives in a few
// tens of kilobytes before any chunk's own 4^3 mip (PROTOCOL.md, "Stream
// batches", kind 7). Levels continue the mips': level 4 is 2^3 per chunk,
// level 5 one voxel per chunk, level 6 one voxel per 2^3 chunks (a block),
// each voxel the downsampling of the eight below it (common/voxel/chunk.h,
// downsample). A client holds a chunk covered by a level-6 image as
// Horizon 5, its voxel its block's (horizon_upsample).
//
// An image is approximate: it is made from the chunks' stored 4^3 mips
// (coarse images), from estimates where a chunk was never generated, and it
// may trail the latest tick. Clients replace it with each chunk's own data;
// nothing exact (edits, hashes, Holdings) ever reads it.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "common/codec/net_codec.h"
#include "common/voxel/box.h"
#include "common/world/coarse_image.h"

namespace terrane {

inline constexpr int kHorizonNearLevel = kMipLevels;      // 4: 2^3 voxels per chunk
inline constexpr int kHorizonFarLevel = kMipLevels + 1;   // 5: 1 voxel per chunk
inline constexpr int kHorizonOuterLevel = kMipLevels + 2; // 6: 1 voxel per 2^3 chunks
inline constexpr int kHorizonLevels = kHorizonOuterLevel - kHorizonNearLevel + 1;
inline constexpr int kHorizonRegionChunks = kCoarseRegionChunks;
inline constexpr int kHorizonRegionSlots = kHorizonRegionChunks * kHorizonRegionChunks * kHorizonRegionChunks;
// Voxels a side of a region's image at level (16 at 4, 8 at 5, 4 at 6).
inline constexpr int horizon_side(int level) { return (kHorizonRegionChunks * kChunkSize) >> level; }
inline constexpr bool is_horizon_level(int level) { return level >= kHorizonNearLevel && level <= kHorizonOuterLevel; }
// The levels a new view's images are sent at (PROTOCOL.md, "Streaming
// order"), by the distance d of a region's nearest chunk in view: level 4
// when d <= min(V / 4, kHorizonNearMax), level 5 when d <= kHorizonFarMax,
// else level 6 (to a client that takes it; level 5 to others).
inline constexpr std::int64_t kHorizonNearMax = 256;
inline constexpr std::int64_t kHorizonFarMax = 1024;
// The level its chunks are held at: a level-6 image's as level 5.
inline constexpr int horizon_held_level(int level) { return level < kHorizonFarLevel ? level : kHorizonFarLevel; }

// A level-6 image (4^3) as the level-5 image its chunks are held from (8^3):
// each voxel repeated 2^3 times.
Box horizon_upsample(const Box& outer);

// A region's image at one level, built chunk by chunk.
class HorizonBuilder {
 public:
  HorizonBuilder(Vec3i region, int level);
  Vec3i region() const { return region_; }
  int level() const { return level_; }
  // Voxels a side per chunk as built (2 at level 4, 1 at levels 5 and 6:
  // a level-6 image is built at level 5 and downsampled when encoded).
  int per_chunk() const { return kChunkSize >> horizon_held_level(level_); }
  // A chunk of the region from its 4^3 mip (a coarse image's entry).
  void put_coarse(Vec3i chunk_pos, const CoarseVoxels& voxels);
  // A chunk of the region from its per_chunk()^3 voxels (Box order, an
  // estimate at that resolution). Chunks never put are Air.
  void put(Vec3i chunk_pos, std::span<const Voxel> voxels);
  // The image at horizon_held_level(level()).
  const Box& image() const { return image_; }

 private:
  Vec3i region_;
  int level_;
  Box image_;
};

// One region's image at one level, encoded once and shared (immutable).
struct HorizonImage {
  Vec3i region;
  int level = kHorizonFarLevel;
  std::vector<std::uint8_t> unit;  // one horizon_side(level)^3 network codec unit; empty: not made
};
using HorizonPtr = std::shared_ptr<const HorizonImage>;

// Its unit in network codec format codec_version (net_codec_encode's).
HorizonPtr encode_horizon(const HorizonBuilder& b, std::uint8_t codec_version = kNetCodecVersion);

}  // namespace terrane
