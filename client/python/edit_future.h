// EditFuture (one edit's outcome, waited for by result()) and what every
// binding shares: its exceptions, raise(), timeouts, the interruptible
// wait on a Client's view (readiness, pauses) and the sync barrier, and
// the checks of a script's coordinates. Called with the GIL held;
// each wait releases it.
#pragma once

#include <pybind11/pybind11.h>

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <stdexcept>
#include <string>
#include <tuple>

#include "client/client.h"
#include "client/python/watches.h"

namespace terrane::python {

// A refusal: the edit was not applied.
class EditRejected : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};
// No answer that says: the edit may or may not have been applied (the
// connection went first, or the server could not learn it). Not an
// EditRejected, so a script that retries refusals does not apply twice.
class EditOutcomeUnknown : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};
class Unreachable : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

[[noreturn]] void raise(PyObject* type, const std::string& what);
// Waits (GIL released) until everything the server sent before it reads
// this request is in the replica: a one-voxel ReadBox, answered in order
// with the world's data. Raises TimeoutError or ConnectionError.
void sync(Client& c, std::chrono::milliseconds timeout);
// Sends sync's barrier, a one-voxel ReadBox at the client's position, and
// returns its request id (its answer is in ClientView::read_results);
// raises ConnectionError when the client is closed.
std::uint32_t request_sync(Client& c);
std::chrono::milliseconds timeout_of(double seconds);
// Waits until pred holds on the client's view (checked after every frame)
// or the timeout passes; Ctrl-C interrupts it. pred runs under the
// client's lock.
bool wait_for(Client& c, std::chrono::milliseconds timeout, const std::function<bool(const ClientView&)>& pred);
// Waits for the Welcome; raises ConnectionError once closed (or closed
// before it came), TimeoutError at the timeout.
void wait_ready(Client& c, std::chrono::milliseconds timeout);
// Waits out a pause (pacing); ends early, raising ConnectionError, only if
// the connection closes. what: "moving", "pacing edits".
void pause(Client& c, std::chrono::milliseconds wait, const char* what);
// A script's coordinates, checked (ValueError naming what): a voxel within
// the wire's +-2^24, a point finite and within it.
Vec3i voxel_of(const std::tuple<std::int64_t, std::int64_t, std::int64_t>& p, const char* what);
Vec3f point_of(const std::tuple<double, double, double>& p, const char* what);

// The outcome of one edit: result() waits for the server's answer.
class EditFuture {
 public:
  EditFuture(std::shared_ptr<Client> c, std::shared_ptr<Watches> watches, std::uint32_t id)
      : c_(std::move(c)), watches_(std::move(watches)), id_(id) {}
  std::uint32_t id() const { return id_; }
  bool done() const;
  // "pending", "applied" (acknowledged: applied and stored), "rejected"
  // (not applied) or "unknown" (edit_outcome_unknown: may have been).
  std::string outcome() const;
  // True when acknowledged (applied and stored) and, with visible, once
  // the replica shows it (sync); raises EditRejected with the server's
  // reason, EditOutcomeUnknown, TimeoutError, or ConnectionError.
  bool result(double timeout, bool visible);
  // Calls fn() on the client's callbacks thread (GIL held) once result
  // would return or raise at once: the edit answered and, with visible and
  // applied, sync's barrier answered after it (or the connection lost or
  // closed). No thread waits meanwhile (asyncio's await, __init__.py).
  void when_done(py::object fn, bool visible);

 private:
  std::shared_ptr<Client> c_;
  std::shared_ptr<Watches> watches_;
  std::uint32_t id_;
};

}  // namespace terrane::python
