#include "client/python/pacing.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace terrane::python {

namespace {
std::chrono::milliseconds ms_of(double seconds) {
  return std::chrono::milliseconds(static_cast<std::int64_t>(std::ceil(std::max(0.0, seconds) * 1000)));
}
}  // namespace

std::chrono::milliseconds Pacing::edit(const WelcomeMsg& w) {
  std::lock_guard lock(mutex_);
  if (reserved_ > 0) {
    --reserved_;
    return std::chrono::milliseconds(0);
  }
  return take(w);
}

std::chrono::milliseconds Pacing::reserve_edit(const WelcomeMsg& w) {
  std::lock_guard lock(mutex_);
  if (!(w.edits_per_second > 0)) return std::chrono::milliseconds(0);
  ++reserved_;
  return take(w);
}

std::chrono::milliseconds Pacing::take(const WelcomeMsg& w) {
  if (!(w.edits_per_second > 0)) return std::chrono::milliseconds(0);
  // Below the server's bucket, with room for jitter on the way.
  const double rate = w.edits_per_second * 0.9, burst = std::max(1.0, w.edit_burst / 2.0);
  const auto now = Clock::now();
  if (!edited_) {
    tokens_ = burst;
    edited_ = true;
  } else {
    tokens_ = std::min(burst, tokens_ + std::chrono::duration<double>(now - refilled_).count() * rate);
  }
  refilled_ = now;
  tokens_ -= 1;  // taken now; a debt is waited off
  return tokens_ < 0 ? ms_of(-tokens_ / rate) : std::chrono::milliseconds(0);
}

double Pacing::max_move() const {
  if (!(max_speed_ > 0)) return std::numeric_limits<double>::infinity();
  return max_speed_ * kMaxMoveWaitSeconds + kSpeedSlackVoxels;
}

std::chrono::milliseconds Pacing::move(double distance) {
  if (!(max_speed_ > 0)) return std::chrono::milliseconds(0);
  // A tenth below the speed and 8 voxels inside the slack.
  const double speed = max_speed_ * 0.9, slack = kSpeedSlackVoxels - 8;
  std::lock_guard lock(mutex_);
  const auto now = Clock::now();
  if (!moved_) {
    moved_ = true;
    moved_at_ = now;
  }
  const auto due = moved_at_ + std::chrono::duration_cast<Clock::duration>(
                                   std::chrono::duration<double>(std::max(0.0, (distance - slack) / speed)));
  moved_at_ = std::max(due, now);
  return ms_of(std::chrono::duration<double>(moved_at_ - now).count());
}

void Pacing::rejoined() {
  std::lock_guard lock(mutex_);
  moved_ = false;
}

}  // namespace terrane::python
