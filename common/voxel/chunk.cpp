#include "common/voxel/chunk.h"

#include <algorithm>
#include <array>

namespace terrane {

Voxel downsample(const Voxel children[8]) {
  // Eight equal children (uniform ground, open sky: most of a world) are
  // their own parent: the rule below gives the same material and, with
  // sum = 8 (o + 1), the byte (8 o + 12) / 8 - 1 = o.
  const Voxel first = children[0];
  bool same = true;
  for (int i = 1; i < 8; ++i) same &= children[i] == first;
  if (same) return first.material == kAir ? Voxel{} : first;
  // The most common non-Air material (ties: the lowest id), counted among
  // the eight children themselves rather than in a table of every material.
  int sum = 0;  // sum of (occupancy + 1) over non-Air children: 256 × fractions
  Material best = kAir;
  int best_count = 0;
  for (int i = 0; i < 8; ++i) {
    const Voxel c = children[i];
    if (c.material == kAir) continue;
    sum += c.occupancy + 1;
    int count = 0;
    for (int j = 0; j < 8; ++j) count += children[j].material == c.material;
    if (count > best_count || (count == best_count && c.material < best)) {
      best = c.material;
      best_count = count;
    }
  }
  if (best == kAir) return Voxel{};
  // mean fraction = sum / (8 · 256); its byte is mean·256 − 1 = sum/8 − 1,
  // rounded to nearest and kept >= 0 (the smallest non-zero occupancy).
  const int byte = std::clamp((sum + 4) / 8 - 1, 0, 255);
  return make_voxel(best, static_cast<std::uint8_t>(byte));
}

Chunk::Chunk(Material fill) : level0_(fill), mip1_(fill), mip2_(fill), mip3_(fill) {}

Chunk Chunk::from_box(const Box& box) {
  Chunk c;
  c.level0_.modify_rows(0, kChunkSize, 0, kChunkSize, [&](int y, int z, Voxel* row) {
    std::copy_n(box.read_row(y, z), kChunkSize, row);
  });
  c.rebuild_mips();
  return c;
}

Chunk Chunk::clone() const {
  Chunk c;
  c.level0_ = level0_.clone();
  c.mip1_ = mip1_.clone();
  c.mip2_ = mip2_.clone();
  c.mip3_ = mip3_.clone();
  return c;
}

bool Chunk::empty() const {
  if (mip3_.is_uniform()) return mip3_.uniform_material() == kAir;
  RowPackedBox<4>::Row scratch;
  for (int y = 0; y < 4; ++y)
    for (int z = 0; z < 4; ++z) {
      const Voxel* row = mip3_.read_row(y, z, scratch);
      for (int x = 0; x < 4; ++x)
        if (row[x].material != kAir) return false;
    }
  return true;
}

Voxel Chunk::mip_get(int level, int x, int y, int z) const {
  switch (level) {
    case 0: return level0_.get(x, y, z);
    case 1: return mip1_.get(x, y, z);
    case 2: return mip2_.get(x, y, z);
    default: return mip3_.get(x, y, z);
  }
}

namespace {
template <int N>
void read_all(const RowPackedBox<N>& b, Box& out) {
  out.resize({N, N, N});
  typename RowPackedBox<N>::Row scratch;
  for (int y = 0; y < N; ++y)
    for (int z = 0; z < N; ++z) std::copy_n(b.read_row(y, z, scratch), N, out.write_row(y, z));
}

// Recomputes the mip voxels of `fine`'s parent level covering the fine-level
// region r (fine-level coordinates), returning the coarse region touched.
template <int NF, int NC>
Region downsample_region(const RowPackedBox<NF>& fine, RowPackedBox<NC>& coarse, const Region& r) {
  const Region c{floor_div(r.min, 2), Vec3i{(r.max.x + 1) / 2, (r.max.y + 1) / 2, (r.max.z + 1) / 2}};
  coarse.modify_rows(c.min.y, c.max.y, c.min.z, c.max.z, [&](int y, int z, Voxel* row) {
    typename RowPackedBox<NF>::Row s00, s01, s10, s11;
    const Voxel* r00 = fine.read_row(2 * y, 2 * z, s00);
    const Voxel* r01 = fine.read_row(2 * y, 2 * z + 1, s01);
    const Voxel* r10 = fine.read_row(2 * y + 1, 2 * z, s10);
    const Voxel* r11 = fine.read_row(2 * y + 1, 2 * z + 1, s11);
    for (int x = c.min.x; x < c.max.x; ++x) {
      const int fx = 2 * x;
      const Voxel children[8] = {r00[fx], r00[fx + 1], r01[fx], r01[fx + 1],
                                 r10[fx], r10[fx + 1], r11[fx], r11[fx + 1]};
      row[x] = downsample(children);
    }
  });
  return c;
}
}  // namespace

void Chunk::read_level(int level, Box& out) const {
  switch (level) {
    case 0: read_all(level0_, out); break;
    case 1: read_all(mip1_, out); break;
    case 2: read_all(mip2_, out); break;
    default: read_all(mip3_, out); break;
  }
}

void Chunk::read_box(Vec3i min, Box& out, Vec3i out_offset, Vec3i size) const {
  Level0::Row scratch;
  for (int y = 0; y < size.y; ++y) {
    for (int z = 0; z < size.z; ++z) {
      const Voxel* row = level0_.read_row(min.y + y, min.z + z, scratch);
      std::copy_n(row + min.x, size.x, out.write_row(out_offset.y + y, out_offset.z + z) + out_offset.x);
    }
  }
}

void Chunk::update_mips(const Region& changed) {
  const Region r1 = downsample_region(level0_, mip1_, changed);
  const Region r2 = downsample_region(mip1_, mip2_, r1);
  downsample_region(mip2_, mip3_, r2);
}

void Chunk::rebuild_mips() { update_mips(Region{{0, 0, 0}, {kChunkSize, kChunkSize, kChunkSize}}); }

void Chunk::fill(Material m) {
  level0_.fill(m);
  mip1_.fill(m);
  mip2_.fill(m);
  mip3_.fill(m);
}

void Chunk::compact() {
  level0_.compact();
  mip1_.compact();
  mip2_.compact();
  mip3_.compact();
}

ChunkMemory Chunk::memory() const {
  ChunkMemory m;
  m.object_bytes = sizeof(Chunk);
  m.level0_bytes = level0_.heap_bytes();
  m.mip_bytes = mip1_.heap_bytes() + mip2_.heap_bytes() + mip3_.heap_bytes();
  return m;
}

}  // namespace terrane
