// Terrane's network voxel codec: a bit-packed RLE for cubic units of N^3
// voxels, N in {4, 8, 16} (16^3 for the initial load, 4^3 for edit updates,
// 16^3/8^3/4^3 for the mip levels of a 32^3 chunk). Format versions 1 and 2
// are specified in common/codec/NET_CODEC.md: version 2 predicts a literal's
// occupancy from the voxels decoded before it and codes the difference.
//
// A unit is a span of N^3 voxels in Box order (x fastest, then z, then y;
// index (y*N+z)*N+x). Each unit encodes and decodes on its own: there is no
// state shared between units or messages. The encoding is a run/copy token
// stream: runs of the previous voxel, copies from the row behind (z-1, offset
// N) and the layer below (y-1, offset N^2), and literals from a per-unit
// material palette; occupancy bytes are only stored for non-default voxels.
//
// Decoders never trust their input: every error comes back as a DecodeError,
// nothing is read outside the given span, nothing is allocated from input
// sizes, and the output buffer is the caller's.
//
// The update batch, which carries 4^3 units with their chunk coordinates, is
// in common/codec/update_batch.h.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "common/codec/decode_error.h"
#include "common/voxel/voxel.h"

namespace terrane {

// The unit format versions: what a unit's first byte says in its low nibble.
// Decoders read both; an encoder writes the version it is asked for.
inline constexpr std::uint8_t kNetCodecVersion1 = 1;
inline constexpr std::uint8_t kNetCodecVersion2 = 2;
// The version written unless the caller asks for another.
inline constexpr std::uint8_t kNetCodecVersion = kNetCodecVersion1;

// True for the unit edge lengths the codec speaks: 4, 8 and 16.
constexpr bool net_codec_valid_size(int n) { return n == 4 || n == 8 || n == 16; }

// The largest encoding of any N^3 unit (random materials and occupancies):
// 1 + min(2 * N^3, ceil((391 + 14 * N^3) / 8)) bytes, i.e. 129, 946 and 7218
// bytes for N = 4, 8, 16: a 64-entry palette then 6-bit indices and 8-bit
// occupancies (1.75 bytes per voxel), or raw 2-byte voxels when smaller.
// Precondition: net_codec_valid_size(n).
constexpr std::size_t net_codec_max_encoded_size(int n) {
  const std::size_t volume = static_cast<std::size_t>(n) * n * n;
  const std::size_t packed = (391 + 14 * volume + 7) / 8;
  return 1 + (packed < 2 * volume ? packed : 2 * volume);
}

// Appends the encoding of one unit, in format version `version`, to out.
// Preconditions: net_codec_valid_size(n), voxels.size() == n^3, every voxel
// has material < kMaterialCount and Air voxels have occupancy 0 (true for
// anything read from a Box or built with make_voxel), version is
// kNetCodecVersion1 or kNetCodecVersion2.
void net_codec_encode(int n, std::span<const Voxel> voxels, std::vector<std::uint8_t>& out,
                      std::uint8_t version = kNetCodecVersion);

// Decodes exactly one unit from all of bytes into out (n^3 voxels, the
// caller's buffer), of either format version. Errors: kTruncated,
// kBadVersion (a version other than 1 or 2), kInvalidValue (unknown
// unit kind, material >= 64, palette index out of range, duplicate palette
// entry, a run or copy past the end of the unit or before its start, an
// occupancy residual out of range, non-zero padding bits), kTrailingBytes (bytes after the unit), kOverLimit (n not a
// valid size or out.size() != n^3). On error out holds unspecified voxels,
// all of them valid (material < 64, Air with occupancy 0).
Status net_codec_decode(int n, std::span<const std::uint8_t> bytes, std::span<Voxel> out);

// Like net_codec_decode but the unit may be followed by other data: returns
// the number of bytes the unit occupied.
Result<std::size_t> net_codec_decode_prefix(int n, std::span<const std::uint8_t> bytes, std::span<Voxel> out);

// Appends count units of n^3 voxels, back to back at the start of bytes, to
// out in format version 1 (for a reader that knows only version 1): a
// version-1 unit is copied, a version-2 unit decoded and encoded again.
// Returns the bytes of `bytes` they took, or the first unit's decode error.
Result<std::size_t> net_codec_append_version1(int n, std::size_t count, std::span<const std::uint8_t> bytes,
                                              std::vector<std::uint8_t>& out);

}  // namespace terrane
