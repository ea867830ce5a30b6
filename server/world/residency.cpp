#include "server/world/residency.h"

#include <algorithm>
#include <stdexcept>
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

Residency::Residency(Strand& strand, Storage& storage, const WorldOptions& options, ServerCounters& counters,
                     const WorldClock& clock, FanOut& clients, HorizonCache& horizons)
    : strand_(strand),
      storage_(storage),
      options_(options),
      counters_(counters),
      clock_(clock),
      clients_(clients),
      horizons_(horizons) {}

void Residency::count_loaded() { counters_.chunks_loaded.store(with_voxels_, std::memory_order_relaxed); }

const Residency::Loaded& Residency::held(Vec3i cp) const {
  const Loaded* l = find(cp);
  if (l == nullptr) throw std::out_of_range("Residency: chunk not held");
  return *l;
}

std::size_t Residency::version_bytes(const ChunkVersion& v) {
  std::size_t n = sizeof(ChunkVersion) + 16;  // and its control block
  if (const Chunk* c = v.chunk()) {
    n += sizeof(Chunk) + c->level0().heap_bytes();
    for (int level = 1; level < kMipLevels; ++level) n += c->mip_unit(level).size();
  } else if (!v.has_voxels()) {
    // Mips only, or the coarsest level only: made with the version.
    for (int level = 1; level < kMipLevels; ++level)
      if (v.has_level(level)) n += v.encoded(level).size();
  }
  return n;
}

void Residency::count_memory() {
  counters_.memory[MemoryPart::kResidency].store(static_cast<std::int64_t>(chunks_.table_bytes() + versions_bytes_),
                                                 std::memory_order_relaxed);
}

void Residency::hold(ChunkState& s, VersionPtr v) {
  if (s.held.current != nullptr) {
    --(s.held.current->has_voxels() ? with_voxels_ : mips_only_);
    versions_bytes_ -= version_bytes(*s.held.current);
  }
  ++(v->has_voxels() ? with_voxels_ : mips_only_);
  versions_bytes_ += version_bytes(*v);
  s.held.published = v;
  s.held.current = std::move(v);
  count_memory();
}

void Residency::drop(Chunks::iterator it) {
  ChunkState& s = it->second;
  if (s.held.current != nullptr) {
    --(s.held.current->has_voxels() ? with_voxels_ : mips_only_);
    versions_bytes_ -= version_bytes(*s.held.current);
  }
  s.held = Loaded{};
  s.replace_queued = false;
  if (s.vacant()) chunks_.erase(it);
  count_memory();
}

std::size_t Residency::estimates_waiting() const {
  return static_cast<std::size_t>(std::count_if(chunks_.begin(), chunks_.end(), [](const auto& kv) {
    const ChunkState& s = kv.second;
    return s.held.current != nullptr && s.held.current->estimate() && (s.replace_queued || s.load != Load::kNone);
  }));
}

void Residency::retry_unreadable() {
  // Each once, those read (or gone) since left out.
  std::erase_if(retry_, [&](Vec3i cp) {
    auto it = chunks_.find(cp);
    return it == chunks_.end() || it->second.load != Load::kUnreadable;
  });
  std::sort(retry_.begin(), retry_.end(),
            [](Vec3i a, Vec3i b) { return std::tie(a.x, a.y, a.z) < std::tie(b.x, b.y, b.z); });
  retry_.erase(std::unique(retry_.begin(), retry_.end()), retry_.end());
  for (const Vec3i cp : retry_) load(cp, Storage::Priority::kStream);
}

void Residency::for_each(const std::function<void(Vec3i, const Loaded&)>& fn) const {
  for (const auto& [cp, s] : chunks_)
    if (s.held.current != nullptr) fn(cp, s.held);
}

const VersionPtr& Residency::advance(VersionPtr v) {
  Loaded& l = chunks_.at(v->pos()).held;
  if (l.current == nullptr) throw std::out_of_range("Residency: chunk not held");
  versions_bytes_ = versions_bytes_ - version_bytes(*l.current) + version_bytes(*v);
  l.current = std::move(v);
  l.used_tick = clock_.tick;
  return l.current;
}

void Residency::publish(const std::vector<VersionPtr>& versions) {
  flush_grants();
  for (const VersionPtr& v : versions) {
    if (auto it = chunks_.find(v->pos()); it != chunks_.end() && it->second.held.published != nullptr &&
                                          it->second.held.published->revision() < v->revision())
      it->second.held.published = v;
    horizons_.changed(v->pos());
  }
}

void Residency::forget(Vec3i cp) {
  auto it = chunks_.find(cp);
  if (it == chunks_.end() || it->second.held.current == nullptr) return;
  horizons_.changed(cp);
  regions_read_.erase(coarse_region_of(cp));
  drop(it);
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
      wait_for(w.chunk_pos, Waiter{id, w.full});
    }
  }
  flush_grants();
}

void Residency::wait_for(Vec3i cp, Waiter w) {
  // (request made its load under way.)
  auto& waiters = chunks_.at(cp).waiters;
  if (waiters == nullptr) waiters = std::make_unique<std::vector<Waiter>>();
  waiters->push_back(w);
}

void Residency::grant(ClientId id, Vec3i cp, bool full) {
  ChunkState& s = chunks_.at(cp);
  Loaded& l = s.held;
  l.used_tick = clock_.tick;
  if (l.published->estimate() && !s.replace_queued && s.load != Load::kReplacing) {
    s.replace_queued = true;
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
  auto it = chunks_.find(cp);
  if (it != chunks_.end()) {
    if (const VersionPtr& v = it->second.held.current; v != nullptr && v->has_level(level) && !(exact && v->estimate()))
      return true;
  } else {
    it = chunks_.try_emplace(cp).first;
  }
  ChunkState& s = it->second;
  const auto priority = level == 0 ? Storage::Priority::kUrgent : Storage::Priority::kStream;
  if (s.load != Load::kNone) {
    // A background replacement waits behind every other load: whoever
    // needs the chunk now moves it to its own priority, or, if it is being
    // generated already, asks again (the first of the two loads to come
    // back serves the waiters; the other is dropped).
    if (s.load == Load::kReplacing) {
      s.load = Load::kLoading;
      --replacing_;
      if (!storage_.promote(cp, priority)) load(cp, priority);
    }
    return false;
  }
  s.load = Load::kLoading;
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
  if (auto it = chunks_.find(cp);
      it != chunks_.end() && (it->second.held.current != nullptr || it->second.load != Load::kNone))
    return false;
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
    const auto know = [&](Vec3i cp, auto make) {
      ChunkState& s = chunks_[cp];
      if (s.held.current != nullptr) return;
      hold(s, make());
      s.held.used_tick = clock_.tick;
    };
    for (const CoarseEntry& e : c.entries)
      know(e.chunk_pos, [&] { return ChunkVersion::coarse_only(e.chunk_pos, e.revision, e.voxels); });
    for (const Vec3i cp : c.air) know(cp, [&] { return ChunkVersion::coarse_only(cp, 0, CoarseVoxels{}); });
    for (const CoarseEntry& e : c.estimates)
      know(e.chunk_pos, [&] { return ChunkVersion::estimated(e.chunk_pos, e.voxels); });
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
      wait_for(cp, w);
  }
  flush_grants();
}

void Residency::replace_estimates() {
  const std::size_t cap = kReplacingLoadsPerWorker * static_cast<std::size_t>(storage_.loader_threads());
  while (replacing_ < cap && !estimates_.empty() && !clock_.stopping) {
    const Vec3i cp = estimates_.front();
    estimates_.pop_front();
    auto it = chunks_.find(cp);
    if (it == chunks_.end() || !it->second.replace_queued) continue;
    ChunkState& s = it->second;
    s.replace_queued = false;
    // Loaded, being loaded for a client, or no longer held by anyone: left.
    if (!s.held.current->estimate() || s.load != Load::kNone || !clients_.watched(cp)) continue;
    s.load = Load::kReplacing;
    ++replacing_;
    load(cp, Storage::Priority::kBackground);
  }
}

void Residency::on_loaded(LoadedChunk c) {
  const Vec3i cp = c.pos;
  apply_loaded(std::move(c));
  if (watcher_ != nullptr) watcher_->landed(cp);
}

void Residency::apply_loaded(LoadedChunk c) {
  auto it = chunks_.find(c.pos);
  // Not loading: a second load of it, dropped (the first served the waiters).
  if (it == chunks_.end() || it->second.load == Load::kNone) return;
  const bool background = it->second.load == Load::kReplacing;  // a replacement nobody else asked for (yet)
  if (background) {
    it->second.load = Load::kLoading;
    --replacing_;
    replace_estimates();
  }
  ChunkState& s = it->second;  // (replace_estimates adds no entry: nothing moved)
  if (!c.ok) {
    // Not served until a later request can read it: the waiters wait, and
    // the load is tried again next second.
    if (s.load != Load::kUnreadable) {
      server_log().error("chunk ({},{},{}): {}; not served until it can be read", c.pos.x, c.pos.y, c.pos.z, c.error);
      retry_.push_back(c.pos);
    }
    s.load = Load::kUnreadable;
    return;
  }
  if (s.held.current != nullptr && !s.held.current->estimate() && c.revision < s.held.current->revision()) {
    // A load that read the store before a later commit (one overtaken by
    // a more urgent load of the same chunk, answering a newer request):
    // never older than what is held. Read again.
    load(c.pos, Storage::Priority::kUrgent);
    return;
  }
  VersionPtr v = std::make_shared<const ChunkVersion>(c.pos, c.revision, std::move(c.chunk));
  // Sky that replaced an estimate, wanted at full resolution by nobody: kept
  // as its mips (all Air, a few bytes; levels 1..3 answer refinements
  // without generating it again), forgotten when unwatched.
  if (background && v->empty() && (s.waiters == nullptr || s.waiters->empty())) v = ChunkVersion::mips_only(*v);
  bool differs = false;
  if (const ChunkVersion* was = s.held.current.get(); was != nullptr) {
    // It was kept as mips only, or known from a coarse image (so committed:
    // the store has this revision) — unless the row turned out damaged and
    // was quarantined, when the chunk comes back generated at a higher one.
    if (was->estimate()) {
      // Its holders are told only when the exact mip differs from the
      // estimate they hold (an all-Air chunk's mip is all Air: a holder
      // within full resolution is sent Empty when it refines it).
      counters_.estimates_replaced.fetch_add(1, std::memory_order_relaxed);
      // (An all-Air version's level 3 is an all-Air unit.)
      differs = !same_voxels(kCoarseSide, was->encoded(kMipLevels - 1), v->encoded(kMipLevels - 1));
      if (differs) counters_.estimates_corrected.fetch_add(1, std::memory_order_relaxed);
    } else if (was->revision() != c.revision) {
      // Expected where another server of a shared world wrote it (read again
      // for that); otherwise a quarantined row came back generated.
      if (watcher_ == nullptr || !watcher_->stale(c.pos))
        server_log().warn("chunk ({},{},{}): loaded at revision {}, held at {}; its holders are sent the new one",
                          c.pos.x, c.pos.y, c.pos.z, c.revision, was->revision());
      differs = true;
    }
  }
  hold(s, v);
  if (differs) {
    horizons_.changed(c.pos);
    // As a commit would: every holder (all hold it coarser than full
    // resolution, since it had no voxels) refreshes from the new version.
    clients_.changed(clock_.tick, v);
  }
  s.held.used_tick = clock_.tick;
  count_loaded();
  s.load = Load::kNone;
  const std::unique_ptr<std::vector<Waiter>> waiters = std::move(s.waiters);
  if (waiters != nullptr)
    for (const Waiter& w : *waiters)
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
  const Loaded* l = find(chunk_of(p));
  if (l == nullptr || l->current->empty() || !l->current->has_voxels()) return Voxel{};
  return l->current->chunk()->get(local_of(p));
}

bool Residency::read_current(const Region& r, Box& out) const {
  bool all = true;
  for_each_chunk_in(r, [&](Vec3i cp) { all = all && loaded(cp); });
  if (!all) return false;
  for_each_chunk_in(r, [&](Vec3i cp) {
    const Region c = intersect(r, chunk_region(cp));
    const ChunkVersion& v = *held(cp).current;
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
    pass.lighten = with_voxels_ > options_.resident_chunks;
    pass.forget = mips_only_ > kMaxMipsOnly;
    pass.drop.clear();
    if (!pass.lighten && !pass.forget) return;  // nothing to do: asked again next tick
  }
  const std::size_t slots = chunks_.slot_count();
  const std::size_t part = slots / std::max<std::uint32_t>(1, options_.tick_hz) + 1;
  const std::size_t from = pass.next_slot, to = std::min(slots, from + part);
  std::vector<Vec3i> forget;
  chunks_.for_each_in_slots(from, to, [&](Vec3i cp, const ChunkState& s) {
    const Loaded& l = s.held;
    if (l.current == nullptr) return;
    if (!l.current->has_voxels()) {
      // (An all-Air chunk has no voxels to drop, but as its mips it can
      // be forgotten.)
      if (pass.forget && forget.size() + kMaxMipsOnly / 2 < mips_only_ && !clients_.watched(cp) &&
          s.load == Load::kNone && s.busy == 0)
        forget.push_back(cp);
      return;
    }
    if (!pass.lighten || s.busy != 0 || l.current != l.published || clients_.held_full(cp) || s.load != Load::kNone)
      return;
    pass.drop.emplace_back(l.used_tick, cp);
  });
  for (const Vec3i cp : forget) {
    // Its region's image is read again when next wanted.
    regions_read_.erase(coarse_region_of(cp));
    drop(chunks_.find(cp));
  }
  pass.next_slot = to;
  if (to < slots) return;
  pass.next_slot = 0;  // the pass is over
  const std::size_t full = with_voxels_;
  if (pass.lighten && full > options_.resident_chunks) {
    std::vector<std::pair<std::uint64_t, Vec3i>>& drop = pass.drop;
    // Seen over the last second: those lightened or gone since are left
    // out (lighten_some was still working through the previous list, and
    // a table rebuilt meanwhile may have shown one twice), the others taken
    // at their latest use.
    std::erase_if(drop, [&](std::pair<std::uint64_t, Vec3i>& d) {
      const Loaded* l = find(d.second);
      if (l == nullptr || !l->current->has_voxels()) return true;
      d.first = l->used_tick;
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
    auto it = chunks_.find(cp);
    if (it == chunks_.end() || it->second.held.current == nullptr) continue;
    ChunkState& s = it->second;
    const Loaded& l = s.held;
    // Checked again: it may have been asked for at full resolution or
    // edited since the list was made.
    if (!l.current->has_voxels() || s.busy != 0 || l.current != l.published || clients_.held_full(cp) ||
        s.load != Load::kNone)
      continue;
    hold(s, ChunkVersion::mips_only(*l.current));
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
    ++chunks_.at(cp).busy;  // (request made its entry)
  });
}

void Residency::unbusy(const Region& r) {
  for_each_chunk_in(r, [&](Vec3i cp) {
    auto it = chunks_.find(cp);
    if (it == chunks_.end() || it->second.busy == 0) return;
    if (--it->second.busy == 0 && it->second.vacant()) chunks_.erase(it);
  });
}

void Residency::copy_into(Grid& scratch, const Region& r, std::unordered_set<Vec3i, Vec3iHash>& copied) const {
  for_each_chunk_in(r, [&](Vec3i cp) {
    if (!copied.insert(cp).second) return;
    const ChunkVersion& v = *held(cp).current;
    if (!v.empty()) scratch.put_chunk(cp, v.chunk()->clone());
  });
}

void Residency::load_unless_loading(Vec3i cp, Storage::Priority priority) {
  ChunkState& s = chunks_[cp];
  if (s.load != Load::kNone) return;
  s.load = Load::kLoading;
  load(cp, priority);
}

}  // namespace terrane
