#include "protocol/chunk_hash.h"

#include <algorithm>

namespace terrane {

std::uint64_t hash_row(std::uint64_t h, const Voxel* row) {
  using namespace chunk_hash_detail;
  if (std::all_of(row, row + kChunkSize, [](Voxel v) { return v.material == 0 && v.occupancy == 0; }))
    return h * kAirRowFactor;
  for (int x = 0; x < kChunkSize; ++x) {
    h ^= row[x].material;
    h *= kFnvPrime;
    h ^= row[x].occupancy;
    h *= kFnvPrime;
  }
  return h;
}

}  // namespace terrane
