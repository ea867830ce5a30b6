// Watches: what asyncio waits for on one client, without a thread waiting.
// It owns the continuations (C++ callables that may hold Python objects)
// registered for an edit's answer or a read's answer, each keyed by a
// token; the client's io side names the edit or read answered (or the
// connection lost or closed) and the continuation is posted to the
// client's callbacks thread (events.h's Dispatcher), where it runs with the
// GIL held. The io side never touches a Python object: it moves tokens.
// Registration and continuations run with the GIL held; the io side's
// methods take only the mutex.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <unordered_map>
#include <vector>

#include "client/client.h"
#include "client/python/events.h"

namespace terrane::python {

class Watches {
 public:
  using Continuation = std::function<void()>;  // runs with the GIL held

  explicit Watches(std::shared_ptr<DispatcherSlot> slot);

  // GIL held. Runs then() on the callbacks thread once edit id is answered
  // (its outcome is in the client's view) or the client closed; at once
  // (here) if it already is.
  void on_edit(Client& c, std::uint32_t id, Continuation then);
  // The same for read request id (a ReadBox, such as sync's barrier), also
  // run when the connection is lost (a read sent before is never answered).
  void on_read(Client& c, std::uint32_t id, Continuation then);

  // GIL held. Runs then() on the callbacks thread once the next event of
  // any kind is queued for next_event (or the client closed).
  void on_event(Continuation then);

  // What the io side holds (no Python object): which ids are watched.
  class Ids {
   public:
    // io side (no GIL): an edit or read was answered, the connection was
    // lost (the reads pending run), or the client closed (all run).
    void edit_answered(std::uint32_t id);
    void read_answered(std::uint32_t id);
    void connection_lost();
    void closed();
    // io side: an event was queued (after EventSink::push).
    void event_queued();

   private:
    friend class Watches;
    struct Pending;
    // Posts the continuations of tokens to the callbacks thread.
    void post(const std::vector<std::uint64_t>& tokens);

    std::shared_ptr<DispatcherSlot> slot_;
    std::weak_ptr<Pending> pending_;  // the continuations, alive while the Watches is
    std::mutex mutex_;  // edits_, reads_, events_
    std::unordered_map<std::uint32_t, std::uint64_t> edits_, reads_;  // id -> token
    std::vector<std::uint64_t> events_;  // tokens waiting for the next event
  };
  // For the client's io callbacks.
  const std::shared_ptr<Ids>& ids() const { return ids_; }

 private:
  enum class Kind { kEdit, kRead };
  // Keeps then (GIL held) and returns its token.
  std::uint64_t keep(Continuation then);
  void watch(Kind kind, std::uint32_t id, bool answered_now, Continuation then);

  std::shared_ptr<Ids> ids_;
  std::shared_ptr<Ids::Pending> pending_;  // GIL: destroyed with the client, under the GIL
};

}  // namespace terrane::python
