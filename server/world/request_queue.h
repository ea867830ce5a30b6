// RequestQueue: clients' comings and goings and streaming's requests (join,
// leave, moved, want, release, want_horizon, holds_full), in the order
// they were queued, drained on the world strand in slices of kSlice.
//
// Owns: the queue (guarded by m_: pushed from the session strands,
// popped on the world strand) and whether a drain is posted. One queue for
// every kind, so a client's requests never pass its join. Between two
// slices whatever else was posted to the strand (a tick, a commit's
// acknowledgements, an edit) runs, instead of waiting behind every request
// a thousand moving clients queued.
#pragma once

#include <asio.hpp>
#include <chrono>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <variant>
#include <vector>

#include "server/world/world_client.h"

namespace terrane {

struct JoinRequest {
  std::string name;
  std::shared_ptr<WorldClient> link;
  bool identified = false;  // the name is proven the player's (Admission::identified)
  bool presence_records = false;  // it takes PresenceRecords (Hello.features)
};
struct LeaveRequest {};
struct MovedRequest {
  Vec3f position;
  std::int32_t view_distance = 0, full_res_radius = 0;
};
struct HoldsFullRequest {
  std::vector<Vec3i> chunks;
};
// A request of client id, queued at queued. The vector kinds: want
// (ChunkWant), release (Vec3i), want_horizon (HorizonWant).
struct WorldRequest {
  ClientId id = 0;
  std::chrono::steady_clock::time_point queued;
  std::variant<std::vector<ChunkWant>, std::vector<Vec3i>, std::vector<HorizonWant>, JoinRequest, LeaveRequest,
               MovedRequest, HoldsFullRequest>
      what;
};

class RequestQueue {
 public:
  using Strand = asio::strand<asio::io_context::executor_type>;
  // The longest the strand spends on requests at a time.
  static constexpr std::chrono::microseconds kSlice{2000};

  // handle runs on strand, once per request, in queue order.
  RequestQueue(Strand& strand, std::function<void(WorldRequest&)> handle);

  // Any thread: stamps r with now and queues it.
  void push(WorldRequest r);
  // How long each request waited in the queue (0 once it is empty), called
  // on the strand. Before the first push.
  void on_wait(std::function<void(std::chrono::nanoseconds)> fn) { wait_ = std::move(fn); }

 private:
  void drain();  // on the strand: one slice

  Strand& strand_;
  std::function<void(WorldRequest&)> handle_;
  std::function<void(std::chrono::nanoseconds)> wait_;
  std::mutex m_;
  std::deque<WorldRequest> queue_;  // guarded by m_
  bool drain_posted_ = false;       // guarded by m_: a drain is on the strand's queue
};

}  // namespace terrane
