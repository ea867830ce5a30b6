// Fuzzes the framed LZ4 block decoder (capped at 1 MB) and the byte RLE + LZ4
// voxel decoder into a 32^3 chunk. Whatever decompresses must survive a
// compress / decompress round trip.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <span>
#include <vector>

#include "common/codec/lz4_block.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace terrane;
  const std::span<const std::uint8_t> in(data, size);

  static std::vector<Voxel> voxels(32 * 32 * 32);
  static std::vector<std::uint8_t> scratch;
  (void)byte_rle_lz4_decode(in, voxels, scratch).ok();

  auto out = lz4_decompress(in, 1 << 20);
  if (!out.ok()) return 0;
  std::vector<std::uint8_t> packed;
  lz4_compress(*out, packed);
  auto back = lz4_decompress(packed, out->size());
  if (!back.ok() || *back != *out) std::abort();
  return 0;
}
