// EmulatedLink: the bytes a client has read from its socket and that an
// emulated slow downstream link (NetworkEmulation, client/client_options.h)
// has not delivered yet, with when each read arrives at the far end.
//
// A single bottleneck queue, first in first out: a read of n bytes leaves
// the link once the link has carried it at bandwidth_bytes_per_s after
// everything before it, plus the fixed one-way latency. The connection
// stops reading while about one bandwidth-delay product (at least one
// socket read) waits, so a capped link pushes back on the server through
// TCP as a real one would.
// Owned by the connection's io side (the owned thread or the strand); no
// timers here, the connection arms one for next_at().
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <optional>
#include <span>
#include <vector>

#include "client/client_options.h"
#include "protocol/framing.h"

namespace terrane {

class EmulatedLink {
 public:
  using Clock = std::chrono::steady_clock;
  // The socket is read this many bytes at a time.
  static constexpr std::size_t kReadChunkBytes = kSocketReadBytes;

  explicit EmulatedLink(NetworkEmulation e) : e_(e) {}

  bool active() const { return e_.active(); }
  // Bytes read at now enter the link. Returns whether to read on; false:
  // too much waits, reading pauses until resume() says otherwise.
  bool carry(std::span<const std::uint8_t> bytes, Clock::time_point now);
  // Reading was paused and deliveries have drained the link below its cap:
  // true (once), reading goes on.
  bool resume();
  // When the oldest bytes arrive (nullopt: nothing waits).
  std::optional<Clock::time_point> next_at() const;
  // The oldest read if it has arrived by now.
  std::optional<std::vector<std::uint8_t>> take_due(Clock::time_point now);
  std::size_t waiting_bytes() const { return waiting_bytes_; }
  // The connection went: what was on its link goes with it (reading is
  // not paused).
  void clear();

 private:
  struct Delayed {
    Clock::time_point deliver_at;
    std::vector<std::uint8_t> bytes;
  };
  std::size_t cap() const;
  bool full() const { return waiting_bytes_ >= cap(); }

  NetworkEmulation e_;
  std::deque<Delayed> delayed_;
  std::size_t waiting_bytes_ = 0;
  Clock::time_point link_free_{};  // when the link has carried everything queued
  bool paused_ = false;            // the connection stopped reading
};

}  // namespace terrane
