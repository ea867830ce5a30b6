// The unit encoder of the network voxel codec (format versions 1 and 2,
// common/codec/NET_CODEC.md): turns one N^3 unit into its bytes, choosing
// the smallest of the uniform kinds, the token stream, the packed form and
// raw voxels.
//
// Its working state (the greedy token parse, literal frequencies, type
// transitions, the unit's palette and type codes, the output scratch) lives
// on the stack of one call: nothing is kept between units, so any thread may
// encode. It reads only the immutable tables of net_codec_tables.h. The
// public entry point is net_codec_encode (net_codec.h).
#pragma once

#include <cstdint>
#include <vector>

#include "common/voxel/voxel.h"

namespace terrane::net_codec_detail {

// Appends the encoding of the n^3 voxels at v to out, in format version
// `version` (1 or 2).
// Preconditions: n is 4, 8 or 16; v points at n^3 voxels, each with
// material < kMaterialCount, Air voxels with occupancy 0.
template <int n>
void encode_unit(const Voxel* v, std::vector<std::uint8_t>& out, std::uint8_t version);

extern template void encode_unit<4>(const Voxel* v, std::vector<std::uint8_t>& out, std::uint8_t version);
extern template void encode_unit<8>(const Voxel* v, std::vector<std::uint8_t>& out, std::uint8_t version);
extern template void encode_unit<16>(const Voxel* v, std::vector<std::uint8_t>& out, std::uint8_t version);

}  // namespace terrane::net_codec_detail
