// MipSchedule: when one client's parked refreshes of mips go out, and in
// which order. Changes of chunks the client holds coarser than full
// resolution are parked in their slots (ChunkSlot::park_mip: the newest
// change of each) and refreshed together every mip_refresh_ms: in the order
// of their first change (entries whose slot has none any more are skipped
// by the replicator), at the first change's time plus mip_refresh_ms, or
// later while streaming yields (stream_yield.h).
//
// Threading: the client's session strand (one replicator's).
#pragma once

#include <algorithm>
#include <chrono>
#include <utility>
#include <vector>

#include "common/voxel/vec3.h"

namespace terrane {

class MipSchedule {
 public:
  using Clock = std::chrono::steady_clock;

  // The first change parked since the last flush: the refreshes are due
  // at due; the order begins again.
  void first_change(Clock::time_point due) {
    due_ = next_flush_ = due;
    order_.clear();
  }
  // The world says the parked refreshes are due now (it gathered them for
  // mip_refresh_ms); first: nothing was parked before, so they are due
  // since now.
  void due_now(Clock::time_point now, bool first) {
    if (first) due_ = now;
    next_flush_ = std::min(next_flush_, now);
  }
  // A chunk's first parked change since the last flush.
  void add(Vec3i chunk_pos) { order_.push_back(chunk_pos); }
  // The chunks, in the order of their first change (maybe repeated, or
  // sent whole since).
  const std::vector<Vec3i>& order() const { return order_; }
  // Nothing is parked any more.
  void forget() { order_.clear(); }
  // The order, for a flush.
  std::vector<Vec3i> take() { return std::exchange(order_, {}); }

  // When they were due (a yield waits kYieldAtMost past it at most).
  Clock::time_point due() const { return due_; }
  // When they are flushed next.
  Clock::time_point next_flush() const { return next_flush_; }
  // The flush waits (streaming yields) until at.
  void put_off(Clock::time_point at) { next_flush_ = at; }

 private:
  std::vector<Vec3i> order_;
  Clock::time_point due_;
  Clock::time_point next_flush_;
};

}  // namespace terrane
