#include "client/shared_updates.h"

#include <algorithm>
#include <functional>
#include <string_view>

namespace terrane {

std::size_t SharedUpdates::key_of(const Chunk* base, std::span<const UnitUpdate> units) {
  // Field by field (a UnitUpdate has padding); a voxel is two plain bytes.
  std::size_t h = std::hash<const void*>{}(base);
  auto mix = [&h](std::size_t v) { h ^= v + 0x9E3779B97F4A7C15ull + (h << 6) + (h >> 2); };
  for (const UnitUpdate& u : units) {
    mix(static_cast<std::size_t>(u.unit_index));
    mix(std::hash<std::string_view>{}(
        std::string_view(reinterpret_cast<const char*>(u.voxels.data()), u.voxels.size() * sizeof(Voxel))));
  }
  return h;
}

namespace {

// Whether two chunks hold the same voxels, row by row (their packing may
// differ: each replica's lineage chose its own palettes).
bool same_voxels(const Chunk& a, const Chunk& b) {
  Chunk::Level0::Row ra, rb;
  for (int y = 0; y < kChunkSize; ++y)
    for (int z = 0; z < kChunkSize; ++z)
      if (const Voxel* row = a.read_row(y, z, ra); !std::equal(row, row + kChunkSize, b.read_row(y, z, rb)))
        return false;
  return true;
}

}  // namespace

std::size_t SharedUpdates::AtHash::operator()(const At& a) const noexcept {
  return Vec3iHash{}(a.chunk_pos) ^ std::hash<std::uint64_t>{}(a.revision) * 0x9E3779B97F4A7C15ull;
}

const SharedUpdates::Entry* SharedUpdates::entry_for(std::size_t key, const std::shared_ptr<const Chunk>& base,
                                                     std::span<const UnitUpdate> units) const {
  const auto it = entries_.find(key);
  if (it == entries_.end()) return nullptr;
  const Entry& e = it->second;
  // The very base object, alive (a dead one's address may be reused), and
  // the same units.
  if (e.base.lock() != base || !std::equal(units.begin(), units.end(), e.units.begin(), e.units.end())) return nullptr;
  return &e;
}

std::shared_ptr<const Chunk> SharedUpdates::find(std::size_t key, const std::shared_ptr<const Chunk>& base,
                                                 std::span<const UnitUpdate> units, std::optional<At> at) {
  std::shared_ptr<const Chunk> twin, result;
  {
    std::lock_guard lock(m_);
    if (const Entry* e = entry_for(key, base, units))
      if (std::shared_ptr<const Chunk> r = e->result.lock()) {
        ++stats_.hits;
        return r;
      }
    // base's twin, if another lineage made these units' result of it.
    if (at)
      if (const auto t = twins_.find(*at); t != twins_.end()) {
        twin = t->second.lock();
        if (twin && twin != base)
          if (const Entry* e = entry_for(key_of(twin.get(), units), twin, units)) result = e->result.lock();
      }
    if (!result) {
      ++stats_.misses;
      return nullptr;
    }
  }
  // (Compared outside the lock: the table serves every io thread.)
  const bool equal = same_voxels(*base, *twin);
  std::lock_guard lock(m_);
  if (!equal) {
    ++stats_.misses;
    return nullptr;
  }
  ++stats_.hits;
  ++stats_.twins;
  // The other replicas holding base find the result by base from here on,
  // without comparing again.
  remember(key, base, units, result);
  return result;
}

std::shared_ptr<const Chunk> SharedUpdates::add(std::size_t key, const std::shared_ptr<const Chunk>& base,
                                                std::span<const UnitUpdate> units,
                                                const std::shared_ptr<const Chunk>& result, std::optional<At> at) {
  // An emptied chunk is not kept: the replica erases it (nothing to share).
  if (!result) return result;
  std::shared_ptr<const Chunk> twin;
  {
    std::lock_guard lock(m_);
    if (const Entry* e = entry_for(key, base, units))
      if (std::shared_ptr<const Chunk> first = e->result.lock()) {
        ++stats_.adopted;
        return first;
      }
    if (at)
      if (const auto t = twins_.find(*at); t != twins_.end()) twin = t->second.lock();
  }
  // Another lineage's result at this revision, with equal voxels: held
  // instead, so the two lineages are one from here on.
  const bool joined = twin && twin != result && same_voxels(*twin, *result);
  std::lock_guard lock(m_);
  if (joined) {
    remember(key, base, units, twin);
    ++stats_.twins;
    return twin;
  }
  remember(key, base, units, result);
  if (at) {
    std::weak_ptr<const Chunk>& slot = twins_[*at];
    if (slot.expired()) slot = result;
  }
  if (kept_.size() < kKept) {
    kept_.push_back(result);
  } else {
    kept_[kept_next_] = result;
    kept_next_ = (kept_next_ + 1) % kKept;
  }
  return result;
}

void SharedUpdates::remember(std::size_t key, const std::shared_ptr<const Chunk>& base,
                             std::span<const UnitUpdate> units, const std::shared_ptr<const Chunk>& result) {
  auto over = [&] {
    return entries_.size() >= kCapacity || twins_.size() >= kCapacity || units_held_ + units.size() > kMaxUnits;
  };
  if (over()) drop_dead();
  if (over()) {
    entries_.clear();
    twins_.clear();
    units_held_ = 0;
  }
  Entry& e = entries_[key];
  units_held_ -= e.units.size();
  units_held_ += units.size();
  e.base = base;
  e.units.assign(units.begin(), units.end());
  e.result = result;
}

void SharedUpdates::drop_dead() {
  std::erase_if(entries_, [&](const auto& kv) {
    const bool dead = kv.second.base.expired() || kv.second.result.expired();
    if (dead) units_held_ -= kv.second.units.size();
    return dead;
  });
  std::erase_if(twins_, [](const auto& kv) { return kv.second.expired(); });
}

SharedUpdates::Stats SharedUpdates::stats() const {
  std::lock_guard lock(m_);
  Stats s = stats_;
  s.entries = entries_.size();
  for (const auto& [key, e] : entries_) s.bytes += sizeof(Entry) + 32 + e.units.capacity() * sizeof(UnitUpdate);
  // A kept result counts as its share (its other holders are replicas).
  for (const auto& c : kept_) s.bytes += c->memory().total() / static_cast<std::size_t>(c.use_count());
  return s;
}

}  // namespace terrane
