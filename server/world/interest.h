// InterestIndex: which clients hold each chunk (chunk -> holders), so a
// tick's changes go to the clients that hold them and to nobody else, and
// a chunk is known to be unwatched without asking every client.
//
// A holder is registered when the world hands it the chunk (so every later
// change reaches it, in order after what it was handed) and removed when it
// says it released the chunk or leaves. "full" marks holders at full
// resolution: their chunks stay resident (edits there are expected).
// Thread-safety: none; the world strand owns it.
#pragma once

#include <algorithm>
#include <cstdint>
#include <vector>

#include "common/voxel/vec3.h"
#include "common/voxel/vec3_map.h"

namespace terrane {

using ClientId = std::uint64_t;

class InterestIndex {
 public:
  struct Holder {
    ClientId id;
    bool full;
  };

  // Adds the holder, or updates whether it holds at full resolution.
  void hold(Vec3i chunk_pos, ClientId id, bool full) {
    auto& v = map_[chunk_pos];
    for (Holder& h : v.holders)
      if (h.id == id) {
        if (h.full != full) v.full += full ? 1 : -1;
        h.full = full;
        return;
      }
    v.holders.push_back(Holder{id, full});
    if (full) ++v.full;
    ++entries_;
  }
  void release(Vec3i chunk_pos, ClientId id) {
    auto it = map_.find(chunk_pos);
    if (it == map_.end()) return;
    auto& hs = it->second.holders;
    for (std::size_t i = 0; i < hs.size(); ++i)
      if (hs[i].id == id) {
        if (hs[i].full) --it->second.full;
        hs[i] = hs.back();
        hs.pop_back();
        --entries_;
        break;
      }
    if (hs.empty()) map_.erase(it);
  }
  // The holders of a chunk (empty if none); valid until the next change.
  const std::vector<Holder>& holders(Vec3i chunk_pos) const {
    auto it = map_.find(chunk_pos);
    return it == map_.end() ? none_ : it->second.holders;
  }
  bool watched(Vec3i chunk_pos) const { return map_.count(chunk_pos) != 0; }
  bool holds(Vec3i chunk_pos, ClientId id) const {
    const auto& hs = holders(chunk_pos);
    return std::any_of(hs.begin(), hs.end(), [id](const Holder& h) { return h.id == id; });
  }
  bool held_full(Vec3i chunk_pos) const {
    auto it = map_.find(chunk_pos);
    return it != map_.end() && it->second.full > 0;
  }
  std::size_t chunks() const { return map_.size(); }
  std::size_t entries() const { return entries_; }

 private:
  struct Entry {
    std::vector<Holder> holders;
    int full = 0;
  };
  Vec3iMap<Entry> map_;
  std::vector<Holder> none_;
  std::size_t entries_ = 0;
};

}  // namespace terrane
