// Snowflake tracing: fragment lighting by wandering particles, after
// A. M. Smith, "Two Methods for Voxel Detail Enhancement" (PCGames 2011),
// section 4.4. See common/enhance/ENHANCE.md for the model.
//
// From every surface fragment (a solid fragment with a face neighbour that
// is not solid) particles are released into the open cells beside it (each
// from one of its exposed faces, at random) and wander in unit steps through
// the fragment grid:
// sun particles drift towards the sun, sky particles each towards a direction
// drawn uniformly on the sphere. A particle whose release and `steps` - 1
// further steps never enter a solid fragment escapes. A fragment's light is
// the weighted share of its particles that escape.
//
// Contract:
//  - Input is a Box of fragments at `origin` (fine world coordinates); solid
//    means enhance_solid(). Space outside the box is empty: the box is open
//    to the sky on every side.
//  - Deterministic and order independent: every particle's random stream is
//    a function of (seed, fragment position, particle number), so relighting
//    a region equals the same part of a full computation.
//  - Dependency window: a fragment's light reads the fragments within
//    Manhattan distance `steps` of it (a particle's path) and its six face
//    neighbours (whether it is a surface fragment). An edit to fragment q
//    changes light only within Chebyshev distance `steps` of q; that is
//    lighting_affected_region().
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "common/voxel/box.h"
#include "common/voxel/vec3.h"

namespace terrane {

struct LightingParams {
  // Towards the sun; need not be normalised, must not be zero.
  Vec3f sun_direction{0.5f, 1.0f, 0.3f};
  int sun_particles = 32;  // [1, 4096]
  int sky_particles = 32;  // [1, 4096]
  // Steps a particle must survive to escape, in fragments; [1, 256]. Long
  // walks give long tower shadows and dark caves, at a larger dependency
  // window and cost.
  int steps = 24;
  // Probability that a step follows the particle's direction (one axis
  // picked with probability proportional to that direction component);
  // otherwise the step goes to one of the six faces uniformly. [0, 1].
  float follow = 0.75f;
  // Weight of sunlight in the result; skylight gets the rest. [0, 1].
  float sun_weight = 0.6f;
  std::uint64_t seed = 1;
};

// Empty when valid, else a message naming the bad field.
std::string validate(const LightingParams& params);

// Light per fragment: 0..255 for surface fragments, 0 for every other cell.
struct LightMap {
  Region region;                    // fine world coordinates covered
  std::vector<std::uint8_t> light;  // Box order over region

  // Precondition: region.contains(p).
  std::uint8_t at(Vec3i p) const;
};

// True for a solid fragment with at least one face neighbour that is not
// solid (outside the box counts as not solid). `local` is box-local.
bool is_surface_fragment(const Box& fine, Vec3i local);

// Called now and then with (fragments done, fragments total).
using LightProgress = std::function<void(std::uint64_t, std::uint64_t)>;

// Lights every fragment of the box. Precondition: validate(params) is empty.
LightMap compute_lighting(const Box& fine, Vec3i origin, const LightingParams& params,
                          const LightProgress& progress = {});

// Recomputes the light of `region` (fine world coordinates, clipped to the
// map) into `map`, reading occupancy from `fine` (which must cover
// map.region at `origin`).
void light_region(const Box& fine, Vec3i origin, const LightingParams& params, const Region& region, LightMap& map);

// Cells whose light can change when the fragments of `changed` change: the
// region grown by `steps` on every side.
Region lighting_affected_region(const Region& changed, const LightingParams& params);

// After the fragments of `changed` were edited in `fine`, relights the
// affected cells of `map` and returns that region (clipped to the map).
Region relight(const Box& fine, Vec3i origin, const LightingParams& params, const Region& changed, LightMap& map);

}  // namespace terrane
