// RegionHolders: the holders of one region's chunks (8^3 chunks, the
// horizon's region, common/world/coarse_image.h): for each client holding
// any of them, which it holds and which of those at full resolution, as
// two 512-bit masks; and for each chunk, how many hold it and how many at
// full resolution.
//
// A client's view holds thousands of chunks, nearly all of them coarser
// than full resolution and in a few dozen regions: kept per chunk, a
// holder costs every chunk of every view an entry (about 20 bytes with its
// share of the chunk's index); kept per region, a region's member costs
// 136 bytes for up to 512 chunks. Holding, releasing and asking about one
// (client, chunk) is a lookup of the member in an IdTable (id_table.h, a
// bounded number of probes however many clients hold the region) and a bit.
// Walking a chunk's holders walks the region's members and tests a bit.
//
// Thread-safety: none (the world strand, through InterestIndex).
#pragma once

#include <array>
#include <cassert>
#include <cstddef>
#include <cstdint>

#include "server/world/id_table.h"

namespace terrane {

// One holder of one chunk: the client and whether it holds the chunk at
// full resolution (8 bytes: the id shifted left by one, the flag in bit 0;
// ids are below 2^63, SessionTable counts them from 1).
class ChunkHolder {
 public:
  ChunkHolder(ClientId id, bool full) : bits_(id << 1 | (full ? 1 : 0)) { assert(id < (ClientId{1} << 63)); }
  ClientId id() const { return bits_ >> 1; }
  bool full() const { return (bits_ & 1) != 0; }

 private:
  std::uint64_t bits_;
};
static_assert(sizeof(ChunkHolder) == 8);

class RegionHolders {
 public:
  static constexpr int kChunks = 512;  // kCoarseRegionChunks^3; index: coarse_index

  // What hold() did.
  enum class Held : std::uint8_t { kAdded, kChanged, kSame };
  // id holds chunk `index` (full: at full resolution), or now at the
  // other resolution.
  Held hold(int index, ClientId id, bool full, std::uint64_t& probes);
  // id no longer holds chunk `index`; false if it did not.
  bool release(int index, ClientId id, std::uint64_t& probes);
  bool holds(int index, ClientId id, std::uint64_t& probes) const {
    const Member* m = members_.find(id, probes);
    return m != nullptr && m->held.test(index);
  }

  // How many hold chunk `index`, and how many of them at full resolution.
  std::uint32_t holders(int index) const { return counts_[static_cast<std::size_t>(index)].held; }
  std::uint32_t full(int index) const { return counts_[static_cast<std::size_t>(index)].full; }
  // fn(ChunkHolder) for each holder of chunk `index`, in no set order.
  template <class Fn>
  void for_each_holder(int index, Fn&& fn) const {
    if (holders(index) == 0) return;
    for (const Member& m : members_.entries())
      if (m.held.test(index)) fn(ChunkHolder(m.id(), m.full.test(index)));
  }

  // Clients holding any of the region's chunks.
  std::size_t members() const { return members_.size(); }
  bool empty() const { return members_.empty(); }
  // The heap bytes this region holds beyond its own size (its members').
  std::size_t heap_bytes() const { return members_.heap_bytes(); }

 private:
  struct Mask {
    std::array<std::uint64_t, kChunks / 64> words{};
    bool test(int i) const { return (words[static_cast<std::size_t>(i >> 6)] >> (i & 63) & 1) != 0; }
    void set(int i, bool on) {
      std::uint64_t& w = words[static_cast<std::size_t>(i >> 6)];
      const std::uint64_t bit = std::uint64_t{1} << (i & 63);
      w = on ? (w | bit) : (w & ~bit);
    }
    bool none() const {
      for (const std::uint64_t w : words)
        if (w != 0) return false;
      return true;
    }
  };
  struct Member {
    ClientId client = 0;
    Mask held, full;  // full: a subset of held
    ClientId id() const { return client; }
  };
  struct Counts {
    std::uint32_t held = 0, full = 0;
  };

  IdTable<Member> members_;
  std::array<Counts, kChunks> counts_{};
};

}  // namespace terrane
