// The unit decoder of the network voxel codec (format versions 1 and 2,
// common/codec/NET_CODEC.md): reads one N^3 unit from untrusted bytes into
// the caller's buffer, or says why it cannot.
//
// Its working state (the bit reader, the unit's palette, its literal lookup
// table, the per-context token tables it selects) lives on the stack of one
// call: nothing is kept between units, so any thread may decode. It reads
// only the immutable tables of net_codec_tables.h. The public entry points
// are net_codec_decode and net_codec_decode_prefix (net_codec.h), which
// check the preconditions below.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>

#include "common/codec/decode_error.h"
#include "common/voxel/voxel.h"

namespace terrane::net_codec_detail {

// Decodes the unit at the start of bytes into out; returns the bytes it
// occupied (later bytes are not read). Errors: kTruncated, kBadVersion,
// kInvalidValue as net_codec_decode lists them. On error out holds
// unspecified valid voxels.
// Preconditions: n is 4, 8 or 16; bytes is not empty; out.size() == n^3.
template <int n>
Result<std::size_t> decode_unit(std::span<const std::uint8_t> bytes, std::span<Voxel> out);

extern template Result<std::size_t> decode_unit<4>(std::span<const std::uint8_t> bytes, std::span<Voxel> out);
extern template Result<std::size_t> decode_unit<8>(std::span<const std::uint8_t> bytes, std::span<Voxel> out);
extern template Result<std::size_t> decode_unit<16>(std::span<const std::uint8_t> bytes, std::span<Voxel> out);

}  // namespace terrane::net_codec_detail
