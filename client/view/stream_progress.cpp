#include "client/view/stream_progress.h"

#include "common/world/view.h"

namespace terrane::view {

StreamProgress stream_progress(const Replica& replica, Vec3f p, std::int32_t vd, std::int32_t full,
                               const WorldBounds& bounds) {
  // The server's view rule (common/world/view.h): the same chunks, the same levels.
  StreamProgress out;
  for (const Vec3i cp : chunks_in_view(p, vd, bounds)) {
    ++out.in_view;
    const Holding* c = replica.holding(cp);
    if (c == nullptr) continue;
    ++out.covered;
    const int level = c->level();
    if (level <= desired_level(p, cp, full)) ++out.settled;
  }
  return out;
}

}  // namespace terrane::view
