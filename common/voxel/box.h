// Box: a dense 3D array of voxels, the unpacked form every read and write
// passes through. Voxels are stored in rows along x, addressed by (y, z):
// index (y * size.z + z) * size.x + x, the same order as VXRAW files, so
// read_row(y, z) is constant time and a row is contiguous.
#pragma once

#include <cassert>
#include <cstddef>
#include <span>
#include <vector>

#include "common/voxel/vec3.h"
#include "common/voxel/voxel.h"

namespace terrane {

class Box {
 public:
  Box() = default;
  // Precondition: every component of size >= 0.
  explicit Box(Vec3i size, Voxel fill = {}) : size_(size), voxels_(volume_of(size), fill) {}

  Vec3i size() const { return size_; }
  std::size_t voxel_count() const { return voxels_.size(); }
  bool empty() const { return voxels_.empty(); }

  std::size_t index(int x, int y, int z) const {
    assert(x >= 0 && y >= 0 && z >= 0 && x < size_.x && y < size_.y && z < size_.z);
    return (static_cast<std::size_t>(y) * size_.z + z) * size_.x + x;
  }
  Voxel get(int x, int y, int z) const { return voxels_[index(x, y, z)]; }
  Voxel get(Vec3i p) const { return get(p.x, p.y, p.z); }
  // Writes go through make_voxel, so Air never carries occupancy.
  void set(int x, int y, int z, Voxel v) { voxels_[index(x, y, z)] = make_voxel(v.material, v.occupancy); }
  void set(Vec3i p, Voxel v) { set(p.x, p.y, p.z, v); }

  // The article's readRow: the size.x voxels of row (y, z).
  const Voxel* read_row(int y, int z) const { return voxels_.data() + index(0, y, z); }
  // Mutable row access for bulk fills. The caller keeps the Air invariant.
  Voxel* write_row(int y, int z) { return voxels_.data() + index(0, y, z); }

  std::span<const Voxel> voxels() const { return voxels_; }
  std::span<Voxel> voxels() { return voxels_; }

  void fill(Voxel v) { std::fill(voxels_.begin(), voxels_.end(), make_voxel(v.material, v.occupancy)); }
  void resize(Vec3i size, Voxel fill = {}) {
    size_ = size;
    voxels_.assign(volume_of(size), fill);
  }

  friend bool operator==(const Box&, const Box&) = default;

 private:
  static std::size_t volume_of(Vec3i s) {
    assert(s.x >= 0 && s.y >= 0 && s.z >= 0);
    return static_cast<std::size_t>(s.x) * s.y * s.z;
  }

  Vec3i size_{};
  std::vector<Voxel> voxels_;
};

}  // namespace terrane
