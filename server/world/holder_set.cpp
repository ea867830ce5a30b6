#include "server/world/holder_set.h"

#include <algorithm>
#include <bit>

namespace terrane {

std::size_t HolderSet::index_size_for(std::size_t n) {
  if (n <= kScanAtMost) return 0;
  // Between 3/8 and 3/4 full after a rebuild; rebuilt again past 3/4
  // (linear probing stays a few probes a lookup up to there, and the
  // index costs about 7 bytes a holder, less than the holder).
  return std::bit_ceil(n * 4 / 3 + 1);
}

std::uint32_t HolderSet::find(ClientId id, std::uint64_t& probes) const {
  if (index_size_ == 0) {
    for (std::size_t i = 0; i < holders_.size(); ++i) {
      ++probes;
      if (holders_[i].id() == id) return static_cast<std::uint32_t>(i);
    }
    return kNone;
  }
  for (std::size_t s = home(id);; s = (s + 1) & (index_size_ - 1)) {
    const std::uint32_t pos = index_[s];
    if (pos == kNone) return kNone;
    ++probes;
    if (holders_[pos].id() == id) return pos;
  }
}

std::size_t HolderSet::slot_of(ClientId id, std::uint32_t pos, std::uint64_t& probes) const {
  for (std::size_t s = home(id);; s = (s + 1) & (index_size_ - 1)) {
    ++probes;
    if (index_[s] == pos) return s;
  }
}

void HolderSet::index_insert(std::uint32_t pos) {
  std::size_t s = home(holders_[pos].id());
  while (index_[s] != kNone) s = (s + 1) & (index_size_ - 1);
  index_[s] = pos;
}

void HolderSet::index_erase(std::size_t slot) {
  // Shifts back the entries after slot whose home is not between slot and
  // them (cyclically), so every entry stays reachable from its home
  // without a tombstone.
  const std::size_t mask = index_size_ - 1;
  std::size_t gap = slot;
  for (std::size_t s = (slot + 1) & mask; index_[s] != kNone; s = (s + 1) & mask) {
    const std::size_t h = home(holders_[index_[s]].id());
    if (((s - h) & mask) >= ((s - gap) & mask)) {
      index_[gap] = index_[s];
      gap = s;
    }
  }
  index_[gap] = kNone;
}

void HolderSet::rebuild(std::size_t size) {
  index_size_ = static_cast<std::uint32_t>(size);
  if (size == 0) {
    index_.reset();
    return;
  }
  index_ = std::make_unique_for_overwrite<std::uint32_t[]>(size);
  std::fill_n(index_.get(), size, kNone);
  for (std::size_t i = 0; i < holders_.size(); ++i) index_insert(static_cast<std::uint32_t>(i));
}

HolderSet::Held HolderSet::hold(ClientId id, bool full, std::uint64_t& probes) {
  const std::uint32_t pos = find(id, probes);
  if (pos != kNone) {
    ChunkHolder& h = holders_[pos];
    if (h.full() == full) return Held::kSame;
    full_ = full ? full_ + 1 : full_ - 1;
    h.set_full(full);
    return Held::kChanged;
  }
  // Grown by a quarter, not doubled: a crowd's chunk keeps thousands.
  if (holders_.size() == holders_.capacity()) holders_.reserve(holders_.size() + holders_.size() / 4 + 2);
  holders_.emplace_back(id, full);
  if (full) ++full_;
  const std::size_t n = holders_.size();
  if (n > kScanAtMost && (index_size_ == 0 || n * 4 > index_size_ * 3))
    rebuild(index_size_for(n));
  else if (index_size_ != 0)
    index_insert(static_cast<std::uint32_t>(n - 1));
  return Held::kAdded;
}

bool HolderSet::release(ClientId id, std::uint64_t& probes) {
  const std::uint32_t pos = find(id, probes);
  if (pos == kNone) return false;
  if (holders_[pos].full()) --full_;
  const auto last = static_cast<std::uint32_t>(holders_.size() - 1);
  if (index_size_ != 0) {
    index_erase(slot_of(id, pos, probes));
    if (pos != last) index_[slot_of(holders_[last].id(), last, probes)] = pos;
  }
  holders_[pos] = holders_[last];
  holders_.pop_back();
  const std::size_t n = holders_.size();
  if (index_size_ != 0 && (n <= kScanAtMost / 2 || n * 16 < index_size_)) rebuild(index_size_for(n));
  // Memory follows the count down (a crowd that left), in halvings.
  if (holders_.capacity() > 2 * kScanAtMost && n * 4 < holders_.capacity()) holders_.shrink_to_fit();
  return true;
}

}  // namespace terrane
