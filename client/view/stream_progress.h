// How far the server's mip-first streaming has got for a client at a
// position, by the view rule the server streams with (common/world/view.h,
// PROTOCOL.md "The view rule"): every chunk in view first gets its coarsest
// form, then is refined to its level.
#pragma once

#include <cstdint>

#include "client/replica.h"
#include "common/voxel/vec3.h"

namespace terrane::view {

struct StreamProgress {
  std::size_t in_view = 0;   // chunks the server will stream
  std::size_t covered = 0;   // of those, held at any level
  std::size_t settled = 0;   // of those, held at their distance's level or finer
};

// view_distance and full_res_radius as the server applies them (capped by
// the Welcome's maxima); bounds the world's (WelcomeMsg::bounds()).
StreamProgress stream_progress(const Replica& replica, Vec3f position, std::int32_t view_distance,
                               std::int32_t full_res_radius, const WorldBounds& bounds);

}  // namespace terrane::view
