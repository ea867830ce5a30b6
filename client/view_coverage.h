// How much of its view a client holds: per chunk in view (the server's view
// rule, common/world/view.h and PROTOCOL.md "The view rule"), what the
// replica holds of it, and whether that is the resolution the server
// streams it at (every chunk in view first gets its coarsest form, then is
// refined to its distance's level). One answer for the bots, the Python
// module and the viewer.
// Plain functions over a Replica: the caller keeps the replica still
// (Client::coverage() and Client::with_replica() hold the Client's lock).
#pragma once

#include <cstddef>
#include <cstdint>

#include "client/replica.h"
#include "common/voxel/vec3.h"
#include "common/voxel/vec3_map.h"
#include "common/world/world_bounds.h"
#include "protocol/messages.h"

namespace terrane {

// A view as the server applies it: the position, and the view distance and
// full-resolution radius after the server's defaults and caps.
struct StreamedView {
  Vec3f position;
  std::int32_t view_distance = 0;
  std::int32_t full_res_radius = 0;
};

// The view the server streams for a ClientState: a 0 distance takes the
// Welcome's default; both are capped by the Welcome's maxima, and the
// full-resolution radius by the view distance.
StreamedView streamed_view(const ClientStateMsg& state, const WelcomeMsg& welcome);

struct ViewCoverage {
  std::size_t in_view = 0;  // chunks in view (those touching the world's bounds)
  // Of those, by what the replica holds (they add up to in_view).
  std::size_t full = 0;
  std::size_t empty = 0;  // all Air, known at full resolution
  std::size_t mip1 = 0, mip2 = 0, mip3 = 0;
  std::size_t estimate = 0;
  std::size_t horizon = 0;  // only a region's horizon image
  std::size_t not_held = 0;
  // Held at their distance's level or finer (an Estimate counts as level 3,
  // a horizon image as 4 or 5).
  std::size_t settled = 0;
  // Within the full-resolution radius, and of those held at full
  // resolution (Full or Empty).
  std::size_t want_full = 0;
  std::size_t held_full = 0;
  // Every chunk in view is held at the resolution the server streams it at.
  bool complete = false;

  std::size_t held() const { return in_view - not_held; }
  bool full_region_held() const { return held_full == want_full; }
};

ViewCoverage coverage(const Replica& replica, const StreamedView& view, const WorldBounds& bounds);

// coverage() for one view that does not move, kept up to date holding
// change by holding change: O(1) per change where coverage() is a pass over
// the view (33^3 chunks at view 512). A bot's join reads it after every
// chunk it receives. It keeps the form it last counted of each chunk in
// view the replica holds (nothing for the rest, so its size follows the
// replica's, whatever view distance a flag or a server allows), so telling
// a chunk's holding twice, or a change it has already seen, changes nothing.
class ViewCoverageCounter {
 public:
  // Counts what `replica` holds now (one pass, as coverage()).
  ViewCoverageCounter(const StreamedView& view, const WorldBounds& bounds, const Replica& replica);

  // What the replica holds of chunk cp is now `now` (nullptr: nothing).
  // Chunks outside the view are ignored.
  void update(Vec3i chunk_pos, const Holding* now);
  const ViewCoverage& coverage() const { return coverage_; }

 private:
  StreamedView view_;
  WorldBounds bounds_;
  Vec3i center_;
  Vec3iMap<HoldingForm> held_;  // chunks in view the replica holds, by their form
  ViewCoverage coverage_;
};

}  // namespace terrane
