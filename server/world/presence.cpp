#include "server/world/presence.h"

#include <algorithm>
#include <cmath>

namespace terrane {

PresenceGrid::Cell PresenceGrid::cell_of(Vec3f p) {
  return {static_cast<std::int32_t>(std::floor(p.x / kCell)), static_cast<std::int32_t>(std::floor(p.z / kCell))};
}

void PresenceGrid::place(ClientId id, Vec3f position) {
  auto it = where_.find(id);
  if (it != where_.end()) {
    const Cell old = cell_of(it->second), now = cell_of(position);
    it->second = position;
    auto& v = cells_[old];
    if (old == now) {
      for (Placed& p : v)
        if (p.id == id) p.position = position;
      return;
    }
    std::erase_if(v, [id](const Placed& p) { return p.id == id; });
    if (v.empty()) cells_.erase(old);
    cells_[now].push_back({id, position});
    return;
  }
  where_.emplace(id, position);
  cells_[cell_of(position)].push_back({id, position});
}

void PresenceGrid::remove(ClientId id) {
  auto it = where_.find(id);
  if (it == where_.end()) return;
  const Cell c = cell_of(it->second);
  auto& v = cells_[c];
  std::erase_if(v, [id](const Placed& p) { return p.id == id; });
  if (v.empty()) cells_.erase(c);
  where_.erase(it);
}

std::vector<PresenceEntryMsg> PresenceGrid::nearest(ClientId id, Vec3f p, float radius, std::size_t max) const {
  std::vector<std::pair<float, Placed>> near;  // (a name-less pair: the entries are made for the nearest only)
  near.reserve(64);
  const Cell lo = cell_of({p.x - radius, 0, p.z - radius}), hi = cell_of({p.x + radius, 0, p.z + radius});
  const float r2 = radius * radius;
  for (std::int32_t cz = lo.z; cz <= hi.z; ++cz)
    for (std::int32_t cx = lo.x; cx <= hi.x; ++cx) {
      auto it = cells_.find(Cell{cx, cz});
      if (it == cells_.end()) continue;
      for (const auto& [other, q] : it->second) {
        if (other == id) continue;
        const float dx = q.x - p.x, dy = q.y - p.y, dz = q.z - p.z;
        const float d2 = dx * dx + dy * dy + dz * dz;
        if (d2 > r2) continue;
        near.push_back({d2, Placed{other, q}});
      }
    }
  const std::size_t keep = std::min(near.size(), max);
  std::partial_sort(near.begin(), near.begin() + static_cast<std::ptrdiff_t>(keep), near.end(),
                    [](const auto& a, const auto& b) {
                      return a.first < b.first || (a.first == b.first && a.second.id < b.second.id);
                    });
  std::vector<PresenceEntryMsg> out;
  out.reserve(keep);
  for (std::size_t i = 0; i < keep; ++i)
    out.push_back(PresenceEntryMsg{static_cast<std::uint32_t>(near[i].second.id), near[i].second.position});
  return out;
}

}  // namespace terrane
