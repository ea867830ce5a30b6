// ViewPlan: what one client's view asks for, around the chunk it stands
// in (the centre): the view's table and the table of the view and its keep
// margin (what is released beyond), both shared ViewTables moved to the
// centre; the coarse pass's cursor (the view's offsets walked nearest
// first from the centre the pass began at, then the chunks that came into
// view by moves since); and the refine queue (chunks that may need
// refining, nearest first).
//
// The refine queue is a heap keyed by the distance to the centre when a
// chunk was pushed. A move only marks the keys stale; they are recomputed
// (and entries no longer needing refinement dropped) when the queue is next
// read, so a client moving chunk after chunk while its coarse view fills
// pays for one reordering, not one per move.
//
// Threading: the client's session strand (one replicator's).
#pragma once

#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <optional>
#include <utility>
#include <vector>

#include "common/voxel/vec3.h"
#include "common/world/world_bounds.h"
#include "protocol/stream_batch.h"
#include "server/replication/view_table.h"

namespace terrane {

class ViewPlan {
 public:
  // bounds: the world's, outlives this (chunks outside it are never in view).
  explicit ViewPlan(const WorldBounds& bounds) : bounds_(bounds) {}

  // Whether there is a plan (the client sent a ClientState).
  bool valid() const { return table_ != nullptr; }
  // Preconditions below: valid().
  Vec3i center() const { return center_; }
  const ViewTable& table() const { return *table_; }
  // The view and its keep margin of margin voxels: got when first asked
  // for (a move), so a new plan does not wait for a second table.
  const ViewTable& keep_table() const;

  // A new plan around center: the coarse pass starts over, the refine
  // queue is emptied.
  void reset(std::int32_t view_distance, std::int32_t full_res_radius, std::int32_t margin, Vec3i center);
  // A move into the neighbouring chunk (each component of d -1..1, d != 0):
  // the chunks entering the view join the coarse pass; the refine queue's
  // keys go stale.
  void shift(Vec3i d);

  // In view of the centre, in the world and within the wire's range.
  bool in_view(Vec3i chunk_pos) const;
  // The level the plan wants: 0..3 in view, kMipLevels (none finer) beyond.
  int desired(Vec3i chunk_pos) const;

  // A region (8^3 chunks) of the view and its first chunk in the view's
  // order (nearest first) that the client knows nothing of.
  struct RegionStart {
    Vec3i region;
    Vec3i first;
  };
  // Every region lying within the wire's range whole with a chunk in view
  // for which known() is false, ordered by those first chunks: the order in
  // which walking the view's offsets meets the regions. A region for which
  // may_know() is false has no known chunk, and its first chunk is found
  // without visiting its chunks (at view 2,048, about 600 regions against
  // 1.1 million offsets); the others' chunks are visited.
  std::vector<RegionStart> unknown_regions(const std::function<bool(Vec3i)>& may_know,
                                           const std::function<bool(Vec3i)>& known) const;
  // The region's chunks in view (in_view), as a Horizon record's mask.
  HorizonMask in_view_mask(Vec3i region) const;

  // The coarse pass's next chunk (it may have left the view since), or
  // nullopt once every one was taken.
  std::optional<Vec3i> next_coarse();
  // Whether the coarse pass took every chunk.
  bool coarse_walked() const { return coarse_pos_ >= table_->offsets().size() && entering_.empty(); }
  // chunk_pos is taken by the coarse pass again (after those queued).
  void enter_again(Vec3i chunk_pos) { entering_.push_back(chunk_pos); }

  // Queues chunk_pos for refining.
  void push_refine(Vec3i chunk_pos);
  // Replaces the refine queue with chunks (any order).
  void refill_refine(const std::vector<Vec3i>& chunks);
  // The nearest chunk queued for refining, or nullopt. Stale keys are
  // recomputed first, and chunks for which needs() is false dropped.
  std::optional<Vec3i> pop_refine(const std::function<bool(Vec3i)>& needs);

 private:
  using RefineEntry = std::pair<std::int64_t, Vec3i>;
  // The refine queue's room kept however short it gets (entries): a
  // move's shell, without a reallocation each time.
  static constexpr std::size_t kRefineRoomKept = 1024;
  struct RefineOrder {
    bool operator()(const RefineEntry& a, const RefineEntry& b) const { return a.first > b.first; }
  };
  void rebuild_refine(const std::function<bool(Vec3i)>& needs);
  // The region's chunks within the world's bounds and the wire's range, per
  // axis (empty when a > b on some axis).
  std::pair<Vec3i, Vec3i> region_span(Vec3i region) const;

  const WorldBounds& bounds_;
  std::shared_ptr<const ViewTable> table_;
  mutable std::shared_ptr<const ViewTable> keep_table_;  // null until asked for
  std::int32_t keep_distance_ = 0;
  Vec3i center_;
  Vec3i coarse_center_;  // the centre the coarse pass walks the table from
  std::size_t coarse_pos_ = 0;
  std::deque<Vec3i> entering_;  // chunks that came into view by moves, for the coarse pass
  std::vector<RefineEntry> refine_;
  bool refine_stale_ = false;
};

}  // namespace terrane
