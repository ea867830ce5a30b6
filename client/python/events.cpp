#include "client/python/events.h"

#include <algorithm>

namespace terrane::python {

UpdateEvent to_event(const UpdateInfo& u) {
  UpdateEvent e;
  e.tick = u.tick;
  for (const auto& r : u.revisions) e.chunks.emplace_back(ivec(r.chunk_pos), r.revision);
  for (const auto& r : u.changed) e.regions.emplace_back(ivec(r.min), ivec(r.max));
  return e;
}

PresenceEvent to_event(const std::vector<PresenceEntryMsg>& p) {
  PresenceEvent e;
  for (const auto& x : p) e.players.push_back(Player{x.client_id, vec(x.position)});
  return e;
}

MessageEvent to_event(const ServerNoticeMsg& n) {
  return MessageEvent{n.kind == wire::NoticeKind::Shutdown ? "shutdown" : "say", n.text, n.seconds_left, n.reconnect};
}

py::object to_python(const Event& e) {
  return std::visit([](const auto& v) { return py::cast(v); }, e);
}

// --- Dispatcher -----------------------------------------------------------------
namespace {
std::mutex g_registry_mutex;
std::vector<std::weak_ptr<Dispatcher>> g_dispatchers;

void remember(const std::shared_ptr<Dispatcher>& d) {
  std::lock_guard lock(g_registry_mutex);
  std::erase_if(g_dispatchers, [](const auto& w) { return w.expired(); });
  g_dispatchers.push_back(d);
}
}  // namespace

void stop_all_dispatchers() {
  std::vector<std::shared_ptr<Dispatcher>> live;
  {
    std::lock_guard lock(g_registry_mutex);
    for (const auto& w : g_dispatchers)
      if (auto d = w.lock()) live.push_back(d);
  }
  for (const auto& d : live) d->stop();
}

Dispatcher::Dispatcher() : state_(std::make_shared<State>()), thread_(&Dispatcher::run, state_) {}

Dispatcher::~Dispatcher() { stop(); }

bool Dispatcher::post(Job job) {
  {
    std::lock_guard lock(state_->mutex);
    if (state_->stopping) return false;
    if (state_->jobs.size() >= kMaxQueuedJobs) {
      ++state_->dropped;
      return false;
    }
    state_->jobs.push_back(std::move(job));
  }
  state_->cv.notify_one();
  return true;
}

void Dispatcher::stop() {
  {
    std::lock_guard lock(state_->mutex);
    state_->stopping = true;
  }
  state_->cv.notify_one();
  if (!thread_.joinable()) return;
  if (thread_.get_id() == std::this_thread::get_id()) {
    thread_.detach();  // the thread holds state_ and ends after this job
    return;
  }
  if (Py_IsInitialized() && PyGILState_Check()) {
    py::gil_scoped_release nogil;
    thread_.join();
  } else {
    thread_.join();
  }
}

std::uint64_t Dispatcher::dropped() const {
  std::lock_guard lock(state_->mutex);
  return state_->dropped;
}

void Dispatcher::run(std::shared_ptr<State> s) {
  for (;;) {
    Job job;
    {
      std::unique_lock lock(s->mutex);
      s->cv.wait(lock, [&] { return s->stopping || !s->jobs.empty(); });
      if (s->jobs.empty()) return;
      job = std::move(s->jobs.front());
      s->jobs.pop_front();
    }
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
}

std::shared_ptr<Dispatcher> DispatcherSlot::get() {
  std::lock_guard lock(mutex_);
  if (!dispatcher_) {
    dispatcher_ = std::make_shared<Dispatcher>();
    remember(dispatcher_);
  }
  return dispatcher_;
}

std::shared_ptr<Dispatcher> DispatcherSlot::peek() const {
  std::lock_guard lock(mutex_);
  return dispatcher_;
}

// --- EventSink --------------------------------------------------------------------
void EventSink::push(Event e) {
  const bool disconnect = std::holds_alternative<DisconnectEvent>(e);
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
  d->post([handlers = handlers_, ev = std::move(*for_callbacks)] {
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
  });
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
