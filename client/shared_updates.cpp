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

std::shared_ptr<const Chunk> SharedUpdates::find(std::size_t key, const std::shared_ptr<const Chunk>& base,
                                                 std::span<const UnitUpdate> units) {
  std::lock_guard lock(m_);
  auto it = entries_.find(key);
  if (it != entries_.end()) {
    const Entry& e = it->second;
    // The very base object, alive (a dead one's address may be reused),
    // and the same units.
    if (e.base.lock() == base && std::equal(units.begin(), units.end(), e.units.begin(), e.units.end())) {
      if (std::shared_ptr<const Chunk> result = e.result.lock()) {
        ++stats_.hits;
        return result;
      }
    }
  }
  ++stats_.misses;
  return nullptr;
}

std::shared_ptr<const Chunk> SharedUpdates::add(std::size_t key, const std::shared_ptr<const Chunk>& base,
                                                std::span<const UnitUpdate> units,
                                                const std::shared_ptr<const Chunk>& result) {
  // An emptied chunk is not kept: the replica erases it (nothing to share).
  if (!result) return result;
  std::lock_guard lock(m_);
  if (const auto it = entries_.find(key); it != entries_.end()) {
    const Entry& e = it->second;
    if (e.base.lock() == base && std::equal(units.begin(), units.end(), e.units.begin(), e.units.end()))
      if (std::shared_ptr<const Chunk> first = e.result.lock()) {
        ++stats_.adopted;
        return first;
      }
  }
  auto over = [&] { return entries_.size() >= kCapacity || units_held_ + units.size() > kMaxUnits; };
  if (over()) drop_dead();
  if (over()) {
    entries_.clear();
    units_held_ = 0;
  }
  Entry& e = entries_[key];
  units_held_ -= e.units.size();
  units_held_ += units.size();
  e.base = base;
  e.units.assign(units.begin(), units.end());
  e.result = result;
  if (kept_.size() < kKept) {
    kept_.push_back(result);
  } else {
    kept_[kept_next_] = result;
    kept_next_ = (kept_next_ + 1) % kKept;
  }
  return result;
}

void SharedUpdates::drop_dead() {
  std::erase_if(entries_, [&](const auto& kv) {
    const bool dead = kv.second.base.expired() || kv.second.result.expired();
    if (dead) units_held_ -= kv.second.units.size();
    return dead;
  });
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
