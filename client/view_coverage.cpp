#include "client/view_coverage.h"

#include <algorithm>

#include "common/world/view.h"

namespace terrane {

StreamedView streamed_view(const ClientStateMsg& s, const WelcomeMsg& w) {
  const std::int32_t view =
      std::min(s.view_distance == 0 ? w.default_view_distance : s.view_distance, w.max_view_distance);
  const std::int32_t full =
      std::min({s.full_res_radius == 0 ? w.default_full_res_radius : s.full_res_radius, w.max_full_res_radius, view});
  return StreamedView{s.position, view, full};
}

namespace {

// One chunk in view at offset o from the view's chunk.
void count(const Replica& replica, Vec3i cp, Vec3i o, const StreamedView& v, ViewCoverage& out) {
  ++out.in_view;
  const int wanted = offset_level(o, v.full_res_radius);
  if (wanted == 0) ++out.want_full;
  const Holding* h = replica.holding(cp);
  if (h == nullptr) {
    ++out.not_held;
    return;
  }
  switch (h->form) {
    case HoldingForm::kFull: ++out.full; break;
    case HoldingForm::kEmpty: ++out.empty; break;
    case HoldingForm::kMip1: ++out.mip1; break;
    case HoldingForm::kMip2: ++out.mip2; break;
    case HoldingForm::kMip3: ++out.mip3; break;
    case HoldingForm::kEstimate: ++out.estimate; break;
    case HoldingForm::kHorizon4:
    case HoldingForm::kHorizon5: ++out.horizon; break;
  }
  if (h->level() <= wanted) ++out.settled;
  if (wanted == 0 && h->full_resolution()) ++out.held_full;
}

}  // namespace

ViewCoverage coverage(const Replica& replica, const StreamedView& v, const WorldBounds& bounds) {
  // The server's view rule (chunks_in_view, without its order or its
  // list: this runs after every frame some callers receive): the same
  // chunks, the same levels.
  ViewCoverage out;
  const Vec3i center = view_chunk(v.position);
  const std::int32_t n = (std::max(v.view_distance, 0) + kChunkSize / 2) / kChunkSize;
  Vec3i o;
  for (o.y = -n; o.y <= n; ++o.y)
    for (o.z = -n; o.z <= n; ++o.z)
      for (o.x = -n; o.x <= n; ++o.x) {
        const Vec3i cp = center + o;
        if (offset_within(o, v.view_distance) && bounds.touches_chunk(cp)) count(replica, cp, o, v, out);
      }
  out.complete = out.settled == out.in_view;
  return out;
}

}  // namespace terrane
