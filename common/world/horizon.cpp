#include "common/world/horizon.h"

#include <algorithm>

#include "common/codec/net_codec.h"

namespace terrane {

HorizonBuilder::HorizonBuilder(Vec3i region, int level)
    : region_(region), level_(level) {
  const int side = horizon_side(horizon_held_level(level));
  image_ = Box(Vec3i{side, side, side});
}

void HorizonBuilder::put_coarse(Vec3i cp, const CoarseVoxels& voxels) {
  Box b(Vec3i{kCoarseSide, kCoarseSide, kCoarseSide});
  std::copy(voxels.begin(), voxels.end(), b.voxels().begin());
  while (b.size().x > per_chunk()) b = downsample_box(b);
  put(cp, b.voxels());
}

void HorizonBuilder::put(Vec3i cp, std::span<const Voxel> voxels) {
  const int n = per_chunk();
  const Vec3i at = floor_mod(cp, kHorizonRegionChunks) * n;
  for (int y = 0; y < n; ++y)
    for (int z = 0; z < n; ++z)
      for (int x = 0; x < n; ++x) image_.set(at + Vec3i{x, y, z}, voxels[static_cast<std::size_t>((y * n + z) * n + x)]);
}

HorizonPtr encode_horizon(const HorizonBuilder& b, std::uint8_t codec_version) {
  auto img = std::make_shared<HorizonImage>();
  img->region = b.region();
  img->level = b.level();
  // Level 6 is built at level 5 (HorizonBuilder::per_chunk).
  const Box outer = b.level() == kHorizonOuterLevel ? downsample_box(b.image()) : Box{};
  const Box& image = b.level() == kHorizonOuterLevel ? outer : b.image();
  net_codec_encode(horizon_side(b.level()), image.voxels(), img->unit, codec_version);
  return img;
}

Box horizon_upsample(const Box& outer) {
  const Vec3i n = outer.size();
  Box out(n * 2);
  for (int y = 0; y < n.y * 2; ++y)
    for (int z = 0; z < n.z * 2; ++z) {
      const Voxel* from = outer.read_row(y / 2, z / 2);
      Voxel* row = out.write_row(y, z);
      for (int x = 0; x < n.x * 2; ++x) row[x] = from[x / 2];
    }
  return out;
}

}  // namespace terrane
