// Test support: the payload of a Full stream record made from a 32^3 box
// (protocol/stream_batch.h: eight 16^3 network codec units, unit i at
// offset (i & 1, (i >> 1) & 1, (i >> 2) & 1) * 16), as a server sends it.
// Header-only.
#pragma once

#include <algorithm>
#include <cstdint>
#include <vector>

#include "common/codec/net_codec.h"
#include "common/voxel/box.h"

namespace terrane::testing_support {

inline std::vector<std::uint8_t> full_payload(const Box& chunk) {
  std::vector<std::uint8_t> out;
  Box unit({16, 16, 16});
  for (int i = 0; i < 8; ++i) {
    const Vec3i off = Vec3i{i & 1, (i >> 1) & 1, (i >> 2) & 1} * 16;
    for (int y = 0; y < 16; ++y)
      for (int z = 0; z < 16; ++z) std::copy_n(chunk.read_row(off.y + y, off.z + z) + off.x, 16, unit.write_row(y, z));
    net_codec_encode(16, unit.voxels(), out);
  }
  return out;
}

}  // namespace terrane::testing_support
