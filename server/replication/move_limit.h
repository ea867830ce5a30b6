// MoveLimit: how far one client may move between two ClientStates. The
// first position it sends is where it joins; after that it moves at most
// max_speed voxels a second since its last accepted move, plus
// kSpeedSlackVoxels for jitter (below). max_speed 0: any
// move is accepted.
//
// Threading: the client's session strand (one replicator's).
#pragma once

#include <chrono>
#include <optional>

#include "common/voxel/vec3.h"

namespace terrane {

// Movement allowed beyond max_speed * elapsed time between two positions
// (network jitter bunches ClientState messages together).
inline constexpr double kSpeedSlackVoxels = 48;

class MoveLimit {
 public:
  using Clock = std::chrono::steady_clock;

  explicit MoveLimit(double max_speed) : max_speed_(max_speed) {}

  // A move from `from` to `to` at now: nullopt if allowed (it then counts
  // as the last move), else the distance, in voxels, that was too far.
  std::optional<double> too_far(Vec3f from, Vec3f to, Clock::time_point now);
  // How far a move at now may go: the budget (max_speed voxels a second
  // since the last accepted move, plus the slack); infinity before the
  // first move or with max_speed 0.
  double allowed(Clock::time_point now) const;
  double max_speed() const { return max_speed_; }

 private:
  const double max_speed_;
  bool moved_ = false;
  Clock::time_point moved_at_;
};

}  // namespace terrane
