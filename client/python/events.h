// Events from the client library to Python, without ever holding the GIL
// on the library's io side.
//
// The io side (a Client's io thread, or a Swarm's pool) turns each event
// into plain C++ data and hands it to an EventSink: the sink keeps the
// latest kMaxQueuedEvents for blocking waits (next_event) and, once a
// callback is registered, posts a job to a Dispatcher. The Dispatcher is
// one thread that takes the GIL only to run callbacks; a Swarm's clients
// share one. No Python object is created, copied or destroyed off the GIL:
// jobs carry C++ data and a weak pointer to the Python side's handlers,
// which live and die under the GIL.
#pragma once

#include <pybind11/pybind11.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <optional>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <tuple>
#include <utility>
#include <variant>
#include <vector>

#include "client/client.h"

namespace terrane::python {

namespace py = pybind11;
using Vec3 = std::tuple<double, double, double>;
using IVec3 = std::tuple<std::int64_t, std::int64_t, std::int64_t>;

inline IVec3 ivec(Vec3i v) { return {v.x, v.y, v.z}; }
inline Vec3 vec(Vec3f v) { return {v.x, v.y, v.z}; }
// A voxel position in messages: "(x, y, z)".
inline std::string str(Vec3i v) {
  return "(" + std::to_string(v.x) + ", " + std::to_string(v.y) + ", " + std::to_string(v.z) + ")";
}

// --- what Python sees ---------------------------------------------------------
struct UpdateEvent {
  std::uint64_t tick = 0;
  std::vector<std::pair<IVec3, std::uint64_t>> chunks;  // (chunk position, new revision)
  std::vector<std::pair<IVec3, IVec3>> regions;        // changed voxels [min, max), per chunk held in full
  // The voxels changed, before and after, when the client records them
  // (Client::capture_voxel_changes; Python builds its list only when read).
  bool voxels_recorded = false;
  std::vector<VoxelChange> voxels;
  bool voxels_truncated = false;
};
// Chunks held at full resolution that were not before, from one StreamBatch.
struct LoadedEvent {
  std::vector<IVec3> chunks;
};
struct Player {
  std::uint32_t id = 0;
  Vec3 position;
  std::string name;  // its Hello's name ('' from a server that sends none)
};
struct PresenceEvent {
  std::vector<Player> players;
  std::vector<Player> joined;       // in players, not in the previous Presence
  std::vector<std::uint32_t> left;  // ids in the previous Presence, not in players
};
struct MessageEvent {
  std::string kind;  // "say" or "shutdown"
  std::string text;
  std::uint32_t seconds_left = 0;
  bool reconnect = false;
};
struct DisconnectEvent {
  std::string reason;
};
// A reconnect (reconnect=True) or a Redirect resumed: the new Welcome came.
struct ReconnectedEvent {};
using Event = std::variant<UpdateEvent, PresenceEvent, MessageEvent, DisconnectEvent, ReconnectedEvent, LoadedEvent>;

inline const char* event_kind(const Event& e) {
  static constexpr const char* kNames[] = {"update", "presence", "message", "disconnect", "reconnected", "loaded"};
  return kNames[e.index()];
}

UpdateEvent to_event(const UpdateInfo& u);
LoadedEvent to_event(const std::vector<Vec3i>& chunk_positions);
PresenceEvent to_event(const std::vector<PresenceEntryMsg>& p);
// Who came into view and who went since the previous Presence: the ids of
// the last one a client received (io side, one per client).
class PresenceChanges {
 public:
  // The event for p, with joined and left against the previous call's p.
  PresenceEvent next(const std::vector<PresenceEntryMsg>& p);

 private:
  std::mutex mutex_;  // a Swarm's io threads may take turns with one client
  std::vector<std::uint32_t> ids_;  // sorted
};
MessageEvent to_event(const ServerNoticeMsg& n);

// --- the callbacks' thread ----------------------------------------------------
// Jobs run in order; a job's Python exception is reported as unraisable
// (printed) and the next job runs. Stopping runs what is queued first.
class Dispatcher {
 public:
  using Job = std::function<void()>;  // runs with the GIL held; owns no Python object
  static constexpr std::size_t kMaxQueuedJobs = 65536;

  Dispatcher();
  ~Dispatcher();
  // Any thread, GIL not needed. False (and counted) when the queue is full,
  // unless must (a client's last event, which is never dropped).
  bool post(Job job, bool must = false);
  // Asks the thread to end once its queue is run, and waits for that
  // (releasing the GIL meanwhile) — except on a callbacks thread (any
  // client's), which never waits for another: two callbacks closing each
  // other's clients would wait for each other for ever.
  void stop();
  std::uint64_t dropped() const;
  // The thread has run its queue and ended.
  bool finished() const;

  struct State {
    std::mutex mutex;
    std::condition_variable cv;  // jobs queued, stopping, finished
    std::deque<Job> jobs;
    bool stopping = false;
    bool finished = false;
    std::uint64_t dropped = 0;
  };

 private:
  static void run(std::shared_ptr<State> state);

  std::shared_ptr<State> state_;  // shared with the thread, which may outlive this object
  std::mutex thread_mutex_;       // joins or detaches thread_ once
  std::thread thread_;
};

// A Dispatcher made on first use, shared by the clients that hold the slot.
class DispatcherSlot {
 public:
  std::shared_ptr<Dispatcher> get();  // GIL held (creates the thread once)
  std::shared_ptr<Dispatcher> peek() const;

 private:
  mutable std::mutex mutex_;
  std::shared_ptr<Dispatcher> dispatcher_;
};

// The Python callbacks of one client (touched only under the GIL).
struct Handlers {
  static constexpr std::size_t kKinds = 6;  // the Event alternatives, in their order
  std::vector<py::object> update, presence, message, disconnect, reconnected, loaded;
  std::vector<py::object>& of(std::size_t kind) {
    switch (kind) {
      case 0: return update;
      case 1: return presence;
      case 2: return message;
      case 3: return disconnect;
      case 4: return reconnected;
      default: return loaded;
    }
  }
};

// Where one client's io side puts its events.
class EventSink {
 public:
  static constexpr std::size_t kMaxQueuedEvents = 4096;

  EventSink(std::shared_ptr<DispatcherSlot> slot, std::weak_ptr<Handlers> handlers)
      : slot_(std::move(slot)), handlers_(std::move(handlers)) {}
  // io side. A DisconnectEvent also marks the sink closed.
  void push(Event e);
  // Posts a job for one handler (index in its kind's list) with an event
  // (on_disconnect registered after the client closed).
  void post_one(std::size_t kind, std::size_t index, Event e);
  // Python side, GIL released: the oldest queued event of kind (any kind
  // when kind is empty), removed from the queue; nullopt at the deadline
  // or, with *closed set, once the client closed and nothing matching is
  // queued.
  std::optional<Event> next(const std::string& kind, std::chrono::milliseconds timeout, bool* closed);
  // Set once a callback is registered (GIL held).
  void enable_callbacks() { callbacks_.store(true); }
  std::uint64_t dropped() const;

 private:
  std::shared_ptr<DispatcherSlot> slot_;
  std::weak_ptr<Handlers> handlers_;
  std::atomic<bool> callbacks_{false};
  mutable std::mutex mutex_;
  std::condition_variable cv_;
  std::deque<Event> queue_;
  bool closed_ = false;
  std::uint64_t dropped_ = 0;
};

// Every live callbacks thread (detached ones too), so Python's exit can
// stop them all before the interpreter finalizes; each gets at most
// `patience` to finish its queue.
void stop_all_dispatchers(std::chrono::milliseconds patience);

py::object to_python(const Event& e);

}  // namespace terrane::python
