#include "common/voxel/chunk.h"

#include <algorithm>
#include <array>
#include <cassert>
#include <cstring>
#include <vector>

#include "common/codec/net_codec.h"

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

Chunk::Chunk(Material fill) : level0_(fill), mip_fill_(fill), empty_(fill == kAir) {}

Chunk Chunk::from_box(const Box& box, Mips mips) {
  Chunk c;
  c.mips_derived_ = mips == Mips::kDerived;
  c.level0_.modify_rows(0, kChunkSize, 0, kChunkSize, [&](int y, int z, Voxel* row) {
    std::copy_n(box.read_row(y, z), kChunkSize, row);
  });
  c.rebuild_mips();
  c.pack_mips();
  return c;
}

Chunk& Chunk::operator=(Chunk&& other) noexcept {
  if (this == &other) return *this;
  level0_ = std::move(other.level0_);
  dense_ = std::move(other.dense_);
  mips_ = std::move(other.mips_);
  mip_end_ = other.mip_end_;
  mip_fill_ = other.mip_fill_;
  empty_ = other.empty_;
  mips_derived_ = other.mips_derived_;
  other.mip_end_ = {};
  other.mip_fill_ = kAir;
  other.empty_ = true;
  other.mips_derived_ = false;
  return *this;
}

Chunk Chunk::clone() const {
  Chunk c;
  c.level0_ = level0_.clone();
  c.mip_end_ = mip_end_;
  c.mip_fill_ = mip_fill_;
  c.empty_ = empty_;
  c.mips_derived_ = mips_derived_;
  if (dense_) c.dense_ = std::make_unique<DenseMips>(*dense_);
  if (mips_) {
    const std::size_t bytes = mip_end_[kMipLevels - 1];
    c.mips_ = std::make_unique<std::uint8_t[]>(bytes);
    std::memcpy(c.mips_.get(), mips_.get(), bytes);
  }
  return c;
}

std::span<const std::uint8_t> Chunk::mip_unit(int level) const {
  if (!mips_ || dense_ || level < 1 || level >= kMipLevels) return {};
  const std::size_t begin = level == 1 ? 0 : mip_end_[static_cast<std::size_t>(level - 1)];
  return {mips_.get() + begin, mip_end_[static_cast<std::size_t>(level)] - begin};
}

Voxel Chunk::mip_get(int level, int x, int y, int z) const {
  if (level == 0) return level0_.get(x, y, z);
  thread_local Box box;
  read_level(level, box);
  return box.get(x, y, z);
}

namespace {
// Recomputes the voxels of `coarse` (the level above `fine`) covering the
// fine-level region r, returning the coarse region touched. Fine rows come
// from read(y, z) -> const Voxel*.
template <class ReadFine>
Region downsample_region(ReadFine&& read, Box& coarse, const Region& r) {
  const Region c{floor_div(r.min, 2), Vec3i{(r.max.x + 1) / 2, (r.max.y + 1) / 2, (r.max.z + 1) / 2}};
  RowPackedBox<32>::Row s00, s01, s10, s11;
  for (int y = c.min.y; y < c.max.y; ++y) {
    for (int z = c.min.z; z < c.max.z; ++z) {
      const Voxel* r00 = read(2 * y, 2 * z, s00);
      const Voxel* r01 = read(2 * y, 2 * z + 1, s01);
      const Voxel* r10 = read(2 * y + 1, 2 * z, s10);
      const Voxel* r11 = read(2 * y + 1, 2 * z + 1, s11);
      Voxel* row = coarse.write_row(y, z);
      for (int x = c.min.x; x < c.max.x; ++x) {
        const int fx = 2 * x;
        const Voxel children[8] = {r00[fx], r00[fx + 1], r01[fx], r01[fx + 1],
                                   r10[fx], r10[fx + 1], r11[fx], r11[fx + 1]};
        row[x] = downsample(children);
      }
    }
  }
  return c;
}

Region downsample_box(const Box& fine, Box& coarse, const Region& r) {
  return downsample_region([&](int y, int z, RowPackedBox<32>::Row&) { return fine.read_row(y, z); }, coarse, r);
}

// Recomputes mip levels 1..last (into *levels[0..last-1], sized already)
// over the level-0 region changed, each from the level below.
void downsample_levels(const RowPackedBox<32>& level0, const std::array<Box*, kMipLevels - 1>& levels, int last,
                       const Region& changed) {
  Region r = downsample_region(
      [&](int y, int z, RowPackedBox<32>::Row& scratch) { return level0.read_row(y, z, scratch); }, *levels[0],
      changed);
  for (int level = 2; level <= last; ++level) r = downsample_box(*levels[level - 2], *levels[level - 1], r);
}
}  // namespace

void Chunk::read_level(int level, Box& out) const {
  const int n = kChunkSize >> level;
  out.resize({n, n, n});
  if (level == 0) {
    Level0::Row scratch;
    for (int y = 0; y < n; ++y)
      for (int z = 0; z < n; ++z) std::copy_n(level0_.read_row(y, z, scratch), n, out.write_row(y, z));
    return;
  }
  if (mips_derived_) {
    // The levels below the one asked in per-thread boxes, that one in out.
    thread_local Box finer[kMipLevels - 2];
    std::array<Box*, kMipLevels - 1> levels{&finer[0], &finer[1], nullptr};
    levels[static_cast<std::size_t>(level - 1)] = &out;
    for (int l = 1; l < level; ++l) levels[static_cast<std::size_t>(l - 1)]->resize({kChunkSize >> l, kChunkSize >> l, kChunkSize >> l});
    downsample_levels(level0_, levels, level, Region{{0, 0, 0}, {kChunkSize, kChunkSize, kChunkSize}});
    return;
  }
  if (dense_) {
    out = dense_->levels[level - 1];
    return;
  }
  if (!mips_) {
    out.fill(solid(mip_fill_));
    return;
  }
  // The units were made by this chunk: a failure is a bug, not bad input.
  [[maybe_unused]] const Status s = net_codec_decode(n, mip_unit(level), out.voxels());
  assert(s.ok());
}

void Chunk::read_box(Vec3i min, Box& out, Vec3i out_offset, Vec3i size) const {
  const Vec3i shift = out_offset - min;
  level0_.read_rows_part(min.y, min.y + size.y, min.z, min.z + size.z, min.x, size.x,
                         [&](int y, int z) { return out.write_row(y + shift.y, z + shift.z) + out_offset.x; });
}

void Chunk::pack_mips() {
  if (!dense_) return;
  const std::unique_ptr<DenseMips> dense = std::move(dense_);
  if (level0_.is_uniform()) {
    mips_.reset();
    mip_end_ = {};
    mip_fill_ = level0_.uniform_material();
    return;
  }
  thread_local std::vector<std::uint8_t> units;
  encode_mip_units(*dense, units, mip_end_);
  mips_ = std::make_unique<std::uint8_t[]>(units.size());
  std::memcpy(mips_.get(), units.data(), units.size());
}

void Chunk::encode_mip_units(const DenseMips& dense, std::vector<std::uint8_t>& units,
                             std::array<std::uint16_t, kMipLevels>& end) {
  units.clear();
  for (int level = 1; level < kMipLevels; ++level) {
    // Version 1: the mesher reads level 1 of every chunk it meshes coarse,
    // and a version-2 unit of smooth terrain decodes at about half the
    // speed (mesh L1 on the generated world 0.85-0.89x of unpacked with
    // version-2 mips, 0.92-0.93x with version 1, 2026-12-03) for 1.5 % of
    // the grid's memory.
    net_codec_encode(kChunkSize >> level, dense.levels[level - 1].voxels(), units, kNetCodecVersion1);
    end[static_cast<std::size_t>(level)] = static_cast<std::uint16_t>(units.size());
  }
}

void Chunk::update_mips(const Region& changed) {
  if (mips_derived_) {
    // Nothing held: only whether the chunk is empty (Air at any level means
    // Air in everything it covers, so level 0 answers for level 3).
    empty_ = !level0_.box_has_solid(0, kChunkSize, 0, kChunkSize, 0, kChunkSize, 0);
    return;
  }
  const bool whole = changed.min == Vec3i{0, 0, 0} && changed.max == Vec3i{kChunkSize, kChunkSize, kChunkSize};
  if (!dense_) {
    auto dense = std::make_unique<DenseMips>();
    for (int level = 1; level < kMipLevels; ++level) {
      Box& box = dense->levels[level - 1];
      if (whole) box.resize({kChunkSize >> level, kChunkSize >> level, kChunkSize >> level});
      else read_level(level, box);
    }
    dense_ = std::move(dense);
    mips_.reset();
    mip_end_ = {};
  }
  Box* l = dense_->levels;  // levels 1, 2, 3
  downsample_levels(level0_, {&l[0], &l[1], &l[2]}, kMipLevels - 1, changed);
  empty_ = all_air(l[2].voxels());
  if (level0_.is_uniform()) mip_fill_ = level0_.uniform_material();
}

void Chunk::rebuild_mips() { update_mips(Region{{0, 0, 0}, {kChunkSize, kChunkSize, kChunkSize}}); }

void Chunk::fill(Material m) {
  level0_.fill(m);
  dense_.reset();
  mips_.reset();
  mip_end_ = {};
  mip_fill_ = m;
  empty_ = m == kAir;
}

void Chunk::compact() {
  level0_.compact();
  pack_mips();
}

bool Chunk::write_image(std::vector<std::uint8_t>& out) const {
  if (mips_derived_) {
    // The image holds the mips: made in a copy that keeps them (as dense
    // boxes, which the image encodes).
    Chunk kept = clone();
    kept.mips_derived_ = false;
    kept.rebuild_mips();
    return kept.write_image(out);
  }
  if (level0_.unpacked()) {
    Chunk packed = clone();
    packed.compact();
    // Records beyond 15-bit offsets stay unpacked (RowPackedBox::compact):
    // such a chunk has no image.
    if (packed.level0_.unpacked()) return false;
    return packed.write_image(out);
  }
  level0_.write_image(out);
  if (level0_.is_uniform()) return true;
  // The units as stored, or as pack_mips() would store them.
  thread_local std::vector<std::uint8_t> encoded;
  std::span<const std::uint8_t> units;
  std::array<std::uint16_t, kMipLevels> end = mip_end_;
  if (dense_) {
    encode_mip_units(*dense_, encoded, end);
    units = encoded;
  } else {
    units = {mips_.get(), mip_end_[kMipLevels - 1]};
  }
  for (int level = 1; level < kMipLevels; ++level) {
    const std::size_t from = end[static_cast<std::size_t>(level - 1)], to = end[static_cast<std::size_t>(level)];
    append_le16(out, static_cast<std::uint16_t>(to - from));
    out.insert(out.end(), units.begin() + static_cast<std::ptrdiff_t>(from), units.begin() + static_cast<std::ptrdiff_t>(to));
  }
  return true;
}

Result<Chunk> Chunk::read_image(std::span<const std::uint8_t> in, std::size_t& pos) {
  auto level0 = Level0::read_image(in, pos);
  if (!level0) return level0.error();
  Chunk c;
  c.level0_ = std::move(*level0);
  if (c.level0_.is_uniform()) {
    c.mip_fill_ = c.level0_.uniform_material();
    c.empty_ = c.mip_fill_ == kAir;
    return c;
  }
  // The three units' places in the image, then each decoded once (to check
  // it) and kept as it is.
  std::array<std::span<const std::uint8_t>, kMipLevels> unit{};
  std::size_t at = pos, total = 0;
  for (int level = 1; level < kMipLevels; ++level) {
    if (in.size() - at < 2) return DecodeError{DecodeErrorCode::kTruncated, at, "chunk image: mip unit length"};
    const std::size_t n = load_le16(in.data() + at);
    total += n;
    if (total > 0xFFFF)
      return DecodeError{DecodeErrorCode::kOverLimit, at, "chunk image: mip units over 65,535 bytes"};
    at += 2;
    if (in.size() - at < n) return DecodeError{DecodeErrorCode::kTruncated, at, "chunk image: mip unit"};
    unit[static_cast<std::size_t>(level)] = in.subspan(at, n);
    at += n;
  }
  c.mips_ = std::make_unique<std::uint8_t[]>(total);
  thread_local Box level_box;
  for (int level = 1; level < kMipLevels; ++level) {
    const std::span<const std::uint8_t> u = unit[static_cast<std::size_t>(level)];
    const int side = kChunkSize >> level;
    level_box.resize({side, side, side});
    if (const Status s = net_codec_decode(side, u, level_box.voxels()); !s) {
      DecodeError e = s.error();
      e.offset += static_cast<std::size_t>(u.data() - in.data());
      return e;
    }
    const std::size_t from = c.mip_end_[static_cast<std::size_t>(level - 1)];
    std::memcpy(c.mips_.get() + from, u.data(), u.size());
    c.mip_end_[static_cast<std::size_t>(level)] = static_cast<std::uint16_t>(from + u.size());
  }
  // Empty is level 0's (every voxel Air), and level 3 must agree: Air at
  // any level means Air in everything it covers.
  c.empty_ = !c.level0_.box_has_solid(0, kChunkSize, 0, kChunkSize, 0, kChunkSize, 0);
  if (c.empty_ != all_air(level_box.voxels()))  // (level 3, the last decoded)
    return DecodeError{DecodeErrorCode::kInvalidValue, static_cast<std::size_t>(unit[kMipLevels - 1].data() - in.data()),
                       "chunk image: level 3 and level 0 disagree on whether the chunk is empty"};
  pos = at;
  return c;
}

ChunkMemory Chunk::memory() const {
  ChunkMemory m;
  m.object_bytes = sizeof(Chunk);
  m.level0_bytes = level0_.heap_bytes();
  m.mip_bytes = (mips_ ? mip_end_[kMipLevels - 1] : 0) +
                (dense_ ? sizeof(DenseMips) + sizeof(Voxel) * (16 * 16 * 16 + 8 * 8 * 8 + 4 * 4 * 4) : 0);
  // (Unpacked mips: three plain boxes until pack_mips().)
  return m;
}

Box downsample_box(const Box& in) {
  const int h = in.size().x / 2;
  Box out(Vec3i{h, h, h});
  for (int y = 0; y < h; ++y)
    for (int z = 0; z < h; ++z)
      for (int x = 0; x < h; ++x) {
        Voxel c[8];
        int i = 0;
        for (int dy = 0; dy < 2; ++dy)
          for (int dz = 0; dz < 2; ++dz)
            for (int dx = 0; dx < 2; ++dx) c[i++] = in.get(2 * x + dx, 2 * y + dy, 2 * z + dz);
        out.set(x, y, z, downsample(c));
      }
  return out;
}

}  // namespace terrane
