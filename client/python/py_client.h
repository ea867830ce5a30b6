// The Python face of the client library: Client (one connection and its
// replica) and IoPool (io threads a Swarm's clients share,
// client/python/swarm.h); EditFuture is in client/python/edit_future.h.
// Every wait releases the GIL; the library's io side never takes it
// (client/python/events.h).
#pragma once

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <asio.hpp>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "client/client.h"
#include "client/python/edit_future.h"
#include "client/python/events.h"
#include "client/python/gil.h"
#include "client/python/pacing.h"
#include "client/python/reporting.h"
#include "client/python/walker.h"
#include "client/python/watches.h"

namespace terrane::python {

using Clock = std::chrono::steady_clock;

// An io_context run by a few threads, shared by a Swarm's clients. It
// outlives every client on it (each client's deleter holds it).
class IoPool {
 public:
  explicit IoPool(int threads);
  ~IoPool();
  asio::io_context& io() { return io_; }

 private:
  asio::io_context io_;
  asio::executor_work_guard<asio::io_context::executor_type> guard_;
  std::vector<std::thread> threads_;
};

struct ConnectArgs {
  std::string address;
  std::string name = "python";
  std::string token;
  std::optional<Vec3> position;  // none: the server's spawn (plus spawn_offset)
  Vec3f spawn_offset{0, 0, 0};
  int view_distance = 128;
  int full_res_radius = 48;
  bool reconnect = false;
  double silence_timeout = 15;  // seconds; 0 = never
  double max_speed = 256;       // the server's --max-speed; 0 = moves not paced
  std::string chunk_cache;      // a directory: chunks kept across sessions (client/chunk_cache.h); empty: none
  std::shared_ptr<IoPool> pool;           // null: the client owns its io thread
  std::shared_ptr<DispatcherSlot> slot;   // null: a slot of its own
};

class PyClient {
 public:
  explicit PyClient(ConnectArgs a);
  ~PyClient();

  // --- events and waits --------------------------------------------------------
  void wait_ready(double timeout);
  void sync(double timeout);
  void wait_loaded(std::optional<double> radius, double timeout);
  bool loaded() const;
  int verify(double timeout);
  py::object next_event(const std::optional<std::string>& kind, double timeout);
  // Registers fn for events of kind (update, presence, message, disconnect,
  // reconnected, loaded: the index in Event). A loaded callback turns
  // Loaded events on (Reporting).
  py::object on(std::size_t kind, py::object fn);
  // What the io side reports beyond the default events: changed voxels,
  // Loaded events (client/python/reporting.h).
  Reporting& reporting() { return reporting_; }
  std::uint64_t events_dropped() const;
  std::uint64_t callbacks_dropped() const;
  // Forgets every callback (GIL held): after the last has run, so a
  // callback that refers to its client no longer keeps it alive.
  void clear_handlers();

  // --- the replica ---------------------------------------------------------------
  py::tuple voxel(const IVec3& p) const;
  int resolution(const IVec3& p) const;
  bool holds(const IVec3& lo, const IVec3& hi) const;
  py::array_t<std::uint8_t> read_box(const IVec3& lo, const IVec3& hi) const;
  py::object raycast(const Vec3& origin, const Vec3& direction, double max_distance) const;
  py::object ground(std::int64_t x, std::int64_t z) const;
  // The voxels of a material nearest near (default: the client's
  // position) within `within` voxels, nearest first, at most max
  // (client/python/find.h).
  std::vector<IVec3> find(const py::object& material, const std::optional<Vec3>& near, double within,
                          std::int64_t max) const;
  std::vector<Player> presence() const;

  // --- edits ---------------------------------------------------------------------
  EditFuture fill_box(const IVec3& lo, const IVec3& hi, const py::object& material, int occupancy);
  EditFuture fill_sphere(const Vec3& center, double radius, const py::object& material);
  EditFuture dig(const Vec3& center, double radius);
  EditFuture paint(const Vec3& center, double radius, const py::object& material);
  EditFuture smooth(const Vec3& center, double radius, double strength);
  // voxels: any array-like of integers (numpy.asarray takes it).
  EditFuture write_box(const IVec3& lo, const py::object& voxels);
  EditFuture undo();
  EditFuture redo();
  // asyncio's pacing: takes the next edit's turn now and returns how many
  // seconds to wait (on the event loop) before sending it; the next edit
  // then goes at once.
  double reserve_edit();
  // Calls fn() on the callbacks thread once everything the server sent so
  // far is applied (sync's barrier answered), or the connection is lost.
  void when_synced(py::object fn);
  // Calls fn() on the callbacks thread once the next event is queued (or
  // the client closed): terrane.event then takes it with next_event.
  void when_event(py::object fn);
  py::array_t<std::uint8_t> read_server_box(const IVec3& lo, const IVec3& hi, double timeout);

  // --- movement: the Walker (client/python/walker.h) ----------------------------------
  Walker& walker() { return walker_; }
  Vec3 position() const;
  // What the eye looks at along the Walker's facing.
  py::object target(double max_distance) const;

  const std::vector<std::string>& materials() const;
  bool closed() const { return c_->closed(); }
  std::string disconnect_reason() const { return utf8(c_->disconnect_reason()); }
  std::string name() const { return name_; }
  void close();

 private:
  ClientStateMsg state() const;
  [[noreturn]] void fail_or_timeout(bool closed, const std::string& what) const;
  // Raises ConnectionError once the client is closed (close() or the end).
  void check_open() const;
  // After a resumed session (a reconnect or a Redirect): waits until the
  // new Welcome has come and every chunk of the full-resolution region
  // claimed in the resume is confirmed or replaced by the server, so the
  // replica holds nothing stale there. Returns the session it settled.
  std::uint64_t settle(Clock::time_point deadline);
  // Raises ValueError naming the limit when an edit's box is over what
  // one edit may touch (kMaxEditVolume).
  void check_edit_size(const EditRequestMsg& e, const char* what) const;
  std::string material_name(Material m) const;
  Material material_of(const py::object& m) const;
  // Sends an edit (send returns its id, 0 if it could not be sent).
  EditFuture sent(const std::function<std::uint32_t()>& send);
  // Keeps this client's edits within the rate the server's Welcome states
  // (waiting, GIL released, when a script edits faster).
  void pace();

  std::string name_;
  std::shared_ptr<DispatcherSlot> slot_;
  bool own_slot_ = false;               // not a Swarm's
  std::shared_ptr<Handlers> handlers_;  // GIL
  std::shared_ptr<EventSink> sink_;
  std::shared_ptr<Watches> watches_;  // what awaits wait for (GIL; the io side holds its Ids)
  std::shared_ptr<Client> c_;
  mutable std::vector<std::string> names_;  // the world's materials, once welcomed
  std::shared_ptr<Pacing> pacing_;  // shared with the reconnected callback (io side) and walker_
  Walker walker_{nullptr, nullptr};  // set once c_ is made
  std::uint64_t confirmations_asked_ = 0;  // the session whose claims settle() asked about
  Reporting reporting_;  // bound to c_ once it is made
};

// Every live client, so Python's exit can close them (registry of weak
// pointers; the module's atexit hook calls close_all_clients).
void remember_client(const std::shared_ptr<PyClient>& c);
void close_all_clients();

}  // namespace terrane::python
