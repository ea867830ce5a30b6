// InterestIndex: which clients hold each chunk (chunk -> holders), so a
// tick's changes go to the clients that hold them and to nobody else, and
// a chunk is known to be unwatched without asking every client.
//
// A holder is registered when the world hands it the chunk (so every later
// change reaches it, in order after what it was handed) and removed when it
// says it released the chunk or leaves. "full" marks holders at full
// resolution: their chunks stay resident (edits there are expected).
//
// The holders are kept per region of 8^3 chunks (RegionHolders,
// region_holders.h): per client a mask of the region's chunks it holds,
// per chunk a count. A view's thousands of chunks, nearly all held coarser
// than full resolution, cost a few dozen regions' members instead of an
// entry each. Holding, releasing and asking about one holder cost a
// bounded number of probes however many hold the chunk (a crowd: every
// client), not a scan of them; probes() counts them all, so the bound is
// testable.
// Thread-safety: none; the world strand owns it.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>

#include "common/voxel/vec3.h"
#include "common/voxel/vec3_map.h"
#include "common/world/coarse_image.h"
#include "server/world/region_holders.h"

namespace terrane {

class InterestIndex {
 public:
  using Holder = ChunkHolder;

  // Adds the holder, or updates whether it holds at full resolution.
  void hold(Vec3i chunk_pos, ClientId id, bool full);
  void release(Vec3i chunk_pos, ClientId id);
  // fn(Holder) for each holder of the chunk, in no set order. fn must not
  // change the index.
  template <class Fn>
  void for_each_holder(Vec3i chunk_pos, Fn&& fn) const {
    if (const RegionHolders* r = region(chunk_pos)) r->for_each_holder(coarse_index(chunk_pos), fn);
  }
  // How many hold the chunk.
  std::size_t holder_count(Vec3i chunk_pos) const {
    const RegionHolders* r = region(chunk_pos);
    return r == nullptr ? 0 : r->holders(coarse_index(chunk_pos));
  }
  bool watched(Vec3i chunk_pos) const { return holder_count(chunk_pos) != 0; }
  bool holds(Vec3i chunk_pos, ClientId id) const {
    const RegionHolders* r = region(chunk_pos);
    return r != nullptr && r->holds(coarse_index(chunk_pos), id, probes_);
  }
  bool held_full(Vec3i chunk_pos) const {
    const RegionHolders* r = region(chunk_pos);
    return r != nullptr && r->full(coarse_index(chunk_pos)) > 0;
  }
  // Chunks with a holder, and (chunk, holder) pairs.
  std::size_t chunks() const { return chunks_; }
  std::size_t entries() const { return entries_; }
  // Regions with a holder, and (region, client) pairs.
  std::size_t regions() const { return map_.size(); }
  std::size_t members() const { return members_; }
  // Holders' ids compared so far by hold, release and holds (the cost
  // bound: a few per call, not the chunk's holders).
  std::uint64_t probes() const { return probes_; }
  // The index's memory: its table of regions, the regions and their
  // members.
  std::size_t memory_bytes() const { return map_.table_bytes() + heap_bytes_; }

 private:
  const RegionHolders* region(Vec3i chunk_pos) const {
    auto it = map_.find(coarse_region_of(chunk_pos));
    return it == map_.end() ? nullptr : it->second.get();
  }

  Vec3iMap<std::unique_ptr<RegionHolders>> map_;  // by coarse_region_of
  std::size_t chunks_ = 0, entries_ = 0, members_ = 0;
  std::size_t heap_bytes_ = 0;  // the regions' own and their heap_bytes
  mutable std::uint64_t probes_ = 0;
};

}  // namespace terrane
