#include "server/world/residency.h"

#include <algorithm>
#include <tuple>

#include "common/codec/net_codec.h"
#include "common/world/coarse_image.h"
#include "server/base/log.h"

namespace terrane {

namespace {

// Whether two n^3 network codec units hold the same voxels (a unit that
// does not decode differs from everything).
bool same_voxels(int n, std::span<const std::uint8_t> a, std::span<const std::uint8_t> b) {
  if (std::equal(a.begin(), a.end(), b.begin(), b.end())) return true;
  const auto count = static_cast<std::size_t>(n) * static_cast<std::size_t>(n) * static_cast<std::size_t>(n);
  std::vector<Voxel> va(count), vb(count);
  return net_codec_decode(n, a, va).ok() && net_codec_decode(n, b, vb).ok() && va == vb;
}

}  // namespace

Residency::Residency(Strand& strand, Storage& storage, const ServerOptions& options, ServerCounters& counters,
                     const WorldClock& clock, FanOut& clients, HorizonCache& horizons)
    : strand_(strand),
      storage_(storage),
      options_(options),
      counters_(counters),
      clock_(clock),
      clients_(clients),
      horizons_(horizons) {}

void Residency::count_loaded() {
  counters_.chunks_loaded.store(loaded_.size() - mips_only_, std::memory_order_relaxed);
}

std::size_t Residency::estimates_waiting() const {
  return static_cast<std::size_t>(std::count_if(loaded_.begin(), loaded_.end(), [this](const auto& kv) {
    return kv.second.current->estimate() &&
           (kv.second.replace != Loaded::Replace::kNo || loading_.count(kv.first) != 0);
  }));
}

void Residency::retry_unreadable() {
  for (auto it = unreadable_.begin(); it != unreadable_.end(); ++it) {
    const Vec3i cp = it->first;
    if (loading_.count(cp) == 0) continue;
    load(cp, Storage::Priority::kStream);
  }
}

void Residency::for_each(const std::function<void(Vec3i, const Loaded&)>& fn) const {
  for (const auto& [cp, l] : loaded_) fn(cp, l);
}

const VersionPtr& Residency::advance(VersionPtr v) {
  Loaded& l = loaded_.at(v->pos());
  l.current = std::move(v);
  l.used_tick = clock_.tick;
  return l.current;
}

void Residency::publish(const std::vector<VersionPtr>& versions) {
  flush_grants();
  for (const VersionPtr& v : versions) {
    if (auto it = loaded_.find(v->pos()); it != loaded_.end() && it->second.published->revision() < v->revision())
      it->second.published = v;
    horizons_.changed(v->pos());
  }
}

void Residency::forget(Vec3i cp) {
  auto it = loaded_.find(cp);
  if (it == loaded_.end()) return;
  horizons_.changed(cp);
  regions_read_.erase(coarse_region_of(cp));
  if (!it->second.current->has_voxels()) --mips_only_;
  loaded_.erase(it);
  count_loaded();
}

void Residency::want(ClientId id, const std::vector<ChunkWant>& chunks) {
  if (!clients_.present(id)) return;
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

void Residency::grant(ClientId id, Vec3i cp, bool full) {
  Loaded& l = loaded_.at(cp);
  l.used_tick = clock_.tick;
  if (l.published->estimate() && l.replace == Loaded::Replace::kNo) {
    l.replace = Loaded::Replace::kQueued;
    estimates_.push_back(cp);
  }
  clients_.hold(cp, id, full);
  grants_[id].push_back(l.published);
}

void Residency::flush_grants() {
  for (auto& [id, versions] : grants_) {
    if (!versions.empty()) clients_.granted(id, std::move(versions));
  }
  grants_.clear();
}

bool Residency::request(Vec3i cp, int level, bool exact) {
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

void Residency::load(Vec3i cp, Storage::Priority priority) {
  storage_.load(
      cp, [this](LoadedChunk c) { asio::post(strand_, [this, c = std::move(c)]() mutable { on_loaded(std::move(c)); }); },
      priority);
}

bool Residency::want_coarse(Vec3i cp, Waiter w) {
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

void Residency::on_coarse_loaded(LoadedCoarse c) {
  auto node = coarse_waiting_.extract(c.region);
  if (c.ok) {
    regions_read_.insert(c.region);
    // What is loaded is as new or newer: the image never overrides it.
    const auto know = [&](Vec3i cp, std::uint64_t revision, const CoarseVoxels& voxels) {
      auto [it, fresh] = loaded_.try_emplace(cp);
      if (!fresh) return;
      const VersionPtr v = ChunkVersion::coarse_only(cp, revision, voxels);
      it->second = Loaded{v, v, clock_.tick};
      ++mips_only_;
    };
    for (const CoarseEntry& e : c.entries) know(e.chunk_pos, e.revision, e.voxels);
    for (const Vec3i cp : c.air) know(cp, 0, CoarseVoxels{});
    for (const CoarseEntry& e : c.estimates) {
      auto [it, fresh] = loaded_.try_emplace(e.chunk_pos);
      if (!fresh) continue;
      const VersionPtr v = ChunkVersion::estimated(e.chunk_pos, e.voxels);
      it->second = Loaded{v, v, clock_.tick};
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
    if (!clients_.present(w.id)) continue;
    if (request(cp, kMipLevels - 1))
      grant(w.id, cp, w.full);
    else
      loading_[cp].push_back(w);
  }
  flush_grants();
}

void Residency::replace_estimates() {
  const std::size_t cap = kReplacingLoadsPerWorker * static_cast<std::size_t>(std::max(1, options_.worker_threads));
  while (replacing_ < cap && !estimates_.empty() && !clock_.stopping) {
    const Vec3i cp = estimates_.front();
    estimates_.pop_front();
    auto it = loaded_.find(cp);
    if (it == loaded_.end() || it->second.replace != Loaded::Replace::kQueued) continue;
    Loaded& l = it->second;
    if (!l.current->estimate() || loading_.count(cp) != 0 || !clients_.watched(cp)) {
      l.replace = Loaded::Replace::kNo;  // loaded, being loaded for a client, or no longer held by anyone
      continue;
    }
    l.replace = Loaded::Replace::kLoading;
    ++replacing_;
    loading_.emplace(cp, std::vector<Waiter>{});
    load(cp, Storage::Priority::kBackground);
  }
}

void Residency::on_loaded(LoadedChunk c) {
  const Vec3i cp = c.pos;
  apply_loaded(std::move(c));
  if (watcher_ != nullptr) watcher_->landed(cp);
}

void Residency::apply_loaded(LoadedChunk c) {
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
      if (watcher_ == nullptr || !watcher_->stale(c.pos))
        server_log().warn("chunk ({},{},{}): loaded at revision {}, held at {}; its holders are sent the new one",
                          c.pos.x, c.pos.y, c.pos.z, c.revision, l.current->revision());
      differs = true;
    }
  }
  l.published = v;
  l.current = v;
  if (!v->has_voxels()) ++mips_only_;
  if (differs) {
    horizons_.changed(c.pos);
    // As a commit would: every holder (all hold it coarser than full
    // resolution, since it had no voxels) refreshes from the new version.
    clients_.changed(clock_.tick, v);
  }
  l.used_tick = clock_.tick;
  count_loaded();
  const std::vector<Waiter> waiters = std::move(waiting->second);
  loading_.erase(waiting);
  for (const Waiter& w : waiters)
    if (clients_.present(w.id)) grant(w.id, c.pos, w.full);
  if (!grants_scheduled_) {
    // Loads finish one by one; hand them over in one go per strand turn.
    grants_scheduled_ = true;
    asio::post(strand_, [this] {
      grants_scheduled_ = false;
      flush_grants();
    });
  }
}

Voxel Residency::get(Vec3i p) const {
  auto it = loaded_.find(chunk_of(p));
  if (it == loaded_.end() || it->second.current->empty() || !it->second.current->has_voxels()) return Voxel{};
  return it->second.current->chunk()->get(local_of(p));
}

bool Residency::read_current(const Region& r, Box& out) const {
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

void Residency::unload_unwatched() {
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
      if (pass.forget && forget.size() + kMaxMipsOnly / 2 < mips_only_ && !clients_.watched(cp) &&
          loading_.count(cp) == 0)
        forget.push_back(cp);
      return;
    }
    if (!pass.lighten || busy_.count(cp) != 0 || l.current != l.published || clients_.held_full(cp) ||
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
  count_loaded();
}

void Residency::lighten_some() {
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
        clients_.held_full(cp) || loading_.count(cp) != 0)
      continue;
    l.published = l.current = ChunkVersion::mips_only(*l.current);
    ++mips_only_;
    ++n;
  }
  if (n > 0) {
    counters_.chunks_unloaded.fetch_add(n, std::memory_order_relaxed);
    count_loaded();
  }
}

void Residency::reserve(const Region& r) {
  for_each_chunk_in(r, [&](Vec3i cp) {
    request(cp);
    ++busy_[cp];
  });
}

void Residency::unbusy(const Region& r) {
  for_each_chunk_in(r, [&](Vec3i cp) {
    auto it = busy_.find(cp);
    if (it != busy_.end() && --it->second <= 0) busy_.erase(it);
  });
}

void Residency::copy_into(Grid& scratch, const Region& r, std::unordered_set<Vec3i, Vec3iHash>& copied) const {
  for_each_chunk_in(r, [&](Vec3i cp) {
    if (!copied.insert(cp).second) return;
    const ChunkVersion& v = *loaded_.at(cp).current;
    if (!v.empty()) scratch.put_chunk(cp, v.chunk()->clone());
  });
}

void Residency::load_unless_loading(Vec3i cp, Storage::Priority priority) {
  if (!loading_.try_emplace(cp).second) return;
  load(cp, priority);
}

}  // namespace terrane
