// TerrainGenerator: Terrane's deterministic, seedable world generator.
//
// Terrain comes from a density function (positive inside terrain) that is
// clamped to [-1, 1] and mapped to occupancy, so the surface is smooth to
// within a voxel; see common/world/GENERATOR.md for the shape, biomes, materials and
// the versioning rule.
//
// Contract:
//  - Deterministic: a voxel depends only on (params, position), never on how
//    regions are cut or in which order they are generated.
//  - Thread-safe: every method is const, so any number of threads may
//    generate regions at once (the only shared state is a cache of column
//    fields, behind a mutex, which never changes what is generated).
//  - Every output voxel satisfies the Air invariant (Air has occupancy 0).
//  - Any change to the output for some (params, position) must bump
//    kGeneratorVersion and the golden hashes in
//    tests/common/world/terrain_generator_test.cpp.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>
#include <string_view>

#include "common/codec/decode_error.h"
#include "common/voxel/box.h"
#include "common/voxel/vec3.h"
#include "common/voxel/voxel.h"

namespace terrane {

inline constexpr std::uint32_t kGeneratorVersion = 1;

// The vertical range a default world is built for (Y is up). The generator
// is defined everywhere: below kWorldMinY + 4 it is solid Basalt, above the
// highest peak it is Air.
inline constexpr std::int32_t kWorldMinY = -128;
inline constexpr std::int32_t kWorldMaxY = 256;

// All knobs are part of the world's metadata (to_metadata); validate() gives
// the accepted ranges.
struct GeneratorParams {
  std::uint64_t seed = 1;
  // Water fills open air below this y (oceans, rivers, swamps).
  std::int32_t sea_level = 32;
  // Horizontal feature size multiplier: 2 makes continents, mountains and
  // rivers twice as wide. Range [0.25, 8].
  float terrain_scale = 1.0f;
  // Peak height of mountain ranges above the land, in voxels. Range [0, 400].
  float mountain_height = 160.0f;
  // Amplitude of rolling hills, in voxels. Range [0, 64].
  float hill_height = 18.0f;
  // Amplitude of the 3D surface perturbation (overhangs, arches) in
  // steep and mountainous terrain, in voxels. Range [0, 16].
  float overhang_strength = 7.0f;
  // Tunnels and caverns underground (and lava deep down).
  bool caves = true;

  friend bool operator==(const GeneratorParams&, const GeneratorParams&) = default;
};

// Returns an empty string when params are valid, else a message naming the
// first bad field.
std::string validate(const GeneratorParams& params);

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

class TerrainGenerator {
 public:
  // Precondition: validate(params) is empty (from_metadata guarantees it;
  // invalid params are clamped into range so a bad caller cannot crash us).
  explicit TerrainGenerator(GeneratorParams params);

  const GeneratorParams& params() const { return params_; }

  // Fills out (resized to region.size()) with the voxels of the half-open
  // region, in Box order. An empty region yields an empty box.
  void generate(const Region& region, Box& out) const;

  // The reference path: one voxel, the same value generate() produces.
  Voxel voxel_at(Vec3i p) const;

  // The terrain at a coarser resolution: out (resized to count) gets, in
  // Box order, one voxel per cell of cell^3 voxels, the cell i covering
  // [origin + cell * i, origin + cell * (i + 1)). Each is evaluated once, at
  // the cell's centre, with the surface's occupancy ramp widened to the
  // cell, so it approximates the mean of the cell's voxels (as the mips'
  // downsampling would give) at 1 / cell^3 of generate()'s cost. An
  // estimate, not a mip: it differs where the terrain has detail finer
  // than a cell. Every output voxel keeps the Air invariant. cell >= 1.
  void coarse_sample(Vec3i origin, int cell, Vec3i count, Box& out) const;

  // The surface height of column (x, z) before 3D overhangs and caves (the
  // terrain density at (x, y, z) is positive for y a little below it), and its
  // biome. Cheap 2D queries for spawn points, maps and tests.
  float surface_height(std::int32_t x, std::int32_t z) const;
  Biome biome_at(std::int32_t x, std::int32_t z) const;
  // The y below which open air in this column is water (sea or lake level).
  std::int32_t water_level(std::int32_t x, std::int32_t z) const;

  // True only if generate(region) would be all Air, judged from the
  // columns alone (no voxel is evaluated): the region lies above every
  // column's terrain, water and lava. Chunks of sky answer true; a false
  // answer means only that generating is needed to know.
  bool all_air(const Region& region) const;

  // Parameters and version as "key=value" lines for the world's metadata.
  std::string to_metadata() const;

  // Parses to_metadata() output. Unknown keys, duplicates, missing keys,
  // malformed or out-of-range values and a different generator version are
  // rejected: the DecodeError carries the byte offset of the bad line and, if
  // `message` is not null, *message names the line and key.
  static Result<TerrainGenerator> from_metadata(std::string_view text, std::string* message = nullptr);

 private:
  struct Surface;  // 2D fields of a column
  struct Column;   // what the voxel loop needs about a column
  Surface surface(std::int32_t x, std::int32_t z) const;
  float raw_height(double px, double pz, Surface* s) const;
  Column column(const Surface& c, float h_xm, float h_xp, float h_zm, float h_zp) const;
  void lattice_sample(std::int32_t lx, std::int32_t ly, std::int32_t lz, float out[4]) const;
  // The 3D fields (overhang, two worms, cavern) at a point; without
  // overhang, out[0] is 0 (for points where shade() does not read it).
  void fields_at(double x, double y, double z, float out[4], bool overhang = true) const;
  // sharpness scales the density before it is clamped: 1 for voxels, 2 /
  // cell for a coarse_sample cell.
  Voxel shade(const Column& col, std::int32_t x, std::int32_t y, std::int32_t z, const float* corners,
              float sharpness = 1.0f) const;

  // The per-column part of generate() for a footprint: 2D noise fields
  // (with a one-voxel margin for the slope) turned into Columns.
  std::vector<Column> columns(std::int32_t x0, std::int32_t z0, int sx, int sz) const;
  // The same for a chunk's 32 x 32 footprint, kept for the chunks above
  // and below it (a column stack shares it; most of a generated chunk's
  // cost was these 2D fields, computed again for every chunk of the stack).
  // The latest kColumnCacheSize footprints are kept.
  std::shared_ptr<const std::vector<Column>> chunk_columns(std::int32_t x0, std::int32_t z0) const;

  struct ColumnCache;  // footprint -> Columns, the latest few (its capacity), behind a mutex
  static constexpr std::size_t kColumnCacheSize = 256;  // ~20 MB of Columns
  static constexpr std::size_t kCoarseColumnCacheSize = 1024;  // 16 Columns each, ~2 MB

  GeneratorParams params_;
  double inv_scale_;          // 1 / terrain_scale
  std::uint32_t seeds_[16];   // one per noise field
  std::shared_ptr<ColumnCache> cache_;  // shared by copies (same params, same columns)
  std::shared_ptr<ColumnCache> coarse_cache_;  // coarse_sample's chunk stacks (4 x 4 columns at cell 8)
};

}  // namespace terrane
