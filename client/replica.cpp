#include "client/replica.h"

#include <algorithm>
#include <array>

namespace terrane {

namespace {
// Units decoded from one UpdateBatch at most: 16 chunks' worth. The server
// sends one chunk per batch; the cap bounds the scratch buffer (~1 MiB).
constexpr std::size_t kMaxBatchUnits = 16 * kUpdateUnitsPerChunk;
}  // namespace

Replica::Replica() : unit_scratch_({kChunkDataUnit, kChunkDataUnit, kChunkDataUnit}) {}

Status Replica::apply_chunk_data(const ChunkDataMsg& m) {
  unit_scratch_.resize({kChunkDataUnit, kChunkDataUnit, kChunkDataUnit});
  if (auto st = net_codec_decode(kChunkDataUnit, m.data, unit_scratch_.voxels()); !st) return st;
  write_unit(m.unit_pos, unit_scratch_);
  return Ok{};
}

void Replica::write_unit(Vec3i unit_pos, const Box& unit) {
  const Vec3i cp = floor_div(unit_pos, kChunkSize / kChunkDataUnit);
  const ChunkCoverage* c = coverage(cp);
  auto it = pending_.find(cp);
  const bool direct = (c != nullptr && c->state == CoverageState::kFull) ||
                      (it == pending_.end() && pending_.size() >= kMaxPendingChunks);
  if (direct) {
    grid_.write_box(unit_pos * kChunkDataUnit, unit);
    voxels_changed(cp);
    return;
  }
  if (it == pending_.end()) it = pending_.emplace(cp, Pending{Box({kChunkSize, kChunkSize, kChunkSize}), 0}).first;
  const Vec3i u = floor_mod(unit_pos, kChunkSize / kChunkDataUnit);
  const Vec3i off = u * kChunkDataUnit;
  for (int y = 0; y < kChunkDataUnit; ++y)
    for (int z = 0; z < kChunkDataUnit; ++z)
      std::copy_n(unit.read_row(y, z), kChunkDataUnit, it->second.voxels.write_row(off.y + y, off.z + z) + off.x);
  it->second.received |= static_cast<std::uint8_t>(1u << ((u.z * 2 + u.y) * 2 + u.x));
}

void Replica::flush_pending(Vec3i cp) {
  auto it = pending_.find(cp);
  if (it == pending_.end()) return;
  Pending& p = it->second;
  if (p.received == 0xff) {
    grid_.put_chunk(cp, Chunk::from_box(p.voxels));
  } else {
    // Not every unit came: keep what the grid had for the others.
    Box unit({kChunkDataUnit, kChunkDataUnit, kChunkDataUnit});
    for (int i = 0; i < 8; ++i) {
      if ((p.received & (1u << i)) == 0) continue;
      const Vec3i off = Vec3i{i & 1, (i >> 1) & 1, (i >> 2) & 1} * kChunkDataUnit;
      for (int y = 0; y < kChunkDataUnit; ++y)
        for (int z = 0; z < kChunkDataUnit; ++z)
          std::copy_n(p.voxels.read_row(off.y + y, off.z + z) + off.x, kChunkDataUnit, unit.write_row(y, z));
      grid_.write_box(chunk_origin(cp) + off, unit);
    }
  }
  pending_.erase(it);
  voxels_changed(cp);
}

void Replica::apply_stream_record(const StreamRecord& r) {
  const Vec3i cp = r.chunk_pos;
  switch (r.kind) {
    case StreamRecordKind::kEmpty:
      apply_coverage(CoverageMsg{cp, wire::CoverageKind::Empty, 0, r.revision});
      return;
    case StreamRecordKind::kReleased:
      apply_coverage(CoverageMsg{cp, wire::CoverageKind::Released, 0, r.revision});
      return;
    case StreamRecordKind::kHorizon: {
      std::vector<Vec3i> covered;
      apply_horizon(r, covered);
      return;
    }
    case StreamRecordKind::kFull: {
      pending_.erase(cp);
      Chunk chunk;
      if (!shared_) {
        chunk = Chunk::from_box(*r.voxels);
      } else if (auto known = shared_->find(r.payload)) {
        chunk = known->clone();
      } else {
        chunk = Chunk::from_box(*r.voxels);
        shared_->add(r.payload, std::make_shared<const Chunk>(chunk.clone()));
      }
      if (chunk.empty())
        grid_.erase_chunk(cp);
      else
        grid_.put_chunk(cp, std::move(chunk));
      Entry& e = chunks_[cp];
      e.mip.reset();
      e.coverage = ChunkCoverage{CoverageState::kFull, 0, r.revision};
      entry_changed(cp, e);
      return;
    }
    case StreamRecordKind::kMip1:
    case StreamRecordKind::kMip2:
    case StreamRecordKind::kMip3:
    case StreamRecordKind::kEstimate: {
      // A refresh of a mip held overwrites it in place (no new allocation).
      Entry& e = chunks_[cp];
      if (e.coverage.state == CoverageState::kMip && e.coverage.level == r.level && e.mip &&
          *e.mip == *r.voxels)
        ++redundant_mips_;
      if (e.mip)
        *e.mip = *r.voxels;
      else
        e.mip = std::make_unique<Box>(*r.voxels);
      pending_.erase(cp);
      e.coverage = ChunkCoverage{CoverageState::kMip, r.level, r.revision, r.kind == StreamRecordKind::kEstimate};
      grid_.erase_chunk(cp);
      entry_changed(cp, e);
      return;
    }
  }
}

void Replica::apply_horizon(const StreamRecord& r, std::vector<Vec3i>& covered) {
  const Vec3i region = floor_div(r.chunk_pos, kHorizonRegionChunks);
  auto [it, fresh] = horizons_.try_emplace(region);
  Horizon& h = it->second;
  // A newer image of the region (another plan's) serves every chunk it covers.
  h.coverage = ChunkCoverage{CoverageState::kMip, r.level, 0};
  h.image = *r.voxels;
  for_each_region_chunk(region, [&](Vec3i cp) {
    const int i = coarse_index(cp);
    if (!horizon_mask_has(*r.mask, i) || h.covers.test(static_cast<std::size_t>(i)) ||
        chunks_.find(cp) != chunks_.end())
      return;
    h.covers.set(static_cast<std::size_t>(i));
    ++horizon_chunks_;
    covered.push_back(cp);
  });
  if (h.covers.none()) horizons_.erase(region);
}

const Replica::Horizon* Replica::horizon_of(Vec3i cp) const {
  if (horizons_.empty()) return nullptr;
  auto it = horizons_.find(floor_div(cp, kHorizonRegionChunks));
  if (it == horizons_.end() || !it->second.covers.test(static_cast<std::size_t>(coarse_index(cp)))) return nullptr;
  return &it->second;
}

void Replica::forget_horizon(Vec3i cp) {
  auto it = horizons_.find(floor_div(cp, kHorizonRegionChunks));
  if (it == horizons_.end()) return;
  const auto i = static_cast<std::size_t>(coarse_index(cp));
  if (!it->second.covers.test(i)) return;
  it->second.covers.reset(i);
  --horizon_chunks_;
  if (it->second.covers.none()) horizons_.erase(it);
}

Replica::MipView Replica::mip_view(Vec3i cp) const {
  if (auto it = chunks_.find(cp); it != chunks_.end())
    return it->second.coverage.state == CoverageState::kMip
               ? MipView{it->second.mip.get(), {0, 0, 0}, it->second.coverage.level}
               : MipView{};
  if (const Horizon* h = horizon_of(cp))
    return MipView{&h->image, floor_mod(cp, kHorizonRegionChunks) * (kChunkSize >> h->coverage.level), h->coverage.level};
  return {};
}

bool Replica::read_mip(Vec3i cp, Box& out) const {
  const MipView m = mip_view(cp);
  if (m.box == nullptr) return false;
  const int n = kChunkSize >> m.level;
  out.resize({n, n, n});
  for (int y = 0; y < n; ++y)
    for (int z = 0; z < n; ++z)
      for (int x = 0; x < n; ++x) out.set(x, y, z, m.box->get(m.origin + Vec3i{x, y, z}));
  return true;
}

Status Replica::apply_mip_data(const MipDataMsg& m) {
  const int n = kChunkSize >> m.level;
  Box mip({n, n, n});
  if (auto st = net_codec_decode(n, m.data, mip.voxels()); !st) return st;
  Entry& e = chunks_[m.chunk_pos];
  e.mip = std::make_unique<Box>(std::move(mip));
  pending_.erase(m.chunk_pos);
  e.coverage = ChunkCoverage{CoverageState::kMip, m.level, m.revision};
  grid_.erase_chunk(m.chunk_pos);
  entry_changed(m.chunk_pos, e);
  return Ok{};
}

void Replica::apply_coverage(const CoverageMsg& m) {
  const Vec3i cp = m.chunk_pos;
  switch (m.kind) {
    case wire::CoverageKind::Empty: {
      if (!pending_.empty()) pending_.erase(cp);
      grid_.erase_chunk(cp);
      Entry& e = chunks_[cp];
      e.mip.reset();
      e.coverage = ChunkCoverage{CoverageState::kEmpty, 0, m.revision};
      entry_changed(cp, e);
      break;
    }
    case wire::CoverageKind::Full: {
      flush_pending(cp);
      Entry& e = chunks_[cp];
      e.mip.reset();
      e.coverage = ChunkCoverage{CoverageState::kFull, 0, m.revision};
      entry_changed(cp, e);
      break;
    }
    case wire::CoverageKind::Mip:
      // Only MipData carries a mip; a bare Mip coverage changes nothing
      // but what the chunk's cached hash and horizon image claimed.
      voxels_changed(cp);
      break;
    case wire::CoverageKind::Released:
      if (!pending_.empty()) pending_.erase(cp);
      grid_.erase_chunk(cp);
      chunks_.erase(cp);
      if (!horizons_.empty()) forget_horizon(cp);
      break;
  }
}

Result<std::size_t> Replica::apply_update_batch(const UpdateBatchMsg& m, std::vector<Region>* changed) {
  const std::size_t cap = std::min(kMaxBatchUnits, m.revisions.size() * kUpdateUnitsPerChunk);
  update_scratch_.resize(cap);
  auto n = net_codec_decode_update_batch(m.data, update_scratch_);
  if (!n) return n.error();
  // Check every unit belongs to a listed chunk before changing anything.
  for (std::size_t i = 0; i < *n; ++i) {
    const Vec3i cp = update_scratch_[i].chunk_pos;
    const bool listed = std::any_of(m.revisions.begin(), m.revisions.end(),
                                    [&](const ChunkRevisionMsg& r) { return r.chunk_pos == cp; });
    if (!listed) return DecodeError{DecodeErrorCode::kInvalidValue, 0, "update for a chunk without a revision"};
  }
  // Each chunk's units are written in one pass over the box that holds
  // them, so its rows are repacked and its mips updated once per batch, not
  // once per unit. (A batch lists units chunk by chunk.)
  std::size_t applied = 0;
  ChunkUnits units;
  for (std::size_t begin = 0; begin < *n;) {
    const Vec3i cp = update_scratch_[begin].chunk_pos;
    std::size_t end = begin;
    while (end < *n && update_scratch_[end].chunk_pos == cp) ++end;
    auto it = chunks_.find(cp);
    if (it == chunks_.end() || it->second.coverage.state == CoverageState::kMip) {
      begin = end;
      continue;
    }
    units.clear();
    for (std::size_t i = begin; i < end; ++i) {
      units.add(update_scratch_[i]);  // (a unit twice: the last one wins)
      ++applied;
    }
    const Vec3i origin = chunk_origin(cp);
    const Region box{origin + units.box().min, origin + units.box().max};
    if (changed != nullptr) changed->push_back(box);
    entry_changed(cp, it->second);
    grid_.modify(box, [&](Vec3i p, Voxel old) { return units.at(p - origin, old); });
    // The chunk's mips stay as plain boxes (Chunk::pack_mips) while updates
    // keep coming: encoding them for every batch would cost a bot more than
    // the update itself; the replica holds full resolution only near it.
    begin = end;
  }
  for (const auto& r : m.revisions) {
    auto it = chunks_.find(r.chunk_pos);
    if (it == chunks_.end() || it->second.coverage.state == CoverageState::kMip) continue;
    it->second.coverage = ChunkCoverage{CoverageState::kFull, 0, r.revision};
    entry_changed(r.chunk_pos, it->second);
  }
  return applied;
}

const ChunkCoverage* Replica::coverage(Vec3i cp) const {
  auto it = chunks_.find(cp);
  if (it != chunks_.end()) return &it->second.coverage;
  const Horizon* h = horizon_of(cp);
  return h == nullptr ? nullptr : &h->coverage;
}

int Replica::resolution_at(Vec3i voxel) const {
  const ChunkCoverage* c = coverage(chunk_of(voxel));
  if (c == nullptr) return kNoResolution;
  return c->state == CoverageState::kMip ? c->level : 0;
}

Voxel Replica::get(Vec3i voxel) const {
  const Vec3i cp = chunk_of(voxel);
  const ChunkCoverage* c = coverage(cp);
  if (c == nullptr || c->state == CoverageState::kEmpty) return Voxel{};
  if (c->state == CoverageState::kFull) return grid_.get(voxel);
  const MipView m = mip_view(cp);
  if (m.box == nullptr) return Voxel{};
  const Vec3i l = local_of(voxel);
  return m.box->get(m.origin + Vec3i{l.x >> m.level, l.y >> m.level, l.z >> m.level});
}

void Replica::read_box(Vec3i min, Box& out) const { grid_.read_box(min, out); }

std::optional<RayHit> Replica::raycast(Vec3f origin, Vec3f direction, float max_distance) const {
  return grid_.raycast(origin, direction, max_distance);
}

std::optional<std::int32_t> Replica::surface_height(std::int32_t x, std::int32_t z, std::int32_t min_y,
                                                    std::int32_t max_y) const {
  // A chunk at a time: one lookup of its coverage and of its voxels (full
  // or mip), then its part of the column from the top.
  for (std::int32_t y = max_y - 1; y >= min_y;) {
    const Vec3i cp = chunk_of(Vec3i{x, y, z});
    const std::int32_t bottom = std::max(min_y, cp.y * kChunkSize);
    const ChunkCoverage* c = coverage(cp);
    const Vec3i l = local_of(Vec3i{x, y, z});
    if (c != nullptr && c->state == CoverageState::kFull) {
      if (const Chunk* chunk = grid_.find_chunk(cp); chunk != nullptr)
        for (std::int32_t v = y; v >= bottom; --v)
          if (chunk->get(l.x, v - cp.y * kChunkSize, l.z).material != kAir) return v + 1;
    } else if (c != nullptr && c->state == CoverageState::kMip) {
      if (const MipView m = mip_view(cp); m.box != nullptr) {
        const int s = m.level;
        for (std::int32_t v = y; v >= bottom; --v)
          if (m.box->get(m.origin + Vec3i{l.x >> s, (v - cp.y * kChunkSize) >> s, l.z >> s}).material != kAir)
            return v + 1;
      }
    }
    // Nothing (known) in the rest of this chunk's column.
    y = bottom - 1;
  }
  return std::nullopt;
}

std::optional<std::uint64_t> Replica::hash(Vec3i cp) const {
  // Only a chunk's own coverage can be Full or Empty (a horizon's is a mip).
  auto it = chunks_.find(cp);
  if (it == chunks_.end() || it->second.coverage.state == CoverageState::kMip) return std::nullopt;
  const Entry& e = it->second;
  if (!e.hash)
    e.hash = region_hash(e.coverage.state == CoverageState::kFull ? grid_.find_chunk(cp) : nullptr, e.coverage.revision);
  return e.hash;
}

std::optional<std::uint64_t> Replica::revision(Vec3i cp) const {
  const ChunkCoverage* c = coverage(cp);
  if (c == nullptr) return std::nullopt;
  return c->revision;
}

std::size_t Replica::estimate_count() const {
  return static_cast<std::size_t>(
      std::count_if(chunks_.begin(), chunks_.end(), [](const auto& kv) { return kv.second.coverage.estimate; }));
}

std::size_t Replica::chunk_count(CoverageState state) const {
  return static_cast<std::size_t>(
             std::count_if(chunks_.begin(), chunks_.end(),
                           [&](const auto& kv) { return kv.second.coverage.state == state; })) +
         (state == CoverageState::kMip ? horizon_chunks_ : 0);
}

}  // namespace terrane
