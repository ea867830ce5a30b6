#include "server/replication/hash_rotation.h"

namespace terrane {

bool HashRotation::due(Clock::time_point now) {
  if (period_.count() <= 0 || now < next_push_) return false;
  next_push_ = now + period_;
  return true;
}

std::optional<std::pair<Vec3i, VersionPtr>> HashRotation::next(const std::function<VersionPtr(Vec3i)>& full) {
  for (std::size_t tries = 0; tries < order_.size(); ++tries) {
    if (cursor_ >= order_.size()) cursor_ = 0;
    const Vec3i cp = order_[cursor_];
    VersionPtr v = full(cp);
    if (!v) {
      order_[cursor_] = order_.back();  // no longer full: forget it
      order_.pop_back();
      continue;
    }
    ++cursor_;
    return std::make_pair(cp, std::move(v));
  }
  return std::nullopt;
}

}  // namespace terrane
