// HashRotation: the pushed chunk hashes of one client. Every hash_push_ms,
// once the client has a plan, the server pushes the hash of the next chunk
// it holds at full resolution, in turn (the client compares it with its
// own copy and asks again for a chunk that differs). This owns the turn:
// the chunks that came to be held Full with a version, a cursor over them
// and the time of the next push.
//
// Threading: the client's session strand (one replicator's).
#pragma once

#include <chrono>
#include <cstddef>
#include <functional>
#include <optional>
#include <utility>
#include <vector>

#include "common/voxel/vec3.h"
#include "server/base/chunk_version.h"

namespace terrane {

class HashRotation {
 public:
  using Clock = std::chrono::steady_clock;

  // period: hash_push_ms (0: hashes are never pushed).
  explicit HashRotation(std::chrono::milliseconds period) : period_(period) {}

  // The client joined (now): the first push is a period away.
  void start(Clock::time_point now) { next_push_ = now + period_; }
  // When the next push is due (time_point::max() when never).
  Clock::time_point next_push() const {
    return period_.count() > 0 ? next_push_ : Clock::time_point::max();
  }
  // True if a push is due at now: the next one is then a period away.
  bool due(Clock::time_point now);

  // chunk_pos came to be held Full with a version.
  void add(Vec3i chunk_pos) { order_.push_back(chunk_pos); }
  // The next chunk in turn and its version, as full() gives it; a chunk
  // for which full() gives none is no longer held Full and is forgotten.
  // nullopt when none is left.
  std::optional<std::pair<Vec3i, VersionPtr>> next(const std::function<VersionPtr(Vec3i)>& full);

 private:
  const std::chrono::milliseconds period_;
  Clock::time_point next_push_;
  std::vector<Vec3i> order_;
  std::size_t cursor_ = 0;
};

}  // namespace terrane
