// Edit requests: queueing, applying at the tick, persisting, acknowledging
// and broadcasting the changed units (see server/server.h, "Tick").
#include "server/edits.h"

#include <array>
#include <cmath>

#include "common/byte_rle.h"

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

namespace {

float sphere_fraction(const EditRequestMsg& e, Vec3i p) {
  const float dx = static_cast<float>(p.x) + 0.5f - e.center.x;
  const float dy = static_cast<float>(p.y) + 0.5f - e.center.y;
  const float dz = static_cast<float>(p.z) + 0.5f - e.center.z;
  return std::clamp(e.radius + 0.5f - std::sqrt(dx * dx + dy * dy + dz * dz), 0.0f, 1.0f);
}

Voxel dig(Voxel old, float f) {
  const float left = std::min(occupancy_fraction(old), 1.0f - f);
  return left < 0.5f / 256.0f ? Voxel{} : make_voxel(old.material, occupancy_byte(left));
}

Voxel fill(Voxel old, float f, Material m) {
  const float had = old.material == m ? occupancy_fraction(old) : 0.0f;
  if (f > had && (old.material == kAir || old.material == m || f >= occupancy_fraction(old)))
    return make_voxel(m, occupancy_byte(f));
  return old;
}

// The smoothing filter of one voxel, reading the pre-edit snapshot src
// (whose origin is origin).
Voxel smooth(const Box& src, Vec3i origin, Vec3i p, float s) {
  const Vec3i l = p - origin;
  const Voxel old = src.get(l.x, l.y, l.z);
  float sum = 0;
  std::array<int, kMaterialCount> votes{};
  for (int dy = -1; dy <= 1; ++dy)
    for (int dz = -1; dz <= 1; ++dz)
      for (int dx = -1; dx <= 1; ++dx) {
        const Voxel n = src.get(l.x + dx, l.y + dy, l.z + dz);
        sum += occupancy_fraction(n);
        if (n.material != kAir) ++votes[n.material];
      }
  const float o = occupancy_fraction(old);
  const float next = o + s * (sum / 27.0f - o);
  if (next < 0.5f / 256.0f) return Voxel{};
  Material m = old.material;
  if (m == kAir) {
    int best = 0;
    for (std::size_t i = 1; i < votes.size(); ++i)
      if (votes[i] > best) {
        best = votes[i];
        m = static_cast<Material>(i);
      }
    if (m == kAir) return old;
  }
  return make_voxel(m, occupancy_byte(next));
}

}  // namespace

std::size_t apply_edit(Grid& grid, const EditRequestMsg& e, const Region& clip, ChangedUnits& changed) {
  const Region r = intersect(e.bounds(), clip);
  if (r.empty()) return 0;
  UnitMarker marker(changed);
  std::size_t n = 0;
  auto count = [&](Vec3i p, Voxel old, Voxel nv) {
    if (nv != old) {
      marker.mark(p);
      ++n;
    }
    return nv;
  };
  switch (e.kind) {
    case EditKind::kUndo:
    case EditKind::kRedo:
      return 0;  // history steps are applied by the server (apply_history)
    case EditKind::kFillBox: {
      const Voxel v = make_voxel(e.material, e.occupancy);
      grid.modify(r, [&](Vec3i p, Voxel old) { return count(p, old, v); });
      return n;
    }
    case EditKind::kWriteBox: {
      const Vec3i size = e.box.size();
      grid.modify(r, [&](Vec3i p, Voxel old) {
        const Vec3i l = p - e.box.min;
        const Voxel v = e.voxels[static_cast<std::size_t>((l.y * size.z + l.z) * size.x + l.x)];
        return count(p, old, make_voxel(v.material, v.occupancy));
      });
      return n;
    }
    case EditKind::kFillSphere:
    case EditKind::kDig:
      grid.modify(r, [&](Vec3i p, Voxel old) {
        const float f = sphere_fraction(e, p);
        if (f <= 0.0f) return old;
        return count(p, old, e.material == kAir ? dig(old, f) : fill(old, f, e.material));
      });
      return n;
    case EditKind::kPaint:
      grid.modify(r, [&](Vec3i p, Voxel old) {
        if (old.material == kAir || sphere_fraction(e, p) < 0.5f) return old;
        return count(p, old, make_voxel(e.material, old.occupancy));
      });
      return n;
    case EditKind::kSmooth: {
      // Snapshot first: the filter reads the pre-edit state only.
      const Region reads = {r.min - Vec3i{1, 1, 1}, r.max + Vec3i{1, 1, 1}};
      Box src(reads.size());
      grid.read_box(reads.min, src);
      const float strength = static_cast<float>(e.occupancy) / 255.0f;
      grid.modify(r, [&](Vec3i p, Voxel old) {
        const float f = sphere_fraction(e, p);
        if (f <= 0.0f) return old;
        return count(p, old, smooth(src, reads.min, p, strength * f));
      });
      return n;
    }
  }
  return n;
}

double total_occupancy(const Grid& grid, const Region& region) {
  double sum = 0;
  for (int y = region.min.y; y < region.max.y; ++y)
    for (int z = region.min.z; z < region.max.z; ++z)
      for (int x = region.min.x; x < region.max.x; ++x) sum += occupancy_fraction(grid.get({x, y, z}));
  return sum;
}

bool Server::holds_full(const Peer& peer, const Region& region) const {
  bool ok = true;
  for_each_chunk_in(region, [&](Vec3i cp) {
    if (!ok) return;
    auto it = peer.held.find(cp);
    ok = it != peer.held.end() && it->second.kind != HeldKind::kMip;
  });
  return ok;
}

void Server::reject_edit(Peer& peer, const EditRequestMsg& edit, const std::string& reason) {
  counters_.edits_rejected.fetch_add(1, std::memory_order_relaxed);
  // The true state of what the edit would have touched, when it is at hand:
  // on the data queue, after every update already queued, so it is the
  // state the client's replica reaches once it has read that far.
  const Region r = world_->meta().bounds.clamp(edit.bounds());
  bool loaded = !r.empty() && r.volume() <= kMaxEditVolume;
  if (loaded) for_each_chunk_in(r, [&](Vec3i cp) { loaded = loaded && cache_->loaded(cp); });
  if (!loaded) {
    peer.session->send(build_edit_reject(edit.edit_id, reason), SendClass::kControl);
    return;
  }
  Box box(r.size());
  cache_->grid().read_box(r.min, box);
  peer.session->send(build_edit_reject(edit.edit_id, reason, r, box.voxels()));
}

void Server::on_edit(Peer& peer, EditRequestMsg edit) {
  const bool history = is_history_edit(edit.kind);
  if (!peer.edit_rate.take(1)) {
    counters_.limit_violations.fetch_add(1, std::memory_order_relaxed);
    violations().warn("session " + std::to_string(peer.session->id()) + " (" + peer.name + "): edit flood; dropping");
    peer.session->close("edit rate limit: more than " +
                        std::to_string(static_cast<long long>(options_.edits_per_second)) + " edits/s");
    return;
  }
  if (history) {
    // Checked when applied, against the history as it is then.
    if (peer.edits_queued >= options_.max_edits_queued_per_client) return reject_edit(peer, edit, "too many edits queued");
    ++peer.edits_queued;
    edits_.push_back(PendingEdit{peer.session->id(), std::move(edit)});
    return;
  }
  if (edit.bounds().volume() > options_.max_edit_voxels)
    return reject_edit(peer, edit, "edit larger than " + std::to_string(options_.max_edit_voxels) + " voxels");
  if (peer.edits_queued >= options_.max_edits_queued_per_client) return reject_edit(peer, edit, "too many edits queued");
  const Region r = world_->meta().bounds.clamp(edit.reads());
  if (r.empty()) return reject_edit(peer, edit, "edit outside the world");
  // Edits are valid only where the client holds the world at full
  // resolution: it can see what it changes, and the server only ever has
  // to load chunks that are already loaded for it.
  if (!holds_full(peer, r)) return reject_edit(peer, edit, "edit outside the full-resolution region");
  ++peer.edits_queued;
  for_each_chunk_in(r, [&](Vec3i cp) { cache_->request(cp); });
  edits_.push_back(PendingEdit{peer.session->id(), std::move(edit)});
}

std::vector<std::uint8_t> Server::snapshot(const Region& box) {
  Box b(box.size());
  cache_->grid().read_box(box.min, b);
  std::vector<std::uint8_t> out;
  byte_rle_encode(b.voxels(), out);
  return out;
}

void Server::push_history(Peer& peer, std::deque<HistoryEntry>& to, HistoryEntry e) {
  peer.history_bytes += e.bytes();
  to.push_back(std::move(e));
  // Over the budget: forget the oldest steps, undo history first.
  while (peer.history_bytes > options_.history_bytes_per_client && !(peer.undo.empty() && peer.redo.empty())) {
    auto& from = !peer.undo.empty() ? peer.undo : peer.redo;
    peer.history_bytes -= from.front().bytes();
    from.pop_front();
  }
}

bool Server::apply_history(Peer& peer, bool redo, ChangedUnits& changed, std::string* why) {
  auto& from = redo ? peer.redo : peer.undo;
  auto& to = redo ? peer.undo : peer.redo;
  if (from.empty()) {
    *why = redo ? "nothing to redo" : "nothing to undo";
    return false;
  }
  HistoryEntry e = std::move(from.back());
  from.pop_back();
  peer.history_bytes -= e.bytes();
  if (!holds_full(peer, world_->meta().bounds.clamp(e.box))) {
    *why = std::string(redo ? "redo" : "undo") + " outside the full-resolution region";
    return false;  // the step is dropped: its box may be stale by the time the client is back
  }
  const auto n = static_cast<std::size_t>(e.box.volume());
  std::vector<Voxel> before(n), after(n);
  if (!byte_rle_decode(e.before, before) || !byte_rle_decode(e.after, after)) {
    *why = "history damaged";  // our own bytes: cannot happen
    return false;
  }
  // Restore only voxels still as this client left them: where another
  // client has since changed a voxel, its change stands.
  HistoryEntry back{e.box, snapshot(e.box), {}};
  const Vec3i size = e.box.size();
  UnitMarker marker(changed);
  cache_->grid().modify(e.box, [&](Vec3i p, Voxel cur) {
    const Vec3i l = p - e.box.min;
    const auto i = static_cast<std::size_t>((l.y * size.z + l.z) * size.x + l.x);
    if (cur != after[i] || before[i] == cur) return cur;
    marker.mark(p);
    return before[i];
  });
  back.after = snapshot(e.box);
  push_history(peer, to, std::move(back));
  return true;
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
    const Region r = bounds.clamp(pe.edit.reads());
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
    auto peer_it = peers_.find(pe.peer_id);
    Peer* peer = peer_it != peers_.end() ? &peer_it->second : nullptr;
    if (peer != nullptr && peer->edits_queued > 0) --peer->edits_queued;
    if (is_history_edit(pe.edit.kind)) {
      std::string why = "client gone";
      if (peer != nullptr && apply_history(*peer, pe.edit.kind == EditKind::kRedo, changed, &why)) {
        acks.push_back(Ack{pe.peer_id, pe.edit.edit_id});
      } else if (peer != nullptr) {
        counters_.edits_rejected.fetch_add(1, std::memory_order_relaxed);
        peer->session->send(build_edit_reject(pe.edit.edit_id, why), SendClass::kControl);
      }
      edits_.pop_front();
      continue;
    }
    const Region box = bounds.clamp(pe.edit.bounds());
    HistoryEntry entry;
    if (peer != nullptr) entry = HistoryEntry{box, snapshot(box), {}};
    apply_edit(cache_->grid(), pe.edit, box, changed);
    if (peer != nullptr) {
      entry.after = snapshot(box);
      push_history(*peer, peer->undo, std::move(entry));
      for (const HistoryEntry& e : peer->redo) peer->history_bytes -= e.bytes();
      peer->redo.clear();  // a new edit forks the history
    }
    acks.push_back(Ack{pe.peer_id, pe.edit.edit_id});
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
    if (auto st = world_->store().save_chunks(writes); !st) {
      // Nothing of this tick may be acknowledged or shown: it is not on
      // disk. The in-memory world is now ahead of the store, so the server
      // stops rather than serve state it could lose.
      server_log().critical("tick {}: saving {} chunks failed: {}; rejecting the tick's edits and stopping", tick_,
                            writes.size(), st.error().message);
      for (const Ack& a : acks)
        if (auto it = peers_.find(a.peer_id); it != peers_.end())
          it->second.session->send(build_edit_reject(a.edit_id, "storage failure: edit not saved"), SendClass::kControl);
      counters_.edits_rejected.fetch_add(acks.size(), std::memory_order_relaxed);
      storage_failed_ = true;
      storage_failed_flag_ = true;
      for (auto& [id, peer] : peers_) peer.session->close("server storage failure");
      stopping_ = true;
      if (options_.on_fatal) options_.on_fatal();
      return;
    }
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
      if (!mip) {
        const EncodedChunk& e = encoded(cp, level);
        mip = std::make_shared<const Frame>(build_mip_data(cp, level, e.revision, e.payload));
      }
      peer.session->send(mip);
      held = Held{HeldKind::kMip, level, rev};
      // A chunk that went from empty to a mip may need refining again.
      peer.refine = 0;
    }
  }
}

}  // namespace terrane
