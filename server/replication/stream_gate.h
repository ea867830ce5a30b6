// StreamGate: streaming yields to live traffic when the server falls behind.
//
// Streaming (chunks a client's view wants: asked of the world, granted,
// encoded and sent) is work without a deadline; edits, their
// acknowledgements, updates and pongs have one. Both run on the same
// threads: the sessions' io threads and the world strand. Left alone,
// streaming takes whatever CPU there is (each grant sent asks for the
// next), and when clients together want more than the machine has, every
// queue grows, the live traffic's with it, and the server stays behind.
//
// The gate measures how late the io threads and the world strand are: a
// probe timer on each, every probe period; its lateness is how long work
// queued there waits. The world's streaming requests have a queue of their
// own (drained between ticks, server/world/world_owner.h): how long they
// wait there is the third probe. A probe later than the threshold closes
// the gate; it opens again once every probe comes back within half of it. While it
// is closed, replicators send and ask for no more streamed chunks, and put
// off refreshing the mips clients hold (they coalesce meanwhile); chunks
// held at full resolution keep being updated, and edits, hashes and pings
// go on; they retry shortly. Streaming then runs at the rate the
// machine can carry beside the live traffic. It slows, never stops: a
// client's streaming that has waited StreamYield::kYieldAtMost (stream_yield.h) goes
// on once, closed or not, unless the gate is held closed by hand.
//
// Threading: open() from any thread; observe() from the probes (or a
// test); start() and stop() from the Server's owner.
#pragma once

#include <asio.hpp>
#include <array>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <memory>
#include <mutex>

namespace terrane {

class StreamGate {
 public:
  // kIo and kWorld: the probe timers (start()); kRequests: how long the
  // world's streaming requests wait in their queue (the world reports it).
  enum class Probe : std::uint8_t { kIo = 0, kWorld = 1, kRequests = 2 };
  // threshold 0: the gate never closes.
  explicit StreamGate(std::chrono::milliseconds threshold);
  ~StreamGate();
  StreamGate(const StreamGate&) = delete;
  StreamGate& operator=(const StreamGate&) = delete;

  bool open() const { return open_.load(std::memory_order_relaxed); }
  // Closed by hold_closed(true), not by the probes.
  bool held() const { return held_flag_.load(std::memory_order_relaxed); }
  std::chrono::milliseconds threshold() const { return threshold_; }

  // One probe's lateness: later than the threshold closes the gate; every
  // probe within half of it opens it. (Threshold 0: ignored.)
  void observe(Probe p, std::chrono::nanoseconds late);
  // Holds the gate closed whatever the probes say (true) or lets them
  // decide again (false): streaming paused by hand (tests, operators).
  void hold_closed(bool held);

  // Probes io (the sessions' threads) and world (the world strand's
  // context) every probe period until stop(). Not with threshold 0.
  void start(asio::io_context& io, asio::io_context& world);
  // Cancels the probes (posted to their contexts; they stop before those do).
  void stop();

  // Times the gate closed, and for how long in all (for /metrics).
  std::uint64_t closed_count() const { return closed_count_.load(std::memory_order_relaxed); }
  double closed_seconds() const;

 private:
  struct Prober;
  void arm(Prober& p);

  const std::chrono::milliseconds threshold_;
  std::atomic<bool> open_{true};
  std::atomic<bool> held_flag_{false};
  mutable std::mutex m_;  // the probes' states and the closed time
  std::array<bool, 3> late_{};
  bool held_ = false;
  std::atomic<std::uint64_t> closed_count_{0};
  std::chrono::steady_clock::duration closed_for_{};
  std::chrono::steady_clock::time_point closed_at_;  // while closed
  void update();  // open_ from late_ and held_ (under m_)
  std::array<std::unique_ptr<Prober>, 2> probers_;
};

}  // namespace terrane
