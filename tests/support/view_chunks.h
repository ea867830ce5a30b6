// Test support: the chunks a client at p is promised within radius (inside
// the world's vertical bounds), by the one view rule of common/world/view.h.
// Header-only; used by the integration tests and the join benchmark.
#pragma once

#include <vector>

#include "common/world/view.h"
#include "protocol/messages.h"

namespace terrane::testing_support {

inline std::vector<Vec3i> chunks_within(Vec3f p, float radius, const WelcomeMsg& w) {
  return chunks_in_view(p, static_cast<std::int32_t>(radius), w.bounds());
}

}  // namespace terrane::testing_support
