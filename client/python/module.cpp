// terrane._native: the bindings of client/python/py_client.h. The package
// terrane (client/python/terrane/__init__.py) re-exports them and adds the
// asyncio helpers; terrane/__init__.pyi holds the type hints.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include "client/python/events.h"
#include "client/python/gil.h"
#include "client/python/py_client.h"
#include "client/python/swarm.h"

namespace {

std::string repr(const terrane::python::Vec3& v) {
  const auto [x, y, z] = v;
  return "(" + std::to_string(x) + ", " + std::to_string(y) + ", " + std::to_string(z) + ")";
}

}  // namespace

PYBIND11_MODULE(_native, m) {
  using namespace terrane::python;
  namespace py = pybind11;
  m.doc() = "Terrane's client library for scripts: connect to a terrane-server, query its world, edit it, walk it.";
  py::register_exception<EditRejected>(m, "EditRejected", PyExc_RuntimeError);
  py::register_exception<EditOutcomeUnknown>(m, "EditOutcomeUnknown", PyExc_RuntimeError);
  py::register_exception<Unreachable>(m, "Unreachable", PyExc_RuntimeError);

  py::class_<UpdateEvent>(m, "Update", "Voxels changed by other clients' (or this one's) edits in one server tick.")
      .def_property_readonly_static("kind", [](const py::object&) { return "update"; })
      .def_readonly("tick", &UpdateEvent::tick, "The server tick the edits were applied in.")
      .def_readonly("chunks", &UpdateEvent::chunks, "[((cx, cy, cz), revision)]: the 32^3 chunks touched.")
      .def_readonly("regions", &UpdateEvent::regions,
                    "[((x0, y0, z0), (x1, y1, z1))]: per chunk held at full resolution, the changed voxels [min, max).")
      .def_property_readonly(
          "voxels",
          [](const UpdateEvent& e) -> py::object {
            if (!e.voxels_recorded) return py::none();
            py::list out(e.voxels.size());
            std::size_t i = 0;
            for (const terrane::VoxelChange& v : e.voxels)
              out[i++] = py::make_tuple(py::make_tuple(v.voxel_pos.x, v.voxel_pos.y, v.voxel_pos.z),
                                        py::make_tuple(int{v.before.material}, int{v.before.occupancy}),
                                        py::make_tuple(int{v.after.material}, int{v.after.occupancy}));
            return out;
          },
          "[((x, y, z), (old material id, old occupancy), (new material id, new occupancy))]: each voxel the batch "
          "changed, in the replica before and after it applied, when the client records them "
          "(record_voxel_changes, or on_update(fn, voxels=True)); None otherwise. At most the recording's max_voxels "
          "(default 4096) per event: voxels_truncated tells when more changed. Client.materials names the ids.")
      .def_readonly("voxels_truncated", &UpdateEvent::voxels_truncated,
                    "True when the batch changed more voxels than were recorded (regions still covers them all).")
      .def("__repr__", [](const UpdateEvent& e) {
        return "<Update tick=" + std::to_string(e.tick) + " chunks=" + std::to_string(e.chunks.size()) + ">";
      });
  py::class_<LoadedEvent>(m, "Loaded",
                          "Chunks held at full resolution that were not before (not held, or only coarser), from one "
                          "batch the server streamed; reported once report_loaded is on (or an on_loaded callback is "
                          "registered).")
      .def_property_readonly_static("kind", [](const py::object&) { return "loaded"; })
      .def_readonly("chunks", &LoadedEvent::chunks,
                    "[(cx, cy, cz)]: the 32^3 chunks, each covering voxels [32 c, 32 c + 32) on every axis.")
      .def("__repr__",
           [](const LoadedEvent& e) { return "<Loaded chunks=" + std::to_string(e.chunks.size()) + ">"; });
  py::class_<Player>(m, "Player", "Another client in view.")
      .def_readonly("id", &Player::id, "The server's id of the client (stable for its connection).")
      .def_readonly("position", &Player::position, "(x, y, z) of its feet.")
      .def_readonly("name", &Player::name, "The name it joined with ('' from a server that does not say).")
      .def("__repr__", [](const Player& p) {
        return "<Player id=" + std::to_string(p.id) + " '" + p.name + "' at " + repr(p.position) + ">";
      });
  py::class_<PresenceEvent>(m, "Presence",
                            "The other clients in view, nearest first. The server sends it when the list changes (who "
                            "is in view, or where), at most twice a second (its --presence-hz); never while nothing "
                            "moves. Places are to an eighth of a voxel; a far client's place is told less often (beyond "
                            "256 voxels, every 4 s at 2 Hz).")
      .def_property_readonly_static("kind", [](const py::object&) { return "presence"; })
      .def_readonly("players", &PresenceEvent::players, "[Player]: the clients in view now, nearest first.")
      .def_readonly("joined", &PresenceEvent::joined, "[Player]: those in view now and not in the previous Presence.")
      .def_readonly("left", &PresenceEvent::left,
                    "[id]: those in the previous Presence and not now (gone out of view, or disconnected).")
      .def("__repr__",
           [](const PresenceEvent& e) { return "<Presence players=" + std::to_string(e.players.size()) + ">"; });
  py::class_<MessageEvent>(m, "Message", "A notice from the server's operators.")
      .def_property_readonly_static("kind", [](const py::object&) { return "message"; })
      .def_readonly("type", &MessageEvent::kind, "'say' (a message) or 'shutdown' (the server is stopping).")
      .def_readonly("text", &MessageEvent::text, "What the operator said, or the shutdown's notice.")
      .def_readonly("seconds_left", &MessageEvent::seconds_left, "shutdown: seconds until the server stops.")
      .def_readonly("reconnect", &MessageEvent::reconnect, "shutdown: whether the server says it comes back.")
      .def("__repr__", [](const MessageEvent& e) { return "<Message " + e.kind + ": " + e.text + ">"; });
  py::class_<DisconnectEvent>(m, "Disconnect", "The connection closed for good.")
      .def_property_readonly_static("kind", [](const py::object&) { return "disconnect"; })
      .def_readonly("reason", &DisconnectEvent::reason, "Why (the server's reason, or the library's).")
      .def("__repr__", [](const DisconnectEvent& e) { return "<Disconnect: " + e.reason + ">"; });
  py::class_<ReconnectedEvent>(m, "Reconnected",
                               "The connection dropped and was resumed (reconnect=True, or a Redirect followed): the "
                               "new server's Welcome came. sync() and wait_loaded() wait until the replica is "
                               "confirmed again.")
      .def_property_readonly_static("kind", [](const py::object&) { return "reconnected"; })
      .def("__repr__", [](const ReconnectedEvent&) { return std::string("<Reconnected>"); });

  py::class_<EditFuture>(m, "EditFuture", "The outcome of one edit, answered by the server.")
      .def_property_readonly("id", &EditFuture::id, "The edit's id on this connection.")
      .def("done", &EditFuture::done,
           "True once the edit has an outcome (acknowledged, rejected, or unknown: the connection went first).")
      .def_property_readonly("outcome", &EditFuture::outcome,
                             "'pending', 'applied' (acknowledged: applied and stored), 'rejected' (not applied) or "
                             "'unknown' (may or may not have been applied: the connection closed before the answer, "
                             "or the server could not learn it). Does not wait.")
      .def("_when_done", &EditFuture::when_done, py::arg("fn"), py::arg("visible") = true,
           "Call fn() on the callbacks thread once result() would return or raise at once (await future).")
      .def("result", &EditFuture::result, py::arg("timeout") = 30.0, py::arg("visible") = true,
           "Wait for the answer: True once the edit is applied and stored (durable) and, with visible, shown by "
           "this client's replica (one more round trip; visible=False for throughput). Raises "
           "EditRejected(reason) when it was not applied, EditOutcomeUnknown(reason) when it may or may not have "
           "been (never an EditRejected: check the world before trying again), TimeoutError or ConnectionError.");

  py::class_<PyClient, std::shared_ptr<PyClient>>(m, "Client",
                                                   R"(A connection to a terrane-server and a replica of what it streams.

Made by terrane.connect(...) (or a Swarm). Queries read the replica: what
the server has sent, at full resolution near the client and as coarse mips
farther out. Edits return an EditFuture. Events (update, presence,
message, disconnect) reach callbacks registered with on_update(fn) and
friends, run on a thread of their own, and wait in a queue for
next_event(). Callbacks hear of events from their registration on; the
queue holds them from the connection on. Every wait releases the GIL and
can be interrupted with Ctrl-C; a closed connection raises ConnectionError
instead of hanging. close() forgets the callbacks (a callback that refers
to its client keeps it alive until then).)")
      // events and waits
      .def("wait_ready", &PyClient::wait_ready, py::arg("timeout") = 30.0,
           "Wait for the server's Welcome (the handshake is done; materials and bounds are known).")
      .def("sync", &PyClient::sync, py::arg("timeout") = 30.0,
           "Wait until everything the server sent before it reads this request is in the replica (one round trip). "
           "After a reconnect, first until it is resumed and the full-resolution region it kept is confirmed by the "
           "server. Raises ConnectionError once closed.")
      .def("wait_loaded", &PyClient::wait_loaded, py::arg("radius") = py::none(), py::arg("timeout") = 60.0,
           "Wait until every chunk within radius (default: the full-resolution radius) of the client is held at "
           "full resolution. Returns only when that is true: after a reconnect, only once it is resumed and every "
           "chunk kept there is confirmed or replaced by the server. Raises ConnectionError once closed.")
      .def_property_readonly("loaded", &PyClient::loaded, "The whole full-resolution region is held now.")
      .def("verify", &PyClient::verify, py::arg("timeout") = 60.0,
           "Ask the server for the chunk hash of every full-resolution chunk and compare each with the replica; "
           "returns how many differ (0: the replica is exact).")
      .def("next_event", &PyClient::next_event, py::arg("kind") = py::none(), py::arg("timeout") = 30.0,
           "The oldest queued event (of kind 'update', 'presence', 'message', 'disconnect', 'reconnected' or 'loaded', "
           "or any), "
           "removed from "
           "the queue. Events queue from the connection on (the latest 4096). Raises TimeoutError, or "
           "ConnectionError once closed with nothing left.")
      .def(
          "on_update",
          [](const std::shared_ptr<PyClient>& c, py::object fn, bool voxels) -> py::object {
            Reporting& r = c->reporting();
            if (voxels && r.recorded_voxels() == 0) r.record_voxel_changes(Reporting::kDefaultRecordedVoxels);
            // @c.on_update(voxels=True): the decorator that registers.
            if (fn.is_none()) return py::cpp_function([c](py::object f) { return c->on(0, std::move(f)); });
            return c->on(0, std::move(fn));
          },
          py::arg("fn") = py::none(), py::kw_only(), py::arg("voxels") = false,
          "Call fn(Update) for every update batch applied to the replica (usable as a decorator, and as "
          "@on_update(voxels=True)). voxels=True starts record_voxel_changes() (unless it is on) so each Update's "
          "voxels holds the changed voxels' old and new values.")
      .def("record_voxel_changes",
           [](PyClient& c, std::int64_t max_voxels) { c.reporting().record_voxel_changes(max_voxels); },
           py::arg("max_voxels") = Reporting::kDefaultRecordedVoxels,
           "From now on every Update (queued or passed to callbacks) carries in voxels each voxel its batch changed, "
           "as the replica held it before the batch and after, at most max_voxels (0..524288; 0 stops) per event, "
           "voxels_truncated set when more changed. Off by default: then applying an update costs nothing more.")
      .def(
          "on_loaded", [](PyClient& c, py::object fn) { return c.on(5, std::move(fn)); }, py::arg("fn"),
          "Call fn(Loaded) when chunks become held at full resolution (turns report_loaded on).")
      .def_property(
          "report_loaded", [](PyClient& c) { return c.reporting().reporting_loaded(); },
          [](PyClient& c, bool on) { c.reporting().report_loaded(on); },
          "Whether Loaded events (chunks newly held at full resolution) are queued for next_event and passed to "
          "callbacks. Off by default, so existing waits on any event are not flooded while the view loads; on_loaded "
          "turns it on.")
      .def(
          "on_presence", [](PyClient& c, py::object fn) { return c.on(1, std::move(fn)); }, py::arg("fn"),
          "Call fn(Presence) when the server says who is in view.")
      .def(
          "on_message", [](PyClient& c, py::object fn) { return c.on(2, std::move(fn)); }, py::arg("fn"),
          "Call fn(Message) for notices from the server's operators.")
      .def(
          "on_disconnect", [](PyClient& c, py::object fn) { return c.on(3, std::move(fn)); }, py::arg("fn"),
          "Call fn(Disconnect) when the connection closes for good.")
      .def(
          "on_reconnect", [](PyClient& c, py::object fn) { return c.on(4, std::move(fn)); }, py::arg("fn"),
          "Call fn(Reconnected) when a dropped connection is resumed.")
      .def_property_readonly("events_dropped", &PyClient::events_dropped,
                             "Events dropped from the queue because nobody took them (the oldest go first).")
      .def_property_readonly("callbacks_dropped", &PyClient::callbacks_dropped,
                             "Events not passed to callbacks because 65,536 were already waiting for the callbacks "
                             "thread (shared by a Swarm); a Disconnect is never dropped.")
      // the replica
      .def("voxel", &PyClient::voxel, py::arg("position"),
           "(material name, occupancy 0..255) at integer (x, y, z), at the best resolution held (Air if nothing).")
      .def("resolution", &PyClient::resolution, py::arg("position"),
           "How the voxel is known: 0 full resolution, 1..3 a mip level, -1 not at all.")
      .def("holds", &PyClient::holds, py::arg("min"), py::arg("max"),
           "True if every voxel of [min, max) is held at full resolution.")
      .def("read_box", &PyClient::read_box, py::arg("min"), py::arg("max"),
           "The replica's full-resolution voxels of [min, max) as a uint8 numpy array of shape (2, y, z, x): "
           "materials, occupancies (Air where not held).")
      .def("raycast", &PyClient::raycast, py::arg("origin"), py::arg("direction"), py::arg("max_distance") = 256.0,
           "The first solid voxel along a ray: ((x, y, z), normal, distance, material) or None.")
      .def("ground", &PyClient::ground, py::arg("x"), py::arg("z"),
           "The y just above the highest solid voxel of column (x, z) as held, or None.")
      .def("find", &PyClient::find, py::arg("material"), py::arg("near") = py::none(), py::arg("within") = 16.0,
           py::arg("max") = 1,
           "The voxels of material (a name or an id) whose centres lie within `within` voxels (at most 64) of near "
           "(default: the client's position), nearest first, at most max of them: a list of (x, y, z). Searches "
           "what the replica holds at full resolution.")
      .def_property_readonly("presence", &PyClient::presence, "The other clients in view, nearest first.")
      .def_property_readonly("materials", &PyClient::materials, "The world's material names, by id.")
      // edits
      .def("fill_box", &PyClient::fill_box, py::arg("min"), py::arg("max"), py::arg("material"),
           py::arg("occupancy") = 255,
           "Fill [min, max) (at most 64^3 voxels, else ValueError) with a material (name, or an id: any integer "
           "such as numpy's; 'Air' clears).")
      .def("fill_sphere", &PyClient::fill_sphere, py::arg("center"), py::arg("radius"), py::arg("material"),
           "Fill a sphere with a material, with a smooth surface. Radius up to 30.5 (31 on some centres): the edit's "
           "box, centre +- (radius + 1), must be at most 64^3 voxels; larger raises ValueError.")
      .def("dig", &PyClient::dig, py::arg("center"), py::arg("radius"),
           "Clear a sphere (radius up to 30.5, as fill_sphere).")
      .def("paint", &PyClient::paint, py::arg("center"), py::arg("radius"), py::arg("material"),
           "Change the material of the solid voxels in a sphere, keeping their shape.")
      .def("smooth", &PyClient::smooth, py::arg("center"), py::arg("radius"), py::arg("strength") = 0.5,
           "Move each voxel's occupancy toward its neighbourhood's mean by strength (0, 1].")
      .def("write_box", &PyClient::write_box, py::arg("min"), py::arg("voxels"),
           "Write an array of integers of shape (2, y, z, x) (materials, occupancies) at min: a numpy array (any "
           "integer dtype) or anything numpy.asarray takes, such as nested lists; at most 32^3 voxels.")
      .def("_reserve_edit", &PyClient::reserve_edit,
           "asyncio's pacing (terrane.pace): takes the next edit's turn and returns the seconds to wait before it.")
      .def("_when_event", &PyClient::when_event, py::arg("fn"),
           "Call fn() on the callbacks thread once the next event is queued or the client closed (terrane.event).")
      .def("_when_synced", &PyClient::when_synced, py::arg("fn"),
           "Call fn() on the callbacks thread once everything the server sent so far is applied (terrane.synced).")
      .def("undo", &PyClient::undo, "Undo this player's last edit (voxels others changed since keep their change): this connection's, and, "
           "when the server's tokens file gives the player its own token (which proves it is the same player), "
           "those of its earlier connections since the server started.")
      .def("redo", &PyClient::redo, "Redo the last undone edit.")
      .def("read_server_box", &PyClient::read_server_box, py::arg("min"), py::arg("max"), py::arg("timeout") = 30.0,
           "The server's voxels of [min, max) (at most 32^3) as read_box returns the replica's.")
      // movement
      .def("move_to", [](PyClient& c, const Vec3& p) { c.walker().move_to(point_of(p, "position")); },
           py::arg("position"),
           "Move to (x, y, z) (feet); the server streams around the new place. Paced within the server's speed "
           "budget (max_speed voxels a second since the last move, plus 48): a far move waits until it is allowed; "
           "one farther than ten seconds of it raises ValueError naming the distance allowed.")
      .def("walk_to",
           [](PyClient& c, const Vec3& target, double speed, double timeout, std::size_t max_nodes) {
             return c.walker().walk_to(point_of(target, "target"), speed, timeout, max_nodes);
           },
           py::arg("target"), py::arg("speed") = 8.0, py::arg("timeout") = 120.0,
           py::arg("max_nodes") = 200000,
           "Walk to the place to stand nearest target over the voxel surface (A*: steps up to 1 voxel, drops up to "
           "3, 2 voxels of head room, never through what is not held at full resolution), at speed voxels per "
           "second. Returns the places walked. Raises Unreachable with the reason when there is no way.")
      .def("find_path",
           [](PyClient& c, const Vec3& target, double timeout, std::size_t max_nodes) {
             return c.walker().find_path(point_of(target, "target"), timeout, max_nodes);
           },
           py::arg("target"), py::arg("timeout") = 30.0,
           py::arg("max_nodes") = 200000,
           "The places walk_to would walk through now, from where the client stands to the place to stand nearest "
           "target, without moving. Raises Unreachable with the reason when there is no way.")
      .def("can_stand", [](PyClient& c, const IVec3& p) { return c.walker().can_stand(voxel_of(p, "can_stand")); },
           py::arg("place"),
           "True if a walker can stand at place now (feet in Air with head room, ground below, all held at full "
           "resolution).")
      .def("look_at", [](PyClient& c, const Vec3& p) { return vec(c.walker().look_at(point_of(p, "point"))); },
           py::arg("point"),
           "Face a point (from the eye, 1.6 above the feet); returns the unit direction. Facing is the script's: "
           "the protocol carries no orientation.")
      .def_property_readonly("facing", [](PyClient& c) { return vec(c.walker().facing()); },
                             "The unit direction the client faces.")
      .def("target", &PyClient::target, py::arg("max_distance") = 64.0,
           "What the client looks at: raycast from the eye along facing.")
      .def_property_readonly("position", &PyClient::position, "(x, y, z) of the client's feet, as last sent.")
      // the connection
      .def_property_readonly("name", &PyClient::name, "The name the client joined with.")
      .def_property_readonly("closed", &PyClient::closed,
                             "True once the connection closed for good (close(), the server, or a lost server with "
                             "reconnect off or given up).")
      .def_property_readonly("disconnect_reason", &PyClient::disconnect_reason,
                             "Why the connection closed ('' while open).")
      .def("close", &PyClient::close, "Say goodbye and close the connection (idempotent).")
      .def("__enter__", [](const std::shared_ptr<PyClient>& c) { return c; })
      .def("__exit__", [](PyClient& c, const py::object&, const py::object&, const py::object&) { c.close(); })
      .def("__repr__", [](const PyClient& c) {
        return "<terrane.Client '" + c.name() + "'" + (c.closed() ? " closed" : "") + ">";
      });

  py::class_<Swarm, std::shared_ptr<Swarm>>(m, "Swarm", R"(Many clients from one script, cheaply.

The clients share one small pool of io threads (as terrane-bots does) and
one thread for their callbacks, so a hundred scripted bots cost a few
threads, not a hundred. A Swarm is a sequence of Clients.)")
      .def(py::init([](int n, const std::string& address, const std::string& name, const std::string& token,
                       double spread, int view_distance, int full_res_radius, int threads, double silence_timeout,
                       double max_speed) {
             ConnectArgs a;
             a.address = address;
             a.name = name;
             a.token = token;
             a.view_distance = view_distance;
             a.full_res_radius = full_res_radius;
             a.silence_timeout = silence_timeout;
             a.max_speed = max_speed;
             return std::make_shared<Swarm>(n, std::move(a), spread, threads);
           }),
           py::arg("n"), py::arg("address"), py::arg("name") = "bot", py::arg("token") = "", py::arg("spread") = 0.0,
           py::arg("view_distance") = 64, py::arg("full_res_radius") = 32, py::arg("threads") = 2,
           py::arg("silence_timeout") = 15.0, py::arg("max_speed") = 256.0,
           "Connect n clients named name-0 .. name-(n-1), spread evenly over a disc of radius spread around the "
           "server's spawn.")
      .def("__len__", &Swarm::size)
      .def("__getitem__", &Swarm::at)
      .def("__iter__", [](const Swarm& s) { return py::iter(py::cast(s.clients())); })
      .def_property_readonly("clients", &Swarm::clients, "The clients, as a list (the Swarm is a sequence of them too).")
      .def("wait_ready", &Swarm::wait_ready, py::arg("timeout") = 60.0, "Wait until every client is welcomed.")
      .def("wait_loaded", &Swarm::wait_loaded, py::arg("timeout") = 120.0,
           "Wait until every client holds its full-resolution region.")
      .def("verify", &Swarm::verify, py::arg("timeout") = 120.0,
           "Every client's verify(): the total of chunks that differ from the server (0: all exact).")
      .def("close", &Swarm::close, "Close every client.")
      .def("__enter__", [](const std::shared_ptr<Swarm>& s) { return s; })
      .def("__exit__", [](Swarm& s, const py::object&, const py::object&, const py::object&) { s.close(); });

  m.def(
      "connect",
      [](const std::string& address, const std::string& name, const std::string& token, std::optional<Vec3> position,
         int view_distance, int full_res_radius, bool reconnect, double silence_timeout, double max_speed,
         std::optional<std::string> chunk_cache) {
        ConnectArgs a;
        if (chunk_cache) {
          if (chunk_cache->empty()) throw py::value_error("chunk_cache: expected a directory, got ''");
          a.chunk_cache = *chunk_cache;
        }
        a.silence_timeout = silence_timeout;
        a.max_speed = max_speed;
        a.address = address;
        a.name = name;
        a.token = token;
        a.position = position;
        a.view_distance = view_distance;
        a.full_res_radius = full_res_radius;
        a.reconnect = reconnect;
        auto c = std::make_shared<PyClient>(std::move(a));
        remember_client(c);
        return c;
      },
      py::arg("address"), py::arg("name") = "python", py::arg("token") = "", py::arg("position") = py::none(),
      py::arg("view_distance") = 128, py::arg("full_res_radius") = 48, py::arg("reconnect") = false,
      py::arg("silence_timeout") = 15.0, py::arg("max_speed") = 256.0, py::arg("chunk_cache") = py::none(),
      "Connect to a terrane-server at 'HOST:PORT'. position None starts at the server's spawn. With reconnect, a "
      "dropped connection is retried with backoff and the replica kept (a Reconnected event when resumed). "
      "silence_timeout: seconds without a byte from the server (it pings every 5 s) after which the connection "
      "counts as lost (0.5..3600, 0 never); a reconnect that reaches a server which then stays silent as long "
      "closes for good (a hung server), so closed and on_disconnect tell. max_speed: the server's --max-speed, by "
      "which move_to paces (0: not paced). chunk_cache: a directory where the chunks this client held are kept when "
      "it closes (at most 1 GiB, shared by the process's clients); a later connect to the same world with it "
      "joins from them and is sent only what changed (client/CHUNK_CACHE.md). Raises ConnectionError if the "
      "server cannot be reached, ValueError for bad arguments, OSError if chunk_cache cannot be made.");

  // Before the interpreter finalizes: close every client and stop every
  // callbacks thread, so none waits for a GIL that will not come back.
  py::module_::import("atexit").attr("register")(py::cpp_function([] {
    g_exiting.store(true);
    close_all_clients();
    stop_all_dispatchers(std::chrono::seconds(10));
  }));
}
