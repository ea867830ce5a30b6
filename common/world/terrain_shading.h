// TerrainShading: turns the field into voxels. It owns the material and
// cave layers: which biome a column is, its topsoil and subsoil, the rock
// strata, where caves are carved, where water, ice and lava fill open space,
// and the Basalt bedrock.
//
// It reads a TerrainField twice: its params and strata seed once, when
// built, and a column's Surface (with its neighbours' heights) in column().
// The 3D fields come in as lattice corners, sampled by the caller from the
// same field. Immutable after construction: every method is const and any
// number of threads may call them at once.
#pragma once

#include <cstdint>

#include "common/voxel/voxel.h"
#include "common/world/generator_params.h"
#include "common/world/terrain_field.h"

namespace terrane {

// Surface classification of a column, used for topsoil and vegetation.
enum class Biome : std::uint8_t {
  kOcean,           // below water: sand, mud and gravel-like ground
  kBeach,           // a thin sand strip at sea level
  kPlains,          // Grass over Ground
  kMeadow,          // wet temperate: LeafyGrass over Ground
  kDesert,          // Sand over Sandstone, stepped canyons
  kSwamp,           // Mud at sea level with pools
  kHighlands,       // terraced rock: Slate, Limestone, thin Grass on flats
  kSnowyMountains,  // Snow above the snow line, Ice on cold water
};
inline constexpr int kBiomeCount = 8;
const char* to_string(Biome biome);

class TerrainShading {
 public:
  // Caves are carved only in [kCaveMinY, surface); below kBedrockY everything
  // is solid Basalt; cave air below kLavaY is CrackedLava.
  static constexpr std::int32_t kCaveMinY = kWorldMinY + 4;
  static constexpr std::int32_t kBedrockY = kWorldMinY + 4;
  static constexpr std::int32_t kLavaY = kWorldMinY + 14;

  // Everything the voxel loop needs about one column.
  struct Column {
    float height;          // surface height
    float inv_len;         // 1 / sqrt(1 + |grad h|^2): vertical distance -> true distance
    float slope;           // |grad h|
    float overhang;        // vertical displacement amplitude of the surface, voxels
    float normal_overhang; // displacement along the surface normal, voxels
    std::int32_t top_y;    // y >= top_y: terrain density <= -1 (no 3D work)
    std::int32_t bot_y;    // y <= bot_y: terrain density >= 1 before caves
    std::int32_t lattice_lo, lattice_hi;  // y range that reads the 3D lattice
    std::int32_t water_level;
    float strata_warp;
    float cave_guard;      // caves fade out within this depth of the surface
    float worm_radius;
    float soil_factor;     // 1 on flats, 0 on cliffs
    float top_depth, sub_depth;
    Material top_mat, sub_mat;
    float desert_depth;    // sandstone strata reach this deep (deserts)
    Biome biome;
    bool cold;
  };

  explicit TerrainShading(const TerrainField& field);

  // The column at surface s, given the heights of its four neighbours
  // (x - 1, x + 1, z - 1, z + 1) for the slope.
  Column column(const TerrainField::Surface& s, float h_xm, float h_xp, float h_zm, float h_zp) const;

  // The voxel at (x, y, z) of a column. `corners` holds the 8 lattice corners
  // of each field (corners[f * 8 + i], i = (dy * 2 + dz) * 2 + dx); it is
  // read only for y in [lattice_lo, lattice_hi] and may be null elsewhere.
  // sharpness scales the density before it is clamped: 1 for voxels, 2 /
  // cell for a coarse cell. The result keeps the Air invariant.
  Voxel shade(const Column& col, std::int32_t x, std::int32_t y, std::int32_t z, const float* corners,
              float sharpness = 1.0f) const;

 private:
  std::int32_t sea_level_;
  float overhang_strength_;
  bool caves_;
  std::uint32_t strata_seed_;  // TerrainField::strata_seed()
};

}  // namespace terrane
