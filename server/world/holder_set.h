// HolderSet: the holders of one chunk (the clients it was granted to),
// each with whether it holds the chunk at full resolution. The interest
// index keeps one per watched chunk.
//
// The holders sit side by side in one vector (the order fan-out walks
// them in; a removal moves the last into the gap). A chunk with more than
// kScanAtMost holders (a crowd: every bot near the spawn holds its chunks)
// also has an index beside them: an open-addressing table, by client id,
// of each holder's position in the vector, at most 3/4 full, linear
// probing, erased by shifting back (no tombstones). So finding, adding and
// removing a holder cost a bounded number of probes whatever the count,
// not a scan; the table is rebuilt when it passes 3/4 full or falls to a
// sixteenth (amortized O(1)). Both are this one structure's
// state, changed together by its own methods.
//
// A holder is 8 bytes: the client id shifted left by one with the full
// flag in bit 0 (ids are below 2^63: SessionTable counts them from 1).
//
// Every operation adds the probes it made (comparisons of a holder's id)
// to the counter it is given: the cost bound is testable.
// Thread-safety: none (the world strand, through InterestIndex).
#pragma once

#include <cassert>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

namespace terrane {

using ClientId = std::uint64_t;

class ChunkHolder {
 public:
  ChunkHolder(ClientId id, bool full) : bits_(id << 1 | (full ? 1 : 0)) { assert(id < (ClientId{1} << 63)); }
  ClientId id() const { return bits_ >> 1; }
  bool full() const { return (bits_ & 1) != 0; }
  void set_full(bool full) { bits_ = (bits_ & ~std::uint64_t{1}) | (full ? 1 : 0); }

 private:
  std::uint64_t bits_;
};
static_assert(sizeof(ChunkHolder) == 8);

class HolderSet {
 public:
  // Up to this many holders a lookup scans them (as fast as a table at
  // that size, and no table's bytes for the many chunks with few holders).
  static constexpr std::size_t kScanAtMost = 8;

  // What hold() did.
  enum class Held : std::uint8_t { kAdded, kChanged, kSame };
  // Adds id, or sets whether it holds at full resolution.
  Held hold(ClientId id, bool full, std::uint64_t& probes);
  // Removes id; false if it was not a holder.
  bool release(ClientId id, std::uint64_t& probes);
  bool contains(ClientId id, std::uint64_t& probes) const { return find(id, probes) != kNone; }

  std::span<const ChunkHolder> holders() const { return holders_; }
  std::size_t size() const { return holders_.size(); }
  bool empty() const { return holders_.empty(); }
  // Holders at full resolution.
  std::size_t full() const { return full_; }
  // The heap bytes this set holds (its holders' and its index's capacity).
  std::size_t heap_bytes() const {
    return holders_.capacity() * sizeof(ChunkHolder) + std::size_t{index_size_} * sizeof(std::uint32_t);
  }
  // The index's slots (0 while the holders are scanned).
  std::size_t index_size() const { return index_size_; }

 private:
  static constexpr std::uint32_t kNone = ~std::uint32_t{0};
  std::size_t home(ClientId id) const {
    return static_cast<std::size_t>((id * 0x9E3779B97F4A7C15ull) >> 32) & (index_size_ - 1);
  }
  // id's position in holders_, or kNone.
  std::uint32_t find(ClientId id, std::uint64_t& probes) const;
  // The index slot holding position pos of id (present).
  std::size_t slot_of(ClientId id, std::uint32_t pos, std::uint64_t& probes) const;
  void index_insert(std::uint32_t pos);
  void index_erase(std::size_t slot);
  // An index of size slots (0: none) for the holders there are.
  void rebuild(std::size_t size);
  // The index's size for n holders: 0 up to kScanAtMost, else a power of
  // two above 4n/3.
  static std::size_t index_size_for(std::size_t n);

  std::vector<ChunkHolder> holders_;
  std::unique_ptr<std::uint32_t[]> index_;  // positions in holders_, kNone: empty
  std::uint32_t index_size_ = 0;
  std::uint32_t full_ = 0;
};

}  // namespace terrane
