// InterestIndex: which clients hold each chunk (chunk -> holders), so a
// tick's changes go to the clients that hold them and to nobody else, and
// a chunk is known to be unwatched without asking every client.
//
// A holder is registered when the world hands it the chunk (so every later
// change reaches it, in order after what it was handed) and removed when it
// says it released the chunk or leaves. "full" marks holders at full
// resolution: their chunks stay resident (edits there are expected).
//
// Each watched chunk's holders are a HolderSet (holder_set.h): holding,
// releasing and asking about one holder cost a bounded number of probes
// however many hold the chunk (a crowd: every client), not a scan of
// them. probes() counts them all, so the bound is testable.
// Thread-safety: none; the world strand owns it.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>

#include "common/voxel/vec3.h"
#include "common/voxel/vec3_map.h"
#include "server/world/holder_set.h"

namespace terrane {

class InterestIndex {
 public:
  using Holder = ChunkHolder;

  // Adds the holder, or updates whether it holds at full resolution.
  void hold(Vec3i chunk_pos, ClientId id, bool full) {
    HolderSet& s = map_[chunk_pos];
    const std::size_t before = s.heap_bytes();
    if (s.hold(id, full, probes_) == HolderSet::Held::kAdded) ++entries_;
    heap_bytes_ += s.heap_bytes() - before;
  }
  void release(Vec3i chunk_pos, ClientId id) {
    auto it = map_.find(chunk_pos);
    if (it == map_.end()) return;
    HolderSet& s = it->second;
    heap_bytes_ -= s.heap_bytes();
    if (s.release(id, probes_)) --entries_;
    if (s.empty())
      map_.erase(it);
    else
      heap_bytes_ += s.heap_bytes();
    // Nobody holds anything (the last client left): the table goes too.
    if (map_.empty()) Vec3iMap<HolderSet>().swap(map_);
  }
  // The holders of a chunk (empty if none); valid until the next change.
  std::span<const Holder> holders(Vec3i chunk_pos) const {
    auto it = map_.find(chunk_pos);
    return it == map_.end() ? std::span<const Holder>{} : it->second.holders();
  }
  bool watched(Vec3i chunk_pos) const { return map_.count(chunk_pos) != 0; }
  bool holds(Vec3i chunk_pos, ClientId id) const {
    auto it = map_.find(chunk_pos);
    return it != map_.end() && it->second.contains(id, probes_);
  }
  bool held_full(Vec3i chunk_pos) const {
    auto it = map_.find(chunk_pos);
    return it != map_.end() && it->second.full() > 0;
  }
  std::size_t chunks() const { return map_.size(); }
  std::size_t entries() const { return entries_; }
  // Holders' ids compared so far by hold, release and holds (the cost
  // bound: a few per call, not the chunk's holders).
  std::uint64_t probes() const { return probes_; }
  // The index's memory: its table of chunks and every chunk's holders.
  std::size_t memory_bytes() const { return map_.table_bytes() + heap_bytes_; }

 private:
  Vec3iMap<HolderSet> map_;
  std::size_t entries_ = 0;
  std::size_t heap_bytes_ = 0;  // the HolderSets' own (heap_bytes)
  mutable std::uint64_t probes_ = 0;
};

}  // namespace terrane
