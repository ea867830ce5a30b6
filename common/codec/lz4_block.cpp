#include "common/codec/lz4_block.h"

#include <lz4.h>

#include <cassert>
#include <climits>

#include "common/codec/bit_io.h"
#include "common/codec/byte_rle.h"

namespace terrane {
namespace {

static_assert(kLz4MaxInputSize == LZ4_MAX_INPUT_SIZE);
static_assert(lz4_max_compressed_size(1000) == kLz4MaxHeaderSize + LZ4_COMPRESSBOUND(1000));

struct Header {
  std::size_t decoded_size;
  std::size_t header_size;
};

Result<Header> read_header(std::span<const std::uint8_t> in) {
  std::size_t pos = 0;
  std::uint64_t v = 0;
  const VarintRead r = get_varint(in, pos, kLz4MaxHeaderSize, v);
  if (r == VarintRead::kTruncated) return DecodeError{DecodeErrorCode::kTruncated, pos, "lz4 block: size varint cut short"};
  if (r == VarintRead::kTooLong) return DecodeError{DecodeErrorCode::kOverLimit, 0, "lz4 block: size varint longer than 5 bytes"};
  if (pos > 1 && in[pos - 1] == 0) return DecodeError{DecodeErrorCode::kInvalidValue, pos - 1, "lz4 block: size varint not minimal"};
  if (v > kLz4MaxInputSize) return DecodeError{DecodeErrorCode::kOverLimit, 0, "lz4 block: size above the LZ4 maximum"};
  return Header{static_cast<std::size_t>(v), pos};
}

// Decompresses the block after `h` into exactly h.decoded_size bytes at dst.
Status decompress_body(std::span<const std::uint8_t> in, const Header& h, std::uint8_t* dst) {
  const std::span<const std::uint8_t> body = in.subspan(h.header_size);
  if (h.decoded_size == 0) {
    if (!body.empty()) return DecodeError{DecodeErrorCode::kTrailingBytes, h.header_size, "lz4 block: data after an empty block"};
    return Ok{};
  }
  if (body.empty()) return DecodeError{DecodeErrorCode::kTruncated, h.header_size, "lz4 block: missing block data"};
  if (body.size() > static_cast<std::size_t>(INT_MAX)) {
    return DecodeError{DecodeErrorCode::kOverLimit, h.header_size, "lz4 block: compressed data too large"};
  }
  // LZ4_decompress_safe never writes past dstCapacity and fails unless the
  // block ends exactly at the end of `body`; a shorter result is caught below.
  const int n = LZ4_decompress_safe(reinterpret_cast<const char*>(body.data()), reinterpret_cast<char*>(dst),
                                    static_cast<int>(body.size()), static_cast<int>(h.decoded_size));
  if (n < 0) return DecodeError{DecodeErrorCode::kInvalidValue, h.header_size, "lz4 block: corrupt data"};
  if (static_cast<std::size_t>(n) != h.decoded_size) {
    return DecodeError{DecodeErrorCode::kInvalidValue, h.header_size, "lz4 block: result shorter than declared"};
  }
  return Ok{};
}

}  // namespace

void lz4_compress(std::span<const std::uint8_t> in, std::vector<std::uint8_t>& out) {
  assert(in.size() <= kLz4MaxInputSize);
  put_varint(static_cast<std::uint32_t>(in.size()), out);
  if (in.empty()) return;
  const std::size_t old = out.size();
  const int bound = LZ4_compressBound(static_cast<int>(in.size()));
  out.resize(old + static_cast<std::size_t>(bound));
  const int n = LZ4_compress_default(reinterpret_cast<const char*>(in.data()), reinterpret_cast<char*>(out.data() + old),
                                     static_cast<int>(in.size()), bound);
  assert(n > 0);  // cannot fail with a full-bound destination
  out.resize(old + static_cast<std::size_t>(n));
}

Result<std::size_t> lz4_decoded_size(std::span<const std::uint8_t> in) {
  auto h = read_header(in);
  if (!h) return h.error();
  return h->decoded_size;
}

Result<std::vector<std::uint8_t>> lz4_decompress(std::span<const std::uint8_t> in, std::size_t max_size) {
  auto h = read_header(in);
  if (!h) return h.error();
  if (h->decoded_size > max_size) return DecodeError{DecodeErrorCode::kOverLimit, 0, "lz4 block: declared size above the cap"};
  std::vector<std::uint8_t> out(h->decoded_size);
  if (Status s = decompress_body(in, *h, out.data()); !s) return s.error();
  return out;
}

Result<std::size_t> lz4_decompress_into(std::span<const std::uint8_t> in, std::span<std::uint8_t> out) {
  auto h = read_header(in);
  if (!h) return h.error();
  if (h->decoded_size > out.size()) return DecodeError{DecodeErrorCode::kOverLimit, 0, "lz4 block: declared size above the buffer"};
  if (Status s = decompress_body(in, *h, out.data()); !s) return s.error();
  return h->decoded_size;
}

void byte_rle_lz4_encode(std::span<const Voxel> voxels, std::vector<std::uint8_t>& out,
                         std::vector<std::uint8_t>& scratch) {
  scratch.clear();
  byte_rle_encode(voxels, scratch);
  lz4_compress(scratch, out);
}

void byte_rle_lz4_encode(std::span<const Voxel> voxels, std::vector<std::uint8_t>& out) {
  std::vector<std::uint8_t> scratch;
  byte_rle_lz4_encode(voxels, out, scratch);
}

Status byte_rle_lz4_decode(std::span<const std::uint8_t> in, std::span<Voxel> out, std::vector<std::uint8_t>& scratch) {
  auto h = read_header(in);
  if (!h) return h.error();
  if (h->decoded_size > byte_rle_max_encoded_size(out.size())) {
    return DecodeError{DecodeErrorCode::kOverLimit, 0, "lz4 block: declared size above the byte RLE bound"};
  }
  if (scratch.size() < h->decoded_size) scratch.resize(h->decoded_size);
  if (Status s = decompress_body(in, *h, scratch.data()); !s) return s;
  return byte_rle_decode(std::span<const std::uint8_t>(scratch.data(), h->decoded_size), out);
}

Status byte_rle_lz4_decode(std::span<const std::uint8_t> in, std::span<Voxel> out) {
  std::vector<std::uint8_t> scratch;
  return byte_rle_lz4_decode(in, out, scratch);
}

}  // namespace terrane
