#include "client/replica.h"

#include "common/codec/chunk_units.h"

#include <algorithm>
#include <array>
#include <bit>

#include "common/codec/net_codec.h"

namespace terrane {

namespace {
// Units decoded from one UpdateBatch at most: 16 chunks' worth. The server
// sends one chunk per batch; the cap bounds the scratch buffer (~1 MiB).
constexpr std::size_t kMaxBatchUnits = 16 * kUpdateUnitsPerChunk;
// The units of the batch being applied: one buffer per thread, not per
// replica (a process of many clients applies batches on a few threads,
// and a buffer grown by one large batch stayed with its replica).
thread_local std::vector<UnitUpdate> update_scratch;

// The last mip decoded on this thread and its voxels: a replica's reads
// of a mip come in runs over one chunk (surface_height, a viewer's or a
// script's reads). Known by its owner (a weak handle: the mip is not kept
// alive, and no other can take its identity while the handle lives).
struct LastDecoded {
  std::weak_ptr<const MipVoxels> mip;
  Box voxels;
};
thread_local LastDecoded last_decoded;

const Box& voxels_of_mip(const std::shared_ptr<const MipVoxels>& mip) {
  if (const Box* box = mip->box()) return *box;
  const bool same = !last_decoded.mip.owner_before(mip) && !mip.owner_before(last_decoded.mip);
  if (!same || last_decoded.mip.expired()) {
    mip->read(last_decoded.voxels);
    last_decoded.mip = mip;
  }
  return last_decoded.voxels;
}

// Whether a mip record brings the very voxels of the mip held: the mip the
// process found its bytes to be (r.known: no voxels decoded), its bytes, or
// its voxels.
bool same_mip(const std::shared_ptr<const MipVoxels>& held, const StreamRecord& r) {
  if (held.get() == r.known.get()) return true;
  if (held->encoded() && !r.payload.empty() && std::ranges::equal(held->unit(), r.payload)) return true;
  if (r.known || held->side() != r.voxels->size().x) return false;
  return voxels_of_mip(held) == *r.voxels;
}
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
      voxels_changed(cp);
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
      if (!shared_) {
        grid_.put_chunk(cp, Chunk::from_box(voxels_of(r), full_mips_));  // (an empty chunk is erased)
      } else {
        // The process's chunk of these bytes, held as it is until an update
        // changes it here (the grid then writes a copy of its own); known
        // before the bytes were decoded, or found by them.
        std::shared_ptr<const Chunk> chunk = std::static_pointer_cast<const Chunk>(r.known);
        if (!chunk) chunk = shared_->find(r.payload);
        if (!chunk) {
          chunk = std::make_shared<const Chunk>(Chunk::from_box(voxels_of(r), full_mips_));
          shared_->add(r.payload, chunk);
        }
        grid_.put_shared_chunk(cp, std::move(chunk));
      }
      Entry& e = chunks_[cp];
      e.mip.reset();
      e.holding = Holding{HoldingForm::kFull, r.revision};
      voxels_changed(cp);
      return;
    }
    case StreamRecordKind::kMipPatch: {
      // The held mip with the record's sub-units replaced (a patch of a
      // chunk not held as that mip is refused before it gets here:
      // patchable()).
      Entry* e = chunks_.find(cp);
      if (e == nullptr || !patchable(r) || !e->mip) return;
      thread_local Box patched;
      patched = voxels_of_mip(e->mip);
      for (std::uint64_t rest = r.patch_mask; rest != 0; rest &= rest - 1) {
        const Vec3i o = patch_subunit_origin(r.level, std::countr_zero(rest));
        for (int y = o.y; y < o.y + 4; ++y)
          for (int z = o.z; z < o.z + 4; ++z) std::copy_n(r.voxels->read_row(y, z) + o.x, 4, patched.write_row(y, z) + o.x);
      }
      e->mip = keep_mip(patched);
      e->holding.revision = r.revision;
      voxels_changed(cp);
      return;
    }
    case StreamRecordKind::kMip1:
    case StreamRecordKind::kMip2:
    case StreamRecordKind::kMip3:
    case StreamRecordKind::kEstimate: {
      Entry& e = chunks_[cp];
      if (e.holding.form == r.form() && e.mip && same_mip(e.mip, r))
        ++redundant_mips_;  // (the mip held stays)
      else if (r.known)  // the process's mip of these very bytes (DecodedMips::known_unit)
        e.mip = std::static_pointer_cast<const MipVoxels>(r.known);
      else
        e.mip = keep_unit(r);
      e.holding = Holding{r.form(), r.revision};
      grid_.erase_chunk(cp);
      voxels_changed(cp);
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
  // Level 6 is held as Horizon 5: each chunk's voxel its block's.
  const Box upsampled = r.level == kHorizonOuterLevel ? horizon_upsample(*r.voxels) : Box{};
  const Box& held = r.level == kHorizonOuterLevel ? upsampled : *r.voxels;
  h.image = keep(DecodedMips::key_of(held), held);
  for_each_region_chunk(region, [&](Vec3i cp) {
    const int i = coarse_index(cp);
    if (!horizon_mask_has(*r.mask, i) || h.covers.test(static_cast<std::size_t>(i)) ||
        chunks_.find(cp) != nullptr)
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

const Box& Replica::voxels_of(const StreamRecord& r) {
  thread_local StreamDecodeScratch scratch;
  return record_voxels(r, scratch);
}

bool Replica::patchable(const StreamRecord& r) const {
  const Entry* e = chunks_.find(r.chunk_pos);
  return e != nullptr && e->mip && e->holding.form == mip_form(r.level);
}

std::shared_ptr<const Box> Replica::keep(std::size_t key, const Box& voxels) {
  if (shared_) return shared_->mips().intern(key, voxels);
  return std::make_shared<const Box>(voxels);
}

std::shared_ptr<const MipVoxels> Replica::keep_unit(const StreamRecord& r) {
  std::span<const std::uint8_t> bytes = r.payload;
  thread_local std::vector<std::uint8_t> encoded;
  if (bytes.empty()) {
    encoded.clear();
    net_codec_encode(r.voxels->size().x, r.voxels->voxels(), encoded);
    bytes = encoded;
  }
  const int side = r.voxels->size().x;
  if (shared_) return shared_->mips().intern_unit(DecodedMips::key_of(bytes, r.level), side, bytes);
  return std::make_shared<const MipVoxels>(MipVoxels::of_unit(side, bytes));
}

std::shared_ptr<const MipVoxels> Replica::keep_mip(const Box& voxels) {
  if (shared_) return shared_->mips().intern_mip_box(DecodedMips::key_of(voxels), voxels);
  return std::make_shared<const MipVoxels>(MipVoxels::of_box(voxels));
}

Replica::MipView Replica::mip_view(Vec3i cp) const {
  if (const Entry* e = chunks_.find(cp)) {
    if (e->holding.full_resolution() || !e->mip) return MipView{};
    return MipView{&voxels_of_mip(e->mip), {0, 0, 0}, e->holding.level()};
  }
  if (const Horizon* h = horizon_of(cp))
    return MipView{h->image.get(), floor_mod(cp, kHorizonRegionChunks) * (kChunkSize >> h->holding.level()),
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

std::optional<Holding> Replica::exact_payload(Vec3i cp, std::vector<std::uint8_t>& out) const {
  const Entry* e = chunks_.find(cp);
  if (e == nullptr || !claimable(e->holding.form)) return std::nullopt;
  switch (e->holding.form) {
    case HoldingForm::kEmpty: break;
    case HoldingForm::kFull: {
      encode_full_units(grid_.find_chunk(cp), out);  // none: all Air
      break;
    }
    default: {
      if (!e->mip) return std::nullopt;
      if (e->mip->encoded()) {
        out.insert(out.end(), e->mip->unit().begin(), e->mip->unit().end());
      } else {
        const Box& v = *e->mip->box();
        net_codec_encode(v.size().x, v.voxels(), out);
      }
    }
  }
  return e->holding;
}

Result<std::size_t> Replica::apply_update_batch(const UpdateBatchMsg& m, std::vector<Region>* changed,
                                                VoxelChanges* voxels) {
  const std::size_t cap = std::min(kMaxBatchUnits, m.revisions.size() * kUpdateUnitsPerChunk);
  std::vector<UnitUpdate>& units_in = update_scratch;
  units_in.resize(cap);
  auto n = net_codec_decode_update_batch(m.data, units_in);
  if (!n) return n.error();
  // Check every unit belongs to a listed chunk before changing anything.
  for (std::size_t i = 0; i < *n; ++i) {
    const Vec3i cp = units_in[i].chunk_pos;
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
    const Vec3i cp = units_in[begin].chunk_pos;
    std::size_t end = begin;
    while (end < *n && units_in[end].chunk_pos == cp) ++end;
    Entry* e = chunks_.find(cp);
    if (e == nullptr || !e->holding.full_resolution()) {
      begin = end;
      continue;
    }
    units.clear();
    for (std::size_t i = begin; i < end; ++i) {
      units.add(units_in[i]);  // (a unit twice: the last one wins)
      ++applied;
    }
    const Vec3i origin = chunk_origin(cp);
    const Region box{origin + units.box().min, origin + units.box().max};
    if (changed != nullptr) changed->push_back(box);
    voxels_changed(cp);
    // A chunk held shared: the process's other replicas that held this very
    // chunk and were sent these units may have made the result already
    // (client/shared_updates.h); else it is made here and offered to them.
    // Not while voxels are recorded: their old values are read as written.
    const std::span<const UnitUpdate> chunk_units(units_in.data() + begin, end - begin);
    std::shared_ptr<const Chunk> base = shared_ && voxels == nullptr ? grid_.shared_chunk(cp) : nullptr;
    const std::size_t key = base ? SharedUpdates::key_of(base.get(), chunk_units) : 0;
    // Twins are kept by position and revision (a Full record of the chunk
    // taken later, or another lineage's result): base's is the revision
    // held now, the result's the one this batch lists.
    if (base) {
      if (std::shared_ptr<const Chunk> made =
              shared_->updates().find(key, base, chunk_units, SharedUpdates::At{cp, e->holding.revision})) {
        grid_.put_shared_chunk(cp, std::move(made));
        begin = end;
        continue;
      }
    }
    if (voxels == nullptr) {
      grid_.modify(box, [&](Vec3i p, Voxel old) { return units.at(p - origin, old); });
    } else {
      grid_.modify(box, [&](Vec3i p, Voxel old) {
        const Voxel now = units.at(p - origin, old);
        if (now != old) {
          if (voxels->changes.size() < voxels->max)
            voxels->changes.push_back(VoxelChange{p, old, now});
          else
            voxels->truncated = true;
        }
        return now;
      });
    }
    if (base) {
      const auto listed = std::find_if(m.revisions.begin(), m.revisions.end(),
                                       [&](const ChunkRevisionMsg& r) { return r.chunk_pos == cp; });
      std::shared_ptr<const Chunk> made = grid_.share_chunk(cp);
      std::shared_ptr<const Chunk> hold =
          shared_->updates().add(key, base, chunk_units, made, SharedUpdates::At{cp, listed->revision});
      if (hold != made) grid_.put_shared_chunk(cp, std::move(hold));  // another replica's, equal: one lineage
    }
    // The chunk's mips stay as plain boxes (Chunk::pack_mips) while updates
    // keep coming: encoding them for every batch would cost a bot more than
    // the update itself; the replica holds full resolution only near it.
    begin = end;
  }
  for (const auto& r : m.revisions) {
    Entry* e = chunks_.find(r.chunk_pos);
    if (e == nullptr || !e->holding.full_resolution()) continue;
    e->holding = Holding{HoldingForm::kFull, r.revision};
    voxels_changed(r.chunk_pos);
  }
  return applied;
}

const Holding* Replica::holding(Vec3i cp) const {
  if (const Entry* e = chunks_.find(cp)) return &e->holding;
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
  const Entry* found = chunks_.find(cp);
  if (found == nullptr || !found->holding.full_resolution()) return std::nullopt;
  const Entry& e = *found;
  if (e.holding.form != HoldingForm::kFull) return chunk_hash(nullptr, e.holding.revision);
  if (const auto it = hashes_.find(cp); it != hashes_.end()) return it->second;
  // A chunk held shared has its hash made once for the process's replicas.
  const std::shared_ptr<const Chunk> shared = shared_ ? grid_.shared_chunk(cp) : nullptr;
  const std::uint64_t h =
      shared ? shared_->hash_of(shared, e.holding.revision) : chunk_hash(grid_.find_chunk(cp), e.holding.revision);
  hashes_.try_emplace(cp, h);
  return h;
}

std::optional<std::uint64_t> Replica::revision(Vec3i cp) const {
  const Holding* c = holding(cp);
  if (c == nullptr) return std::nullopt;
  return c->revision;
}

std::size_t Replica::estimate_count() const {
  return chunk_count(HoldingForm::kEstimate);
}

std::size_t Replica::chunk_count(HoldingForm form) const {
  if (form == HoldingForm::kHorizon4 || form == HoldingForm::kHorizon5) {
    std::size_t n = 0;
    for (const auto& [region, h] : horizons_)
      if (h.holding.form == form) n += h.covers.count();
    return n;
  }
  std::size_t n = 0;
  chunks_.for_each([&](Vec3i, const Entry& e) { n += e.holding.form == form ? 1 : 0; });
  return n;
}

ReplicaMemory& ReplicaMemory::operator+=(const ReplicaMemory& o) {
  full.chunks += o.full.chunks;
  full.map_bytes += o.full.map_bytes;
  full.object_bytes += o.full.object_bytes;
  full.level0_bytes += o.full.level0_bytes;
  full.mip_bytes += o.full.mip_bytes;
  full.level0_rows += o.full.level0_rows;
  entry_table_bytes += o.entry_table_bytes;
  mips += o.mips;
  mip_bytes += o.mip_bytes;
  horizon_table_bytes += o.horizon_table_bytes;
  horizon_image_bytes += o.horizon_image_bytes;
  return *this;
}

namespace {
// An object's heap bytes (with its shared_ptr control block) over its holders.
std::size_t shared_bytes(std::size_t bytes, long holders) {
  return (bytes + 2 * sizeof(long)) / static_cast<std::size_t>(std::max(1L, holders));
}
std::size_t shared_bytes(const Box& box, long holders) {
  return shared_bytes(sizeof(Box) + box.voxel_count() * sizeof(Voxel), holders);
}
}  // namespace

ReplicaMemory Replica::memory() const {
  ReplicaMemory m;
  m.full = grid_.memory();
  m.entry_table_bytes = chunks_.heap_bytes() + hashes_.table_bytes();
  chunks_.for_each([&](Vec3i, const Entry& e) {
    if (!e.mip) return;
    ++m.mips;
    m.mip_bytes += shared_bytes(e.mip->heap_bytes(), e.mip.use_count());
  });
  m.horizon_table_bytes = horizons_.table_bytes();
  for (const auto& [region, h] : horizons_) m.horizon_image_bytes += shared_bytes(*h.image, h.image.use_count());
  return m;
}

}  // namespace terrane
