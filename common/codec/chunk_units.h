// A chunk's full resolution as network-codec units: the eight 16^3 units of
// a Full stream record and the 4^3 units of an update piece, read from any
// chunk-like reader: a Chunk on the server (server/base/chunk_version.cpp)
// and, in the consumers' benchmark (tests/bench/consumers_bench.cpp), the
// same voxels as a plain array, so both run exactly this code.
//
// C has `Voxel get(Vec3i local) const`,
// `const Voxel* read_row(int y, int z, std::array<Voxel, 32>& scratch) const`
// and `void read_box(Vec3i local_min, Box& out, Vec3i out_offset, Vec3i size) const`
// (chunk.h). A null chunk is all Air. Stateless: any thread may call.
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "common/codec/net_codec.h"
#include "common/codec/update_batch.h"
#include "common/voxel/box.h"
#include "common/voxel/chunk.h"

namespace terrane {

// Appends the eight 16^3 units of level 0 in unit index order (x, then y,
// then z halves: unit i covers origin (i & 1, (i >> 1) & 1, (i >> 2) & 1) * 16).
template <class C>
void encode_full_units(const C* chunk, std::vector<std::uint8_t>& out) {
  constexpr int u = kChunkSize / 2;
  Box box({u, u, u});
  for (int i = 0; i < 8; ++i) {
    const Vec3i o{i & 1, (i >> 1) & 1, (i >> 2) & 1};
    if (chunk)
      chunk->read_box(o * u, box, Vec3i{0, 0, 0}, Vec3i{u, u, u});
    else
      box.fill(Voxel{});
    net_codec_encode(u, box.voxels(), out);
  }
}

// The voxels of 4^3 unit unit_index (0..511, (uy*8+uz)*8+ux) in Box order.
template <class C>
void read_update_unit(const C* chunk, std::uint16_t unit_index, std::array<Voxel, kUpdateUnitVoxels>& out) {
  const int i = unit_index;
  const Vec3i base{(i % 8) * 4, (i / 64) * 4, ((i / 8) % 8) * 4};
  for (int y = 0; y < 4; ++y)
    for (int z = 0; z < 4; ++z)
      for (int x = 0; x < 4; ++x)
        out[static_cast<std::size_t>((y * 4 + z) * 4 + x)] = chunk ? chunk->get(base + Vec3i{x, y, z}) : Voxel{};
}

}  // namespace terrane
