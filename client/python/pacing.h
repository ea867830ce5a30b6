// Pacing: keeps one Python client within the server's budgets, so a script
// that edits or moves faster than a server allows waits instead of being
// dropped. It owns two budgets:
//   edits  the Welcome's token bucket (edits_per_second, edit_burst);
//   moves  PROTOCOL.md's movement rule: a move at most max_speed voxels a
//          second since the last accepted move plus kSpeedSlackVoxels (the
//          server's --max-speed; the Welcome does not carry it, so the
//          script says it, 256 by default).
// Both keep below the server's figure (jitter on the way may bunch frames).
// Any thread: a script's threads may edit and move at once (a mutex).
#pragma once

#include <chrono>
#include <mutex>

#include "protocol/messages.h"

namespace terrane::python {

class Pacing {
 public:
  using Clock = std::chrono::steady_clock;
  // PROTOCOL.md: a move may exceed max_speed * elapsed by this much.
  static constexpr double kSpeedSlackVoxels = 48;
  // A move that would wait longer than this is refused (walk, or move in steps).
  static constexpr double kMaxMoveWaitSeconds = 10;

  // max_speed: the server's --max-speed (voxels a second); 0 = not paced.
  explicit Pacing(double max_speed) : max_speed_(max_speed) {}

  // Takes an edit's token now; returns how long to wait before sending it
  // (0 when the bucket had one, or the server states no rate).
  // A turn taken by reserve_edit is used instead, without a wait.
  std::chrono::milliseconds edit(const WelcomeMsg& w);
  // Takes an edit's token for an edit sent later (asyncio waits the time
  // returned on its event loop, then sends): the next edit() uses it.
  std::chrono::milliseconds reserve_edit(const WelcomeMsg& w);
  // The farthest one move may go: kMaxMoveWaitSeconds of the budget plus
  // the slack (as the server counts it); infinity when not paced.
  double max_move() const;
  // Counts a move of distance voxels as made once the budget allows it;
  // returns how long to wait until then. The first move after joining
  // counts from now (when the server took the joining position is not
  // known here: assuming just now never moves too soon).
  std::chrono::milliseconds move(double distance);
  // A new session (a reconnect): the server counts the next position as
  // the joining one.
  void rejoined();

 private:
  const double max_speed_;
  std::mutex mutex_;
  // Takes a token now (the lock held); returns the wait its debt means.
  std::chrono::milliseconds take(const WelcomeMsg& w);

  bool edited_ = false;
  double tokens_ = 0;
  int reserved_ = 0;  // tokens taken by reserve_edit, not used yet
  Clock::time_point refilled_;
  bool moved_ = false;
  Clock::time_point moved_at_;
};

}  // namespace terrane::python
