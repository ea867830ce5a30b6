// A chunk's full resolution as network-codec units: the eight 16^3 units of
// a Full stream record and the 4^3 units of an update piece, read from any
// chunk-like reader: a Chunk on the server (server/base/chunk_version.cpp)
// and, in the consumers' benchmark (tests/bench/consumers_bench.cpp), the
// same voxels as a plain array, so both run exactly this code.
//
// C has `const Voxel* read_row(int y, int z, std::array<Voxel, 32>& scratch) const`
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
// The two units side by side along x (i and i + 1) share their rows: each
// row of the chunk is read once, its halves copied into the two units.
// Units in network codec format codec_version (net_codec_encode's).
template <class C>
void encode_full_units(const C* chunk, std::vector<std::uint8_t>& out, std::uint8_t codec_version = kNetCodecVersion) {
  constexpr int u = kChunkSize / 2;
  Box low({u, u, u}), high({u, u, u});
  if (chunk == nullptr) {
    for (int i = 0; i < 8; ++i) net_codec_encode(u, low.voxels(), out, codec_version);
    return;
  }
  std::array<Voxel, kChunkSize> scratch;
  for (int oz = 0; oz < 2; ++oz)
    for (int oy = 0; oy < 2; ++oy) {
      for (int y = 0; y < u; ++y)
        for (int z = 0; z < u; ++z) {
          const Voxel* row = chunk->read_row(oy * u + y, oz * u + z, scratch);
          std::copy_n(row, u, low.write_row(y, z));
          std::copy_n(row + u, u, high.write_row(y, z));
        }
      net_codec_encode(u, low.voxels(), out, codec_version);
      net_codec_encode(u, high.voxels(), out, codec_version);
    }
}

// Fills each update's voxels with its 4^3 unit (unit_index 0..511,
// (uy*8+uz)*8+ux, in Box order). Units in the same row of units (equal uy and
// uz) that follow each other share their 16 row reads: a packed row is
// decoded once for all of them, not voxel by voxel.
template <class C>
void read_update_units(const C* chunk, std::span<UnitUpdate> units) {
  std::array<Voxel, kChunkSize> scratch;
  for (std::size_t first = 0; first < units.size();) {
    const int row_of_units = units[first].unit_index / 8;  // uy*8+uz
    std::size_t last = first + 1;
    while (last < units.size() && units[last].unit_index / 8 == row_of_units) ++last;
    const int y0 = (row_of_units / 8) * 4, z0 = (row_of_units % 8) * 4;
    for (int y = 0; y < 4; ++y)
      for (int z = 0; z < 4; ++z) {
        const Voxel* row = chunk ? chunk->read_row(y0 + y, z0 + z, scratch) : nullptr;
        for (std::size_t i = first; i < last; ++i) {
          Voxel* out = units[i].voxels.data() + (y * 4 + z) * 4;
          if (row == nullptr) {
            std::fill_n(out, 4, Voxel{});
          } else {
            std::copy_n(row + (units[i].unit_index % 8) * 4, 4, out);
          }
        }
      }
    first = last;
  }
}

}  // namespace terrane
