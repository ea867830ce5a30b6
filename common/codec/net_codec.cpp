// Network voxel codec units, format versions 1 and 2 (see common/codec/NET_CODEC.md):
// the public entry points, which check sizes and pick the unit size's
// encoder or decoder. The code tables are in net_codec_tables.cpp, the
// encoder in net_codec_encoder.cpp, the decoder in net_codec_decoder.cpp;
// update batches are in update_batch.cpp.
#include "common/codec/net_codec.h"

#include "common/codec/net_codec_decoder.h"
#include "common/codec/net_codec_encoder.h"

namespace terrane {

void net_codec_encode(int n, std::span<const Voxel> voxels, std::vector<std::uint8_t>& out, std::uint8_t version) {
  switch (n) {
    case 4: return net_codec_detail::encode_unit<4>(voxels.data(), out, version);
    case 8: return net_codec_detail::encode_unit<8>(voxels.data(), out, version);
    default: return net_codec_detail::encode_unit<16>(voxels.data(), out, version);
  }
}

Result<std::size_t> net_codec_decode_prefix(int n, std::span<const std::uint8_t> bytes, std::span<Voxel> out) {
  if (!net_codec_valid_size(n)) return DecodeError{DecodeErrorCode::kOverLimit, 0, "unit size is not 4, 8 or 16"};
  if (out.size() != static_cast<std::size_t>(n) * n * n) {
    return DecodeError{DecodeErrorCode::kOverLimit, 0, "output buffer is not N^3 voxels"};
  }
  if (bytes.empty()) return DecodeError{DecodeErrorCode::kTruncated, 0, "empty unit"};
  switch (n) {
    case 4: return net_codec_detail::decode_unit<4>(bytes, out);
    case 8: return net_codec_detail::decode_unit<8>(bytes, out);
    default: return net_codec_detail::decode_unit<16>(bytes, out);
  }
}

Result<std::size_t> net_codec_append_version1(int n, std::size_t count, std::span<const std::uint8_t> bytes,
                                              std::vector<std::uint8_t>& out) {
  if (!net_codec_valid_size(n)) return DecodeError{DecodeErrorCode::kOverLimit, 0, "unit size is not 4, 8 or 16"};
  thread_local std::vector<Voxel> voxels;
  voxels.resize(static_cast<std::size_t>(n) * n * n);
  std::size_t at = 0;
  for (std::size_t i = 0; i < count; ++i) {
    const auto rest = bytes.subspan(at);
    auto used = net_codec_decode_prefix(n, rest, voxels);
    if (!used) {
      DecodeError e = used.error();
      e.offset += at;
      return e;
    }
    if ((rest[0] & 0x0F) == kNetCodecVersion1) {
      out.insert(out.end(), rest.begin(), rest.begin() + static_cast<std::ptrdiff_t>(*used));
    } else {
      net_codec_encode(n, voxels, out, kNetCodecVersion1);
    }
    at += *used;
  }
  return at;
}

Status net_codec_decode(int n, std::span<const std::uint8_t> bytes, std::span<Voxel> out) {
  auto used = net_codec_decode_prefix(n, bytes, out);
  if (!used) return used.error();
  if (*used != bytes.size()) return DecodeError{DecodeErrorCode::kTrailingBytes, *used, "bytes after the unit"};
  return Ok{};
}

}  // namespace terrane
