#include "server/base/chunk_version.h"

#include <algorithm>
#include <cstring>

#include "common/codec/chunk_units.h"
#include "common/voxel/box.h"
#include "common/world/world_store.h"
#include "protocol/messages.h"
#include "server/base/log.h"

namespace terrane {

EncodeCounters& encode_counters() {
  static EncodeCounters c;
  return c;
}

ChunkVersion::ChunkVersion(Vec3i pos, std::uint64_t revision, std::shared_ptr<const Chunk> chunk,
                           UnitBits changed_units, std::array<std::uint64_t, kMipLevels> level_since)
    : pos_(pos),
      revision_(revision),
      chunk_(std::move(chunk)),
      changed_units_(changed_units),
      level_since_(level_since),
      empty_(chunk_ == nullptr) {}

ChunkVersion::ChunkVersion(Vec3i pos, std::uint64_t revision, std::shared_ptr<const Chunk> chunk)
    : ChunkVersion(pos, revision, std::move(chunk), UnitBits{}, {revision, revision, revision, revision}) {}

std::shared_ptr<const ChunkVersion> ChunkVersion::after(const ChunkVersion& prev, std::unique_ptr<Chunk> chunk,
                                                      UnitBits changed) {
  std::shared_ptr<const Chunk> next;
  if (chunk && !chunk->empty()) {
    // A level 0 that tiny writes left unpacked is packed again.
    if (chunk->level0().unpacked()) chunk->compact();
    chunk->pack_mips();
    next = std::move(chunk);
  }
  const std::uint64_t rev = prev.revision() + 1;
  const auto differs = levels_changed(prev.chunk(), next.get());
  std::array<std::uint64_t, kMipLevels> since{};
  for (int level = 0; level < kMipLevels; ++level)
    since[static_cast<std::size_t>(level)] = differs[static_cast<std::size_t>(level)] ? rev : prev.level_since(level);
  return std::make_shared<const ChunkVersion>(prev.pos(), rev, std::move(next), changed, since);
}

std::shared_ptr<const ChunkVersion> ChunkVersion::mips_only(const ChunkVersion& full) {
  auto v = std::make_shared<ChunkVersion>(full.pos_, full.revision_, nullptr, UnitBits{}, full.level_since_);
  v->empty_ = full.empty_;
  v->has_voxels_ = false;
  v->finest_level_ = 1;
  for (int level = 1; level < kMipLevels; ++level) {
    const auto bytes = full.encoded(level);
    const auto l = static_cast<std::size_t>(level);
    std::call_once(v->encoded_once_[l], [&] { v->encoded_[l].assign(bytes.begin(), bytes.end()); });
  }
  return v;
}

std::shared_ptr<ChunkVersion> ChunkVersion::level3_only(Vec3i pos, std::uint64_t revision,
                                                       const CoarseVoxels& voxels) {
  auto v = std::make_shared<ChunkVersion>(pos, revision, nullptr);
  v->has_voxels_ = false;
  v->finest_level_ = kMipLevels - 1;
  const auto l = static_cast<std::size_t>(kMipLevels - 1);
  std::call_once(v->encoded_once_[l], [&] { net_codec_encode(kCoarseSide, voxels, v->encoded_[l]); });
  return v;
}

std::shared_ptr<const ChunkVersion> ChunkVersion::coarse_only(Vec3i pos, std::uint64_t revision,
                                                              const CoarseVoxels& voxels) {
  auto v = level3_only(pos, revision, voxels);
  // The coarsest mip is Air only when every voxel is (one non-Air child
  // makes its parent non-Air), so an all-Air image entry is an empty chunk.
  v->empty_ = all_air(voxels);
  return v;
}

std::shared_ptr<const ChunkVersion> ChunkVersion::estimated(Vec3i pos, const CoarseVoxels& voxels) {
  auto v = level3_only(pos, 0, voxels);
  v->empty_ = false;
  v->estimate_ = true;
  return v;
}

std::span<const std::uint8_t> ChunkVersion::encoded(int level) const {
  // Precondition: has_level(level) (a version without the voxels cannot
  // make a finer level; asking is a bug in the caller).
  if (!has_level(level)) {
    server_log().error("chunk ({},{},{}): level {} asked of a version that holds only {}..3", pos_.x, pos_.y, pos_.z,
                       level, finest_level_);
    return {};
  }
  const auto l = static_cast<std::size_t>(level);
  encode_counters().asked.fetch_add(1, std::memory_order_relaxed);
  // A chunk keeps its mips as exactly these units: the version hands out
  // the chunk's own bytes (immutable, owned with the chunk).
  if (level > 0 && chunk_ && !chunk_->mip_unit(level).empty()) return chunk_->mip_unit(level);
  std::call_once(encoded_once_[l], [&] {
    encode_counters().made.fetch_add(1, std::memory_order_relaxed);
    std::vector<std::uint8_t>& out = encoded_[l];
    if (level > 0) {
      const int n = kChunkSize >> level;
      Box box({n, n, n});
      if (chunk_) chunk_->read_level(level, box);
      net_codec_encode(n, box.voxels(), out);
      return;
    }
    encode_full_units(chunk_.get(), out);
  });
  return encoded_[l];
}

const UpdatePiece& ChunkVersion::update_piece() const {
  std::call_once(piece_once_, [&] {
    std::vector<UnitUpdate> units;
    units.reserve(changed_units_.count());
    for (std::size_t i = 0; i < changed_units_.size(); ++i) {
      if (!changed_units_.test(i)) continue;
      UnitUpdate u;
      u.chunk_pos = pos_;
      u.unit_index = static_cast<std::uint16_t>(i);
      units.push_back(u);
    }
    read_update_units(chunk_.get(), std::span<UnitUpdate>(units));
    if (!units.empty()) piece_ = net_codec_encode_update_piece(units);
  });
  return piece_;
}

std::uint64_t ChunkVersion::hash() const {
  std::call_once(hash_once_, [&] { hash_ = chunk_hash(chunk_.get(), revision_); });
  return hash_;
}

std::span<const std::uint8_t> ChunkVersion::blob() const {
  std::call_once(blob_once_, [&] { blob_ = chunk_ ? encode_chunk_blob(*chunk_) : encode_chunk_blob(Chunk()); });
  return blob_;
}

std::array<bool, kMipLevels> levels_changed(const Chunk* prev, const Chunk* next) {
  std::array<bool, kMipLevels> out{};
  out[0] = true;
  for (int level = 1; level < kMipLevels; ++level) {
    // Units are canonical (one content, one encoding): compare them when
    // both chunks keep theirs, else the decoded levels.
    if (prev && next && !prev->mip_unit(level).empty() && !next->mip_unit(level).empty()) {
      const auto a = prev->mip_unit(level), b = next->mip_unit(level);
      out[static_cast<std::size_t>(level)] = !std::equal(a.begin(), a.end(), b.begin(), b.end());
      continue;
    }
    const int n = kChunkSize >> level;
    Box a({n, n, n}), b({n, n, n});
    if (prev) prev->read_level(level, a);
    if (next) next->read_level(level, b);
    out[static_cast<std::size_t>(level)] =
        std::memcmp(a.voxels().data(), b.voxels().data(), a.voxels().size() * sizeof(Voxel)) != 0;
  }
  return out;
}

}  // namespace terrane
