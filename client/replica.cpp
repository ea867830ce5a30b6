#include "client/replica.h"

#include <algorithm>
#include <array>

namespace terrane {

namespace {
// Units decoded from one UpdateBatch at most: 16 chunks' worth. The server
// sends one chunk per batch; the cap bounds the scratch buffer (~1 MiB).
constexpr std::size_t kMaxBatchUnits = 16 * kUpdateUnitsPerChunk;
}  // namespace

Replica::Replica() = default;

void Replica::apply_stream_record(const StreamRecord& r) {
  const Vec3i cp = r.chunk_pos;
  switch (r.kind) {
    case StreamRecordKind::kEmpty: {
      grid_.erase_chunk(cp);
      Entry& e = chunks_[cp];
      e.mip.reset();
      e.holding = Holding{HoldingForm::kEmpty, r.revision};
      entry_changed(cp, e);
      return;
    }
    case StreamRecordKind::kReleased:
      grid_.erase_chunk(cp);
      chunks_.erase(cp);
      if (!horizons_.empty()) forget_horizon(cp);
      return;
    case StreamRecordKind::kHorizon: {
      std::vector<Vec3i> covered;
      apply_horizon(r, covered);
      return;
    }
    case StreamRecordKind::kFull: {
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
      e.holding = Holding{HoldingForm::kFull, r.revision};
      entry_changed(cp, e);
      return;
    }
    case StreamRecordKind::kMip1:
    case StreamRecordKind::kMip2:
    case StreamRecordKind::kMip3:
    case StreamRecordKind::kEstimate: {
      // A refresh of a mip held overwrites it in place (no new allocation).
      Entry& e = chunks_[cp];
      if (e.holding.form == r.form() && e.mip && *e.mip == *r.voxels) ++redundant_mips_;
      if (e.mip)
        *e.mip = *r.voxels;
      else
        e.mip = std::make_unique<Box>(*r.voxels);
      e.holding = Holding{r.form(), r.revision};
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
  h.holding = Holding{horizon_form(r.level), 0};
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
    return it->second.holding.full_resolution()
               ? MipView{}
               : MipView{it->second.mip.get(), {0, 0, 0}, it->second.holding.level()};
  if (const Horizon* h = horizon_of(cp))
    return MipView{&h->image, floor_mod(cp, kHorizonRegionChunks) * (kChunkSize >> h->holding.level()),
                   h->holding.level()};
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
    if (it == chunks_.end() || !it->second.holding.full_resolution()) {
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
    if (it == chunks_.end() || !it->second.holding.full_resolution()) continue;
    it->second.holding = Holding{HoldingForm::kFull, r.revision};
    entry_changed(r.chunk_pos, it->second);
  }
  return applied;
}

const Holding* Replica::holding(Vec3i cp) const {
  auto it = chunks_.find(cp);
  if (it != chunks_.end()) return &it->second.holding;
  const Horizon* h = horizon_of(cp);
  return h == nullptr ? nullptr : &h->holding;
}

int Replica::resolution_at(Vec3i voxel) const {
  const Holding* c = holding(chunk_of(voxel));
  if (c == nullptr) return kNoResolution;
  return c->level();
}

Voxel Replica::get(Vec3i voxel) const {
  const Vec3i cp = chunk_of(voxel);
  const Holding* c = holding(cp);
  if (c == nullptr || c->form == HoldingForm::kEmpty) return Voxel{};
  if (c->form == HoldingForm::kFull) return grid_.get(voxel);
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
  // A chunk at a time: one lookup of its holding and of its voxels (full
  // or mip), then its part of the column from the top.
  for (std::int32_t y = max_y - 1; y >= min_y;) {
    const Vec3i cp = chunk_of(Vec3i{x, y, z});
    const std::int32_t bottom = std::max(min_y, cp.y * kChunkSize);
    const Holding* c = holding(cp);
    const Vec3i l = local_of(Vec3i{x, y, z});
    if (c != nullptr && c->form == HoldingForm::kFull) {
      if (const Chunk* chunk = grid_.find_chunk(cp); chunk != nullptr)
        for (std::int32_t v = y; v >= bottom; --v)
          if (chunk->get(l.x, v - cp.y * kChunkSize, l.z).material != kAir) return v + 1;
    } else if (c != nullptr && !c->full_resolution()) {
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
  // Only a chunk's own record can make it Full or Empty.
  auto it = chunks_.find(cp);
  if (it == chunks_.end() || !it->second.holding.full_resolution()) return std::nullopt;
  const Entry& e = it->second;
  if (!e.hash)
    e.hash = chunk_hash(e.holding.form == HoldingForm::kFull ? grid_.find_chunk(cp) : nullptr, e.holding.revision);
  return e.hash;
}

std::optional<std::uint64_t> Replica::revision(Vec3i cp) const {
  const Holding* c = holding(cp);
  if (c == nullptr) return std::nullopt;
  return c->revision;
}

std::size_t Replica::estimate_count() const {
  return static_cast<std::size_t>(
      std::count_if(chunks_.begin(), chunks_.end(),
                    [](const auto& kv) { return kv.second.holding.form == HoldingForm::kEstimate; }));
}

std::size_t Replica::chunk_count(HoldingForm form) const {
  if (form == HoldingForm::kHorizon4 || form == HoldingForm::kHorizon5) {
    std::size_t n = 0;
    for (const auto& [region, h] : horizons_)
      if (h.holding.form == form) n += h.covers.count();
    return n;
  }
  return static_cast<std::size_t>(
      std::count_if(chunks_.begin(), chunks_.end(), [&](const auto& kv) { return kv.second.holding.form == form; }));
}

}  // namespace terrane
