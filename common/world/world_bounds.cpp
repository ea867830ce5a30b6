#include "common/world/world_bounds.h"

#include <algorithm>

#include "common/voxel/chunk.h"

namespace terrane {

bool WorldBounds::contains(Vec3i v) const {
  if (v.y < min_y || v.y >= max_y) return false;
  if (!bounded_xz) return true;
  return v.x >= min_x && v.x < max_x && v.z >= min_z && v.z < max_z;
}

Region WorldBounds::clamp(const Region& r) const {
  Region out = r;
  out.min.y = std::max(out.min.y, min_y);
  out.max.y = std::min(out.max.y, max_y);
  if (bounded_xz) {
    out.min.x = std::max(out.min.x, min_x);
    out.max.x = std::min(out.max.x, max_x);
    out.min.z = std::max(out.min.z, min_z);
    out.max.z = std::min(out.max.z, max_z);
  }
  return out;
}

std::string WorldBounds::validate() const {
  auto in_range = [](std::int64_t v) { return v >= -kMaxWorldCoordinate && v <= kMaxWorldCoordinate; };
  if (!in_range(min_y) || !in_range(max_y)) return "vertical bounds beyond +-2^30";
  if (min_y >= max_y) return "vertical bounds empty (min_y >= max_y)";
  if (bounded_xz) {
    if (!in_range(min_x) || !in_range(max_x) || !in_range(min_z) || !in_range(max_z))
      return "horizontal bounds beyond +-2^30";
    if (min_x >= max_x || min_z >= max_z) return "horizontal bounds empty";
  }
  return {};
}

bool WorldBounds::touches_chunk(Vec3i chunk_pos) const {
  const Vec3i o = chunk_origin(chunk_pos);
  return !clamp(Region{o, o + Vec3i{kChunkSize, kChunkSize, kChunkSize}}).empty();
}

WorldBounds WorldBounds::with_border(const WorldBounds& border) const {
  WorldBounds b = *this;
  b.bounded_xz = border.bounded_xz;
  b.min_x = border.min_x;
  b.max_x = border.max_x;
  b.min_z = border.min_z;
  b.max_z = border.max_z;
  return b;
}

bool WorldBounds::same_border(const WorldBounds& border) const {
  if (bounded_xz != border.bounded_xz) return false;
  return !bounded_xz ||
         (min_x == border.min_x && max_x == border.max_x && min_z == border.min_z && max_z == border.max_z);
}

}  // namespace terrane
