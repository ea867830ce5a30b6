#include "server/world/region_holders.h"

namespace terrane {

RegionHolders::Held RegionHolders::hold(int index, ClientId id, bool full, std::uint64_t& probes) {
  assert(index >= 0 && index < kChunks);
  Counts& c = counts_[static_cast<std::size_t>(index)];
  Member* m = members_.find(id, probes);
  if (m == nullptr) m = &members_.add(Member{id, {}, {}});
  if (m->held.test(index)) {
    if (m->full.test(index) == full) return Held::kSame;
    m->full.set(index, full);
    c.full = full ? c.full + 1 : c.full - 1;
    return Held::kChanged;
  }
  m->held.set(index, true);
  m->full.set(index, full);
  ++c.held;
  if (full) ++c.full;
  return Held::kAdded;
}

bool RegionHolders::release(int index, ClientId id, std::uint64_t& probes) {
  assert(index >= 0 && index < kChunks);
  Member* m = members_.find(id, probes);
  if (m == nullptr || !m->held.test(index)) return false;
  Counts& c = counts_[static_cast<std::size_t>(index)];
  --c.held;
  if (m->full.test(index)) --c.full;
  m->held.set(index, false);
  m->full.set(index, false);
  if (m->held.none()) members_.erase(id, probes);
  return true;
}

}  // namespace terrane
