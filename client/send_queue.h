// SendQueue: the frames a connection has to write, in order, and the bytes
// they take.
//
// The byte count is reserved by the thread that sends (any thread: a send
// fails at once when the queue would pass its cap) before the frame is
// posted to the io side; everything else is the io side's (the owned
// thread or the strand). One frame is written at a time: start_write()
// hands out the front, finish_write() takes it off. A frame cut off by a
// Redirect in mid-write may or may not have gone: it is marked skipped,
// stays queued while the old write may still read it, and is dropped when
// the next connection's writes reach it.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <vector>

#include "protocol/framing.h"
#include "protocol/messages.h"

namespace terrane {

struct Outbound {
  Frame frame;
  wire::Body type = wire::Body::NONE;
  std::uint32_t edit_id = 0;  // an EditRequest's
  bool skip = false;          // cut off mid-write by a Redirect: not sent again
};

class SendQueue {
 public:
  explicit SendQueue(std::size_t max_bytes) : max_bytes_(max_bytes) {}

  // Any thread: reserves n bytes for a frame about to be pushed; false
  // (nothing reserved) when the queue would pass its cap.
  bool reserve(std::size_t n);
  // Any thread: gives back bytes reserved for a frame never pushed.
  void unreserve(std::size_t n) { bytes_.fetch_sub(n, std::memory_order_relaxed); }
  std::size_t bytes() const { return bytes_.load(std::memory_order_relaxed); }

  // --- io side -------------------------------------------------------------
  // Appends a frame whose bytes were reserved.
  void push_back(Outbound o) { frames_.push_back(std::move(o)); }
  // Puts frames (counted here, over the cap if need be: they open a
  // session) ahead of everything queued, in their order.
  void push_front(std::vector<Outbound> frames);
  // Drops every queued frame of this type (not the one being written).
  void drop(wire::Body type);
  // The next frame to write (frames marked skipped are dropped on the
  // way), now being written; null when nothing is queued or a write is
  // under way.
  const Outbound* start_write();
  bool writing() const { return writing_; }
  // The frame being written (precondition: writing()).
  const Outbound& in_flight() const { return frames_.front(); }
  // The write of the front ended: it leaves the queue.
  void finish_write();
  // The write under way is abandoned (the connection goes): its frame is
  // skipped from now on. Returns its edit id (0 if none).
  std::uint32_t abandon_write();
  // Everything goes (a connection that is gone); any write is forgotten.
  void clear();
  std::size_t size() const { return frames_.size(); }

 private:
  std::size_t max_bytes_;
  std::atomic<std::size_t> bytes_{0};
  std::deque<Outbound> frames_;
  bool writing_ = false;
};

}  // namespace terrane
