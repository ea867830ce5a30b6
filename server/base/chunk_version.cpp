#include "server/base/chunk_version.h"

#include <algorithm>
#include <bit>
#include <cstring>

#include "common/codec/chunk_units.h"
#include "common/codec/net_codec.h"
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
    : pos_(pos), revision_(revision), chunk_(std::move(chunk)), level_since_(level_since) {
  empty_ = chunk_ == nullptr;
  if (changed_units.any()) {
    auto h = std::make_shared<EditHistory>();
    h->changed_units = changed_units;
    history_ = std::move(h);
  }
}

const UnitBits& ChunkVersion::no_units() {
  static const UnitBits none;
  return none;
}

void ChunkVersion::Bytes::assign(std::span<const std::uint8_t> bytes) {
  data = std::make_unique_for_overwrite<std::uint8_t[]>(bytes.size());
  if (!bytes.empty()) std::memcpy(data.get(), bytes.data(), bytes.size());
  size = static_cast<std::uint32_t>(bytes.size());
}

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
  auto v = std::make_shared<ChunkVersion>(prev.pos(), rev, std::move(next), UnitBits{}, since);
  // The level-1 sub-units the changed units reach: unit (ux, uy, uz) of
  // level 0 covers level-1 voxels 2u..2u+1, in sub-unit u / 2.
  std::uint64_t own = 0;
  for (int i = 0; i < kUpdateUnitsPerChunk; ++i)
    if (changed.test(static_cast<std::size_t>(i))) {
      const int ux = i % 8, uz = (i / 8) % 8, uy = i / 64;
      own |= std::uint64_t{1} << (((uy / 2) * 4 + uz / 2) * 4 + ux / 2);
    }
  auto h = std::make_shared<EditHistory>();
  h->changed_units = changed;
  h->level1_changed[0] = own;
  const int prev_history = prev.history_ ? prev.history_->patch_history : 0;
  for (int k = 1; k < kPatchHistory && k <= prev_history; ++k)
    h->level1_changed[static_cast<std::size_t>(k)] =
        own | prev.history_->level1_changed[static_cast<std::size_t>(k - 1)];
  h->patch_history = static_cast<std::uint8_t>(std::min<int>(prev_history + 1, kPatchHistory));
  v->history_ = std::move(h);
  return v;
}

std::optional<std::uint64_t> ChunkVersion::changed_since(int level, std::uint64_t held_revision) const {
  const int history = history_ ? history_->patch_history : 0;
  if (held_revision >= revision_ || revision_ - held_revision > static_cast<std::uint64_t>(history)) return std::nullopt;
  const std::uint64_t l1 = history_->level1_changed[static_cast<std::size_t>(revision_ - held_revision - 1)];
  if (level == 1) return l1;
  // Level 2: sub-unit (x, y, z) of level 1 lies in (x, y, z) / 2.
  std::uint64_t l2 = 0;
  for (std::uint64_t rest = l1; rest != 0; rest &= rest - 1) {
    const int i = std::countr_zero(rest);
    const int x = i % 4, z = (i / 4) % 4, y = i / 16;
    l2 |= std::uint64_t{1} << (((y / 2) * 2 + z / 2) * 2 + x / 2);
  }
  return l2;
}

void ChunkVersion::append_patch_units(int level, std::uint64_t mask, std::vector<std::uint8_t>& out) const {
  const auto l = static_cast<std::size_t>(level - 1);
  std::call_once(patch_once_[l], [&] {
    patch_units_[l] = std::make_unique<PatchUnits>();
    PatchUnits& p = *patch_units_[l];
    const int n = kChunkSize >> level, side = n / 4;
    Box mip({n, n, n});
    if (!empty_) {
      const auto bytes = encoded(level);
      if (!net_codec_decode(n, bytes, mip.voxels()))
        server_log().error("chunk ({},{},{}): its own level {} did not decode", pos_.x, pos_.y, pos_.z, level);
    }
    Box unit({4, 4, 4});
    for (int i = 0; i < side * side * side; ++i) {
      const Vec3i o = Vec3i{i % side, i / (side * side), (i / side) % side} * 4;
      for (int y = 0; y < 4; ++y)
        for (int z = 0; z < 4; ++z) std::copy_n(mip.read_row(o.y + y, o.z + z) + o.x, 4, unit.write_row(y, z));
      p.starts.push_back(static_cast<std::uint32_t>(p.bytes.size()));
      std::vector<std::uint8_t> one;
      net_codec_encode(4, unit.voxels(), one, kServedCodecVersion);
      p.bytes.insert(p.bytes.end(), one.begin(), one.end());
    }
    p.starts.push_back(static_cast<std::uint32_t>(p.bytes.size()));
  });
  const PatchUnits& p = *patch_units_[l];
  for (std::uint64_t rest = mask; rest != 0; rest &= rest - 1) {
    const auto i = static_cast<std::size_t>(std::countr_zero(rest));
    if (i + 1 >= p.starts.size()) break;  // (beyond the level's sub-units: a caller's bug)
    out.insert(out.end(), p.bytes.begin() + p.starts[i], p.bytes.begin() + p.starts[i + 1]);
  }
}

std::shared_ptr<const ChunkVersion> ChunkVersion::mips_only(const ChunkVersion& full) {
  auto v = std::make_shared<ChunkVersion>(full.pos_, full.revision_, nullptr, UnitBits{}, full.level_since_);
  v->empty_ = full.empty_;
  v->has_voxels_ = false;
  v->finest_level_ = 1;
  // The patch history goes with the mips (a refresh of them may still
  // send patches); the changed units do not (changed_units() answers none
  // for a version without voxels).
  v->history_ = full.history_;
  for (int level = 1; level < kMipLevels; ++level) {
    const auto bytes = full.encoded(level);
    const auto l = static_cast<std::size_t>(level);
    std::call_once(v->encoded_once_[l], [&] { v->encoded_[l].assign(bytes); });
  }
  return v;
}

std::shared_ptr<ChunkVersion> ChunkVersion::level3_only(Vec3i pos, std::uint64_t revision,
                                                       const CoarseVoxels& voxels) {
  auto v = std::make_shared<ChunkVersion>(pos, revision, nullptr);
  v->has_voxels_ = false;
  v->finest_level_ = kMipLevels - 1;
  const auto l = static_cast<std::size_t>(kMipLevels - 1);
  std::call_once(v->encoded_once_[l], [&] {
    v->encoded_[l].make([&](std::vector<std::uint8_t>& out) { net_codec_encode(kCoarseSide, voxels, out, kServedCodecVersion); });
  });
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
    encoded_[l].make([&](std::vector<std::uint8_t>& out) {
      if (level == 0) return encode_full_units(chunk_.get(), out, kServedCodecVersion);
      const int n = kChunkSize >> level;
      Box box({n, n, n});
      if (chunk_) chunk_->read_level(level, box);
      net_codec_encode(n, box.voxels(), out, kServedCodecVersion);
    });
  });
  return encoded_[l].span();
}

const UpdatePiece& ChunkVersion::update_piece() const {
  std::call_once(piece_once_, [&] { piece_ = std::make_unique<UpdatePiece>(make_update_piece(kServedCodecVersion)); });
  return *piece_;
}

UpdatePiece ChunkVersion::make_update_piece(std::uint8_t codec_version) const {
  std::vector<UnitUpdate> units;
  const UnitBits& changed = changed_units();
  units.reserve(changed.count());
  for (std::size_t i = 0; i < changed.size(); ++i) {
    if (!changed.test(i)) continue;
    UnitUpdate u;
    u.chunk_pos = pos_;
    u.unit_index = static_cast<std::uint16_t>(i);
    units.push_back(u);
  }
  read_update_units(chunk_.get(), std::span<UnitUpdate>(units));
  if (units.empty()) return {};
  return net_codec_encode_update_piece(units, codec_version);
}

std::uint64_t ChunkVersion::hash() const {
  std::call_once(hash_once_, [&] { hash_ = chunk_hash(chunk_.get(), revision_); });
  return hash_;
}

std::vector<std::uint8_t> ChunkVersion::blob() const {
  return chunk_ ? encode_chunk_blob(*chunk_) : encode_chunk_blob(Chunk());
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
