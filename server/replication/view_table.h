// ViewTable: the view rule of common/world/view.h for one view distance and one
// full-resolution radius, precomputed once and shared by every replicator
// that uses them. Since the rule depends only on the offset from the
// client's chunk, a client's plan is the table moved to its chunk, and a
// move into a neighbouring chunk (delta d, each component -1..1) changes
// only thin shells, also precomputed (lazily, once per delta):
//   entering(d): offsets from the new chunk that were not in view before,
//   leaving(d):  offsets from the old chunk that are not in view now,
//   finer(d):    offsets from the new chunk whose level is finer than the
//                same chunk's level before (or that just entered), below 3.
// Thread-safety: immutable after construction except the lazy shells,
// each made once under std::call_once.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <mutex>
#include <vector>

#include "common/voxel/vec3.h"

namespace terrane {

class ViewTable {
 public:
  ViewTable(std::int32_t view_distance, std::int32_t full_res_radius);

  // Shared tables: one per (view, full) pair for the whole process, at most
  // kMaxShared of them kept.
  static std::shared_ptr<const ViewTable> get(std::int32_t view_distance, std::int32_t full_res_radius);
  static constexpr std::size_t kMaxShared = 64;
  static std::size_t shared_count();

  std::int32_t view_distance() const { return view_; }
  std::int32_t full_res_radius() const { return full_; }
  // Every offset in view, nearest first.
  const std::vector<Vec3i>& offsets() const { return offsets_; }
  bool contains(Vec3i offset) const;
  int level(Vec3i offset) const;

  // Precondition: d != 0 and every component in -1..1.
  const std::vector<Vec3i>& entering(Vec3i d) const { return shells(d).entering; }
  const std::vector<Vec3i>& leaving(Vec3i d) const { return shells(d).leaving; }
  const std::vector<Vec3i>& finer(Vec3i d) const { return shells(d).finer; }

 private:
  struct Shells {
    std::vector<Vec3i> entering, leaving, finer;
  };
  const Shells& shells(Vec3i d) const;
  static std::size_t delta_index(Vec3i d) {
    return static_cast<std::size_t>(((d.y + 1) * 3 + (d.z + 1)) * 3 + (d.x + 1));
  }

  std::int32_t view_, full_;
  std::int32_t n_;  // offsets lie in [-n, n]^3
  std::vector<Vec3i> offsets_;
  std::vector<std::int8_t> levels_;  // per cell of the cube; -1 outside the view
  mutable std::array<std::once_flag, 27> shells_once_;
  mutable std::array<Shells, 27> shells_;
};

}  // namespace terrane
