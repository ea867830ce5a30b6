// TerrainGenerator: Terrane's deterministic, seedable world generator.
//
// Terrain comes from a density function (positive inside terrain) that is
// clamped to [-1, 1] and mapped to occupancy, so the surface is smooth to
// within a voxel; see common/world/GENERATOR.md for the shape, biomes, materials and
// the versioning rule.
//
// It composes three owners: GeneratorParams (the knobs and their metadata
// text, generator_params.h), TerrainField (the height and density field and
// its noise state, terrain_field.h) and TerrainShading (materials, biomes,
// caves and water, terrain_shading.h). What it owns itself is box
// generation: the columns of a footprint, the 3D lattice a region reads,
// the voxel loop, coarse samples, and the caches of chunk footprints' columns.
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
#include "common/world/generator_params.h"
#include "common/world/terrain_field.h"
#include "common/world/terrain_shading.h"

namespace terrane {

class TerrainGenerator {
 public:
  // Precondition: validate(params) is empty (from_metadata guarantees it;
  // invalid params are clamped into range so a bad caller cannot crash us).
  explicit TerrainGenerator(GeneratorParams params);

  const GeneratorParams& params() const { return field_.params(); }

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
  // than a cell. From cells of 16 voxels up, a column's slope (which
  // shades it) is measured between its neighbouring cells' centres: the
  // cell's mean slope. Every output voxel keeps the Air invariant. cell >= 1.
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
  using Column = TerrainShading::Column;

  // The column at (x, z), from its surface and its neighbours' heights.
  Column column_at(std::int32_t x, std::int32_t z) const;
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

  TerrainField field_;
  TerrainShading shading_;  // built from field_
  std::shared_ptr<ColumnCache> cache_;  // shared by copies (same params, same columns)
  std::shared_ptr<ColumnCache> coarse_cache_;  // coarse_sample's chunk stacks (4 x 4 columns at cell 8)
};

}  // namespace terrane
