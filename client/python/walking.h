// The walker's search, shared by Client.walk_to (blocking) and terrane.walk
// (asyncio: it steps on the event loop, so cancelling stops the walker):
// a way from where the client stands to a target over the client's live
// replica, and whether a place can still be stood in. Free functions over
// a Client, no state of their own; called with the GIL held, the search
// runs with it released.
#pragma once

#include <vector>

#include "client/client.h"
#include "client/path.h"

namespace terrane::python {

// A way from here to a place within 8 voxels of target (client/path.h's
// find_path). Raises Unreachable with the reason (no ground under the
// client or near the target held at full resolution, no way), TimeoutError
// past o.deadline, KeyboardInterrupt on Ctrl-C.
std::vector<Vec3i> plan_walk(const Client& c, Vec3f here, Vec3f target, const PathOptions& o);
// A walker can stand at p (the way may have changed since it was planned).
bool can_stand(const Client& c, Vec3i p, const PathOptions& o);

}  // namespace terrane::python
