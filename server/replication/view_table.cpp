#include "server/replication/view_table.h"

#include <map>

#include "common/world/view.h"

namespace terrane {

ViewTable::ViewTable(std::int32_t view_distance, std::int32_t full_res_radius)
    : view_(view_distance),
      full_(full_res_radius),
      n_((std::max(view_distance, 0) + kChunkSize / 2) / kChunkSize),
      offsets_(view_offsets(view_distance)) {
  const std::size_t side = static_cast<std::size_t>(2 * n_ + 1);
  levels_.assign(side * side * side, -1);
  for (const Vec3i o : offsets_) {
    const std::size_t i = (static_cast<std::size_t>(o.y + n_) * side + static_cast<std::size_t>(o.z + n_)) * side +
                          static_cast<std::size_t>(o.x + n_);
    levels_[i] = static_cast<std::int8_t>(offset_level(o, full_));
  }
}

namespace {

struct SharedTables {
  std::mutex mutex;
  std::map<std::pair<std::int32_t, std::int32_t>, std::shared_ptr<const ViewTable>> tables;
};

SharedTables& shared_tables() {
  static SharedTables t;
  return t;
}

}  // namespace

std::size_t ViewTable::shared_count() {
  auto& [mutex, tables] = shared_tables();
  std::lock_guard lock(mutex);
  return tables.size();
}

std::shared_ptr<const ViewTable> ViewTable::get(std::int32_t view_distance, std::int32_t full_res_radius) {
  // A process-wide cache: clients mostly ask for the same few radii. Guarded
  // by a mutex: replicators on any io thread look tables up on (re)plans.
  // The radii come from clients, so the cache is bounded: when full, the
  // tables no replicator uses any more go, and past that a table is made
  // for its caller alone.
  auto& [mutex, tables] = shared_tables();
  std::lock_guard lock(mutex);
  const std::pair key{view_distance, full_res_radius};
  if (auto it = tables.find(key); it != tables.end()) return it->second;
  if (tables.size() >= kMaxShared) std::erase_if(tables, [](const auto& e) { return e.second.use_count() == 1; });
  auto t = std::make_shared<const ViewTable>(view_distance, full_res_radius);
  if (tables.size() < kMaxShared) tables.emplace(key, t);
  return t;
}

int ViewTable::level(Vec3i o) const {
  if (o.x < -n_ || o.x > n_ || o.y < -n_ || o.y > n_ || o.z < -n_ || o.z > n_) return -1;
  const std::size_t side = static_cast<std::size_t>(2 * n_ + 1);
  return levels_[(static_cast<std::size_t>(o.y + n_) * side + static_cast<std::size_t>(o.z + n_)) * side +
                 static_cast<std::size_t>(o.x + n_)];
}

bool ViewTable::contains(Vec3i o) const { return level(o) >= 0; }

const ViewTable::Shells& ViewTable::shells(Vec3i d) const {
  const std::size_t k = delta_index(d);
  std::call_once(shells_once_[k], [&] {
    Shells& s = shells_[k];
    for (const Vec3i o : offsets_) {
      // The chunk at new + o was at offset o + d from the old chunk.
      const int before = level(o + d);
      if (before < 0) s.entering.push_back(o);
      if (!contains(o - d)) s.leaving.push_back(o);
      const int now = level(o);
      if (now < 3 && (before < 0 || now < before)) s.finer.push_back(o);
    }
  });
  return shells_[k];
}

}  // namespace terrane
