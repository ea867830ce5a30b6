// Units of n³ voxels for the codec tests (net_codec_test, update_batch_test):
// empty or filled, random, and smooth terrain.
#pragma once

#include <random>
#include <vector>

#include "common/voxel/voxel.h"

namespace terrane::test_units {

inline std::vector<Voxel> make_unit(int n, Voxel fill = {}) {
  return std::vector<Voxel>(static_cast<std::size_t>(n * n * n), fill);
}
inline std::size_t idx(int n, int x, int y, int z) { return static_cast<std::size_t>((y * n + z) * n + x); }

inline std::vector<Voxel> random_unit(int n, std::mt19937& rng, int materials, bool partial) {
  auto v = make_unit(n);
  for (Voxel& x : v) {
    const auto m = static_cast<Material>(rng() % static_cast<unsigned>(materials));
    x = make_voxel(m, partial ? static_cast<std::uint8_t>(rng()) : default_occupancy(m));
  }
  return v;
}

// Smooth terrain: a sloped surface with fractional occupancy, strata below.
inline std::vector<Voxel> terrain_unit(int n, float base, float slope) {
  auto v = make_unit(n);
  for (int y = 0; y < n; ++y) {
    for (int z = 0; z < n; ++z) {
      for (int x = 0; x < n; ++x) {
        const float h = base + slope * static_cast<float>(x) + 0.3f * static_cast<float>(z);
        const float f = h - static_cast<float>(y);
        if (f <= 0) continue;
        const Material m = f < 2 ? materials::kGrass : (y % 5 == 0 ? materials::kSlate : materials::kRock);
        v[idx(n, x, y, z)] = make_voxel(m, f >= 1 ? kFullOccupancy : occupancy_byte(f));
      }
    }
  }
  return v;
}

// Whether any solid voxel has an occupancy other than the default (255).
inline bool partial_occupancies(const std::vector<Voxel>& v) {
  for (Voxel x : v)
    if (x.material != kAir && x.occupancy != kFullOccupancy) return true;
  return false;
}

}  // namespace terrane::test_units
