#include "server/world/interest.h"

namespace terrane {

void InterestIndex::hold(Vec3i chunk_pos, ClientId id, bool full) {
  std::unique_ptr<RegionHolders>& r = map_[coarse_region_of(chunk_pos)];
  if (!r) {
    r = std::make_unique<RegionHolders>();
    heap_bytes_ += sizeof(RegionHolders);
  }
  const int index = coarse_index(chunk_pos);
  const std::size_t heap = r->heap_bytes(), members = r->members();
  if (r->hold(index, id, full, probes_) == RegionHolders::Held::kAdded) {
    ++entries_;
    if (r->holders(index) == 1) ++chunks_;
  }
  heap_bytes_ += r->heap_bytes() - heap;
  members_ += r->members() - members;
}

void InterestIndex::release(Vec3i chunk_pos, ClientId id) {
  auto it = map_.find(coarse_region_of(chunk_pos));
  if (it == map_.end()) return;
  RegionHolders& r = *it->second;
  const int index = coarse_index(chunk_pos);
  heap_bytes_ -= r.heap_bytes();
  members_ -= r.members();
  if (r.release(index, id, probes_)) {
    --entries_;
    if (r.holders(index) == 0) --chunks_;
  }
  members_ += r.members();
  if (r.empty()) {
    heap_bytes_ -= sizeof(RegionHolders);
    map_.erase(it);
  } else {
    heap_bytes_ += r.heap_bytes();
  }
  // Nobody holds anything (the last client left): the table goes too.
  if (map_.empty()) Vec3iMap<std::unique_ptr<RegionHolders>>().swap(map_);
}

}  // namespace terrane
