// Per-material look of the smooth surface: a colour and how the material
// shapes the surface (after the smooth terrain article: the same occupancy
// data gives rounded sand and faceted rock).
//   sharpness 0: vertices at the smooth occupancy crossing, normals from the
//                occupancy gradient (soft: sand, snow, grass, mud);
//   sharpness 1: vertices pulled towards their cell centre and jittered, and
//                flat per-triangle normals in the shader (faceted: rock,
//                basalt, bricks, concrete).
#pragma once

#include <array>
#include <cstdint>

#include "common/voxel/voxel.h"

namespace terrane::view {

struct MaterialStyle {
  std::uint8_t r, g, b;  // sRGB base colour
  float sharpness;       // 0 soft .. 1 faceted
};

// Indexed by material id; ids beyond the default table get a neutral grey.
const MaterialStyle& material_style(Material m);

}  // namespace terrane::view
