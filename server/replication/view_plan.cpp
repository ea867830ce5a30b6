#include "server/replication/view_plan.h"

#include <algorithm>
#include <tuple>

#include "common/world/view.h"
#include "protocol/messages.h"

namespace terrane {

void ViewPlan::reset(std::int32_t view_distance, std::int32_t full_res_radius, std::int32_t margin, Vec3i center) {
  table_ = ViewTable::get(view_distance, full_res_radius);
  keep_table_ = ViewTable::get(view_distance + margin, full_res_radius);
  center_ = center;
  coarse_center_ = center;
  coarse_pos_ = 0;
  entering_.clear();
  refine_.clear();
  refine_stale_ = false;
}

void ViewPlan::shift(Vec3i d) {
  center_ = center_ + d;
  for (const Vec3i o : table_->entering(d)) entering_.push_back(center_ + o);
  refine_stale_ = true;  // keys are distances to the old centre: recomputed when next read
}

bool ViewPlan::in_view(Vec3i cp) const {
  // A chunk beyond the wire's range (+-2^19 chunks) is never in view: a
  // client near x = +-2^24 would take its record for a protocol error.
  return table_->contains(cp - center_) && bounds_.touches_chunk(cp) && wire_chunk_ok(cp);
}

int ViewPlan::desired(Vec3i cp) const {
  const int level = table_->level(cp - center_);
  return level < 0 ? kMipLevels : level;  // kept beyond the view: wants nothing finer
}

std::optional<Vec3i> ViewPlan::next_coarse() {
  const auto& offsets = table_->offsets();
  if (coarse_pos_ < offsets.size()) return coarse_center_ + offsets[coarse_pos_++];
  if (entering_.empty()) return std::nullopt;
  const Vec3i cp = entering_.front();
  entering_.pop_front();
  return cp;
}

void ViewPlan::push_refine(Vec3i cp) {
  refine_.emplace_back(offset_center_dist2(cp - center_), cp);
  if (!refine_stale_) std::push_heap(refine_.begin(), refine_.end(), RefineOrder{});
}

void ViewPlan::refill_refine(const std::vector<Vec3i>& chunks) {
  refine_.clear();
  for (const Vec3i cp : chunks) refine_.emplace_back(offset_center_dist2(cp - center_), cp);
  std::make_heap(refine_.begin(), refine_.end(), RefineOrder{});
  refine_stale_ = false;
}

std::optional<Vec3i> ViewPlan::pop_refine(const std::function<bool(Vec3i)>& needs) {
  if (refine_stale_) rebuild_refine(needs);
  if (refine_.empty()) return std::nullopt;
  std::pop_heap(refine_.begin(), refine_.end(), RefineOrder{});
  const Vec3i cp = refine_.back().second;
  refine_.pop_back();
  // A joining client queues most of its view once: the room goes when
  // the queue drains (shrinking keeps the heap's order).
  if (refine_.capacity() > kRefineRoomKept && refine_.size() * 4 < refine_.capacity()) refine_.shrink_to_fit();
  return cp;
}

void ViewPlan::rebuild_refine(const std::function<bool(Vec3i)>& needs) {
  std::erase_if(refine_, [&](const RefineEntry& e) { return !needs(e.second); });
  for (RefineEntry& e : refine_) e.first = offset_center_dist2(e.second - center_);
  // Nearest first, ties by position; repeats (pushed again by later moves) once.
  std::sort(refine_.begin(), refine_.end(), [](const RefineEntry& a, const RefineEntry& b) {
    return std::tie(a.first, a.second.y, a.second.z, a.second.x) < std::tie(b.first, b.second.y, b.second.z, b.second.x);
  });
  refine_.erase(std::unique(refine_.begin(), refine_.end()), refine_.end());
  std::make_heap(refine_.begin(), refine_.end(), RefineOrder{});
  refine_stale_ = false;
}

}  // namespace terrane
