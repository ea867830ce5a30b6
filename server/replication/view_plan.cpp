#include "server/replication/view_plan.h"

#include <algorithm>
#include <limits>
#include <optional>
#include <tuple>

#include "common/world/coarse_image.h"
#include "common/world/view.h"
#include "protocol/messages.h"

namespace terrane {

namespace {
// Chunk coordinates the wire carries: -kWireChunks..kWireChunks.
constexpr std::int32_t kWireChunks = kMaxWireCoordinate / kChunkSize;
}  // namespace

void ViewPlan::reset(std::int32_t view_distance, std::int32_t full_res_radius, std::int32_t margin, Vec3i center) {
  table_ = ViewTable::get(view_distance, full_res_radius);
  keep_distance_ = view_distance + margin;
  if (keep_table_ != nullptr &&
      (keep_table_->view_distance() != keep_distance_ || keep_table_->full_res_radius() != full_res_radius))
    keep_table_.reset();
  center_ = center;
  coarse_center_ = center;
  coarse_pos_ = 0;
  entering_.clear();
  refine_.clear();
  refine_stale_ = false;
}

const ViewTable& ViewPlan::keep_table() const {
  if (keep_table_ == nullptr) keep_table_ = ViewTable::get(keep_distance_, table_->full_res_radius());
  return *keep_table_;
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

std::pair<Vec3i, Vec3i> ViewPlan::region_span(Vec3i region) const {
  // The chunk ranges per axis that touch the world's bounds (a chunk touches
  // them when it does on every axis) and lie within the wire's range.
  const auto span = [](std::int32_t min, std::int32_t max) {
    return std::pair{std::max(floor_div(min, kChunkSize), -kWireChunks), std::min(floor_div(max - 1, kChunkSize), kWireChunks)};
  };
  const auto [ylo, yhi] = span(bounds_.min_y, bounds_.max_y);
  const auto [xlo, xhi] = bounds_.bounded_xz ? span(bounds_.min_x, bounds_.max_x) : std::pair{-kWireChunks, kWireChunks};
  const auto [zlo, zhi] = bounds_.bounded_xz ? span(bounds_.min_z, bounds_.max_z) : std::pair{-kWireChunks, kWireChunks};
  const Vec3i first = region * kCoarseRegionChunks;
  const Vec3i last = first + Vec3i{kCoarseRegionChunks - 1, kCoarseRegionChunks - 1, kCoarseRegionChunks - 1};
  return {Vec3i{std::max(first.x, xlo), std::max(first.y, ylo), std::max(first.z, zlo)},
          Vec3i{std::min(last.x, xhi), std::min(last.y, yhi), std::min(last.z, zhi)}};
}

std::vector<ViewPlan::RegionStart> ViewPlan::unknown_regions(const std::function<bool(Vec3i)>& may_know,
                                                              const std::function<bool(Vec3i)>& known) const {
  const std::int32_t view = table_->view_distance();
  const std::int32_t n = (std::max(view, 0) + kChunkSize / 2) / kChunkSize;  // offsets lie in [-n, n]^3
  // The view's order: nearest centre first, ties by y, z, x of the offset.
  using Key = std::tuple<std::int64_t, std::int32_t, std::int32_t, std::int32_t>;
  const auto key = [&](Vec3i cp) {
    const Vec3i o = cp - center_;
    return Key{offset_center_dist2(o), o.y, o.z, o.x};
  };
  std::vector<std::pair<Key, RegionStart>> found;
  const Vec3i lo = floor_div(center_ - Vec3i{n, n, n}, kCoarseRegionChunks);
  const Vec3i hi = floor_div(center_ + Vec3i{n, n, n}, kCoarseRegionChunks);
  for (std::int32_t ry = lo.y; ry <= hi.y; ++ry)
    for (std::int32_t rz = lo.z; rz <= hi.z; ++rz)
      for (std::int32_t rx = lo.x; rx <= hi.x; ++rx) {
        const Vec3i region{rx, ry, rz};
        const Vec3i first = region * kCoarseRegionChunks;
        // A Horizon record's region lies within the wire's range whole.
        if (!wire_chunk_ok(first) ||
            !wire_chunk_ok(first + Vec3i{kCoarseRegionChunks - 1, kCoarseRegionChunks - 1, kCoarseRegionChunks - 1}))
          continue;
        const auto [a, b] = region_span(region);
        if (a.x > b.x || a.y > b.y || a.z > b.z) continue;
        std::optional<Key> best;
        Vec3i best_cp{};
        if (!may_know(region)) {
          // Both distances grow with |o| on each axis: the chunk nearest the
          // centre on every axis comes first, and is in view if any is.
          const Vec3i cp{std::clamp(center_.x, a.x, b.x), std::clamp(center_.y, a.y, b.y),
                         std::clamp(center_.z, a.z, b.z)};
          if (offset_within(cp - center_, view)) {
            best = key(cp);
            best_cp = cp;
          }
        } else {
          for (std::int32_t y = a.y; y <= b.y; ++y)
            for (std::int32_t z = a.z; z <= b.z; ++z)
              for (std::int32_t x = a.x; x <= b.x; ++x) {
                const Vec3i cp{x, y, z};
                if (!offset_within(cp - center_, view) || known(cp)) continue;
                const Key k = key(cp);
                if (!best || k < *best) {
                  best = k;
                  best_cp = cp;
                }
              }
        }
        if (best) found.push_back({*best, RegionStart{region, best_cp}});
      }
  std::sort(found.begin(), found.end(), [](const auto& p, const auto& q) { return p.first < q.first; });
  std::vector<RegionStart> out;
  out.reserve(found.size());
  for (const auto& [k, r] : found) out.push_back(r);
  return out;
}

HorizonMask ViewPlan::in_view_mask(Vec3i region) const {
  HorizonMask mask{};
  const auto [a, b] = region_span(region);
  if (a.x > b.x || a.y > b.y || a.z > b.z) return mask;
  const std::int32_t view = table_->view_distance();
  // The chunk farthest from the centre on every axis: when it is in view,
  // the whole span is.
  const auto far = [](std::int32_t c, std::int32_t lo, std::int32_t hi) { return c - lo > hi - c ? lo : hi; };
  const bool whole = offset_within(Vec3i{far(center_.x, a.x, b.x), far(center_.y, a.y, b.y), far(center_.z, a.z, b.z)} -
                                       center_,
                                   view);
  for (std::int32_t y = a.y; y <= b.y; ++y)
    for (std::int32_t z = a.z; z <= b.z; ++z)
      for (std::int32_t x = a.x; x <= b.x; ++x)
        if (whole || offset_within(Vec3i{x, y, z} - center_, view)) horizon_mask_set(mask, coarse_index(Vec3i{x, y, z}));
  return mask;
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
