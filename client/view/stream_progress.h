// How far the server's mip-first streaming has got for a client at a
// position, by the rule in protocol/PROTOCOL.md ("Streaming order"): every
// chunk in view first gets its coarsest form, then is refined to the level
// its distance asks for (full resolution within the full-resolution
// radius F, level 1 within 2 max(F, 32), level 2 within 4 max(F, 32), else
// level 3).
#pragma once

#include <cstdint>

#include "client/replica.h"
#include "common/vec3.h"

namespace terrane::view {

struct StreamProgress {
  std::size_t in_view = 0;   // chunks the server will stream
  std::size_t covered = 0;   // of those, held at any level
  std::size_t settled = 0;   // of those, held at their distance's level or finer
};

// The level (0 full .. 3) the server refines a chunk to.
int desired_stream_level(Vec3f position, Vec3i chunk_pos, std::int32_t full_res_radius);

// view_distance and full_res_radius as the server applies them (capped by
// the Welcome's maxima); min_y/max_y the world's vertical bounds.
StreamProgress stream_progress(const Replica& replica, Vec3f position, std::int32_t view_distance,
                               std::int32_t full_res_radius, std::int32_t min_y, std::int32_t max_y);

}  // namespace terrane::view
