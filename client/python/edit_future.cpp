#include "client/python/edit_future.h"

#include <algorithm>
#include <cmath>

#include "client/python/gil.h"

namespace terrane::python {

using Clock = std::chrono::steady_clock;

[[noreturn]] void raise(PyObject* type, const std::string& what) {
  PyErr_SetString(type, utf8(what).c_str());
  throw py::error_already_set();
}

std::chrono::milliseconds timeout_of(double seconds) {
  if (!(seconds >= 0) || seconds > 86400) raise(PyExc_ValueError, "timeout must be 0..86400 seconds");
  return std::chrono::milliseconds(static_cast<std::int64_t>(seconds * 1000));
}

bool wait_for(Client& c, std::chrono::milliseconds timeout, const std::function<bool(const ClientView&)>& pred) {
  return wait_interruptibly(timeout, [&](std::chrono::milliseconds slice) { return c.wait_until(pred, slice); });
}

void wait_ready(Client& c, std::chrono::milliseconds timeout) {
  bool ready = false, closed = false;
  wait_for(c, timeout, [&](const ClientView& v) {
    ready = v.welcomed;
    closed = v.closed;
    return ready || closed;
  });
  if (ready) return;
  if (closed) raise(PyExc_ConnectionError, "connection closed: " + c.disconnect_reason());
  raise(PyExc_TimeoutError, "no Welcome within the timeout");
}

void pause(Client& c, std::chrono::milliseconds wait, const char* what) {
  if (wait.count() == 0) return;
  bool closed = false;
  wait_for(c, wait, [&](const ClientView& v) { return closed = v.closed; });
  if (closed)
    raise(PyExc_ConnectionError, std::string("connection closed while ") + what + ": " + c.disconnect_reason());
}

Vec3i voxel_of(const std::tuple<std::int64_t, std::int64_t, std::int64_t>& p, const char* what) {
  const auto [x, y, z] = p;
  for (const std::int64_t v : {x, y, z})
    if (v < -kMaxWireCoordinate || v > kMaxWireCoordinate)
      raise(PyExc_ValueError, std::string(what) + ": coordinates must lie within +-2^24");
  return {static_cast<std::int32_t>(x), static_cast<std::int32_t>(y), static_cast<std::int32_t>(z)};
}

Vec3f point_of(const std::tuple<double, double, double>& p, const char* what) {
  const auto [x, y, z] = p;
  for (const double v : {x, y, z})
    if (!std::isfinite(v) || std::abs(v) > kMaxWireCoordinate)
      raise(PyExc_ValueError, std::string(what) + ": coordinates must be finite, within +-2^24");
  return {static_cast<float>(x), static_cast<float>(y), static_cast<float>(z)};
}

bool EditFuture::done() const {
  bool d = false;
  c_->wait_until([&](const ClientView& v) { return d = v.edits.count(id_) != 0; }, std::chrono::milliseconds(0));
  return d;
}

std::string EditFuture::outcome() const {
  std::string out = "pending";
  c_->wait_until(
      [&](const ClientView& v) {
        if (auto it = v.edits.find(id_); it != v.edits.end())
          out = it->second.accepted ? "applied" : edit_outcome_unknown(it->second) ? "unknown" : "rejected";
        return true;
      },
      std::chrono::milliseconds(0));
  return out;
}

namespace {
// sync's barrier: a one-voxel ReadBox at the client's position; 0 when it
// could not be sent.
std::uint32_t send_barrier(Client& c) {
  const Vec3f p = c.last_state().value_or(ClientStateMsg{}).position;
  const Vec3i v{static_cast<std::int32_t>(std::floor(p.x)), static_cast<std::int32_t>(std::floor(p.y)),
                static_cast<std::int32_t>(std::floor(p.z))};
  return c.request_read_box(Region{v, v + Vec3i{1, 1, 1}});
}
}  // namespace

std::uint32_t request_sync(Client& c) {
  const std::uint32_t id = send_barrier(c);
  if (id == 0) raise(PyExc_ConnectionError, "connection closed");
  return id;
}

void sync(Client& c, std::chrono::milliseconds timeout) {
  const std::uint32_t id = request_sync(c);
  bool answered = false, closed = false;
  wait_for(c, timeout,
        [&](const ClientView& view) {
          answered = view.read_results.count(id) != 0;
          closed = view.closed;
          return answered || closed;
        });
  if (answered) return;
  if (closed) raise(PyExc_ConnectionError, "connection closed: " + c.disconnect_reason());
  raise(PyExc_TimeoutError, "the server did not answer within the timeout");
}

bool EditFuture::result(double timeout, bool visible) {
  const auto t = timeout_of(timeout);
  const auto start = Clock::now();
  std::optional<EditOutcome> o;
  bool closed = false;
  wait_for(*c_, t,
        [&](const ClientView& v) {
          if (auto it = v.edits.find(id_); it != v.edits.end()) o = it->second;
          closed = v.closed;
          return o.has_value() || closed;
        });
  if (o && o->accepted) {
    const auto spent = std::chrono::duration_cast<std::chrono::milliseconds>(Clock::now() - start);
    if (visible) sync(*c_, std::max(std::chrono::milliseconds(0), t - spent));
    return true;
  }
  if (o && edit_outcome_unknown(*o)) throw EditOutcomeUnknown(utf8(o->reason));
  if (o) throw EditRejected(utf8(o->reason));
  if (closed) raise(PyExc_ConnectionError, "connection closed before the edit was answered: " + c_->disconnect_reason());
  raise(PyExc_TimeoutError, "edit " + std::to_string(id_) + " not answered within the timeout");
}

void EditFuture::when_done(py::object fn, bool visible) {
  if (!PyCallable_Check(fn.ptr())) raise(PyExc_TypeError, "when_done: fn must be callable");
  // Weak: the continuation is kept by the Watches it would point to.
  std::weak_ptr<Watches> weak = watches_;
  watches_->on_edit(*c_, id_, [c = c_, weak, id = id_, fn, visible] {
    // The client's lock is taken with the GIL released (the io side may
    // hold it for a while).
    bool applied = false;
    without_gil([&] {
      c->wait_until(
          [&](const ClientView& v) {
            const auto it = v.edits.find(id);
            applied = it != v.edits.end() && it->second.accepted && !v.closed;
            return true;
          },
          std::chrono::milliseconds(0));
    });
    if (applied && visible)
      if (auto w = weak.lock()) {
        if (const std::uint32_t read = without_gil([&] { return send_barrier(*c); }); read != 0) {
          w->on_read(*c, read, [fn] { fn(); });
          return;
        }
      }
    fn();
  });
}

}  // namespace terrane::python
