// A self-describing LZ4 block: the uncompressed size as a LEB128 varint
// (1..5 bytes, minimal form), then one raw LZ4 block holding exactly that many
// bytes. An empty input is the single byte 0x00 with no block after it.
// Spec: common/codec/BYTE_RLE.md, "LZ4 block framing".
//
// Also the voxel convenience codec the storage article describes: byte RLE
// first (common/codec/byte_rle.h), then LZ4 over the RLE bytes.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "common/codec/decode_error.h"
#include "common/voxel/voxel.h"

namespace terrane {

// liblz4's LZ4_MAX_INPUT_SIZE: the largest block it compresses.
inline constexpr std::size_t kLz4MaxInputSize = 0x7E000000;
inline constexpr std::size_t kLz4MaxHeaderSize = 5;

// Worst-case framed size for `n` input bytes (header + LZ4_COMPRESSBOUND).
// Precondition: n <= kLz4MaxInputSize.
constexpr std::size_t lz4_max_compressed_size(std::size_t n) { return kLz4MaxHeaderSize + n + n / 255 + 16; }

// Appends the framed block of `in` to `out`.
// Precondition: in.size() <= kLz4MaxInputSize.
void lz4_compress(std::span<const std::uint8_t> in, std::vector<std::uint8_t>& out);

// Reads only the header: the declared uncompressed size. Errors: kTruncated,
// kInvalidValue (non-minimal varint), kOverLimit (above kLz4MaxInputSize).
Result<std::size_t> lz4_decoded_size(std::span<const std::uint8_t> in);

// Decompresses a framed block. The declared size is checked against
// `max_size` before anything is allocated (kOverLimit). Corrupt data, a
// result shorter or longer than declared, or extra bytes are kInvalidValue;
// a missing block is kTruncated.
Result<std::vector<std::uint8_t>> lz4_decompress(std::span<const std::uint8_t> in, std::size_t max_size);

// Allocation-free form: decompresses into the front of `out` and returns the
// size. A declared size above out.size() is kOverLimit.
Result<std::size_t> lz4_decompress_into(std::span<const std::uint8_t> in, std::span<std::uint8_t> out);

// Byte RLE, then LZ4, appended to `out`. `scratch` holds the RLE bytes; pass
// the same vector every call to avoid reallocating. Same precondition as
// byte_rle_encode.
void byte_rle_lz4_encode(std::span<const Voxel> voxels, std::vector<std::uint8_t>& out,
                         std::vector<std::uint8_t>& scratch);
void byte_rle_lz4_encode(std::span<const Voxel> voxels, std::vector<std::uint8_t>& out);

// Decodes byte_rle_lz4_encode output into `out`, which it must fill exactly.
// The declared RLE size is capped at byte_rle_max_encoded_size(out.size())
// before `scratch` grows. LZ4 errors carry offsets into `in`; byte RLE errors
// carry offsets into the decompressed RLE stream.
Status byte_rle_lz4_decode(std::span<const std::uint8_t> in, std::span<Voxel> out,
                           std::vector<std::uint8_t>& scratch);
Status byte_rle_lz4_decode(std::span<const std::uint8_t> in, std::span<Voxel> out);

}  // namespace terrane
