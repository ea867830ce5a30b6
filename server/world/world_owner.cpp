#include "server/world/world_owner.h"

#include <algorithm>
#include <tuple>

#include "common/codec/byte_rle.h"
#include "common/codec/net_codec.h"
#include "common/world/view.h"
#include "server/base/log.h"

namespace terrane {

namespace {

// Edits applied per tick at most: bounds a tick's work on the strand (each
// edit touches at most kMaxEditVolume voxels).
constexpr std::size_t kMaxEditsPerTick = 256;
// Edits set aside to wait, per tick, before the rest wait for the next.
constexpr std::size_t kMaxEditsWaitingPerTick = 1024;

// Whether two n^3 network codec units hold the same voxels (a unit that
// does not decode differs from everything).
bool same_voxels(int n, std::span<const std::uint8_t> a, std::span<const std::uint8_t> b) {
  if (std::equal(a.begin(), a.end(), b.begin(), b.end())) return true;
  const auto count = static_cast<std::size_t>(n) * static_cast<std::size_t>(n) * static_cast<std::size_t>(n);
  std::vector<Voxel> va(count), vb(count);
  return net_codec_decode(n, a, va).ok() && net_codec_decode(n, b, vb).ok() && va == vb;
}

}  // namespace

WorldOwner::WorldOwner(asio::io_context& io, World& world, Storage& storage, const ServerOptions& options,
                       ServerCounters& counters)
    : world_(world),
      storage_(storage),
      options_(options),
      counters_(counters),
      strand_(asio::make_strand(io)),
      tick_timer_(strand_),
      fan_out_(options, counters),
      requests_(strand_, [this](WorldRequest& r) { handle(r); }) {}

void WorldOwner::start() {
  asio::post(strand_, [this] {
    next_tick_ = std::chrono::steady_clock::now();
    arm_tick();
    // Edits forwarded while this server was away.
    if (storage_.leased()) take_inbox();
  });
}

void WorldOwner::stop() {
  std::promise<void> applied;
  auto drained = drained_.get_future();
  asio::post(strand_, [this, &applied] {
    stopping_ = true;
    tick_timer_.cancel();
    // Edits received but not yet applied are applied now so nothing
    // acknowledged-to-be is lost (unless the store already failed).
    if (!storage_failed_) {
      while (!edits_.empty()) {
        const std::size_t before = edits_.size();
        apply_edits();
        if (edits_.size() == before) break;
      }
    }
    fail_rollbacks("the server is stopping");  // any the store's failure left queued
    drain_wanted_ = true;
    if (commits_pending_ == 0) drained_.set_value();
    applied.set_value();
  });
  applied.get_future().wait();
  drained.wait();
}

// --- clients -------------------------------------------------------------------

void WorldOwner::join(ClientId id, std::string name, std::shared_ptr<WorldClient> client) {
  requests_.push(WorldRequest{id, {}, JoinRequest{std::move(name), std::move(client)}});
}

void WorldOwner::leave(ClientId id) { requests_.push(WorldRequest{id, {}, LeaveRequest{}}); }

void WorldOwner::moved(ClientId id, Vec3f position, std::int32_t view_distance, std::int32_t full_res_radius) {
  requests_.push(WorldRequest{id, {}, MovedRequest{position, view_distance, full_res_radius}});
}

void WorldOwner::want(ClientId id, std::vector<ChunkWant> chunks) {
  requests_.push(WorldRequest{id, {}, std::move(chunks)});
}

void WorldOwner::release(ClientId id, std::vector<Vec3i> chunks) {
  requests_.push(WorldRequest{id, {}, std::move(chunks)});
}

void WorldOwner::want_horizon(ClientId id, std::vector<HorizonWant> wants) {
  requests_.push(WorldRequest{id, {}, std::move(wants)});
}

void WorldOwner::holds_full(ClientId id, std::vector<Vec3i> chunks) {
  requests_.push(WorldRequest{id, {}, HoldsFullRequest{std::move(chunks)}});
}

void WorldOwner::handle(WorldRequest& r) {
  std::visit(
      [&](auto& what) {
        using T = std::decay_t<decltype(what)>;
        if constexpr (std::is_same_v<T, std::vector<ChunkWant>>) {
          do_want(r.id, what);
        } else if constexpr (std::is_same_v<T, std::vector<Vec3i>>) {
          fan_out_.release(r.id, what);
        } else if constexpr (std::is_same_v<T, std::vector<HorizonWant>>) {
          do_want_horizon(r.id, what);
        } else if constexpr (std::is_same_v<T, JoinRequest>) {
          editors_.emplace(r.id, Editor{std::move(what.name), 0, History(options_.history_bytes_per_client)});
          fan_out_.join(r.id, std::move(what.link));
        } else if constexpr (std::is_same_v<T, LeaveRequest>) {
          // The replicator released what it held or had asked for just
          // before; after this nothing more is granted to id. Its queued
          // edits stay queued (their acks go nowhere).
          editors_.erase(r.id);
          fan_out_.leave(r.id);
          grants_.erase(r.id);
        } else if constexpr (std::is_same_v<T, HoldsFullRequest>) {
          fan_out_.holds_full(r.id, what.chunks);
        } else {
          fan_out_.moved(r.id, what.position, what.view_distance, what.full_res_radius);
        }
      },
      r.what);
}

void WorldOwner::do_want(ClientId id, const std::vector<ChunkWant>& chunks) {
  if (!fan_out_.present(id)) return;
  // Room for the whole batch at once: grown one grant at a time, the list
  // was reallocated again and again (with a thousand clients moving, a
  // few percent of this strand's time, with the consolidation it set off).
  auto& granted = grants_[id];
  granted.reserve(granted.size() + chunks.size());
  for (const ChunkWant& w : chunks) {
    if (w.level == kMipLevels - 1 && !w.exact && want_coarse(w.chunk_pos, Waiter{id, w.full})) continue;
    if (request(w.chunk_pos, w.level, w.exact)) {
      grant(id, w.chunk_pos, w.full);
    } else {
      loading_[w.chunk_pos].push_back(Waiter{id, w.full});
    }
  }
  flush_grants();
}

void WorldOwner::do_want_horizon(ClientId id, const std::vector<HorizonWant>& wants) {
  if (!fan_out_.present(id)) return;
  std::vector<HorizonPtr> ready;
  const auto now = std::chrono::steady_clock::now();
  for (const HorizonWant& w : wants) {
    const auto k = static_cast<std::size_t>(w.level - kHorizonNearLevel);
    if (auto it = horizons_[k].find(w.region);
        it != horizons_[k].end() && (!it->second.changed || now - it->second.made < kHorizonRefresh)) {
      ready.push_back(it->second.image);
      continue;
    }
    auto [making, fresh] = horizon_making_[k].try_emplace(w.region);
    making->second.waiting.push_back(id);
    if (fresh)
      storage_.load_horizon(w.region, w.level, [this](LoadedHorizon h) {
        asio::post(strand_, [this, h = std::move(h)]() mutable { on_horizon_loaded(std::move(h)); });
      });
  }
  if (!ready.empty()) fan_out_.horizons(id, std::move(ready));
}

void WorldOwner::on_horizon_loaded(LoadedHorizon h) {
  const auto k = static_cast<std::size_t>(h.level - kHorizonNearLevel);
  auto node = horizon_making_[k].extract(h.region);
  const bool changed = !node.empty() && node.mapped().changed;
  HorizonPtr image = h.image;
  if (!image) {
    server_log().error("horizon image of region ({},{},{}): {}; its chunks are sent as usual", h.region.x, h.region.y,
                       h.region.z, h.error);
    image = std::make_shared<const HorizonImage>(HorizonImage{h.region, h.level, {}});
  } else {
    // Kept even when its region changed while it was being made (marked so):
    // in a busy region that happens often, and the refresh rule applies.
    if (horizons_[k].size() >= kMaxHorizons) horizons_[k].clear();
    horizons_[k].insert_or_assign(h.region, KeptHorizon{image, std::chrono::steady_clock::now(), changed});
  }
  if (node.empty()) return;
  for (const ClientId id : node.mapped().waiting)
    fan_out_.horizons(id, {image});
}

void WorldOwner::horizon_changed(Vec3i cp) {
  const Vec3i region = coarse_region_of(cp);
  for (std::size_t k = 0; k < 2; ++k) {
    if (auto it = horizons_[k].find(region); it != horizons_[k].end()) it->second.changed = true;
    if (auto it = horizon_making_[k].find(region); it != horizon_making_[k].end()) it->second.changed = true;
  }
}

void WorldOwner::grant(ClientId id, Vec3i cp, bool full) {
  Loaded& l = loaded_.at(cp);
  l.used_tick = tick_;
  if (l.published->estimate() && l.replace == Loaded::Replace::kNo) {
    l.replace = Loaded::Replace::kQueued;
    estimates_.push_back(cp);
  }
  fan_out_.hold(cp, id, full);
  grants_[id].push_back(l.published);
}

void WorldOwner::flush_grants() {
  for (auto& [id, versions] : grants_) {
    if (!versions.empty()) fan_out_.granted(id, std::move(versions));
  }
  grants_.clear();
}

// --- chunks --------------------------------------------------------------------

bool WorldOwner::request(Vec3i cp, int level, bool exact) {
  if (auto it = loaded_.find(cp);
      it != loaded_.end() && it->second.current->has_level(level) && !(exact && it->second.current->estimate()))
    return true;
  const auto priority = level == 0 ? Storage::Priority::kUrgent : Storage::Priority::kStream;
  if (loading_.count(cp) != 0) {
    // A background replacement waits behind every other load: whoever
    // needs the chunk now moves it to its own priority, or, if it is being
    // generated already, asks again (the first of the two loads to come
    // back serves the waiters; the other is dropped).
    if (auto it = loaded_.find(cp); it != loaded_.end() && it->second.replace == Loaded::Replace::kLoading) {
      it->second.replace = Loaded::Replace::kNo;
      --replacing_;
      if (!storage_.promote(cp, priority)) load(cp, priority);
    }
    return false;
  }
  loading_.emplace(cp, std::vector<Waiter>{});
  load(cp, priority);
  return false;
}

void WorldOwner::load(Vec3i cp, Storage::Priority priority) {
  storage_.load(
      cp, [this](LoadedChunk c) { asio::post(strand_, [this, c = std::move(c)]() mutable { on_loaded(std::move(c)); }); },
      priority);
}

bool WorldOwner::want_coarse(Vec3i cp, Waiter w) {
  // Loaded in any form, or being loaded: the usual way serves it.
  if (loaded_.count(cp) != 0 || loading_.count(cp) != 0) return false;
  const Vec3i region = coarse_region_of(cp);
  // Read, and the chunk had no entry: it was never stored (generated).
  if (regions_read_.count(region) != 0) return false;
  auto [it, fresh] = coarse_waiting_.try_emplace(region);
  it->second.emplace_back(cp, w);
  if (fresh)
    storage_.load_coarse(region, [this](LoadedCoarse c) {
      asio::post(strand_, [this, c = std::move(c)]() mutable { on_coarse_loaded(std::move(c)); });
    });
  return true;
}

void WorldOwner::on_coarse_loaded(LoadedCoarse c) {
  auto node = coarse_waiting_.extract(c.region);
  if (c.ok) {
    regions_read_.insert(c.region);
    // What is loaded is as new or newer: the image never overrides it.
    const auto know = [&](Vec3i cp, std::uint64_t revision, const CoarseVoxels& voxels) {
      auto [it, fresh] = loaded_.try_emplace(cp);
      if (!fresh) return;
      const VersionPtr v = ChunkVersion::coarse_only(cp, revision, voxels);
      it->second = Loaded{v, v, tick_};
      ++mips_only_;
    };
    for (const CoarseEntry& e : c.entries) know(e.chunk_pos, e.revision, e.voxels);
    for (const Vec3i cp : c.air) know(cp, 0, CoarseVoxels{});
    for (const CoarseEntry& e : c.estimates) {
      auto [it, fresh] = loaded_.try_emplace(e.chunk_pos);
      if (!fresh) continue;
      const VersionPtr v = ChunkVersion::estimated(e.chunk_pos, e.voxels);
      it->second = Loaded{v, v, tick_};
      ++mips_only_;
    }
  } else {
    // Served by reading the chunks instead (a damaged image is found by
    // terrane-world check).
    server_log().error("coarse image of region ({},{},{}): {}; reading its chunks instead", c.region.x, c.region.y,
                       c.region.z, c.error);
    regions_read_.insert(c.region);
  }
  if (node.empty()) return;
  for (const auto& [cp, w] : node.mapped()) {
    if (!fan_out_.present(w.id)) continue;
    if (request(cp, kMipLevels - 1))
      grant(w.id, cp, w.full);
    else
      loading_[cp].push_back(w);
  }
  flush_grants();
}

void WorldOwner::replace_estimates() {
  const std::size_t cap = kReplacingLoadsPerWorker * static_cast<std::size_t>(std::max(1, options_.worker_threads));
  while (replacing_ < cap && !estimates_.empty() && !stopping_) {
    const Vec3i cp = estimates_.front();
    estimates_.pop_front();
    auto it = loaded_.find(cp);
    if (it == loaded_.end() || it->second.replace != Loaded::Replace::kQueued) continue;
    Loaded& l = it->second;
    if (!l.current->estimate() || loading_.count(cp) != 0 || !fan_out_.watched(cp)) {
      l.replace = Loaded::Replace::kNo;  // loaded, being loaded for a client, or no longer held by anyone
      continue;
    }
    l.replace = Loaded::Replace::kLoading;
    ++replacing_;
    loading_.emplace(cp, std::vector<Waiter>{});
    load(cp, Storage::Priority::kBackground);
  }
}

void WorldOwner::on_loaded(LoadedChunk c) {
  const Vec3i cp = c.pos;
  apply_loaded(std::move(c));
  refreshed(cp);
}

void WorldOwner::apply_loaded(LoadedChunk c) {
  bool background = false;  // a replacement nobody else asked for (yet)
  if (auto it = loaded_.find(c.pos); it != loaded_.end() && it->second.replace == Loaded::Replace::kLoading) {
    it->second.replace = Loaded::Replace::kNo;
    --replacing_;
    background = true;
    replace_estimates();
  }
  auto waiting = loading_.find(c.pos);
  if (waiting == loading_.end()) return;
  if (!c.ok) {
    // Not served until a later request can read it: the waiters wait, and
    // the load is tried again next second.
    if (unreadable_.emplace(c.pos, c.error).second)
      server_log().error("chunk ({},{},{}): {}; not served until it can be read", c.pos.x, c.pos.y, c.pos.z, c.error);
    return;
  }
  if (auto it = loaded_.find(c.pos);
      it != loaded_.end() && !it->second.current->estimate() && c.revision < it->second.current->revision()) {
    // A load that read the store before a later commit (one overtaken by
    // a more urgent load of the same chunk, answering a newer request):
    // never older than what is held. Read again.
    load(c.pos, Storage::Priority::kUrgent);
    return;
  }
  unreadable_.erase(c.pos);
  VersionPtr v = std::make_shared<const ChunkVersion>(c.pos, c.revision, std::move(c.chunk));
  // Sky that replaced an estimate, wanted at full resolution by nobody: kept
  // as its mips (all Air, a few bytes; levels 1..3 answer refinements
  // without generating it again), forgotten when unwatched.
  if (background && v->empty() && waiting->second.empty()) v = ChunkVersion::mips_only(*v);
  auto [it, fresh] = loaded_.try_emplace(c.pos);
  Loaded& l = it->second;
  bool differs = false;
  if (!fresh) {
    // It was kept as mips only, or known from a coarse image (so committed:
    // the store has this revision) — unless the row turned out damaged and
    // was quarantined, when the chunk comes back generated at a higher one.
    if (!l.current->has_voxels()) --mips_only_;
    if (l.current->estimate()) {
      // Its holders are told only when the exact mip differs from the
      // estimate they hold (an all-Air chunk's mip is all Air: a holder
      // within full resolution is sent Empty when it refines it).
      counters_.estimates_replaced.fetch_add(1, std::memory_order_relaxed);
      // (An all-Air version's level 3 is an all-Air unit.)
      differs = !same_voxels(kCoarseSide, l.current->encoded(kMipLevels - 1), v->encoded(kMipLevels - 1));
      if (differs) counters_.estimates_corrected.fetch_add(1, std::memory_order_relaxed);
    } else if (l.current->revision() != c.revision) {
      // Expected where another server of a shared world wrote it (read again
      // for that); otherwise a quarantined row came back generated.
      if (stale_.count(c.pos) == 0)
        server_log().warn("chunk ({},{},{}): loaded at revision {}, held at {}; its holders are sent the new one",
                          c.pos.x, c.pos.y, c.pos.z, c.revision, l.current->revision());
      differs = true;
    }
  }
  l.published = v;
  l.current = v;
  if (!v->has_voxels()) ++mips_only_;
  if (differs) {
    horizon_changed(c.pos);
    // As a commit would: every holder (all hold it coarser than full
    // resolution, since it had no voxels) refreshes from the new version.
    fan_out_.changed(tick_, v);
  }
  l.used_tick = tick_;
  counters_.chunks_loaded.store(loaded_.size() - mips_only_, std::memory_order_relaxed);
  const std::vector<Waiter> waiters = std::move(waiting->second);
  loading_.erase(waiting);
  for (const Waiter& w : waiters)
    if (fan_out_.present(w.id)) grant(w.id, c.pos, w.full);
  if (!grants_scheduled_) {
    // Loads finish one by one; hand them over in one go per strand turn.
    grants_scheduled_ = true;
    asio::post(strand_, [this] {
      grants_scheduled_ = false;
      flush_grants();
    });
  }
}

void WorldOwner::retry_pending() {
  // Loads that failed to read are tried again.
  for (auto it = unreadable_.begin(); it != unreadable_.end(); ++it) {
    const Vec3i cp = it->first;
    if (loading_.count(cp) == 0) continue;
    load(cp, Storage::Priority::kStream);
  }
  // Reads and hashes whose chunks have arrived.
  std::size_t kept = 0;
  for (auto& [id, req] : reads_) {
    if (!fan_out_.present(id)) continue;
    Box box(req.box.size());
    if (!read_current(req.box, box)) {
      // Asked again: a chunk of the box may have been lightened meanwhile.
      for_each_chunk_in(req.box, [&](Vec3i cp) { request(cp); });
      reads_[kept++] = {id, req};
      continue;
    }
    fan_out_.send(id, std::make_shared<const Frame>(build_read_box_result(req.request_id, req.box, box.voxels())),
                  SendClass::kData);
  }
  reads_.resize(kept);
  kept = 0;
  for (auto& [id, cp] : hashes_) {
    if (!fan_out_.present(id)) continue;
    if (!request(cp)) {
      hashes_[kept++] = {id, cp};
      continue;
    }
    const VersionPtr& v = loaded_.at(cp).published;
    fan_out_.send(id, std::make_shared<const Frame>(build_chunk_hash(ChunkHashMsg{cp, v->revision(), v->hash()})),
                  SendClass::kData);
  }
  hashes_.resize(kept);
}

Voxel WorldOwner::get(Vec3i p) const {
  auto it = loaded_.find(chunk_of(p));
  if (it == loaded_.end() || it->second.current->empty() || !it->second.current->has_voxels()) return Voxel{};
  return it->second.current->chunk()->get(local_of(p));
}

bool WorldOwner::read_current(const Region& r, Box& out) const {
  bool all = true;
  for_each_chunk_in(r, [&](Vec3i cp) { all = all && loaded(cp); });
  if (!all) return false;
  for_each_chunk_in(r, [&](Vec3i cp) {
    const Region c = intersect(r, chunk_region(cp));
    const ChunkVersion& v = *loaded_.at(cp).current;
    const Vec3i size = c.size();
    if (v.empty()) {
      for (int y = 0; y < size.y; ++y)
        for (int z = 0; z < size.z; ++z)
          for (int x = 0; x < size.x; ++x) out.set(c.min.x - r.min.x + x, c.min.y - r.min.y + y, c.min.z - r.min.z + z, Voxel{});
      return;
    }
    v.chunk()->read_box(c.min - chunk_origin(cp), out, c.min - r.min, size);
  });
  return true;
}

void WorldOwner::unload_unwatched() {
  // Beyond resident_chunks, the least recently used chunks nobody holds at
  // full resolution, with no edit queued and nothing uncommitted, keep only
  // their mips: clients holding mips are served and refreshed from those,
  // and the voxels come back from the store when needed. Edits are
  // committed at the tick that applies them, so this loses nothing. And
  // mips nobody holds are forgotten when there are very many.
  //
  // One pass over every loaded chunk a second, a tick's share of the table
  // each tick: a whole pass at once (hundreds of thousands of chunks at a
  // thousand clients) took a tick 15-40 ms, and every edit arriving
  // meanwhile waited for it.
  UnloadPass& pass = unload_pass_;
  if (pass.next_slot == 0) {
    pass.lighten = loaded_.size() - mips_only_ > options_.resident_chunks;
    pass.forget = mips_only_ > kMaxMipsOnly;
    pass.drop.clear();
    if (!pass.lighten && !pass.forget) return;  // nothing to do: asked again next tick
  }
  const std::size_t slots = loaded_.slot_count();
  const std::size_t part = slots / std::max<std::uint32_t>(1, options_.tick_hz) + 1;
  const std::size_t from = pass.next_slot, to = std::min(slots, from + part);
  std::vector<Vec3i> forget;
  loaded_.for_each_in_slots(from, to, [&](Vec3i cp, const Loaded& l) {
    if (!l.current->has_voxels()) {
      // (An all-Air chunk has no voxels to drop, but as its mips it can
      // be forgotten.)
      if (pass.forget && forget.size() + kMaxMipsOnly / 2 < mips_only_ && !fan_out_.watched(cp) &&
          loading_.count(cp) == 0)
        forget.push_back(cp);
      return;
    }
    if (!pass.lighten || busy_.count(cp) != 0 || l.current != l.published || fan_out_.held_full(cp) ||
        loading_.count(cp) != 0)
      return;
    pass.drop.emplace_back(l.used_tick, cp);
  });
  for (const Vec3i cp : forget) {
    // Its region's image is read again when next wanted.
    regions_read_.erase(coarse_region_of(cp));
    loaded_.erase(cp);
    --mips_only_;
  }
  pass.next_slot = to;
  if (to < slots) return;
  pass.next_slot = 0;  // the pass is over
  const std::size_t full = loaded_.size() - mips_only_;
  if (pass.lighten && full > options_.resident_chunks) {
    std::vector<std::pair<std::uint64_t, Vec3i>>& drop = pass.drop;
    // Seen over the last second: those lightened or gone since are left
    // out (lighten_some was still working through the previous list, and
    // a table rebuilt meanwhile may have shown one twice), the others taken
    // at their latest use.
    std::erase_if(drop, [&](std::pair<std::uint64_t, Vec3i>& d) {
      auto it = loaded_.find(d.second);
      if (it == loaded_.end() || !it->second.current->has_voxels()) return true;
      d.first = it->second.used_tick;
      return false;
    });
    std::sort(drop.begin(), drop.end(), [](const auto& x, const auto& y) {
      return std::tie(x.second.x, x.second.y, x.second.z) < std::tie(y.second.x, y.second.y, y.second.z);
    });
    drop.erase(std::unique(drop.begin(), drop.end(), [](const auto& x, const auto& y) { return x.second == y.second; }),
               drop.end());
    const std::size_t excess = full - options_.resident_chunks;
    if (drop.size() > excess) {
      std::nth_element(drop.begin(), drop.begin() + static_cast<std::ptrdiff_t>(excess), drop.end(),
                       [](const auto& x, const auto& y) { return x.first < y.first; });
      drop.resize(excess);
    }
    // Reduced a few per tick (lighten_some), so no tick waits for thousands;
    // each is checked again then (it may have been asked for or edited).
    std::sort(drop.begin(), drop.end(), [](const auto& x, const auto& y) { return x.first > y.first; });
    lighten_.clear();
    for (const auto& [t, cp] : drop) lighten_.push_back(cp);
  }
  pass.drop.clear();
  counters_.chunks_loaded.store(loaded_.size() - mips_only_, std::memory_order_relaxed);
}

// --- edits ---------------------------------------------------------------------

void WorldOwner::reject(ClientId id, const EditRequestMsg& edit, RejectReason why, const std::string& reason) {
  counters_.rejected(why);
  if (!fan_out_.present(id)) return;
  // The true state of what the edit would have touched, when it is at hand:
  // on the data queue, after every change already sent, so it is the state
  // the client's replica reaches once it has read that far.
  const Region r = world_.meta().bounds.clamp(edit.bounds());
  if (!r.empty() && r.volume() <= kMaxEditVolume) {
    Box box(r.size());
    if (read_current(r, box)) {
      fan_out_.send(id, std::make_shared<const Frame>(build_edit_reject(edit.edit_id, reason, r, box.voxels())),
                    SendClass::kData);
      return;
    }
  }
  fan_out_.send(id, std::make_shared<const Frame>(build_edit_reject(edit.edit_id, reason)), SendClass::kControl);
}

void WorldOwner::edit(ClientId id, EditRequestMsg e) {
  asio::post(strand_, [this, id, e = std::move(e), received = std::chrono::steady_clock::now()]() mutable {
    auto it = editors_.find(id);
    if (it == editors_.end() || stopping_) return;
    Editor& c = it->second;
    if (c.edits_queued >= options_.max_edits_queued_per_client) return reject(id, e, RejectReason::kQueueFull, "too many edits queued");
    if (!is_history_edit(e.kind)) {
      const Region r = world_.meta().bounds.clamp(e.reads());
      if (r.empty()) return reject(id, e, RejectReason::kOutsideWorld, "edit outside the world");
      reserve(r);
    }
    ++c.edits_queued;
    edits_.push_back(PendingEdit{id, std::move(e), c.name, nullptr, std::nullopt, received});
  });
}

void WorldOwner::rollback(std::string actor, std::vector<EditLogEntry> entries, std::optional<Region> within,
                          std::function<void(RollbackResult)> done) {
  asio::post(strand_, [this, actor = std::move(actor), entries = std::move(entries), within,
                       done = std::move(done)]() mutable {
    if (stopping_) return done(RollbackResult{false, "the server is stopping", 0, 0});
    const WorldBounds& bounds = world_.meta().bounds;
    for (const EditLogEntry& e : entries)
      for_each_chunk_in(bounds.clamp(e.box), [&](Vec3i cp) {
        request(cp);
        ++busy_[cp];
      });
    auto job = std::make_shared<Rollback>();
    job->actor = std::move(actor);
    job->entries = std::move(entries);
    job->within = within;
    job->done = std::move(done);
    edits_.push_back(PendingEdit{0, EditRequestMsg{}, job->actor, std::move(job), std::nullopt});
  });
}

void WorldOwner::reserve(const Region& r) {
  for_each_chunk_in(r, [&](Vec3i cp) {
    request(cp);
    ++busy_[cp];
  });
}

void WorldOwner::unbusy(const Region& r) {
  for_each_chunk_in(r, [&](Vec3i cp) {
    auto it = busy_.find(cp);
    if (it != busy_.end() && --it->second <= 0) busy_.erase(it);
  });
}

void WorldOwner::refuse(ClientId id, EditRequestMsg e, RejectReason why, std::string reason) {
  asio::post(strand_, [this, id, e = std::move(e), why, reason = std::move(reason)] { reject(id, e, why, reason); });
}

void WorldOwner::copy_into(Grid& scratch, const Region& r, std::unordered_set<Vec3i, Vec3iHash>& copied) {
  for_each_chunk_in(r, [&](Vec3i cp) {
    if (!copied.insert(cp).second) return;
    const ChunkVersion& v = *loaded_.at(cp).current;
    if (!v.empty()) scratch.put_chunk(cp, v.chunk()->clone());
  });
}

// One tick's edits as they apply (WorldOwner::apply_edits): copies of the
// chunks they touch, what they changed, and whom to tell once committed.
struct WorldOwner::TickEdits {
  std::uint64_t tick = 0;
  std::int64_t now_ms = 0;
  Grid scratch;
  std::unordered_set<Vec3i, Vec3iHash> copied;
  ChangedUnits changed;
  std::vector<Ack> acks;
  std::vector<ForwardAnswer> answers, refused;  // to forwarded edits: applied (in the commit), refused (at once)
  std::vector<EditLogEntry> log;
  std::vector<std::shared_ptr<Rollback>> rollbacks;
  // An edit that must wait (for its chunks, a claim) is set aside and the
  // edits behind it go on, except those that touch a chunk of a waiting
  // edit or are a waiting edit's player's: those keep arrival order. The
  // edits set aside go back to the queue's front after the tick.
  std::deque<PendingEdit> waiting;
  std::unordered_set<Vec3i, Vec3iHash> waiting_chunks;
  std::unordered_set<std::string> waiting_players;

  void refuse(const Forwarded& f, std::string why) {
    refused.push_back(ForwardAnswer{f.inbox_id, f.from, false, 0, std::move(why)});
  }
  void log_step(const std::string& player, const Region& box, std::vector<std::uint8_t> before,
                std::vector<std::uint8_t> after) {
    if (before == after) return;  // nothing changed: nothing to log
    log.push_back(EditLogEntry{0, tick, now_ms, player, box, std::move(before), std::move(after)});
  }
  bool behind_waiting(const Region& r) const {
    bool meets = false;
    for_each_chunk_in(r, [&](Vec3i cp) { meets = meets || waiting_chunks.count(cp) != 0; });
    return meets;
  }
  void mark_waiting(const Region& r) {
    for_each_chunk_in(r, [&](Vec3i cp) { waiting_chunks.insert(cp); });
  }
};

void WorldOwner::apply_edits() {
  ++tick_;
  counters_.ticks.fetch_add(1, std::memory_order_relaxed);
  // The tick's edits apply to copies of the chunks they touch; each changed
  // chunk then becomes a new version.
  TickEdits t;
  t.tick = tick_;
  t.now_ms =
      std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::system_clock::now().time_since_epoch()).count();
  while (!edits_.empty() && t.acks.size() + t.rollbacks.size() < kMaxEditsPerTick &&
         t.waiting.size() < kMaxEditsWaitingPerTick)
    if ((edits_.front().rollback ? apply_rollback(t) : apply_player_edit(t)) == EditStep::kStop) break;
  for (; !t.waiting.empty(); t.waiting.pop_back()) edits_.push_front(std::move(t.waiting.back()));
  if (!t.refused.empty()) storage_.answer(std::move(t.refused));
  counters_.edits_applied.fetch_add(t.acks.size() + t.answers.size(), std::memory_order_relaxed);

  std::vector<VersionPtr> versions;
  versions.reserve(t.changed.size());
  for (const auto& [cp, bits] : t.changed) {
    if (bits.none()) continue;
    Loaded& l = loaded_.at(cp);
    l.current = ChunkVersion::after(*l.current, t.scratch.take_chunk(cp), bits);
    l.used_tick = tick_;
    versions.push_back(l.current);
  }
  if (versions.empty() && t.acks.empty() && t.rollbacks.empty() && t.answers.empty()) return;
  ++commits_pending_;
  const std::uint64_t tick = tick_;
  storage_.commit(
      versions, std::move(t.log),
      [this, tick, versions, acks = std::move(t.acks), rollbacks = std::move(t.rollbacks)](const FileStatus& st) {
        asio::post(strand_, [this, tick, versions, acks, rollbacks, st] {
          on_committed(tick, versions, acks, st);
          for (const auto& job : rollbacks)
            job->done(st ? RollbackResult{true, "", tick, job->restored}
                         : RollbackResult{false, "storage failure: rollback not saved", tick, 0});
        });
      },
      std::move(t.answers), tick);
}

void WorldOwner::set_aside(TickEdits& t) {
  t.waiting.push_back(std::move(edits_.front()));
  edits_.pop_front();
}

WorldOwner::EditStep WorldOwner::apply_rollback(TickEdits& t) {
  const WorldBounds& bounds = world_.meta().bounds;
  PendingEdit& pe = edits_.front();
  Rollback& job = *pe.rollback;
  bool behind = false;
  for (const EditLogEntry& e : job.entries) behind = behind || t.behind_waiting(bounds.clamp(e.box));
  if (behind) {
    for (const EditLogEntry& e : job.entries) t.mark_waiting(bounds.clamp(e.box));
    set_aside(t);
    return EditStep::kNext;
  }
  bool ready = true;
  for (const EditLogEntry& e : job.entries)
    for_each_chunk_in(bounds.clamp(e.box), [&](Vec3i cp) { ready = request(cp) && ready; });
  std::string not_ours;
  Writable w = Writable::kYes;
  for (const EditLogEntry& e : job.entries)
    if (w != Writable::kNo)
      if (const Writable here = writable(bounds.clamp(e.box), &not_ours); here != Writable::kYes) w = here;
  if ((!ready || w == Writable::kWaiting) && !stopping_) {  // wait for its chunks and leases
    for (const EditLogEntry& e : job.entries) t.mark_waiting(bounds.clamp(e.box));
    set_aside(t);
    return EditStep::kNext;
  }
  for (const EditLogEntry& e : job.entries) unbusy(bounds.clamp(e.box));
  if (!ready || w != Writable::kYes) {
    job.done(RollbackResult{false, w == Writable::kNo ? not_ours : std::string("the server is stopping"), 0, 0});
    edits_.pop_front();
    return EditStep::kNext;
  }
  for (const EditLogEntry& e : job.entries) copy_into(t.scratch, bounds.clamp(e.box), t.copied);
  UnitMarker marker(t.changed);
  std::unordered_map<Vec3i, Voxel, Vec3iHash> first;  // each restored voxel's value before the rollback
  for (const EditLogEntry& e : job.entries) {
    Region b = bounds.clamp(e.box);
    if (job.within) b = intersect(b, *job.within);
    if (b.empty()) continue;
    const auto n = static_cast<std::size_t>(e.box.volume());
    std::vector<Voxel> before(n), after(n);
    if (!byte_rle_decode(e.before, before) || !byte_rle_decode(e.after, after)) continue;  // damaged entry
    auto was = snapshot(t.scratch, b);
    const Vec3i size = e.box.size();
    t.scratch.modify(b, [&](Vec3i p, Voxel cur) {
      const Vec3i l = p - e.box.min;
      const auto i = static_cast<std::size_t>((l.y * size.z + l.z) * size.x + l.x);
      if (cur != after[i] || before[i] == cur) return cur;
      marker.mark(p);
      first.emplace(p, cur);
      return before[i];
    });
    t.log_step(job.actor, b, std::move(was), snapshot(t.scratch, b));
  }
  for (const auto& [p, v] : first) job.restored += t.scratch.get(p) != v ? 1 : 0;
  t.rollbacks.push_back(std::move(pe.rollback));
  edits_.pop_front();
  return EditStep::kNext;
}

// A client's edit (an undo or redo too) or one forwarded from another
// server's inbox.
WorldOwner::EditStep WorldOwner::apply_player_edit(TickEdits& t) {
  const WorldBounds& bounds = world_.meta().bounds;
  PendingEdit& pe = edits_.front();
  auto cit = editors_.find(pe.id);
  Editor* client = cit != editors_.end() ? &cit->second : nullptr;
  const bool history = is_history_edit(pe.edit.kind);
  const bool redo = pe.edit.kind == EditKind::kRedo;
  Region r;
  if (history) {
    const HistoryEntry* top = client != nullptr ? client->history.top(redo) : nullptr;
    if (top != nullptr) r = bounds.clamp(top->box);
  } else {
    r = bounds.clamp(pe.edit.reads());
  }
  // (r, what the edit reads, holds what it writes.)
  const auto wait = [&] {
    t.mark_waiting(r);
    t.waiting_players.insert(pe.player);
    set_aside(t);
  };
  // A client's edit also waits while one of its edits whose chunks it
  // meets is forwarded and not answered: another server may apply that.
  if (t.waiting_players.count(pe.player) != 0 || t.behind_waiting(r) ||
      (client != nullptr && !pe.forwarded && forward_pending(pe.id, r))) {
    wait();
    return EditStep::kNext;
  }
  bool ready = true;
  for_each_chunk_in(r, [&](Vec3i cp) { ready = request(cp) && ready; });
  if (!ready) {
    if (!stopping_) {  // wait for its chunks
      wait();
      return EditStep::kNext;
    }
    // Shutting down: chunks still loading will not be waited for.
    if (client != nullptr) reject(pe.id, pe.edit, RejectReason::kShutdown, "server shutting down");
    if (pe.forwarded) t.refuse(*pe.forwarded, "the region's server is shutting down");
    if (!history) unbusy(r);
    if (client != nullptr && client->edits_queued > 0) --client->edits_queued;
    edits_.pop_front();
    return EditStep::kNext;
  }
  // In a shared world, only regions this server holds are written; a
  // client's edit in another server's is forwarded to it.
  std::string not_ours;
  std::optional<std::uint32_t> holder;
  const Region writes = history ? r : bounds.clamp(pe.edit.bounds());
  const Writable w =
      writable(writes, &not_ours, &holder,
               client != nullptr && !history && !pe.forwarded ? ClaimRule::kPreferNeighbours : ClaimRule::kAny);
  // Another server's region in it: which of the others are this server's
  // decides what goes with the edit, so claims under way are waited for.
  const auto claiming = [&] {
    bool any = false;
    for_each_chunk_in(writes, [&](Vec3i cp) {
      auto l = leases_.find(lease_region_of(cp));
      any = any || (l != leases_.end() && (l->second.state == RegionLeaseState::kClaiming ||
                                           l->second.state == RegionLeaseState::kRefreshing));
    });
    return any;
  };
  if ((w == Writable::kWaiting || (w == Writable::kNo && !history && claiming())) && !stopping_) {
    wait();  // for the claims
    return EditStep::kNext;
  }
  if (w != Writable::kYes) {
    // An edit across a border also writes regions of this server's: they
    // are handed over with it to the server holding the rest, once nothing
    // of them is in flight. A forwarded edit goes on so too (relayed: its
    // inbox row readdressed, its sender and age kept), with regions of
    // this server's or none (they moved on since its sender looked); a
    // row older than the forward wait is t.refused wherever it is, so no
    // relay goes on longer. Never back to its sender: there the player's
    // next edit on those chunks waits for this one's answer, and this one
    // would wait behind it (t.refused instead; the player tries again).
    std::unordered_set<Vec3i, Vec3iHash> mine;
    const bool may_go_on = w == Writable::kNo && holder && !history && !stopping_ &&
                           (client != nullptr || (pe.forwarded && *holder != pe.forwarded->from));
    if (may_go_on)
      for_each_chunk_in(writes, [&](Vec3i cp) {
        if (writes_region(lease_region_of(cp))) mine.insert(lease_region_of(cp));
      });
    if (may_go_on) {
      // Handed over only with nothing of this server's in flight: no commit
      // under way, nothing applied yet this tick, no edit set aside in the
      // regions. Nothing behind it is applied meanwhile, so that comes
      // within a commit's time (or an edit's wait).
      const bool in_flight = commits_pending_ > 0 || !t.changed.empty() ||
                             std::any_of(t.waiting_chunks.begin(), t.waiting_chunks.end(),
                                         [&](Vec3i cp) { return mine.count(lease_region_of(cp)) != 0; });
      if (!mine.empty() && in_flight) return EditStep::kStop;
      if (pe.forwarded)
        relay(pe, writes, *holder);
      else
        forward(pe, writes, *holder);
    } else if (pe.forwarded) {
      t.refuse(*pe.forwarded, w == Writable::kNo ? "not held by the server it was sent to: " + not_ours
                                               : std::string("the region's server is shutting down"));
    } else if (client != nullptr) {
      if (w == Writable::kNo)
        reject(pe.id, pe.edit, RejectReason::kNotOwner,
               std::string(history ? "undo and redo only where this server writes; " : "") +
                   "not this server's region: " + not_ours);
      else
        reject(pe.id, pe.edit, RejectReason::kShutdown, "server shutting down");
    }
    if (!history) unbusy(r);
    if (client != nullptr && client->edits_queued > 0) --client->edits_queued;
    edits_.pop_front();
    return EditStep::kNext;
  }
  copy_into(t.scratch, r, t.copied);
  if (client != nullptr && client->edits_queued > 0) --client->edits_queued;
  if (history) {
    std::string why = "client gone";
    if (client != nullptr && client->history.top(redo) == nullptr) {
      why = redo ? "nothing to redo" : "nothing to undo";
    } else if (client != nullptr && !fan_out_.within_full_res(pe.id, r)) {
      why = std::string(redo ? "redo" : "undo") + " outside the full-resolution region";
      client->history.drop(redo);  // its box may be stale by the time the client is back
    } else if (auto was = client != nullptr ? snapshot(t.scratch, r) : std::vector<std::uint8_t>{};
               client != nullptr && client->history.apply(t.scratch, redo, t.changed, &why)) {
      t.log_step(pe.player, r, std::move(was), snapshot(t.scratch, r));
      t.acks.push_back(Ack{pe.id, pe.edit.edit_id, pe.received});
      edits_.pop_front();
      return EditStep::kNext;
    }
    if (client != nullptr) reject(pe.id, pe.edit, RejectReason::kHistory, why);
    edits_.pop_front();
    return EditStep::kNext;
  }
  const Region box = bounds.clamp(pe.edit.bounds());
  HistoryEntry entry{box, snapshot(t.scratch, box), {}};
  apply_edit(t.scratch, pe.edit, box, t.changed);
  entry.after = snapshot(t.scratch, box);
  t.log_step(pe.player, box, entry.before, entry.after);
  if (client != nullptr) client->history.record(std::move(entry));
  unbusy(r);
  if (pe.forwarded)
    t.answers.push_back(ForwardAnswer{pe.forwarded->inbox_id, pe.forwarded->from, true, tick_, ""});
  else
    t.acks.push_back(Ack{pe.id, pe.edit.edit_id, pe.received});
  edits_.pop_front();
  return EditStep::kNext;
}

void WorldOwner::on_committed(std::uint64_t tick, const std::vector<VersionPtr>& versions, const std::vector<Ack>& acks,
                              const FileStatus& status) {
  --commits_pending_;
  if (!status) {
    if (!storage_failed_) {
      server_log().critical("tick {}: saving {} chunks failed: {}; rejecting the tick's edits and stopping", tick,
                            versions.size(), status.error().message);
    }
    // Nothing of this tick may be acknowledged or shown: it is not on disk.
    for (const Ack& a : acks)
      fan_out_.send(a.id, std::make_shared<const Frame>(build_edit_reject(a.edit_id, "storage failure: edit not saved")),
                    SendClass::kControl);
    counters_.rejected(RejectReason::kStorageFailure, acks.size());
    fatal_storage(status.error().message);
  } else {
    const auto t0 = std::chrono::steady_clock::now();
    // Publish, then tell each holder once about all of its changed chunks,
    // then acknowledge: on a client's strand the news is handled before the
    // ack is queued, so whatever the client asks after reading its ack (a
    // chunk hash, a read) is answered from the new versions.
    // Holders at full resolution hear of every tick; the others' news is
    // gathered and handed over every mip_refresh_ms (deliver_mip_news).
    publish(tick, versions, t0);
    const auto acked_at = std::chrono::steady_clock::now();
    for (const Ack& a : acks) {
      if (!fan_out_.present(a.id)) continue;  // gone: nothing acknowledged
      // Counted before the ack leaves, so a client that read it sees it counted.
      counters_.edit_ack_duration.observe(acked_at - a.received);
      fan_out_.send(a.id, std::make_shared<const Frame>(build_edit_ack(a.edit_id, tick)), SendClass::kControl);
    }
    counters_.fanout_duration.observe(std::chrono::steady_clock::now() - t0);
  }
  if (status) last_committed_tick_ = std::max(last_committed_tick_, tick);
  for (auto it = flush_waiters_.begin(); it != flush_waiters_.end();) {
    if (commits_pending_ == 0 || it->first <= last_committed_tick_) {
      it->second(it->first, !storage_failed_);
      it = flush_waiters_.erase(it);
    } else {
      ++it;
    }
  }
  if (drain_wanted_ && commits_pending_ == 0) {
    drain_wanted_ = false;
    drained_.set_value();
  }
}

void WorldOwner::publish(std::uint64_t tick, const std::vector<VersionPtr>& versions,
                         std::chrono::steady_clock::time_point now) {
  // Grants not yet handed over go first: a holder hears of a version after
  // it was granted the one before (a replicator drops news of a chunk it
  // was not granted yet).
  flush_grants();
  for (const VersionPtr& v : versions) {
    if (auto it = loaded_.find(v->pos()); it != loaded_.end() && it->second.published->revision() < v->revision())
      it->second.published = v;
    horizon_changed(v->pos());
  }
  fan_out_.publish(tick, versions, now);
}

void WorldOwner::fail_rollbacks(const std::string& why) {
  for (auto it = edits_.begin(); it != edits_.end();) {
    if (it->rollback) {
      it->rollback->done(RollbackResult{false, why, 0, 0});
      it = edits_.erase(it);
    } else {
      ++it;
    }
  }
}

void WorldOwner::fatal_storage(const std::string& why) {
  if (storage_failed_) return;
  (void)why;
  fail_rollbacks("storage failure: rollback not applied");
  storage_failed_ = true;
  storage_failed_flag_ = true;
  // The owner hears of the failure before any client does: a client that reads
  // "server storage failure" may ask the server, and finds it failed.
  if (options_.on_fatal) options_.on_fatal();
  fan_out_.close_all(CloseReason::kStorageFailure, "server storage failure");
  stopping_ = true;
  tick_timer_.cancel();
}

// --- queries -------------------------------------------------------------------

void WorldOwner::read_box(ClientId id, ReadBoxMsg req) {
  asio::post(strand_, [this, id, req] {
    if (!fan_out_.present(id)) return;
    for_each_chunk_in(req.box, [&](Vec3i cp) { request(cp); });
    reads_.emplace_back(id, req);
    retry_pending();
  });
}

void WorldOwner::hash(ClientId id, Vec3i cp) {
  asio::post(strand_, [this, id, cp] {
    hashes_.emplace_back(id, cp);
    retry_pending();
  });
}

// --- tick ----------------------------------------------------------------------

void WorldOwner::arm_tick() {
  if (stopping_) return;
  // A fixed schedule: the next tick is due one period after the last one was
  // due, however long the work took; a tick more than a period late starts
  // the schedule again from now (counted) rather than bunching ticks up.
  const auto period = std::chrono::microseconds(1'000'000 / std::max<std::uint32_t>(1, options_.tick_hz));
  next_tick_ += period;
  const auto now = std::chrono::steady_clock::now();
  if (next_tick_ + period < now) {
    counters_.ticks_late.fetch_add(1, std::memory_order_relaxed);
    next_tick_ = now;
  }
  tick_timer_.expires_at(next_tick_);
  tick_timer_.async_wait([this](const asio::error_code& ec) {
    if (ec || stopping_) return;
    on_tick();
    arm_tick();
  });
}

void WorldOwner::lighten_some() {
  std::size_t n = 0;
  while (!lighten_.empty() && n < kLightenPerTick) {
    const Vec3i cp = lighten_.back();
    lighten_.pop_back();
    auto it = loaded_.find(cp);
    if (it == loaded_.end()) continue;
    Loaded& l = it->second;
    // Checked again: it may have been asked for at full resolution or
    // edited since the list was made.
    if (!l.current->has_voxels() || busy_.count(cp) != 0 || l.current != l.published ||
        fan_out_.held_full(cp) || loading_.count(cp) != 0)
      continue;
    l.published = l.current = ChunkVersion::mips_only(*l.current);
    ++mips_only_;
    ++n;
  }
  if (n > 0) {
    counters_.chunks_unloaded.fetch_add(n, std::memory_order_relaxed);
    counters_.chunks_loaded.store(loaded_.size() - mips_only_, std::memory_order_relaxed);
  }
}

void WorldOwner::on_tick() {
  using Clock = std::chrono::steady_clock;
  const auto t0 = Clock::now();
  replace_estimates();
  counters_.tick_lag_ns.store(
      static_cast<std::uint64_t>(std::max<std::int64_t>(0, std::chrono::nanoseconds(t0 - next_tick_).count())),
      std::memory_order_relaxed);
  lighten_some();
  fan_out_.deliver_mip_news(std::chrono::steady_clock::now());
  const auto t_edits = Clock::now();
  apply_edits();
  if (!forwarded_.empty()) settle_forwarded();
  const auto t_presence = Clock::now();
  const std::uint32_t hz = std::max<std::uint32_t>(1, options_.tick_hz);
  if (options_.presence_hz > 0) fan_out_.send_presence(tick_);
  const auto t_unload = Clock::now();
  unload_unwatched();
  if (tick_ % hz == 0) retry_pending();
  const auto t1 = Clock::now();
  counters_.tick_duration.observe(t1 - t0);
  counters_.last_tick_at_ns.store(std::chrono::nanoseconds(t1.time_since_epoch()).count(), std::memory_order_relaxed);
  // A tick longer than half its period delays every edit that arrives
  // meanwhile: said, with its parts, at most once every 10 s.
  const auto period = std::chrono::microseconds(1'000'000 / hz);
  if (t1 - t0 > period / 2) {
    ++slow_ticks_;
    if (t1 >= next_slow_tick_report_) {
      const auto ms = [](Clock::duration d) { return std::chrono::duration<double, std::milli>(d).count(); };
      server_log().warn(
          "tick {} took {:.1f} ms (period {:.1f}): loads and lightening {:.1f}, edits {:.1f}, presence {:.1f}, "
          "unloading {:.1f}; {} such ticks since the last report",
          tick_, ms(t1 - t0), ms(period), ms(t_edits - t0), ms(t_presence - t_edits), ms(t_unload - t_presence),
          ms(t1 - t_unload), slow_ticks_);
      slow_ticks_ = 0;
      next_slow_tick_report_ = t1 + std::chrono::seconds(10);
    }
  }
}

void WorldOwner::flush(std::function<void(std::uint64_t tick, bool stored)> done) {
  asio::post(strand_, [this, done = std::move(done)]() mutable {
    if (commits_pending_ == 0) return done(tick_, !storage_failed_);
    flush_waiters_.emplace_back(tick_, std::move(done));
  });
}

void WorldOwner::inspect(const std::function<void(const WorldView&)>& fn) {
  std::promise<void> done;
  asio::post(strand_, [&] {
    fn(*this);
    done.set_value();
  });
  done.get_future().wait();
}

}  // namespace terrane
