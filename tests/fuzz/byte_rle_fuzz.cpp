// Fuzzes byte_rle_decode into a fixed 32^3 chunk. Whatever decodes must
// re-encode canonically (never longer than the input) and decode back to the
// same voxels.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <span>
#include <vector>

#include "common/codec/byte_rle.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace terrane;
  static std::vector<Voxel> out(32 * 32 * 32);
  static std::vector<Voxel> again(32 * 32 * 32);
  static std::vector<std::uint8_t> encoded;
  if (!byte_rle_decode(std::span(data, size), out).ok()) return 0;

  for (Voxel v : out) {
    if (v.material >= kMaterialCount || (v.material == kAir && v.occupancy != 0)) std::abort();
  }
  encoded.clear();
  byte_rle_encode(out, encoded);
  // The canonical encoding is the shortest one.
  if (encoded.size() > size || encoded.size() > byte_rle_max_encoded_size(out.size())) std::abort();
  if (!byte_rle_decode(encoded, again).ok()) std::abort();
  if (again != out) std::abort();
  return 0;
}
