// Byte RLE: the storage article's disk encoding of a run of voxels, version 1
// (spec: common/codec/BYTE_RLE.md).
//
// Each run is a lead byte, then an optional occupancy byte, then an optional
// count byte:
//
//   lead:  bit 7      bit 6       bits 5..0
//          count?     occupancy?  material
//
// The occupancy byte is present only when the run's occupancy differs from
// the material's default (255 for solids; Air never has one). The count byte
// holds length - 1 and is present only for runs longer than one voxel, so a
// run covers 1..256 voxels and a count byte of 0 is reserved.
//
// The encoder is canonical: maximal runs, split every 256 voxels, occupancy
// only when not the default. The decoder accepts any valid stream (also a
// redundant occupancy byte equal to the default) and rejects everything else.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "common/codec/decode_error.h"
#include "common/voxel/voxel.h"

namespace terrane {

inline constexpr int kByteRleVersion = 1;
inline constexpr std::uint8_t kByteRleMaterialMask = 0x3F;
inline constexpr std::uint8_t kByteRleOccupancyBit = 0x40;
inline constexpr std::uint8_t kByteRleCountBit = 0x80;
inline constexpr std::size_t kByteRleMaxRun = 256;

// Upper bound on the encoded size of voxel_count voxels. The worst case is a
// run of one voxel with a non-default occupancy: two bytes, the size of the
// voxel itself, so the encoding never grows the data.
constexpr std::size_t byte_rle_max_encoded_size(std::size_t voxel_count) { return 2 * voxel_count; }

// Appends the encoding of `voxels` to `out` (never clears it).
// Precondition: every material < kMaterialCount (true of any Box filled
// through make_voxel or a validating decoder). Air is written as Air whatever
// its occupancy byte, so the output always decodes.
void byte_rle_encode(std::span<const Voxel> voxels, std::vector<std::uint8_t>& out);

// Allocation-free form: writes into `out` and returns the number of bytes
// written. Precondition: out.size() >= byte_rle_max_encoded_size(voxels.size()).
std::size_t byte_rle_encode_to(std::span<const Voxel> voxels, std::span<std::uint8_t> out);

// Decodes `in` into `out`, which it must fill exactly. Allocation-free.
// Errors (DecodeError::offset is the byte offset in `in`):
//   kTruncated      input ends before `out` is full, or inside a run
//   kInvalidValue   a count byte of 0, or Air with the occupancy bit
//   kOverLimit      a run reaching past the end of `out`
//   kTrailingBytes  bytes left over once `out` is full
// On error the contents of `out` are unspecified.
Status byte_rle_decode(std::span<const std::uint8_t> in, std::span<Voxel> out);

}  // namespace terrane
