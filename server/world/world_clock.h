// WorldClock: the world strand's tick count and whether it is stopping,
// written by the tick (Tick) and read by the other owners of the strand
// (Residency stamps chunks with the tick they were last used at; shared
// worlds' bookkeeping refuses new work while stopping). Plain data.
#pragma once

#include <cstdint>

namespace terrane {

struct WorldClock {
  std::uint64_t tick = 0;  // the last tick applied
  bool stopping = false;   // stop() was called, or the store failed
};

}  // namespace terrane
