#include "client/python/walking.h"

#include <cmath>
#include <optional>

#include "client/python/edit_future.h"
#include "client/python/events.h"
#include "client/python/gil.h"

namespace terrane::python {

namespace {
// The replica as the path search reads it: each query takes the client's
// lock on its own, so the io thread goes on applying frames during a long
// search.
struct LiveReplica {
  const Client& c;
  Voxel get(Vec3i p) const { return c.get(p); }
  int resolution_at(Vec3i p) const { return c.resolution_at(p); }
};

std::int32_t floor_of(float v) { return static_cast<std::int32_t>(std::floor(v)); }
}  // namespace

std::vector<Vec3i> plan_walk(const Client& c, Vec3f here, Vec3f target, const PathOptions& o) {
  const LiveReplica world{c};
  const Vec3i goal_voxel{floor_of(target.x), floor_of(target.y), floor_of(target.z)};
  std::optional<Vec3i> start, goal;
  PathResult path;
  int goal_resolution = 0;
  without_gil([&] {
    start = place_near(world, floor_of(here.x), floor_of(here.z), floor_of(here.y + 0.01f), 32, o);
    goal = place_near(world, goal_voxel.x, goal_voxel.z, goal_voxel.y, 8, o);
    goal_resolution = world.resolution_at(goal_voxel);
    if (start && goal) path = find_path(world, *start, *goal, o);
  });
  if (PyErr_CheckSignals() != 0) throw py::error_already_set();
  if (!start)
    throw Unreachable("walk_to: no ground held at full resolution under the client at " +
                      str({floor_of(here.x), floor_of(here.y), floor_of(here.z)}));
  if (!goal)
    throw Unreachable(goal_resolution != 0
                          ? "walk_to: the target " + str(goal_voxel) +
                                " is not held at full resolution (beyond the full-resolution radius, or not loaded yet)"
                          : "walk_to: no place to stand within 8 voxels of the target " + str(goal_voxel));
  if (path.timed_out) raise(PyExc_TimeoutError, "walk_to: the target was not reached within the timeout");
  if (!path.found) throw Unreachable("walk_to: " + path.error);
  return path.steps;
}

bool can_stand(const Client& c, Vec3i p, const PathOptions& o) {
  return without_gil([&] { return is_place(LiveReplica{c}, p, o); });
}

}  // namespace terrane::python
