// IdTable<Entry>: entries with distinct client ids, side by side in one
// vector (the order fan-out walks them in; a removal moves the last into
// the gap), found by id in a bounded number of probes however many there
// are. Up to kScanAtMost entries a lookup scans them (as fast as a table at
// that size, and no table's bytes for the many sets with few entries);
// past that an index sits beside them: an open-addressing table, by id, of
// each entry's position in the vector, at most 3/4 full, linear probing,
// erased by shifting back (no tombstones), rebuilt when it passes 3/4 full
// or falls to a sixteenth (amortized O(1)). Both are this one structure's
// state, changed together by its own methods.
//
// Entry: copyable, with `ClientId id() const`. The interest index keeps
// one table per region of 8^3 chunks: its clients (RegionHolders).
//
// Every lookup adds the probes it made (comparisons of an entry's id) to
// the counter it is given: the cost bound is testable.
// Thread-safety: none (the world strand, through InterestIndex).
#pragma once

#include <algorithm>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

namespace terrane {

using ClientId = std::uint64_t;

template <class Entry>
class IdTable {
 public:
  static constexpr std::size_t kScanAtMost = 8;

  // id's entry, or null (valid until the next change).
  Entry* find(ClientId id, std::uint64_t& probes) {
    const std::uint32_t pos = position(id, probes);
    return pos == kNone ? nullptr : &entries_[pos];
  }
  const Entry* find(ClientId id, std::uint64_t& probes) const {
    const std::uint32_t pos = position(id, probes);
    return pos == kNone ? nullptr : &entries_[pos];
  }
  // Adds e (precondition: its id is not here); returns it in place.
  Entry& add(const Entry& e) {
    // Grown by a quarter, not doubled: a crowd's chunk keeps thousands.
    if (entries_.size() == entries_.capacity()) entries_.reserve(entries_.size() + entries_.size() / 4 + 2);
    entries_.push_back(e);
    const std::size_t n = entries_.size();
    if (n > kScanAtMost && (index_size_ == 0 || n * 4 > index_size_ * 3))
      rebuild(index_size_for(n));
    else if (index_size_ != 0)
      index_insert(static_cast<std::uint32_t>(n - 1));
    return entries_.back();
  }
  // Removes id's entry; false if there is none.
  bool erase(ClientId id, std::uint64_t& probes) {
    const std::uint32_t pos = position(id, probes);
    if (pos == kNone) return false;
    const auto last = static_cast<std::uint32_t>(entries_.size() - 1);
    if (index_size_ != 0) {
      index_erase(slot_of(id, pos, probes));
      if (pos != last) index_[slot_of(entries_[last].id(), last, probes)] = pos;
    }
    entries_[pos] = entries_[last];
    entries_.pop_back();
    const std::size_t n = entries_.size();
    if (index_size_ != 0 && (n <= kScanAtMost / 2 || n * 16 < index_size_)) rebuild(index_size_for(n));
    // Memory follows the count down (a crowd that left), in halvings.
    if (entries_.capacity() > 2 * kScanAtMost && n * 4 < entries_.capacity()) entries_.shrink_to_fit();
    return true;
  }

  std::span<const Entry> entries() const { return entries_; }
  std::size_t size() const { return entries_.size(); }
  bool empty() const { return entries_.empty(); }
  // The heap bytes this table holds (its entries' and its index's capacity).
  std::size_t heap_bytes() const {
    return entries_.capacity() * sizeof(Entry) + std::size_t{index_size_} * sizeof(std::uint32_t);
  }
  // The index's slots (0 while the entries are scanned).
  std::size_t index_size() const { return index_size_; }

 private:
  static constexpr std::uint32_t kNone = ~std::uint32_t{0};

  std::size_t home(ClientId id) const {
    return static_cast<std::size_t>((id * 0x9E3779B97F4A7C15ull) >> 32) & (index_size_ - 1);
  }
  // id's position in entries_, or kNone.
  std::uint32_t position(ClientId id, std::uint64_t& probes) const {
    if (index_size_ == 0) {
      for (std::size_t i = 0; i < entries_.size(); ++i) {
        ++probes;
        if (entries_[i].id() == id) return static_cast<std::uint32_t>(i);
      }
      return kNone;
    }
    for (std::size_t s = home(id);; s = (s + 1) & (index_size_ - 1)) {
      const std::uint32_t pos = index_[s];
      if (pos == kNone) return kNone;
      ++probes;
      if (entries_[pos].id() == id) return pos;
    }
  }
  // The index slot holding position pos of id (present).
  std::size_t slot_of(ClientId id, std::uint32_t pos, std::uint64_t& probes) const {
    for (std::size_t s = home(id);; s = (s + 1) & (index_size_ - 1)) {
      ++probes;
      if (index_[s] == pos) return s;
    }
  }
  void index_insert(std::uint32_t pos) {
    std::size_t s = home(entries_[pos].id());
    while (index_[s] != kNone) s = (s + 1) & (index_size_ - 1);
    index_[s] = pos;
  }
  // Shifts back the entries after slot whose home is not between slot and
  // them (cyclically), so every entry stays reachable from its home
  // without a tombstone.
  void index_erase(std::size_t slot) {
    const std::size_t mask = index_size_ - 1;
    std::size_t gap = slot;
    for (std::size_t s = (slot + 1) & mask; index_[s] != kNone; s = (s + 1) & mask) {
      const std::size_t h = home(entries_[index_[s]].id());
      if (((s - h) & mask) >= ((s - gap) & mask)) {
        index_[gap] = index_[s];
        gap = s;
      }
    }
    index_[gap] = kNone;
  }
  // An index of size slots (0: none) for the entries there are.
  void rebuild(std::size_t size) {
    index_size_ = static_cast<std::uint32_t>(size);
    if (size == 0) {
      index_.reset();
      return;
    }
    index_ = std::make_unique_for_overwrite<std::uint32_t[]>(size);
    std::fill_n(index_.get(), size, kNone);
    for (std::size_t i = 0; i < entries_.size(); ++i) index_insert(static_cast<std::uint32_t>(i));
  }
  // The index's size for n entries: 0 up to kScanAtMost, else a power of
  // two above 4n/3 (between 3/8 and 3/4 full after a rebuild; linear
  // probing stays a few probes a lookup up to there, and the index costs
  // about 7 bytes an entry).
  static std::size_t index_size_for(std::size_t n) {
    if (n <= kScanAtMost) return 0;
    return std::bit_ceil(n * 4 / 3 + 1);
  }

  std::vector<Entry> entries_;
  std::unique_ptr<std::uint32_t[]> index_;  // positions in entries_, kNone: empty
  std::uint32_t index_size_ = 0;
};

}  // namespace terrane
