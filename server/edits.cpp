// Edit requests: queueing, applying at the tick, persisting, acknowledging
// and broadcasting the changed units (see server/server.h, "Tick").
#include "server/edits.h"

#include <cmath>

#include "server/log.h"
#include "server/server.h"

namespace terrane {

namespace {

// Edits applied per tick at most: bounds the owner strand's tick time
// (each edit touches at most kMaxEditVolume voxels).
constexpr std::size_t kMaxEditsPerTick = 256;

class UnitMarker {
 public:
  explicit UnitMarker(ChangedUnits& changed) : changed_(changed) {}
  void mark(Vec3i p) {
    const Vec3i cp = chunk_of(p);
    if (bits_ == nullptr || cp != last_) {
      bits_ = &changed_[cp];
      last_ = cp;
    }
    const Vec3i l = local_of(p);
    bits_->set(static_cast<std::size_t>(((l.y / 4) * 8 + l.z / 4) * 8 + l.x / 4));
  }

 private:
  ChangedUnits& changed_;
  std::bitset<kUpdateUnitsPerChunk>* bits_ = nullptr;
  Vec3i last_;
};

}  // namespace

std::size_t apply_edit(Grid& grid, const EditRequestMsg& e, const Region& clip, ChangedUnits& changed) {
  const Region r = intersect(e.bounds(), clip);
  if (r.empty()) return 0;
  UnitMarker marker(changed);
  std::size_t n = 0;
  if (e.kind == EditKind::kFillBox) {
    const Voxel v = make_voxel(e.material, e.occupancy);
    grid.modify(r, [&](Vec3i p, Voxel old) {
      if (old != v) {
        marker.mark(p);
        ++n;
      }
      return v;
    });
    return n;
  }
  grid.modify(r, [&](Vec3i p, Voxel old) {
    const float dx = static_cast<float>(p.x) + 0.5f - e.center.x;
    const float dy = static_cast<float>(p.y) + 0.5f - e.center.y;
    const float dz = static_cast<float>(p.z) + 0.5f - e.center.z;
    const float f = std::clamp(e.radius + 0.5f - std::sqrt(dx * dx + dy * dy + dz * dz), 0.0f, 1.0f);
    if (f <= 0.0f) return old;
    Voxel nv = old;
    if (e.material == kAir) {
      const float left = std::min(occupancy_fraction(old), 1.0f - f);
      nv = left < 0.5f / 256.0f ? Voxel{} : make_voxel(old.material, occupancy_byte(left));
    } else {
      const float had = old.material == e.material ? occupancy_fraction(old) : 0.0f;
      if (f > had && (old.material == kAir || old.material == e.material || f >= occupancy_fraction(old)))
        nv = make_voxel(e.material, occupancy_byte(f));
    }
    if (nv != old) {
      marker.mark(p);
      ++n;
    }
    return nv;
  });
  return n;
}

double total_occupancy(const Grid& grid, const Region& region) {
  double sum = 0;
  for (int y = region.min.y; y < region.max.y; ++y)
    for (int z = region.min.z; z < region.max.z; ++z)
      for (int x = region.min.x; x < region.max.x; ++x) sum += occupancy_fraction(grid.get({x, y, z}));
  return sum;
}

void Server::on_edit(Peer& peer, const EditRequestMsg& edit) {
  if (peer.edits_queued >= options_.max_edits_queued_per_client) {
    counters_.edits_rejected.fetch_add(1, std::memory_order_relaxed);
    peer.session->send(build_edit_reject(edit.edit_id, "too many edits queued"), SendClass::kControl);
    return;
  }
  const Region r = world_->meta().bounds.clamp(edit.bounds());
  if (r.empty()) {
    counters_.edits_rejected.fetch_add(1, std::memory_order_relaxed);
    peer.session->send(build_edit_reject(edit.edit_id, "edit outside the world"), SendClass::kControl);
    return;
  }
  ++peer.edits_queued;
  edits_.push_back(PendingEdit{peer.session->id(), edit});
  for_each_chunk_in(r, [&](Vec3i cp) { cache_->request(cp); });
}

void Server::apply_edits() {
  if (edits_.empty()) return;
  ChangedUnits changed;
  struct Ack {
    std::uint64_t peer_id;
    std::uint32_t edit_id;
  };
  std::vector<Ack> acks;
  const WorldBounds& bounds = world_->meta().bounds;
  while (!edits_.empty() && acks.size() < kMaxEditsPerTick) {
    const PendingEdit& pe = edits_.front();
    const Region r = bounds.clamp(pe.edit.bounds());
    bool ready = true;
    for_each_chunk_in(r, [&](Vec3i cp) { ready = cache_->request(cp) && ready; });
    if (!ready) {
      if (!stopping_) break;  // wait for its chunks (arrival order is kept)
      // Shutting down: chunks still generating will not arrive.
      if (auto it = peers_.find(pe.peer_id); it != peers_.end())
        it->second.session->send(build_edit_reject(pe.edit.edit_id, "server shutting down"), SendClass::kControl);
      edits_.pop_front();
      continue;
    }
    apply_edit(cache_->grid(), pe.edit, r, changed);
    acks.push_back(Ack{pe.peer_id, pe.edit.edit_id});
    if (auto it = peers_.find(pe.peer_id); it != peers_.end() && it->second.edits_queued > 0) --it->second.edits_queued;
    edits_.pop_front();
  }
  counters_.edits_applied.fetch_add(acks.size(), std::memory_order_relaxed);

  // Persist before anyone hears about it.
  std::vector<ChunkWrite> writes;
  writes.reserve(changed.size());
  for (const auto& [cp, bits] : changed) {
    const std::uint64_t rev = cache_->revision(cp) + 1;
    cache_->set_revision(cp, rev);
    const Chunk* c = cache_->chunk(cp);
    writes.push_back(ChunkWrite{cp, rev, c != nullptr ? encode_chunk_blob(*c) : encode_chunk_blob(Chunk())});
  }
  if (!writes.empty()) {
    if (auto st = world_->store().save_chunks(writes); !st)
      server_log().error("tick {}: saving {} chunks failed: {}", tick_, writes.size(), st.error().message);
  }

  for (const Ack& a : acks)
    if (auto it = peers_.find(a.peer_id); it != peers_.end())
      it->second.session->send(build_edit_ack(a.edit_id, tick_), SendClass::kControl);

  // Broadcast: one batch per changed chunk, encoded once.
  std::vector<UnitUpdate> updates;
  std::vector<std::uint8_t> data;
  for (const auto& [cp, bits] : changed) {
    const Chunk* c = cache_->chunk(cp);
    const std::uint64_t rev = cache_->revision(cp);
    updates.clear();
    for (std::size_t i = 0; i < bits.size(); ++i) {
      if (!bits.test(i)) continue;
      UnitUpdate u;
      u.chunk_pos = cp;
      u.unit_index = static_cast<std::uint16_t>(i);
      const Vec3i base{static_cast<int>(i % 8) * 4, static_cast<int>(i / 64) * 4, static_cast<int>((i / 8) % 8) * 4};
      for (int y = 0; y < 4; ++y)
        for (int z = 0; z < 4; ++z)
          for (int x = 0; x < 4; ++x)
            u.voxels[static_cast<std::size_t>((y * 4 + z) * 4 + x)] =
                c != nullptr ? c->get(base + Vec3i{x, y, z}) : Voxel{};
      updates.push_back(u);
    }
    if (updates.empty()) continue;
    data.clear();
    net_codec_encode_update_batch(updates, data);
    const ChunkRevisionMsg revs[1] = {{cp, rev}};
    SharedFrame batch;
    std::array<SharedFrame, kMipLevels> mips{};
    for (auto& [id, peer] : peers_) {
      auto h = peer.held.find(cp);
      if (h == peer.held.end()) continue;
      Held& held = h->second;
      const bool near = desired_level(peer, cp) == 0;
      if (held.kind == HeldKind::kFull || (held.kind == HeldKind::kEmpty && near)) {
        held = Held{HeldKind::kFull, 0, rev};
        if (faults_left_ > 0) {
          --faults_left_;
          counters_.updates_dropped_by_fault.fetch_add(1, std::memory_order_relaxed);
          continue;
        }
        if (corruptions_left_ > 0) {
          --corruptions_left_;
          counters_.updates_corrupted_by_fault.fetch_add(1, std::memory_order_relaxed);
          std::vector<UnitUpdate> bad = updates;
          Voxel& v = bad.front().voxels[0];
          v = v.material == kAir ? solid(materials::kRock) : Voxel{};
          std::vector<std::uint8_t> bad_data;
          net_codec_encode_update_batch(bad, bad_data);
          peer.session->send(build_update_batch(tick_, bad_data, revs));
          continue;
        }
        if (!batch) batch = std::make_shared<const Frame>(build_update_batch(tick_, data, revs));
        peer.session->send(batch);
        counters_.update_batches_sent.fetch_add(1, std::memory_order_relaxed);
        continue;
      }
      const int level = held.kind == HeldKind::kMip ? held.level : kMipLevels - 1;
      if (c == nullptr) {
        peer.session->send(build_coverage(CoverageMsg{cp, wire::CoverageKind::Empty, 0, rev}));
        held = Held{HeldKind::kEmpty, 0, rev};
        continue;
      }
      auto& mip = mips[static_cast<std::size_t>(level)];
      if (!mip) mip = std::make_shared<const Frame>(mip_frame(cp, level));
      peer.session->send(mip);
      held = Held{HeldKind::kMip, level, rev};
      // A chunk that went from empty to a mip may need refining again.
      peer.refine = 0;
    }
  }
}

}  // namespace terrane
