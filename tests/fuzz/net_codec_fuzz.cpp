// Fuzz target for the network voxel codec: arbitrary bytes decoded as a unit
// of each size into a fixed buffer, and as an update batch. Whatever decodes
// must hold valid voxels and survive an encode/decode round trip in both
// format versions.
#include <array>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <span>
#include <vector>

#include "common/codec/net_codec.h"
#include "common/codec/update_batch.h"

using namespace terrane;

namespace {

void check_unit(int n, std::span<const Voxel> voxels) {
  for (Voxel v : voxels) {
    if (v.material >= kMaterialCount || (v.material == kAir && v.occupancy != 0)) std::abort();
  }
  for (std::uint8_t version : {kNetCodecVersion1, kNetCodecVersion2}) {
    std::vector<std::uint8_t> bytes;
    net_codec_encode(n, voxels, bytes, version);
    if (bytes.size() > net_codec_max_encoded_size(n)) std::abort();
    std::array<Voxel, 4096> again;
    std::span<Voxel> out(again.data(), voxels.size());
    if (!net_codec_decode(n, bytes, out).ok()) std::abort();
    for (std::size_t i = 0; i < voxels.size(); ++i) {
      if (!(out[i] == voxels[i])) std::abort();
    }
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::span<const std::uint8_t> bytes(data, size);
  static std::array<Voxel, 4096> buffer;
  for (int n : {4, 8, 16}) {
    std::span<Voxel> out(buffer.data(), static_cast<std::size_t>(n * n * n));
    if (net_codec_decode(n, bytes, out).ok()) check_unit(n, out);
  }
  static std::array<UnitUpdate, 16> updates;
  auto count = net_codec_decode_update_batch(bytes, updates);
  if (count.ok()) {
    std::vector<std::uint8_t> again;
    net_codec_encode_update_batch(std::span<const UnitUpdate>(updates.data(), *count), again);
    std::array<UnitUpdate, 16> back;
    auto n2 = net_codec_decode_update_batch(again, back);
    if (!n2.ok() || *n2 != *count) std::abort();
  }
  return 0;
}
