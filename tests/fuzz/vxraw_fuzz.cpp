// Fuzzes vxraw_decode (plain and gzip) with a small voxel limit, so a
// header cannot ask for more than a few hundred kilobytes. A decoded box must
// hold only valid voxels and re-encode to an image that decodes identically.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <span>

#include "common/vxraw/vxraw.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace terrane;
  const VxrawLimits limits{1 << 16};
  auto r = vxraw_decode(std::span(data, size), limits);
  if (!r.ok()) return 0;
  for (Voxel v : r->box.voxels()) {
    if (v.material >= kMaterialCount || (v.material == kAir && v.occupancy != 0)) std::abort();
  }
  const auto bytes = vxraw_encode(r->box, r->origin);
  auto again = vxraw_decode(bytes, limits);
  if (!again.ok() || again->box != r->box || again->origin != r->origin || again->repaired_air != 0) std::abort();
  return 0;
}
