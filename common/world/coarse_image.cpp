#include "common/world/coarse_image.h"

#include <algorithm>

#include "common/codec/lz4_block.h"

namespace terrane {

namespace {
constexpr std::uint8_t kVersion = 1;
constexpr std::uint8_t kCodecLz4 = 1;
constexpr std::size_t kEntryBytes = 2 + 8 + 2 * kCoarseVoxels;
constexpr std::size_t kMaxEntries = kCoarseRegionChunks * kCoarseRegionChunks * kCoarseRegionChunks;

DecodeError bad(std::size_t offset, const char* what) { return DecodeError{DecodeErrorCode::kInvalidValue, offset, what}; }
}  // namespace

CoarseVoxels coarse_voxels(const Chunk* chunk) {
  CoarseVoxels out{};
  if (chunk == nullptr) return out;
  Box box;
  chunk->read_level(kMipLevels - 1, box);
  std::copy_n(box.voxels().begin(), kCoarseVoxels, out.begin());
  return out;
}

CoarseVoxels coarse_voxels(const Box& box) {
  // 32 -> 16 -> 8 -> 4, each level from the one before (as Chunk's mips).
  Box level = downsample_box(box);
  while (level.size().x > kCoarseSide) level = downsample_box(level);
  CoarseVoxels out{};
  std::copy_n(level.voxels().begin(), kCoarseVoxels, out.begin());
  return out;
}

std::vector<std::uint8_t> encode_coarse_image(Vec3i region, std::vector<CoarseEntry> entries) {
  std::sort(entries.begin(), entries.end(),
            [](const CoarseEntry& a, const CoarseEntry& b) { return coarse_index(a.chunk_pos) < coarse_index(b.chunk_pos); });
  (void)region;
  std::vector<std::uint8_t> raw;
  raw.reserve(2 + entries.size() * kEntryBytes);
  const auto put16 = [&](std::uint32_t v) {
    raw.push_back(static_cast<std::uint8_t>(v));
    raw.push_back(static_cast<std::uint8_t>(v >> 8));
  };
  put16(static_cast<std::uint32_t>(entries.size()));
  for (const CoarseEntry& e : entries) {
    put16(static_cast<std::uint32_t>(coarse_index(e.chunk_pos)));
    for (int i = 0; i < 8; ++i) raw.push_back(static_cast<std::uint8_t>(e.revision >> (8 * i)));
    for (const Voxel v : e.voxels) {
      raw.push_back(v.material);
      raw.push_back(v.occupancy);
    }
  }
  std::vector<std::uint8_t> out{kVersion, kCodecLz4};
  lz4_compress(raw, out);
  return out;
}

Result<std::vector<CoarseEntry>> decode_coarse_image(Vec3i region, std::span<const std::uint8_t> blob) {
  if (blob.size() < 2) return DecodeError{DecodeErrorCode::kTruncated, blob.size(), "coarse image header"};
  if (blob[0] != kVersion) return bad(0, "coarse image version");
  if (blob[1] != kCodecLz4) return bad(1, "coarse image codec");
  auto raw = lz4_decompress(blob.subspan(2), 2 + kMaxEntries * kEntryBytes);
  if (!raw) return raw.error();
  const std::vector<std::uint8_t>& r = *raw;
  if (r.size() < 2) return DecodeError{DecodeErrorCode::kTruncated, r.size(), "coarse image count"};
  const std::size_t count = r[0] | (std::size_t{r[1]} << 8);
  if (count > kMaxEntries) return bad(0, "coarse image: more entries than a region has chunks");
  if (r.size() != 2 + count * kEntryBytes) return bad(r.size(), "coarse image: size does not match its count");
  std::vector<CoarseEntry> out(count);
  std::size_t at = 2;
  int last = -1;
  const Vec3i base = region * kCoarseRegionChunks;
  for (CoarseEntry& e : out) {
    const int index = r[at] | (r[at + 1] << 8);
    if (index >= static_cast<int>(kMaxEntries) || index <= last) return bad(at, "coarse image: index out of order");
    last = index;
    at += 2;
    e.chunk_pos = base + Vec3i{index % kCoarseRegionChunks, index / (kCoarseRegionChunks * kCoarseRegionChunks),
                               (index / kCoarseRegionChunks) % kCoarseRegionChunks};
    for (int i = 0; i < 8; ++i) e.revision |= std::uint64_t{r[at + static_cast<std::size_t>(i)]} << (8 * i);
    at += 8;
    for (Voxel& v : e.voxels) {
      v.material = r[at];
      v.occupancy = r[at + 1];
      if (v.material >= kMaterialCount) return bad(at, "coarse image: material out of range");
      if (v.material == kAir && v.occupancy != 0) return bad(at + 1, "coarse image: Air with occupancy");
      at += 2;
    }
  }
  return out;
}

}  // namespace terrane
