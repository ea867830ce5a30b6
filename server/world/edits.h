// Applying edit requests to the authoritative grid, recording which 4^3
// units changed (the unit of UpdateBatch, common/codec/update_batch.h).
//
// FillBox writes one voxel (material, occupancy) over the box.
// WriteBox writes the given voxels over the box.
// Sphere kinds give each voxel the fraction f of its cube inside the sphere,
// approximated as clamp(r + 0.5 - |centre - voxel centre|, 0, 1), so the
// total occupancy written matches the sphere's volume (4/3 pi r^3) to within
// a few percent for r >= 2; voxels whose f is zero keep their value.
//   FillSphere: a voxel becomes the edit's material with occupancy
//     max(f, its old fraction when it already had that material); a voxel of
//     another solid material is replaced only where f >= its fraction.
//     With material Air it digs (same as Dig).
//   Dig: the old fraction becomes min(old, 1 - f), Air when nothing is left.
//   Paint: non-Air voxels with f >= 0.5 take the edit's material and keep
//     their occupancy.
//   Smooth: with s = strength/255 * f, a voxel's occupancy o becomes
//     o + s * (m - o), where m is the mean occupancy of its 3x3x3
//     neighbourhood as it was before the edit (a box filter, so the result
//     does not depend on visiting order). A voxel that gains occupancy from
//     Air takes the most common non-Air material among its neighbours; one
//     left below half a step becomes Air.
// Thread-safety: none; the caller owns the grid (the world strand's scratch).
#pragma once

#include <bitset>
#include <unordered_map>

#include "common/codec/update_batch.h"
#include "common/voxel/grid.h"
#include "protocol/messages.h"

namespace terrane {

// Changed 4^3 units per chunk; bit index (uy*8+uz)*8+ux.
using ChangedUnits = std::unordered_map<Vec3i, std::bitset<kUpdateUnitsPerChunk>, Vec3iHash>;

// Marks the 4^3 units of voxels as changed (consecutive voxels of one chunk
// cost one lookup).
class UnitMarker {
 public:
  explicit UnitMarker(ChangedUnits& changed) : changed_(changed) {}
  void mark(Vec3i p) {
    const Vec3i cp = chunk_of(p);
    if (bits_ == nullptr || cp != last_) {
      bits_ = &changed_[cp];
      last_ = cp;
    }
    const Vec3i l = local_of(p);
    bits_->set(static_cast<std::size_t>(((l.y / 4) * 8 + l.z / 4) * 8 + l.x / 4));
  }

 private:
  ChangedUnits& changed_;
  std::bitset<kUpdateUnitsPerChunk>* bits_ = nullptr;
  Vec3i last_;
};

// Applies edit to grid, only inside clip. Returns the number of voxels that
// changed value and adds their units to changed.
std::size_t apply_edit(Grid& grid, const EditRequestMsg& edit, const Region& clip, ChangedUnits& changed);

// Sum of occupancy fractions over region (tests and tools).
double total_occupancy(const Grid& grid, const Region& region);

}  // namespace terrane
