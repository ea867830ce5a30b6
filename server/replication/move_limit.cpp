#include "server/replication/move_limit.h"

#include <cmath>
#include <limits>

namespace terrane {

double MoveLimit::allowed(Clock::time_point now) const {
  if (!moved_ || !(max_speed_ > 0)) return std::numeric_limits<double>::infinity();
  return max_speed_ * std::chrono::duration<double>(now - moved_at_).count() + kSpeedSlackVoxels;
}

std::optional<double> MoveLimit::too_far(Vec3f a, Vec3f b, Clock::time_point now) {
  if (moved_ && max_speed_ > 0) {
    const double d = std::sqrt(double{b.x - a.x} * (b.x - a.x) + double{b.y - a.y} * (b.y - a.y) +
                               double{b.z - a.z} * (b.z - a.z));
    if (d > allowed(now)) return d;
  }
  moved_ = true;
  moved_at_ = now;
  return std::nullopt;
}

}  // namespace terrane
