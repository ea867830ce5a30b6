#include "client/python/py_client.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <mutex>

#include "client/path.h"
#include "client/python/find.h"
#include "common/cli/cli.h"
#include "common/world/view.h"

namespace terrane::python {

namespace {

// What is left of a deadline.
std::chrono::milliseconds until(Clock::time_point deadline) {
  return std::chrono::duration_cast<std::chrono::milliseconds>(
      std::max(Clock::duration::zero(), deadline - Clock::now()));
}

float radius_of(double r) {
  if (!(r > 0) || r > kMaxSphereRadius)
    raise(PyExc_ValueError,
          "radius must be in (0, 32] (and the edit's box, centre +- (radius + 1), within 64^3 voxels)");
  return static_cast<float>(r);
}

Region box_of(const IVec3& lo, const IVec3& hi, const char* what) {
  const Region r{voxel_of(lo, what), voxel_of(hi, what)};
  if (r.empty()) raise(PyExc_ValueError, std::string(what) + ": max must exceed min on every axis");
  return r;
}

// (2, y, z, x) uint8: materials, occupancies.
py::array_t<std::uint8_t> planes(Vec3i s, const auto& voxel_at) {
  py::array_t<std::uint8_t> out({std::size_t{2}, std::size_t(s.y), std::size_t(s.z), std::size_t(s.x)});
  auto m = out.mutable_unchecked<4>();
  for (int y = 0; y < s.y; ++y)
    for (int z = 0; z < s.z; ++z)
      for (int x = 0; x < s.x; ++x) {
        const Voxel v = voxel_at(x, y, z);
        m(0, y, z, x) = v.material;
        m(1, y, z, x) = v.occupancy;
      }
  return out;
}

// Under the client's lock (a wait_until predicate): touches only v. Every
// chunk of region held at full resolution (region: a view whose
// full-resolution radius is its view distance).
bool held_full(const ClientView& v, const StreamedView& region, const WorldBounds& bounds) {
  return v.welcomed && coverage(v.replica, region, bounds).complete;
}

std::mutex g_clients_mutex;
std::vector<std::weak_ptr<PyClient>> g_clients;

}  // namespace

void remember_client(const std::shared_ptr<PyClient>& c) {
  std::lock_guard lock(g_clients_mutex);
  std::erase_if(g_clients, [](const auto& w) { return w.expired(); });
  g_clients.push_back(c);
}

void close_all_clients() {
  std::vector<std::shared_ptr<PyClient>> live;
  {
    std::lock_guard lock(g_clients_mutex);
    for (const auto& w : g_clients)
      if (auto c = w.lock()) live.push_back(c);
  }
  for (const auto& c : live) c->close();
}

// --- IoPool -----------------------------------------------------------------------
IoPool::IoPool(int threads) : guard_(asio::make_work_guard(io_)) {
  for (int i = 0; i < threads; ++i) threads_.emplace_back([this] { io_.run(); });
}

IoPool::~IoPool() {
  guard_.reset();
  io_.stop();
  without_gil([&] {
    for (auto& t : threads_) t.join();
  });
}

// --- PyClient ---------------------------------------------------------------------
namespace {

// One cache per directory for the process's clients (they share its size
// and its files' use order).
std::shared_ptr<ChunkCache> chunk_cache_at(const std::string& dir) {
  static std::mutex mutex;
  static std::map<std::string, std::weak_ptr<ChunkCache>> open;
  std::lock_guard lock(mutex);
  const std::string key = ChunkCache::normal_dir(dir);
  if (auto c = open[key].lock()) return c;
  auto c = ChunkCache::open(dir, std::uint64_t{1} << 30);
  if (!c) raise(PyExc_OSError, "chunk_cache: " + c.error().message);
  open[key] = *c;
  return *c;
}

}  // namespace

PyClient::PyClient(ConnectArgs a) : name_(a.name) {
  const auto hp = parse_host_port(a.address);
  if (!hp) raise(PyExc_ValueError, "address: " + hp.error().message);
  if (hp->second == 0) raise(PyExc_ValueError, "address '" + a.address + "': port must be 1..65535");
  if (a.name.empty() || a.name.size() > kMaxClientNameBytes) raise(PyExc_ValueError, "name must be 1..64 bytes");
  if (a.view_distance < 1 || a.view_distance > 16384 || a.full_res_radius < 1 || a.full_res_radius > a.view_distance)
    raise(PyExc_ValueError, "view_distance must be 1..16384 and full_res_radius 1..view_distance");
  // At least half a second: the keepalive then pings four times a second.
  if (!(a.silence_timeout == 0 || (a.silence_timeout >= 0.5 && a.silence_timeout <= 3600)))
    raise(PyExc_ValueError, "silence_timeout must be 0 (never) or 0.5..3600 seconds");
  if (!(a.max_speed >= 0) || a.max_speed > 1e6)
    raise(PyExc_ValueError, "max_speed must be 0 (not paced) or up to 10^6");
  ClientOptions o;
  o.host = hp->first;
  o.port = hp->second;
  o.name = a.name;
  o.auth_token = a.token;
  o.reconnect = a.reconnect;
  o.silence_timeout = std::chrono::milliseconds(static_cast<std::int64_t>(a.silence_timeout * 1000));
  o.state.view_distance = a.view_distance;
  o.state.full_res_radius = a.full_res_radius;
  o.spawn_offset = a.spawn_offset;
  if (a.position) {
    o.start_at_spawn = false;
    o.state.position = point_of(*a.position, "position");
  }
  if (a.pool) o.io_context = &a.pool->io();
  if (!a.chunk_cache.empty()) o.chunk_cache = chunk_cache_at(a.chunk_cache);
  own_slot_ = !a.slot;
  slot_ = a.slot ? a.slot : std::make_shared<DispatcherSlot>();
  handlers_ = std::make_shared<Handlers>();
  sink_ = std::make_shared<EventSink>(slot_, handlers_);
  watches_ = std::make_shared<Watches>(slot_);
  ClientCallbacks cb;
  // Each event queued wakes the awaits of terrane.event (Watches).
  const auto push = [sink = sink_, ids = watches_->ids()](Event e) {
    sink->push(std::move(e));
    ids->event_queued();
  };
  cb.on_update = [push](const UpdateInfo& u) { push(to_event(u)); };
  cb.on_chunks_loaded = [push, on = reporting_.loaded_flag()](const std::vector<Vec3i>& chunks) {
    if (on->load()) push(to_event(chunks));
  };
  cb.on_presence = [push, seen = std::make_shared<PresenceChanges>()](const std::vector<PresenceEntryMsg>& p) {
    push(seen->next(p));
  };
  cb.on_notice = [push](const ServerNoticeMsg& n) { push(to_event(n)); };
  cb.on_edit_result = [ids = watches_->ids()](std::uint32_t id, const EditOutcome&) { ids->edit_answered(id); };
  cb.on_read_result = [ids = watches_->ids()](std::uint32_t id) { ids->read_answered(id); };
  cb.on_connection_lost = [ids = watches_->ids()](const std::string&) { ids->connection_lost(); };
  cb.on_disconnected = [sink = sink_, ids = watches_->ids()](const std::string& reason) {
    sink->push(DisconnectEvent{reason});
    ids->closed();
  };
  pacing_ = std::make_shared<Pacing>(a.max_speed);
  cb.on_reconnected = [push, pacing = pacing_] {
    pacing->rejoined();  // the server counts the next position as joining
    push(ReconnectedEvent{});
  };
  // The pool outlives the client: the deleter holds it.
  c_ = std::shared_ptr<Client>(new Client(o, std::move(cb)), [pool = a.pool](Client* c) { delete c; });
  walker_ = Walker(c_, pacing_);
  reporting_.bind(c_);
  std::string err;
  bool ok = false;
  ok = without_gil([&] { return c_->connect(&err); });
  // The library's reason names the address ("cannot connect to H:P: ...").
  if (!ok) raise(PyExc_ConnectionError, err);
}

PyClient::~PyClient() {
  without_gil([&] { c_->disconnect(); });
}

void PyClient::close() {
  without_gil([&] { c_->disconnect(); });
  // A client of its own: its callbacks thread ends once the disconnect
  // event has run (a Swarm's ends with the Swarm); then its handlers go,
  // so a callback that refers to the client no longer keeps it alive.
  if (own_slot_)
    if (auto d = slot_->peek()) {
      d->stop();
      if (d->finished()) clear_handlers();
    }
}

void PyClient::clear_handlers() {
  for (std::size_t k = 0; k < Handlers::kKinds; ++k) handlers_->of(k).clear();
}

void PyClient::check_open() const {
  if (c_->closed()) raise(PyExc_ConnectionError, "connection closed: " + c_->disconnect_reason());
}

void PyClient::wait_ready(double timeout) {
  const auto t = timeout_of(timeout);
  check_open();
  python::wait_ready(*c_, t);
}

void PyClient::sync(double timeout) {
  const auto deadline = Clock::now() + timeout_of(timeout);
  check_open();
  for (;;) {
    const std::uint64_t session = settle(deadline);
    // python::sync's barrier; a reconnect during its round trip loses the
    // answer: then again on the new session.
    const std::uint32_t id = request_sync(*c_);
    bool answered = false, closed = false, moved_on = false;
    wait_for(*c_, until(deadline),
             [&](const ClientView& view) {
               answered = view.read_results.count(id) != 0;
               closed = view.closed;
               moved_on = !view.linked || view.sessions != session;
               return answered || closed || moved_on;
             });
    if (answered && !moved_on) return;
    if (!moved_on) fail_or_timeout(closed, "the server did not answer within the timeout");
  }
}

std::uint64_t PyClient::settle(Clock::time_point deadline) {
  for (;;) {
    bool linked = false, closed = false;
    wait_for(*c_, until(deadline), [&](const ClientView& v) {
      // (A chunk cache still loading claims its chunks once loaded.)
      linked = v.linked && !v.cache_loading;
      closed = v.closed;
      return linked || closed;
    });
    if (!linked) fail_or_timeout(closed, "not reconnected within the timeout");
    // The claims within the full-resolution region not yet confirmed: a
    // hash request for each is answered once the server has confirmed or
    // replaced it (answers arrive in order with the data they describe).
    const WelcomeMsg w = *c_->welcome();
    const StreamedView view = streamed_view(state(), w);
    std::vector<Vec3i> asked;
    std::uint64_t session = 0;
    c_->wait_until(
        [&](const ClientView& v) {
          session = v.sessions;
          if (!v.unconfirmed.empty())
            for (const Vec3i cp : chunks_in_view(view.position, view.full_res_radius, w.bounds()))
              if (v.unconfirmed.count(cp) != 0) asked.push_back(cp);
          return true;
        },
        std::chrono::milliseconds(0));
    if (asked.empty()) return session;
    // Once a session: a request stays pending on the server until it is
    // answered (a wait that timed out and is tried again asks nothing twice).
    if (confirmations_asked_ != session) {
      confirmations_asked_ = session;
      for (const Vec3i cp : asked)
        if (!c_->request_chunk_hash(cp)) break;  // closed, or dropped: seen below
    }
    bool done = false, moved_on = false;
    wait_for(*c_, until(deadline), [&](const ClientView& v) {
      closed = v.closed;
      moved_on = !v.linked || v.sessions != session;
      done = std::none_of(asked.begin(), asked.end(), [&](Vec3i cp) { return v.unconfirmed.count(cp) != 0; });
      return done || closed || moved_on;
    });
    if (done) return session;
    if (!moved_on) fail_or_timeout(closed, "the resumed chunks were not confirmed within the timeout");
  }
}

void PyClient::wait_loaded(std::optional<double> radius, double timeout) {
  const auto t = timeout_of(timeout);
  const auto deadline = Clock::now() + t;
  wait_ready(timeout);
  const std::uint64_t session = settle(deadline);
  const WelcomeMsg w = *c_->welcome();
  const StreamedView view = streamed_view(state(), w);
  const std::int32_t full = view.full_res_radius;
  std::int32_t r = full;
  if (radius) {
    if (!(*radius > 0) || *radius > full)
      raise(PyExc_ValueError, "radius must be in (0, " + std::to_string(full) + "], the full-resolution radius");
    r = static_cast<std::int32_t>(std::ceil(*radius));
  }
  const StreamedView region{view.position, r, r};
  const WorldBounds bounds = w.bounds();
  bool loaded = false, closed = false, moved_on = false;
  wait_for(*c_, until(deadline),
        [&](const ClientView& v) {
          closed = v.closed;
          moved_on = !v.linked || v.sessions != session;
          loaded = !moved_on && held_full(v, region, bounds);
          return loaded || closed || moved_on;
        });
  // Dropped again meanwhile: wait for that session instead.
  if (moved_on && !closed) return wait_loaded(radius, std::chrono::duration<double>(deadline - Clock::now()).count());
  if (!loaded) fail_or_timeout(closed, "the full-resolution region was not loaded within the timeout");
}

bool PyClient::loaded() const {
  const auto w = c_->welcome();
  if (!w) return false;
  const StreamedView view = streamed_view(state(), *w);
  const StreamedView region{view.position, view.full_res_radius, view.full_res_radius};
  const WorldBounds bounds = w->bounds();
  const auto chunks = chunks_in_view(view.position, view.full_res_radius, bounds);
  bool l = false;
  c_->wait_until(
      [&](const ClientView& v) {
        // After a reconnect, also resumed and with nothing kept unconfirmed.
        l = v.linked && held_full(v, region, bounds) &&
            std::none_of(chunks.begin(), chunks.end(), [&](Vec3i cp) { return v.unconfirmed.count(cp) != 0; });
        return true;
      },
      std::chrono::milliseconds(0));
  return l;
}

int PyClient::verify(double timeout) {
  const auto t = timeout_of(timeout);
  const auto start = Clock::now();
  wait_ready(timeout);
  const WelcomeMsg w = *c_->welcome();
  const auto chunks = chunks_in_view(state().position, streamed_view(state(), w).full_res_radius, w.bounds());
  for (const Vec3i cp : chunks)
    if (!c_->request_chunk_hash(cp)) raise(PyExc_ConnectionError, "connection closed");
  // The answers come in order with the world's data: once the barrier's
  // does, every chunk asked about has its answer (a chunk the client does
  // not hold is not answered, and counts as differing).
  python::sync(*c_, std::max(std::chrono::milliseconds(0),
                             t - std::chrono::duration_cast<std::chrono::milliseconds>(Clock::now() - start)));
  int bad = 0;
  c_->wait_until(
      [&](const ClientView& v) {
    bad = 0;
    for (const Vec3i cp : chunks) {
      const Holding* cov = v.replica.holding(cp);
      const auto it = v.hash_checks.find(cp);
          if (cov == nullptr || !cov->full_resolution() || it == v.hash_checks.end() || !it->second) ++bad;
        }
        return true;
      },
      std::chrono::milliseconds(0));
  return bad;
}

py::object PyClient::next_event(const std::optional<std::string>& kind_or_none, double timeout) {
  const std::string kind = kind_or_none.value_or("");
  if (!kind.empty() && kind != "update" && kind != "presence" && kind != "message" && kind != "disconnect" &&
      kind != "reconnected" && kind != "loaded")
    raise(PyExc_ValueError,
          "kind must be None, 'update', 'presence', 'message', 'disconnect', 'reconnected' or 'loaded', not '" +
              kind + "'");
  const auto t = timeout_of(timeout);
  std::optional<Event> e;
  bool closed = false;
  wait_interruptibly(t, [&](std::chrono::milliseconds slice) {
    e = sink_->next(kind, slice, &closed);
    return e.has_value() || closed;
  });
  if (e) return to_python(*e);
  fail_or_timeout(closed, "no " + (kind.empty() ? std::string("event") : kind + " event") + " within the timeout");
}

py::object PyClient::on(std::size_t kind, py::object fn) {
  if (!PyCallable_Check(fn.ptr())) raise(PyExc_TypeError, "the callback must be callable");
  handlers_->of(kind).push_back(fn);
  if (kind == 5) reporting_.report_loaded(true);
  slot_->get();
  sink_->enable_callbacks();
  // Registered after the end: it still hears of it.
  if (kind == 3 && c_->closed()) sink_->post_one(kind, handlers_->of(kind).size() - 1, DisconnectEvent{utf8(c_->disconnect_reason())});
  return fn;
}

std::uint64_t PyClient::events_dropped() const { return sink_->dropped(); }

std::uint64_t PyClient::callbacks_dropped() const {
  const auto d = slot_->peek();
  return d ? d->dropped() : 0;
}

py::tuple PyClient::voxel(const IVec3& p) const {
  const Voxel v = c_->get(voxel_of(p, "voxel"));
  return py::make_tuple(material_name(v.material), v.occupancy);
}

int PyClient::resolution(const IVec3& p) const { return c_->resolution_at(voxel_of(p, "resolution")); }

bool PyClient::holds(const IVec3& lo, const IVec3& hi) const {
  const Region r = box_of(lo, hi, "holds");
  const Vec3i c0 = chunk_of(r.min), c1 = chunk_of(r.max - Vec3i{1, 1, 1});
  if ((std::int64_t{c1.x} - c0.x + 1) * (std::int64_t{c1.y} - c0.y + 1) * (std::int64_t{c1.z} - c0.z + 1) > 1 << 20)
    raise(PyExc_ValueError, "holds: at most 2^20 chunks at once");
  return c_->with_replica([&](const Replica& rep) {
    for (int y = c0.y; y <= c1.y; ++y)
      for (int z = c0.z; z <= c1.z; ++z)
        for (int x = c0.x; x <= c1.x; ++x) {
          const Holding* c = rep.holding({x, y, z});
          if (c == nullptr || !c->full_resolution()) return false;
        }
    return true;
  });
}

py::array_t<std::uint8_t> PyClient::read_box(const IVec3& lo, const IVec3& hi) const {
  const Region r = box_of(lo, hi, "read_box");
  if (r.volume() > (std::int64_t{1} << 26)) raise(PyExc_ValueError, "read_box: at most 2^26 voxels at once");
  Box box(r.size());
  c_->read_box(r.min, box);
  return planes(r.size(), [&](int x, int y, int z) { return box.get(x, y, z); });
}

py::object PyClient::raycast(const Vec3& origin, const Vec3& direction, double max_distance) const {
  const Vec3f d = point_of(direction, "direction");
  if (d.x == 0 && d.y == 0 && d.z == 0) raise(PyExc_ValueError, "raycast: the direction must not be zero");
  if (!(max_distance > 0) || max_distance > 4096) raise(PyExc_ValueError, "raycast: max_distance must be in (0, 4096]");
  const auto hit = c_->raycast(point_of(origin, "origin"), d, static_cast<float>(max_distance));
  if (!hit) return py::none();
  return py::make_tuple(py::make_tuple(hit->voxel.x, hit->voxel.y, hit->voxel.z),
                        py::make_tuple(hit->normal.x, hit->normal.y, hit->normal.z), hit->distance,
                        material_name(hit->value.material));
}

py::object PyClient::ground(std::int64_t x, std::int64_t z) const {
  const Vec3i p = voxel_of({x, 0, z}, "ground");
  const auto h = c_->surface_height(p.x, p.z);
  return h ? py::object(py::int_(*h)) : py::none();
}

std::vector<IVec3> PyClient::find(const py::object& material, const std::optional<Vec3>& near, double within,
                                   std::int64_t max) const {
  const Material m = material_of(material);
  if (!(within > 0) || within > kMaxFindRadius)
    raise(PyExc_ValueError, "find: within must be in (0, " + std::to_string(static_cast<int>(kMaxFindRadius)) + "] voxels");
  if (max < 1 || max > 1'000'000) raise(PyExc_ValueError, "find: max must be 1..1000000");
  const Vec3f p = near ? point_of(*near, "near") : state().position;
  const auto found =
      without_gil([&] { return find_voxels(*c_, m, p, within, static_cast<std::size_t>(max)); });
  std::vector<IVec3> out;
  out.reserve(found.size());
  for (const Vec3i v : found) out.push_back(ivec(v));
  return out;
}

std::vector<Player> PyClient::presence() const { return to_event(c_->presence()).players; }

EditFuture PyClient::fill_box(const IVec3& lo, const IVec3& hi, const py::object& material, int occupancy) {
  const Region r = box_of(lo, hi, "fill_box");
  if (occupancy < 0 || occupancy > 255) raise(PyExc_ValueError, "occupancy must be 0..255");
  const Material m = material_of(material);
  if (r.volume() > kMaxEditVolume)
    raise(PyExc_ValueError, "fill_box: " + std::to_string(r.volume()) + " voxels; one edit touches at most " +
                                std::to_string(kMaxEditVolume) + " voxels (64^3): fill it in pieces");
  pace();
  return sent([&] { return c_->fill_box(r, m == kAir ? Voxel{} : make_voxel(m, static_cast<std::uint8_t>(occupancy))); });
}
namespace {
EditRequestMsg sphere_edit(EditKind kind, Vec3f center, float radius) {
  EditRequestMsg e;
  e.kind = kind;
  e.center = center;
  e.radius = radius;
  return e;
}
}  // namespace

void PyClient::check_edit_size(const EditRequestMsg& e, const char* what) const {
  const std::int64_t v = e.bounds().volume();
  if (v <= kMaxEditVolume) return;
  raise(PyExc_ValueError, std::string(what) + ": the sphere's box (centre +- (radius + 1)) is " + std::to_string(v) +
                              " voxels; one edit touches at most " + std::to_string(kMaxEditVolume) +
                              " voxels (64^3): a radius up to 30.5 always fits, 31 only on some centres");
}

EditFuture PyClient::fill_sphere(const Vec3& center, double radius, const py::object& material) {
  const Vec3f c = point_of(center, "center");
  const float r = radius_of(radius);
  check_edit_size(sphere_edit(EditKind::kFillSphere, c, r), "fill_sphere");
  const Material m = material_of(material);
  pace();
  return sent([&] { return c_->fill_sphere(c, r, m); });
}
EditFuture PyClient::dig(const Vec3& center, double radius) {
  const Vec3f c = point_of(center, "center");
  const float r = radius_of(radius);
  check_edit_size(sphere_edit(EditKind::kDig, c, r), "dig");
  pace();
  return sent([&] { return c_->dig(c, r); });
}
EditFuture PyClient::paint(const Vec3& center, double radius, const py::object& material) {
  const Vec3f c = point_of(center, "center");
  const float r = radius_of(radius);
  check_edit_size(sphere_edit(EditKind::kPaint, c, r), "paint");
  const Material m = material_of(material);
  pace();
  return sent([&] { return c_->paint(c, r, m); });
}
EditFuture PyClient::smooth(const Vec3& center, double radius, double strength) {
  if (!(strength > 0) || strength > 1) raise(PyExc_ValueError, "smooth: strength must be in (0, 1]");
  check_edit_size(sphere_edit(EditKind::kSmooth, point_of(center, "center"), radius_of(radius)), "smooth");
  pace();
  return sent([&] { return c_->smooth(point_of(center, "center"), radius_of(radius), static_cast<float>(strength)); });
}

EditFuture PyClient::write_box(const IVec3& lo, const py::object& array_like) {
  // Any array-like (nested lists too), as numpy.asarray takes it.
  const py::array in = py::module_::import("numpy").attr("asarray")(array_like);
  // Integers 0..255 of any integer type (as read_box returns, or numpy's
  // default int64); floats would be truncated without a word, so they are refused.
  const char kind = in.dtype().kind();
  if (kind != 'u' && kind != 'i')
    raise(PyExc_TypeError, std::string("write_box: the array must hold integers (uint8 as read_box returns), not dtype '") +
                               std::string(py::str(in.dtype())) + "'");
  const auto a = py::array_t<std::int64_t, py::array::c_style | py::array::forcecast>::ensure(in);
  if (!a || a.ndim() != 4 || a.shape(0) != 2) raise(PyExc_ValueError, "write_box: the array must have shape (2, y, z, x)");
  const Vec3i size{static_cast<int>(a.shape(3)), static_cast<int>(a.shape(1)), static_cast<int>(a.shape(2))};
  const Vec3i min = voxel_of(lo, "write_box min");
  const Region r{min, min + size};
  if (r.empty() || r.volume() > kMaxRawBoxVolume)
    raise(PyExc_ValueError, "write_box: 1 to " + std::to_string(kMaxRawBoxVolume) + " voxels");
  const std::size_t known = std::max<std::size_t>(materials().size(), 1);
  auto m = a.unchecked<4>();
  std::vector<Voxel> voxels;
  voxels.reserve(static_cast<std::size_t>(r.volume()));
  for (int y = 0; y < size.y; ++y)
    for (int z = 0; z < size.z; ++z)
      for (int x = 0; x < size.x; ++x) {
        const std::int64_t mat = m(0, y, z, x), occ = m(1, y, z, x);
        if (mat < 0 || static_cast<std::uint64_t>(mat) >= known)
          raise(PyExc_ValueError, "write_box: material " + std::to_string(mat) + " at " + str({x, y, z}) +
                                      " is not one of this world's");
        if (occ < 0 || occ > 255)
          raise(PyExc_ValueError, "write_box: occupancy " + std::to_string(occ) + " at " + str({x, y, z}) +
                                      " is not 0..255");
        voxels.push_back(mat == kAir ? Voxel{} : make_voxel(static_cast<Material>(mat), static_cast<std::uint8_t>(occ)));
      }
  pace();
  return sent([&] { return c_->write_box(r, voxels); });
}

EditFuture PyClient::undo() {
  pace();
  return sent([&] { return c_->undo(); });
}
EditFuture PyClient::redo() {
  pace();
  return sent([&] { return c_->redo(); });
}

py::array_t<std::uint8_t> PyClient::read_server_box(const IVec3& lo, const IVec3& hi, double timeout) {
  const auto t = timeout_of(timeout);
  const Region r = box_of(lo, hi, "read_server_box");
  if (r.volume() > kMaxRawBoxVolume)
    raise(PyExc_ValueError, "read_server_box: 1 to " + std::to_string(kMaxRawBoxVolume) + " voxels");
  const std::uint32_t id = c_->request_read_box(r);
  if (id == 0) raise(PyExc_ConnectionError, "connection closed");
  std::optional<ReadBoxResultMsg> res;
  bool closed = false;
  wait_for(*c_, t,
        [&](const ClientView& v) {
          if (auto it = v.read_results.find(id); it != v.read_results.end()) res = it->second;
          closed = v.closed;
          return res.has_value() || closed;
        });
  if (!res) fail_or_timeout(closed, "the server did not answer the read within the timeout");
  if (!res->error.empty()) raise(PyExc_ValueError, "read_server_box: " + res->error);
  // The answer must be for the box asked (the server is not trusted).
  if (!(res->box == r) || res->voxels.size() != static_cast<std::size_t>(r.volume()))
    raise(PyExc_ConnectionError, "read_server_box: the server answered for another box");
  const Vec3i s = r.size();
  return planes(s, [&](int x, int y, int z) { return res->voxels[static_cast<std::size_t>((y * s.z + z) * s.x + x)]; });
}

py::object PyClient::target(double max_distance) const {
  return raycast(vec(walker_.eye()), vec(walker_.facing()), max_distance);
}

Vec3 PyClient::position() const { return vec(walker_.position()); }

const std::vector<std::string>& PyClient::materials() const {
  // Read once from the Welcome (every query names materials; copying the
  // Welcome each time cost more than the query). Under the GIL, like every
  // other member.
  if (names_.empty())
    if (const auto w = c_->welcome())
      for (const auto& n : w->materials) names_.push_back(utf8(n));
  return names_;
}

ClientStateMsg PyClient::state() const { return c_->last_state().value_or(ClientStateMsg{}); }

void PyClient::fail_or_timeout(bool closed, const std::string& what) const {
  if (closed) raise(PyExc_ConnectionError, "connection closed: " + c_->disconnect_reason());
  raise(PyExc_TimeoutError, what);
}

std::string PyClient::material_name(Material m) const {
  const auto& names = materials();
  return m < names.size() ? names[m] : std::to_string(m);
}

namespace {
// numpy.bool_, without importing numpy (an import on a script's first edit
// stalled its event loop for tens of ms): if numpy is not imported, m is not one.
bool is_numpy_bool(const py::object& m) {
  PyObject* numpy = PyImport_GetModule(py::str("numpy").ptr());
  if (numpy == nullptr) {
    if (PyErr_Occurred()) throw py::error_already_set();
    return false;
  }
  return py::isinstance(m, py::reinterpret_steal<py::object>(numpy).attr("bool_"));
}
}  // namespace

Material PyClient::material_of(const py::object& m) const {
  const auto& names = materials();
  if (py::isinstance<py::bool_>(m) || is_numpy_bool(m))
    raise(PyExc_TypeError, "material must be a name (str) or an id (int), not bool");
  // Any integer: int, numpy's integers, whatever has __index__.
  if (!py::isinstance<py::str>(m) && PyIndex_Check(m.ptr())) {
    const py::int_ as_int = py::reinterpret_steal<py::int_>(PyNumber_Index(m.ptr()));
    if (!as_int) throw py::error_already_set();
    int overflow = 0;
    const long long id = PyLong_AsLongLongAndOverflow(as_int.ptr(), &overflow);
    if (overflow != 0) raise(PyExc_ValueError, "unknown material: an id too large for any world (0..63)");
    if (id < 0 || static_cast<std::size_t>(id) >= std::max<std::size_t>(names.size(), 1))
      raise(PyExc_ValueError, "unknown material " + std::to_string(id) + ": this world defines 0.." +
                                  std::to_string(names.empty() ? 0 : names.size() - 1));
    return static_cast<Material>(id);
  }
  if (py::isinstance<py::str>(m)) {
    const std::string s = m.cast<std::string>();
    for (std::size_t i = 0; i < names.size(); ++i)
      if (names[i] == s) return static_cast<Material>(i);
    std::string known;
    for (const auto& n : names) known += (known.empty() ? "" : ", ") + n;
    raise(PyExc_ValueError, "unknown material '" + s + "': this world has " + known);
  }
  raise(PyExc_TypeError, "material must be a name (str) or an id (int)");
}

double PyClient::reserve_edit() {
  check_open();
  const auto w = without_gil([&] { return c_->welcome(); });
  return w ? std::chrono::duration<double>(pacing_->reserve_edit(*w)).count() : 0.0;
}

void PyClient::when_event(py::object fn) {
  if (!PyCallable_Check(fn.ptr())) raise(PyExc_TypeError, "when_event: fn must be callable");
  watches_->on_event([fn] { fn(); });
  if (c_->closed()) watches_->ids()->closed();
}

void PyClient::when_synced(py::object fn) {
  if (!PyCallable_Check(fn.ptr())) raise(PyExc_TypeError, "when_synced: fn must be callable");
  watches_->on_read(*c_, request_sync(*c_), [fn] { fn(); });
}

void PyClient::pace() {
  const auto w = without_gil([&] { return c_->welcome(); });
  if (w) python::pause(*c_, pacing_->edit(*w), "pacing edits");
}

EditFuture PyClient::sent(const std::function<std::uint32_t()>& send) {
  // The GIL released: sending takes the client's lock, which the io side
  // may hold for a while (applying a large update).
  const std::uint32_t id = without_gil(send);
  if (id == 0) raise(PyExc_ConnectionError, "the edit could not be sent (connection closed or queue full)");
  return EditFuture(c_, watches_, id);
}

}  // namespace terrane::python
