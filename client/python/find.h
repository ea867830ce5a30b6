// Client.find: the voxels of a material nearest a point, over what a
// client's replica holds at full resolution (a chunk seen only as a mip or
// not held is not searched). A free function over a Client, no state of its
// own; it reads the replica under the client's lock, one chunk at a time.
#pragma once

#include <cstddef>
#include <vector>

#include "client/client.h"

namespace terrane::python {

// Searches no farther than this (a cube of 129^3 voxels at most).
inline constexpr double kMaxFindRadius = 64;

// The voxels of material m whose centres lie within `within` of near,
// nearest first (ties in x, y, z order), at most max of them.
std::vector<Vec3i> find_voxels(const Client& c, Material m, Vec3f near, double within, std::size_t max);

}  // namespace terrane::python
