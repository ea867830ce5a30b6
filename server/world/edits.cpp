// Applying edit requests to a grid (server/world/edits.h).
#include "server/world/edits.h"

#include <array>
#include <cmath>

#include "common/codec/byte_rle.h"

namespace terrane {

namespace {

float sphere_fraction(const EditRequestMsg& e, Vec3i p) {
  const float dx = static_cast<float>(p.x) + 0.5f - e.center.x;
  const float dy = static_cast<float>(p.y) + 0.5f - e.center.y;
  const float dz = static_cast<float>(p.z) + 0.5f - e.center.z;
  return std::clamp(e.radius + 0.5f - std::sqrt(dx * dx + dy * dy + dz * dz), 0.0f, 1.0f);
}

Voxel dig(Voxel old, float f) {
  const float left = std::min(occupancy_fraction(old), 1.0f - f);
  return left < 0.5f / 256.0f ? Voxel{} : make_voxel(old.material, occupancy_byte(left));
}

Voxel fill(Voxel old, float f, Material m) {
  const float had = old.material == m ? occupancy_fraction(old) : 0.0f;
  if (f > had && (old.material == kAir || old.material == m || f >= occupancy_fraction(old)))
    return make_voxel(m, occupancy_byte(f));
  return old;
}

// The smoothing filter of one voxel, reading the pre-edit snapshot src
// (whose origin is origin).
Voxel smooth(const Box& src, Vec3i origin, Vec3i p, float s) {
  const Vec3i l = p - origin;
  const Voxel old = src.get(l.x, l.y, l.z);
  float sum = 0;
  std::array<int, kMaterialCount> votes{};
  for (int dy = -1; dy <= 1; ++dy)
    for (int dz = -1; dz <= 1; ++dz)
      for (int dx = -1; dx <= 1; ++dx) {
        const Voxel n = src.get(l.x + dx, l.y + dy, l.z + dz);
        sum += occupancy_fraction(n);
        if (n.material != kAir) ++votes[n.material];
      }
  const float o = occupancy_fraction(old);
  const float next = o + s * (sum / 27.0f - o);
  if (next < 0.5f / 256.0f) return Voxel{};
  Material m = old.material;
  if (m == kAir) {
    int best = 0;
    for (std::size_t i = 1; i < votes.size(); ++i)
      if (votes[i] > best) {
        best = votes[i];
        m = static_cast<Material>(i);
      }
    if (m == kAir) return old;
  }
  return make_voxel(m, occupancy_byte(next));
}

}  // namespace

std::size_t apply_edit(Grid& grid, const EditRequestMsg& e, const Region& clip, ChangedUnits& changed) {
  const Region r = intersect(e.bounds(), clip);
  if (r.empty()) return 0;
  UnitMarker marker(changed);
  std::size_t n = 0;
  auto count = [&](Vec3i p, Voxel old, Voxel nv) {
    if (nv != old) {
      marker.mark(p);
      ++n;
    }
    return nv;
  };
  switch (e.kind) {
    case EditKind::kUndo:
    case EditKind::kRedo:
      return 0;  // history steps are applied by the server (apply_history)
    case EditKind::kFillBox: {
      const Voxel v = make_voxel(e.material, e.occupancy);
      grid.modify(r, [&](Vec3i p, Voxel old) { return count(p, old, v); });
      return n;
    }
    case EditKind::kWriteBox: {
      const Vec3i size = e.box.size();
      grid.modify(r, [&](Vec3i p, Voxel old) {
        const Vec3i l = p - e.box.min;
        const Voxel v = e.voxels[static_cast<std::size_t>((l.y * size.z + l.z) * size.x + l.x)];
        return count(p, old, make_voxel(v.material, v.occupancy));
      });
      return n;
    }
    case EditKind::kFillSphere:
    case EditKind::kDig:
      grid.modify(r, [&](Vec3i p, Voxel old) {
        const float f = sphere_fraction(e, p);
        if (f <= 0.0f) return old;
        return count(p, old, e.material == kAir ? dig(old, f) : fill(old, f, e.material));
      });
      return n;
    case EditKind::kPaint:
      grid.modify(r, [&](Vec3i p, Voxel old) {
        if (old.material == kAir || sphere_fraction(e, p) < 0.5f) return old;
        return count(p, old, make_voxel(e.material, old.occupancy));
      });
      return n;
    case EditKind::kSmooth: {
      // Snapshot first: the filter reads the pre-edit state only.
      const Region reads = {r.min - Vec3i{1, 1, 1}, r.max + Vec3i{1, 1, 1}};
      Box src(reads.size());
      grid.read_box(reads.min, src);
      const float strength = static_cast<float>(e.occupancy) / 255.0f;
      grid.modify(r, [&](Vec3i p, Voxel old) {
        const float f = sphere_fraction(e, p);
        if (f <= 0.0f) return old;
        return count(p, old, smooth(src, reads.min, p, strength * f));
      });
      return n;
    }
  }
  return n;
}

double total_occupancy(const Grid& grid, const Region& region) {
  double sum = 0;
  for (int y = region.min.y; y < region.max.y; ++y)
    for (int z = region.min.z; z < region.max.z; ++z)
      for (int x = region.min.x; x < region.max.x; ++x) sum += occupancy_fraction(grid.get({x, y, z}));
  return sum;
}

}  // namespace terrane
