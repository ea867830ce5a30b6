// The Terrane voxel: a material and an occupancy, two bytes.
//
// Material is a 6-bit id (0..63) into the world's material table; 0 is Air.
// Occupancy is the amount of matter around the voxel centre, quantized to a
// byte: a non-Air byte v decodes to (v + 1) / 256, so 255 is completely full
// and the value is exact in floating point. Air always has occupancy 0; every
// constructor enforces that without a branch, so an invalid Air voxel can
// never enter a grid.
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>
#include <span>
#include <string_view>
#include <type_traits>

namespace terrane {

using Material = std::uint8_t;

inline constexpr Material kAir = 0;
inline constexpr int kMaterialBits = 6;
inline constexpr int kMaterialCount = 1 << kMaterialBits;  // ids 0..63
inline constexpr std::uint8_t kFullOccupancy = 255;

// Trivial (no member initialisers) so that buffers of voxels can be copied
// with memcpy; Voxel{} is Air.
struct Voxel {
  Material material;
  std::uint8_t occupancy;

  friend constexpr bool operator==(Voxel, Voxel) = default;
};
static_assert(sizeof(Voxel) == 2, "a voxel is two bytes");
static_assert(std::is_trivial_v<Voxel>, "voxel buffers are copied with memcpy");

// Builds a voxel, forcing occupancy to 0 for Air without branching
// (the mask is all ones for any non-zero material, zero for Air).
// Precondition: material < kMaterialCount (our own callers; decoders validate
// untrusted ids before they get here).
constexpr Voxel make_voxel(Material material, std::uint8_t occupancy) {
  const auto mask = static_cast<std::uint8_t>(-static_cast<int>(material) >> 31);
  return Voxel{material, static_cast<std::uint8_t>(occupancy & mask)};
}

// Whether every voxel is Air (an empty chunk, mip or box).
inline bool all_air(std::span<const Voxel> voxels) {
  return std::all_of(voxels.begin(), voxels.end(), [](Voxel v) { return v.material == kAir; });
}

// The occupancy a material has when nothing says otherwise: full for solids,
// zero for Air. Uniform rows and byte-RLE runs without an occupancy byte use it.
constexpr std::uint8_t default_occupancy(Material material) {
  return material == kAir ? 0 : kFullOccupancy;
}

constexpr Voxel solid(Material material) {
  return make_voxel(material, default_occupancy(material));
}

// Whether a voxel stops a ray cast or an overlap test: non-Air with an
// occupancy byte of at least min_occupancy.
constexpr bool solid_enough(Voxel v, std::uint8_t min_occupancy) {
  return v.material != kAir && v.occupancy >= min_occupancy;
}
// Whether any of voxels [x0, x1) of a row does.
inline bool any_solid_enough(const Voxel* row, int x0, int x1, std::uint8_t min_occupancy) {
  for (int x = x0; x < x1; ++x)
    if (solid_enough(row[x], min_occupancy)) return true;
  return false;
}

constexpr bool has_default_occupancy(Voxel v) {
  return v.occupancy == default_occupancy(v.material);
}

// Occupancy as a fraction in [0, 1]: (v + 1) / 256 for non-Air, 0 for Air.
constexpr float occupancy_fraction(Voxel v) {
  return v.material == kAir ? 0.0f : static_cast<float>(v.occupancy + 1) / 256.0f;
}

// The byte that best represents fraction f for a non-Air material: the
// nearest of the 256 representable values (1/256 .. 1). f <= 0 has no non-Air
// representation; callers writing "nothing" write Air.
constexpr std::uint8_t occupancy_byte(float f) {
  const float scaled = f * 256.0f - 1.0f;
  if (scaled <= 0.0f) return 0;
  if (scaled >= 255.0f) return 255;
  return static_cast<std::uint8_t>(scaled + 0.5f);
}

// The article's default material table (23 entries, ids 0..22).
inline constexpr std::array<std::string_view, 23> kDefaultMaterialNames = {
    "Air",   "Water",     "Grass",       "Slate",     "Concrete", "Brick",
    "Sand",  "WoodPlanks", "Rock",       "Glacier",   "Snow",     "Sandstone",
    "Mud",   "Basalt",    "Ground",      "CrackedLava", "Asphalt", "Cobblestone",
    "Ice",   "LeafyGrass", "Salt",       "Limestone", "Pavement"};

namespace materials {
inline constexpr Material kAir = 0, kWater = 1, kGrass = 2, kSlate = 3, kConcrete = 4,
                          kBrick = 5, kSand = 6, kWoodPlanks = 7, kRock = 8, kGlacier = 9,
                          kSnow = 10, kSandstone = 11, kMud = 12, kBasalt = 13, kGround = 14,
                          kCrackedLava = 15, kAsphalt = 16, kCobblestone = 17, kIce = 18,
                          kLeafyGrass = 19, kSalt = 20, kLimestone = 21, kPavement = 22;
}  // namespace materials

}  // namespace terrane
