// WorldBounds: which voxels a world may hold (its vertical range, and an
// optional horizontal border). Stored in the world's meta
// (common/world/WORLD_FORMAT.md), sent to clients in Welcome, and the one test
// for "inside the world" everywhere: storage, streaming, edits, and the
// clients' view of what a complete view is (common/world/view.h).
#pragma once

#include <cstdint>
#include <string>

#include "common/voxel/vec3.h"

namespace terrane {

// World coordinates stay within +-2^30 voxels, so chunk and voxel
// arithmetic never overflows 32 bits.
inline constexpr std::int32_t kMaxWorldCoordinate = 1 << 30;

// Which voxels a world may hold. Vertical range always; horizontal optional.
struct WorldBounds {
  std::int32_t min_y = -128;
  std::int32_t max_y = 256;  // exclusive
  bool bounded_xz = false;
  std::int32_t min_x = 0, max_x = 0, min_z = 0, max_z = 0;  // exclusive max, if bounded_xz

  bool contains(Vec3i voxel) const;
  // True if any voxel of the chunk lies inside the bounds.
  bool touches_chunk(Vec3i chunk_pos) const;
  Region clamp(const Region& r) const;
  // Empty when valid, else what is wrong: every limit within
  // +-kMaxWorldCoordinate and each max above its min.
  std::string validate() const;
  // These bounds with border's horizontal limits (or none, when border is
  // not bounded_xz): what a world border (terrane-server --border) makes of
  // a world's bounds. same_border: whether border would change nothing.
  WorldBounds with_border(const WorldBounds& border) const;
  bool same_border(const WorldBounds& border) const;
};

}  // namespace terrane
