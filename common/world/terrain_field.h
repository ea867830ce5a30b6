// TerrainField: the generator's height and density field, and the noise
// state it is built from (one seed per noise stream, derived from the
// world's seed, and the horizontal scale).
//
// It answers two kinds of questions, both pure functions of (params,
// position): a column's 2D fields (surface height, water level, biome
// weights, strata warp, cave amounts) and the 3D fields at a point (overhang
// perturbation, two cave worms, caverns). What those fields become as
// voxels is TerrainShading's; see common/world/GENERATOR.md for the shapes.
//
// Immutable after construction: every method is const and any number of
// threads may call them at once. Copies are independent and equal.
#pragma once

#include <cstdint>

#include "common/world/generator_params.h"

namespace terrane {

class TerrainField {
 public:
  // The 3D fields are sampled on a lattice of this spacing and interpolated
  // in between. They are smooth at this scale (their shortest period is 10+
  // voxels), so trilinear interpolation of the lattice is indistinguishable
  // from evaluating every voxel at 1/64 of the cost.
  static constexpr std::int32_t kLatticeStep = 4;
  // The 3D fields, in this order: overhang, worm a, worm b, cavern.
  static constexpr int kFieldCount = 4;

  // 2D fields of one column, before its neighbours are known.
  struct Surface {
    float height = 0;  // final surface height
    float cont = 0, mountain = 0, highland = 0, desert = 0, swamp = 0, lake = 0;  // weights in [0, 1] (cont: raw)
    float temperature = 0, humidity = 0;
    float strata_warp = 0, entrance = 0, cave_amount = 0;
    std::int32_t water_level = 0;
  };

  // params are clamped into validate()'s ranges (clamped()), so a caller
  // that skipped validation still gets bounded work per voxel.
  explicit TerrainField(const GeneratorParams& params);

  // The clamped params the field was built from.
  const GeneratorParams& params() const { return params_; }

  // The 2D fields of column (x, z). Surface::height is the surface before 3D
  // overhangs and caves; Surface::water_level is the sea's, or a lake's
  // inside a lake.
  Surface surface(std::int32_t x, std::int32_t z) const;

  // The 3D fields at a point, each in about [-1, 1]: out[0] the overhang
  // perturbation (0 when `overhang` is false, for points where it is not
  // read), out[1], out[2] the two worm noises, out[3] the cavern noise. The
  // cave fields are 0 when params().caves is false.
  void fields_at(double x, double y, double z, float out[kFieldCount], bool overhang = true) const;
  // fields_at() at lattice point (lx, ly, lz), i.e. voxel (lx, ly, lz) * kLatticeStep.
  void lattice_sample(std::int32_t lx, std::int32_t ly, std::int32_t lz, float out[kFieldCount]) const;

  // The seed that picks the rock of each strata band (the same stream that
  // warps the bands, Surface::strata_warp).
  std::uint32_t strata_seed() const;

 private:
  // The height of a column from continents, hills, mountains, highlands,
  // deserts, rivers and swamps (everything but lakes). px, pz are world
  // coordinates divided by terrain_scale. Fills *s when not null.
  float raw_height(double px, double pz, Surface* s) const;

  GeneratorParams params_;  // clamped
  double inv_scale_;         // 1 / terrain_scale
  std::uint32_t seeds_[16];  // one per noise stream
};

}  // namespace terrane
