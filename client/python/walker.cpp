#include "client/python/walker.h"

#include <chrono>
#include <cmath>
#include <optional>
#include <string>

#include "client/python/edit_future.h"
#include "client/python/gil.h"

namespace terrane::python {

namespace {
using Clock = std::chrono::steady_clock;

// The replica as the path search reads it: each query takes the client's
// lock on its own, so the io thread goes on applying frames during a long
// search.
struct LiveReplica {
  const Client& c;
  Voxel get(Vec3i p) const { return c.get(p); }
  int resolution_at(Vec3i p) const { return c.resolution_at(p); }
};

std::int32_t floor_of(float v) { return static_cast<std::int32_t>(std::floor(v)); }
double length(Vec3f d) { return std::sqrt(double{d.x} * d.x + double{d.y} * d.y + double{d.z} * d.z); }

PathOptions options(std::size_t max_nodes, Clock::time_point deadline) {
  if (max_nodes < 1 || max_nodes > 2'000'000) raise(PyExc_ValueError, "walk_to: max_nodes must be 1..2000000");
  PathOptions o;
  o.max_nodes = max_nodes;
  o.deadline = deadline;
  return o;
}
}  // namespace

Vec3f Walker::position() const { return c_->last_state().value_or(ClientStateMsg{}).position; }

Vec3f Walker::look_at(Vec3f point) {
  const Vec3f d = point - eye();
  const float len = std::sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
  if (!(len > 1e-6f)) raise(PyExc_ValueError, "look_at: the point is at the client's eye");
  facing_ = d * (1.0f / len);
  return facing_;
}

void Walker::move_to(Vec3f position) {
  ClientStateMsg s = c_->last_state().value_or(ClientStateMsg{});
  const double distance = length(position - s.position);
  s.position = position;
  // The server's speed budget: a far move waits until it is allowed.
  if (distance > pacing_->max_move())
    raise(PyExc_ValueError, "move_to: " + std::to_string(std::lround(distance)) + " voxels at once; at most " +
                                std::to_string(std::lround(pacing_->max_move())) +
                                " (ten seconds of the server's speed budget, max_speed voxels a second plus 48): "
                                "walk_to, or move in steps");
  pause(*c_, pacing_->move(distance), "moving");
  if (!c_->set_state(s)) raise(PyExc_ConnectionError, "connection closed");
}

std::vector<Vec3i> Walker::plan(Vec3f target, const PathOptions& o) const {
  const LiveReplica world{*c_};
  const Vec3f here = position();
  const Vec3i goal_voxel{floor_of(target.x), floor_of(target.y), floor_of(target.z)};
  std::optional<Vec3i> start, goal;
  PathResult path;
  int goal_resolution = 0;
  without_gil([&] {
    start = place_near(world, floor_of(here.x), floor_of(here.z), floor_of(here.y + 0.01f), 32, o);
    goal = place_near(world, goal_voxel.x, goal_voxel.z, goal_voxel.y, 8, o);
    goal_resolution = world.resolution_at(goal_voxel);
    if (start && goal) path = terrane::find_path(world, *start, *goal, o);
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

std::vector<IVec3> Walker::walk_to(Vec3f target, double speed, double timeout, std::size_t max_nodes) {
  if (!(speed > 0) || speed > 64) raise(PyExc_ValueError, "walk_to: speed must be in (0, 64] voxels per second");
  const auto deadline = Clock::now() + timeout_of(timeout);
  const PathOptions o = options(max_nodes, deadline);
  wait_ready(*c_, timeout_of(timeout));
  const auto out_of_time = [&] { raise(PyExc_TimeoutError, "walk_to: the target was not reached within the timeout"); };
  std::vector<IVec3> walked;
  // The world may change under the walker: each step is checked before it
  // is taken, and a blocked way is searched again (a few times).
  constexpr int kReplans = 3;
  for (int attempt = 0;; ++attempt) {
    if (Clock::now() >= deadline) out_of_time();
    const std::vector<Vec3i> steps = plan(target, o);
    bool blocked = false;
    Vec3f at = position();
    for (const Vec3i s : steps) {
      if (!can_stand(s)) {
        blocked = true;
        break;
      }
      const Vec3f next{static_cast<float>(s.x) + 0.5f, static_cast<float>(s.y), static_cast<float>(s.z) + 0.5f};
      const auto pace = std::chrono::milliseconds(static_cast<std::int64_t>(length(next - at) / speed * 1000));
      if (Clock::now() + pace > deadline) out_of_time();
      bool closed = false;
      // Walking pace: the wait ends early only if the connection closes.
      wait_for(*c_, pace, [&](const ClientView& v) { return closed = v.closed; });
      if (closed) raise(PyExc_ConnectionError, "connection closed while walking: " + c_->disconnect_reason());
      move_to(next);
      at = next;
      walked.push_back(ivec(s));
    }
    if (!blocked) return walked;
    if (attempt == kReplans) throw Unreachable("walk_to: the way kept changing under the walker");
  }
}

std::vector<IVec3> Walker::find_path(Vec3f target, double timeout, std::size_t max_nodes) {
  const auto deadline = Clock::now() + timeout_of(timeout);
  const PathOptions o = options(max_nodes, deadline);
  wait_ready(*c_, timeout_of(timeout));
  std::vector<IVec3> out;
  for (const Vec3i s : plan(target, o)) out.push_back(ivec(s));
  return out;
}

bool Walker::can_stand(Vec3i p) const {
  return without_gil([&] { return is_place(LiveReplica{*c_}, p, PathOptions{}); });
}

}  // namespace terrane::python
