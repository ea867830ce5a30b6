// Fuzzes the chunk image reader (Chunk::read_image: a row-packed level 0 and
// three mip units, common/world/WORLD_FORMAT.md "Chunk image") and the chunk
// blob decoder around it. Whatever reads must read safely: every row, every
// mip level, every voxel valid, its own image must read back as the same
// chunk, and writes on it must read back as on a dense copy. Seeds: images of real chunks (tests/fuzz/corpus/chunk-image/).
#include <cstddef>
#include <cstdint>
#include <algorithm>
#include <cstdlib>
#include <span>
#include <vector>

#include "common/voxel/chunk.h"
#include "common/world/world_store.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace terrane;
  const std::span<const std::uint8_t> in(data, size);
  (void)decode_chunk_blob(in).ok();

  std::size_t pos = 0;
  auto chunk = Chunk::read_image(in, pos);
  if (!chunk.ok()) return 0;
  if (pos > size) std::abort();
  RowPackedBox<32>::Row scratch;
  for (int y = 0; y < 32; ++y)
    for (int z = 0; z < 32; ++z) {
      const Voxel* row = chunk->read_row(y, z, scratch);
      for (int x = 0; x < 32; ++x) {
        if (row[x].material >= kMaterialCount || (row[x].material == kAir && row[x].occupancy != 0)) std::abort();
        if (!(row[x] == chunk->get(x, y, z))) std::abort();
      }
    }
  Box level;
  for (int l = 1; l < kMipLevels; ++l) chunk->read_level(l, level);
  std::vector<std::uint8_t> image;
  chunk->write_image(image);
  std::size_t again_pos = 0;
  auto again = Chunk::read_image(image, again_pos);
  if (!again.ok() || again_pos != image.size()) std::abort();
  for (int y = 0; y < 32; ++y)
    for (int z = 0; z < 32; ++z)
      for (int x = 0; x < 32; ++x)
        if (!(again->get(x, y, z) == chunk->get(x, y, z))) std::abort();
  const auto blob = encode_chunk_blob(*chunk);
  if (!decode_chunk_blob(blob).ok()) std::abort();
  // Writes on what was read (records shared or rewritten in place), against
  // a dense copy: a row here and a small box there.
  Box dense;
  chunk->read_level(0, dense);
  const int a = size > 0 ? data[0] % 32 : 0, b = size > 1 ? data[1] % 32 : 0;
  const Voxel v = make_voxel(static_cast<Material>(size > 2 ? data[2] % 64 : 1), size > 3 ? data[3] : 255);
  const Region writes[] = {Region{{0, a, b}, {32, a + 1, b + 1}}, Region{{b, a, 0}, {std::min(b + 3, 32), a + 1, 3}}};
  Chunk edited = chunk->clone();
  for (const Region& r : writes) {
    edited.modify(r, [&](Vec3i, Voxel) { return v; });
    for (int y = r.min.y; y < r.max.y; ++y)
      for (int z = r.min.z; z < r.max.z; ++z)
        for (int x = r.min.x; x < r.max.x; ++x) dense.set(x, y, z, v);
  }
  for (int y = 0; y < 32; ++y)
    for (int z = 0; z < 32; ++z) {
      const Voxel* row = edited.read_row(y, z, scratch);
      for (int x = 0; x < 32; ++x)
        if (!(row[x] == dense.get(x, y, z))) std::abort();
    }
  return 0;
}
