#include "client/python/events.h"

#include "client/python/gil.h"

#include <algorithm>

namespace terrane::python {

UpdateEvent to_event(const UpdateInfo& u) {
  UpdateEvent e;
  e.tick = u.tick;
  for (const auto& r : u.revisions) e.chunks.emplace_back(ivec(r.chunk_pos), r.revision);
  for (const auto& r : u.changed) e.regions.emplace_back(ivec(r.min), ivec(r.max));
  e.voxels_recorded = u.voxels_recorded;
  e.voxels = u.voxels;
  e.voxels_truncated = u.voxels_truncated;
  return e;
}

LoadedEvent to_event(const std::vector<Vec3i>& chunk_positions) {
  LoadedEvent e;
  e.chunks.reserve(chunk_positions.size());
  for (const Vec3i cp : chunk_positions) e.chunks.push_back(ivec(cp));
  return e;
}

PresenceEvent to_event(const std::vector<PresenceEntryMsg>& p) {
  PresenceEvent e;
  for (const auto& x : p) e.players.push_back(Player{x.client_id, vec(x.position), utf8(x.name)});
  return e;
}

PresenceEvent PresenceChanges::next(const std::vector<PresenceEntryMsg>& p) {
  PresenceEvent e = to_event(p);
  std::vector<std::uint32_t> ids;
  for (const auto& x : p) ids.push_back(x.client_id);
  std::sort(ids.begin(), ids.end());
  std::lock_guard lock(mutex_);
  for (const auto& player : e.players)
    if (!std::binary_search(ids_.begin(), ids_.end(), player.id)) e.joined.push_back(player);
  for (const std::uint32_t id : ids_)
    if (!std::binary_search(ids.begin(), ids.end(), id)) e.left.push_back(id);
  ids_ = std::move(ids);
  return e;
}

MessageEvent to_event(const ServerNoticeMsg& n) {
  return MessageEvent{n.kind == wire::NoticeKind::Shutdown ? "shutdown" : "say", utf8(n.text), n.seconds_left,
                      n.reconnect};
}

py::object to_python(const Event& e) {
  return std::visit([](const auto& v) { return py::cast(v); }, e);
}

// --- Dispatcher -----------------------------------------------------------------
namespace {
thread_local bool t_callbacks_thread = false;

std::mutex g_registry_mutex;
std::vector<std::weak_ptr<Dispatcher::State>> g_states;

void remember(const std::shared_ptr<Dispatcher::State>& s) {
  std::lock_guard lock(g_registry_mutex);
  std::erase_if(g_states, [](const auto& w) { return w.expired(); });
  g_states.push_back(s);
}

void ask_to_stop(Dispatcher::State& s) {
  {
    std::lock_guard lock(s.mutex);
    s.stopping = true;
  }
  s.cv.notify_all();
}

// Waits (GIL released) until the thread has run its queue and ended its loop.
bool wait_finished(Dispatcher::State& s, std::chrono::milliseconds patience) {
  return without_gil([&] {
    std::unique_lock lock(s.mutex);
    return s.cv.wait_for(lock, patience, [&] { return s.finished; });
  });
}
}  // namespace

void stop_all_dispatchers(std::chrono::milliseconds patience) {
  std::vector<std::shared_ptr<Dispatcher::State>> live;
  {
    std::lock_guard lock(g_registry_mutex);
    for (const auto& w : g_states)
      if (auto s = w.lock()) live.push_back(s);
  }
  for (const auto& s : live) ask_to_stop(*s);
  if (t_callbacks_thread) return;
  for (const auto& s : live) wait_finished(*s, patience);
}

Dispatcher::Dispatcher() : state_(std::make_shared<State>()), thread_(&Dispatcher::run, state_) { remember(state_); }

Dispatcher::~Dispatcher() {
  stop();
  std::lock_guard lock(thread_mutex_);
  if (thread_.joinable()) thread_.detach();  // a callbacks thread's: it ends on its own
}

bool Dispatcher::post(Job job, bool must) {
  {
    std::lock_guard lock(state_->mutex);
    if (state_->stopping && !must) return false;
    if (state_->jobs.size() >= kMaxQueuedJobs && !must) {
      ++state_->dropped;
      return false;
    }
    state_->jobs.push_back(std::move(job));
  }
  state_->cv.notify_all();
  return true;
}

void Dispatcher::stop() {
  ask_to_stop(*state_);
  if (t_callbacks_thread) return;
  wait_finished(*state_, std::chrono::hours(24));
  std::lock_guard lock(thread_mutex_);
  if (thread_.joinable()) thread_.join();  // finished: returns at once
}

bool Dispatcher::finished() const {
  std::lock_guard lock(state_->mutex);
  return state_->finished;
}

std::uint64_t Dispatcher::dropped() const {
  std::lock_guard lock(state_->mutex);
  return state_->dropped;
}

void Dispatcher::run(std::shared_ptr<State> s) {
  t_callbacks_thread = true;
  for (;;) {
    Job job;
    {
      std::unique_lock lock(s->mutex);
      s->cv.wait(lock, [&] { return s->stopping || !s->jobs.empty(); });
      if (s->jobs.empty()) break;
      job = std::move(s->jobs.front());
      s->jobs.pop_front();
    }
    if (!Py_IsInitialized()) continue;  // Python is gone: nothing to call
    py::gil_scoped_acquire gil;
    try {
      job();
    } catch (py::error_already_set& e) {
      e.discard_as_unraisable("a terrane callback");
    } catch (const std::exception& e) {
      PyErr_SetString(PyExc_RuntimeError, e.what());
      PyErr_WriteUnraisable(nullptr);
    }
  }
  {
    std::lock_guard lock(s->mutex);
    s->finished = true;
  }
  s->cv.notify_all();
}

std::shared_ptr<Dispatcher> DispatcherSlot::get() {
  std::lock_guard lock(mutex_);
  if (!dispatcher_) dispatcher_ = std::make_shared<Dispatcher>();
  return dispatcher_;
}

std::shared_ptr<Dispatcher> DispatcherSlot::peek() const {
  std::lock_guard lock(mutex_);
  return dispatcher_;
}

// --- EventSink --------------------------------------------------------------------
void EventSink::push(Event e) {
  const bool disconnect = std::holds_alternative<DisconnectEvent>(e);
  if (auto* d = std::get_if<DisconnectEvent>(&e)) d->reason = utf8(d->reason);
  std::optional<Event> for_callbacks;
  if (callbacks_.load()) for_callbacks = e;
  {
    std::lock_guard lock(mutex_);
    queue_.push_back(std::move(e));
    if (queue_.size() > kMaxQueuedEvents) {
      queue_.pop_front();
      ++dropped_;
    }
    if (disconnect) closed_ = true;
  }
  cv_.notify_all();
  if (!for_callbacks) return;
  auto d = slot_->peek();
  if (!d) return;
  d->post(
      [handlers = handlers_, ev = std::move(*for_callbacks)] {
    auto h = handlers.lock();
    if (!h) return;
    const auto fns = h->of(ev.index());  // a copy: a callback may register another
    if (fns.empty()) return;
    const py::object arg = to_python(ev);
    for (const auto& f : fns) {
      try {
        f(arg);
      } catch (py::error_already_set& err) {
        err.discard_as_unraisable(f);
      }
    }
      },
      disconnect);
}

void EventSink::post_one(std::size_t kind, std::size_t index, Event e) {
  auto d = slot_->peek();
  if (!d) return;
  d->post(
      [handlers = handlers_, kind, index, ev = std::move(e)] {
        auto h = handlers.lock();
        if (!h || index >= h->of(kind).size()) return;
        const py::object f = h->of(kind)[index];
        f(to_python(ev));
      },
      true);
}

std::optional<Event> EventSink::next(const std::string& kind, std::chrono::milliseconds timeout, bool* closed) {
  std::unique_lock lock(mutex_);
  std::optional<Event> found;
  const auto match = [&] {
    for (auto it = queue_.begin(); it != queue_.end(); ++it)
      if (kind.empty() || kind == event_kind(*it)) {
        found = std::move(*it);
        queue_.erase(it);
        return true;
      }
    return closed_;
  };
  cv_.wait_for(lock, timeout, match);
  *closed = !found && closed_;
  return found;
}

std::uint64_t EventSink::dropped() const {
  std::lock_guard lock(mutex_);
  return dropped_;
}

}  // namespace terrane::python
