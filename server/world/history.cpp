#include "server/world/history.h"

#include "common/codec/byte_rle.h"

namespace terrane {

std::vector<std::uint8_t> snapshot(const Grid& grid, const Region& box) {
  Box b(box.size());
  grid.read_box(box.min, b);
  std::vector<std::uint8_t> out;
  byte_rle_encode(b.voxels(), out);
  return out;
}

void History::push(std::deque<HistoryEntry>& to, HistoryEntry e) {
  bytes_ += e.bytes();
  to.push_back(std::move(e));
  while (bytes_ > max_bytes_ && !(undo_.empty() && redo_.empty())) {
    auto& from = !undo_.empty() ? undo_ : redo_;
    bytes_ -= from.front().bytes();
    from.pop_front();
  }
}

void History::record(HistoryEntry e) {
  for (const HistoryEntry& r : redo_) bytes_ -= r.bytes();
  redo_.clear();
  push(undo_, std::move(e));
}

const HistoryEntry* History::top(bool redo) const {
  const auto& from = redo ? redo_ : undo_;
  return from.empty() ? nullptr : &from.back();
}

void History::drop(bool redo) {
  auto& from = redo ? redo_ : undo_;
  if (from.empty()) return;
  bytes_ -= from.back().bytes();
  from.pop_back();
}

bool History::apply(Grid& grid, bool redo, ChangedUnits& changed, std::string* why) {
  auto& from = redo ? redo_ : undo_;
  auto& to = redo ? undo_ : redo_;
  if (from.empty()) {
    *why = redo ? "nothing to redo" : "nothing to undo";
    return false;
  }
  HistoryEntry e = std::move(from.back());
  from.pop_back();
  bytes_ -= e.bytes();
  const auto n = static_cast<std::size_t>(e.box.volume());
  std::vector<Voxel> before(n), after(n);
  if (!byte_rle_decode(e.before, before) || !byte_rle_decode(e.after, after)) {
    *why = "history damaged";  // our own bytes: cannot happen
    return false;
  }
  HistoryEntry back{e.box, snapshot(grid, e.box), {}};
  const Vec3i size = e.box.size();
  UnitMarker marker(changed);
  grid.modify(e.box, [&](Vec3i p, Voxel cur) {
    const Vec3i l = p - e.box.min;
    const auto i = static_cast<std::size_t>((l.y * size.z + l.z) * size.x + l.x);
    if (cur != after[i] || before[i] == cur) return cur;
    marker.mark(p);
    return before[i];
  });
  back.after = snapshot(grid, e.box);
  push(to, std::move(back));
  (void)to;
  return true;
}

}  // namespace terrane
