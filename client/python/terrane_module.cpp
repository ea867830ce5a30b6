// The `terrane` Python module: the client library (client/client.h) for
// scripts. A Client connects, keeps a replica, answers queries from it and
// sends edits whose outcome is an EditFuture. Every wait releases the GIL;
// the library's io thread never takes it (no Python callbacks run there).
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <chrono>
#include <cmath>
#include <memory>
#include <optional>
#include <string>
#include <tuple>
#include <variant>
#include <vector>

#include "client/client.h"
#include "common/cli.h"
#include "common/view.h"

namespace py = pybind11;

namespace terrane::python {
namespace {

using Clock = std::chrono::steady_clock;
using Vec3 = std::tuple<double, double, double>;
using IVec3 = std::tuple<std::int64_t, std::int64_t, std::int64_t>;

[[noreturn]] void raise(PyObject* type, const std::string& what) {
  PyErr_SetString(type, what.c_str());
  throw py::error_already_set();
}

std::chrono::milliseconds ms(double seconds) {
  if (!(seconds >= 0) || seconds > 86400) raise(PyExc_ValueError, "timeout must be 0..86400 seconds");
  return std::chrono::milliseconds(static_cast<std::int64_t>(seconds * 1000));
}

Vec3i voxel_of(const IVec3& p, const char* what) {
  const auto [x, y, z] = p;
  for (const std::int64_t v : {x, y, z})
    if (v < -kMaxWireCoordinate || v > kMaxWireCoordinate)
      raise(PyExc_ValueError, std::string(what) + ": coordinates must lie within +-2^24");
  return {static_cast<std::int32_t>(x), static_cast<std::int32_t>(y), static_cast<std::int32_t>(z)};
}

Vec3f point_of(const Vec3& p, const char* what) {
  const auto [x, y, z] = p;
  for (const double v : {x, y, z})
    if (!std::isfinite(v) || std::abs(v) > kMaxWireCoordinate)
      raise(PyExc_ValueError, std::string(what) + ": coordinates must be finite, within +-2^24");
  return {static_cast<float>(x), static_cast<float>(y), static_cast<float>(z)};
}

class EditRejected : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// The outcome of one edit: result() waits for the server's answer.
class EditFuture {
 public:
  EditFuture(std::shared_ptr<Client> c, std::uint32_t id) : c_(std::move(c)), id_(id) {}
  std::uint32_t id() const { return id_; }
  bool done() const {
    bool d = false;
    c_->wait_until([&](const ClientView& v) { return d = v.edits.count(id_) != 0; }, std::chrono::milliseconds(0));
    return d;
  }
  // True when acknowledged (applied and stored); raises EditRejected with
  // the server's reason, TimeoutError, or ConnectionError.
  bool result(double timeout) {
    std::optional<EditOutcome> o;
    bool closed = false;
    {
      py::gil_scoped_release nogil;
      c_->wait_until(
          [&](const ClientView& v) {
            if (auto it = v.edits.find(id_); it != v.edits.end()) o = it->second;
            closed = v.closed;
            return o.has_value() || closed;
          },
          ms(timeout));
    }
    if (o && o->accepted) return true;
    if (o) throw EditRejected(o->reason);
    if (closed) raise(PyExc_ConnectionError, "connection closed before the edit was answered: " + c_->disconnect_reason());
    raise(PyExc_TimeoutError, "edit " + std::to_string(id_) + " not answered within the timeout");
  }

 private:
  std::shared_ptr<Client> c_;
  std::uint32_t id_;
};

class PyClient {
 public:
  PyClient(const std::string& address, const std::string& name, const std::string& token,
           std::optional<Vec3> position, int view_distance, int full_res_radius, bool reconnect) {
    const auto hp = parse_host_port(address);
    if (!hp) raise(PyExc_ValueError, "address: " + hp.error().message);
    if (hp->second == 0) raise(PyExc_ValueError, "address '" + address + "': port must be 1..65535");
    if (name.empty() || name.size() > kMaxClientNameBytes) raise(PyExc_ValueError, "name must be 1..64 bytes");
    if (view_distance < 1 || view_distance > 16384 || full_res_radius < 1 || full_res_radius > view_distance)
      raise(PyExc_ValueError, "view_distance must be 1..16384 and full_res_radius 1..view_distance");
    ClientOptions o;
    o.host = hp->first;
    o.port = hp->second;
    o.name = name;
    o.auth_token = token;
    o.reconnect = reconnect;
    o.state.view_distance = view_distance;
    o.state.full_res_radius = full_res_radius;
    if (position) {
      o.start_at_spawn = false;
      o.state.position = point_of(*position, "position");
    }
    c_ = std::make_shared<Client>(o);
    std::string err;
    bool ok = false;
    {
      py::gil_scoped_release nogil;
      ok = c_->connect(&err);
    }
    if (!ok) raise(PyExc_ConnectionError, "cannot connect to " + address + ": " + err);
  }

  // Waits for the handshake; the world's Welcome from then on.
  void wait_ready(double timeout) {
    bool ready = false, closed = false;
    {
      py::gil_scoped_release nogil;
      c_->wait_until(
          [&](const ClientView& v) {
            ready = v.welcomed;
            closed = v.closed;
            return ready || closed;
          },
          ms(timeout));
    }
    if (!ready) fail_or_timeout(closed, "no Welcome within the timeout");
  }

  // Waits until every chunk of the full-resolution region around the
  // client's position is held at full resolution (true only when it is).
  void wait_loaded(double timeout) {
    wait_ready(timeout);
    // The chunks first: the predicate runs under the client's lock.
    const auto chunks = full_chunks(*c_->welcome());
    bool loaded = false, closed = false;
    {
      py::gil_scoped_release nogil;
      c_->wait_until(
          [&](const ClientView& v) {
            closed = v.closed;
            loaded = held_full(v, chunks);
            return loaded || closed;
          },
          ms(timeout));
    }
    if (!loaded) fail_or_timeout(closed, "the full-resolution region was not loaded within the timeout");
  }

  bool loaded() const {
    const auto w = c_->welcome();
    if (!w) return false;
    const auto chunks = full_chunks(*w);
    bool l = false;
    c_->wait_until([&](const ClientView& v) { return l = held_full(v, chunks); }, std::chrono::milliseconds(0));
    return l;
  }

  // Asks the server for the region hash of every full-resolution chunk and
  // compares each with the replica: the number that differ (0: all match).
  int verify(double timeout) {
    wait_ready(timeout);
    const WelcomeMsg w = *c_->welcome();
    const auto chunks = full_chunks(w);
    std::uint64_t before = 0;
    c_->wait_until([&](const ClientView& v) { return before = v.counters.hash_matches + v.counters.hash_mismatches, true; },
                   std::chrono::milliseconds(0));
    for (const Vec3i cp : chunks)
      if (!c_->request_region_hash(cp)) raise(PyExc_ConnectionError, "connection closed");
    bool done = false, closed = false;
    int bad = 0;
    {
      py::gil_scoped_release nogil;
      c_->wait_until(
          [&](const ClientView& v) {
            closed = v.closed;
            done = v.counters.hash_matches + v.counters.hash_mismatches >= before + chunks.size();
            if (done) {
              bad = 0;
              for (const Vec3i cp : chunks)
                if (auto it = v.hash_checks.find(cp); it == v.hash_checks.end() || !it->second) ++bad;
            }
            return done || closed;
          },
          ms(timeout));
    }
    if (!done) fail_or_timeout(closed, "region hashes not answered within the timeout");
    return bad;
  }

  py::tuple voxel(const IVec3& p) const {
    const Voxel v = c_->get(voxel_of(p, "voxel"));
    return py::make_tuple(material_name(v.material), v.occupancy);
  }

  // Material and occupancy planes of [min, max): shape (2, y, z, x), uint8.
  py::array_t<std::uint8_t> read_box(const IVec3& lo, const IVec3& hi) const {
    const Vec3i a = voxel_of(lo, "read_box min"), b = voxel_of(hi, "read_box max");
    const Region r{a, b};
    if (r.empty()) raise(PyExc_ValueError, "read_box: max must exceed min on every axis");
    if (r.volume() > (std::int64_t{1} << 26)) raise(PyExc_ValueError, "read_box: at most 2^26 voxels at once");
    const Vec3i s = r.size();
    Box box(s);
    c_->read_box(a, box);
    py::array_t<std::uint8_t> out({std::size_t{2}, std::size_t(s.y), std::size_t(s.z), std::size_t(s.x)});
    auto m = out.mutable_unchecked<4>();
    for (int y = 0; y < s.y; ++y)
      for (int z = 0; z < s.z; ++z)
        for (int x = 0; x < s.x; ++x) {
          const Voxel v = box.get(x, y, z);
          m(0, y, z, x) = v.material;
          m(1, y, z, x) = v.occupancy;
        }
    return out;
  }

  EditFuture fill_box(const IVec3& lo, const IVec3& hi, const py::object& material, int occupancy) {
    const Region r{voxel_of(lo, "fill_box min"), voxel_of(hi, "fill_box max")};
    if (r.empty()) raise(PyExc_ValueError, "fill_box: max must exceed min on every axis");
    if (occupancy < 0 || occupancy > 255) raise(PyExc_ValueError, "occupancy must be 0..255");
    const Material m = material_of(material);
    return sent(c_->fill_box(r, m == kAir ? Voxel{} : make_voxel(m, static_cast<std::uint8_t>(occupancy))));
  }
  EditFuture fill_sphere(const Vec3& center, double radius, const py::object& material) {
    return sent(c_->fill_sphere(point_of(center, "center"), radius_of(radius), material_of(material)));
  }
  EditFuture dig(const Vec3& center, double radius) {
    return sent(c_->dig(point_of(center, "center"), radius_of(radius)));
  }
  EditFuture paint(const Vec3& center, double radius, const py::object& material) {
    return sent(c_->paint(point_of(center, "center"), radius_of(radius), material_of(material)));
  }
  // Writes [min, min + shape) from a uint8 array of shape (2, y, z, x)
  // (materials, occupancies), as read_box returns it; at most 32^3 voxels.
  EditFuture write_box(const IVec3& lo, const py::array_t<std::uint8_t, py::array::c_style | py::array::forcecast>& a) {
    if (a.ndim() != 4 || a.shape(0) != 2) raise(PyExc_ValueError, "write_box: the array must have shape (2, y, z, x)");
    const Vec3i size{static_cast<int>(a.shape(3)), static_cast<int>(a.shape(1)), static_cast<int>(a.shape(2))};
    const Vec3i min = voxel_of(lo, "write_box min");
    const Region r{min, min + size};
    if (r.empty() || r.volume() > kMaxRawBoxVolume)
      raise(PyExc_ValueError, "write_box: 1 to " + std::to_string(kMaxRawBoxVolume) + " voxels");
    const auto names = materials();
    auto m = a.unchecked<4>();
    std::vector<Voxel> voxels;
    voxels.reserve(static_cast<std::size_t>(r.volume()));
    for (int y = 0; y < size.y; ++y)
      for (int z = 0; z < size.z; ++z)
        for (int x = 0; x < size.x; ++x) {
          const std::uint8_t mat = m(0, y, z, x), occ = m(1, y, z, x);
          if (mat >= std::max<std::size_t>(names.size(), 1))
            raise(PyExc_ValueError, "write_box: material " + std::to_string(mat) + " at (" + std::to_string(x) + ", " +
                                        std::to_string(y) + ", " + std::to_string(z) + ") is not one of this world's");
          voxels.push_back(mat == kAir ? Voxel{} : make_voxel(mat, occ));
        }
    return sent(c_->write_box(r, voxels));
  }

  // The first solid voxel along a ray: ((x, y, z), (nx, ny, nz), distance,
  // material name) or None (only what the replica holds counts).
  py::object raycast(const Vec3& origin, const Vec3& direction, double max_distance) const {
    const Vec3f d = point_of(direction, "direction");
    if (d.x == 0 && d.y == 0 && d.z == 0) raise(PyExc_ValueError, "raycast: the direction must not be zero");
    if (!(max_distance > 0) || max_distance > 4096) raise(PyExc_ValueError, "raycast: max_distance must be in (0, 4096]");
    const auto hit = c_->raycast(point_of(origin, "origin"), d, static_cast<float>(max_distance));
    if (!hit) return py::none();
    return py::make_tuple(py::make_tuple(hit->voxel.x, hit->voxel.y, hit->voxel.z),
                          py::make_tuple(hit->normal.x, hit->normal.y, hit->normal.z), hit->distance,
                          material_name(hit->value.material));
  }

  // The y just above the highest solid voxel of column (x, z), or None.
  py::object ground(std::int64_t x, std::int64_t z) const {
    const Vec3i p = voxel_of({x, 0, z}, "ground");
    const auto h = c_->surface_height(p.x, p.z);
    return h ? py::object(py::int_(*h)) : py::none();
  }

  // The server's voxels of [min, max) (at most 32^3), as read_box returns
  // the replica's: for comparing, or reading what the replica lacks.
  py::array_t<std::uint8_t> read_server_box(const IVec3& lo, const IVec3& hi, double timeout) {
    const Region r{voxel_of(lo, "min"), voxel_of(hi, "max")};
    if (r.empty() || r.volume() > kMaxRawBoxVolume)
      raise(PyExc_ValueError, "read_server_box: 1 to " + std::to_string(kMaxRawBoxVolume) + " voxels");
    const std::uint32_t id = c_->request_read_box(r);
    if (id == 0) raise(PyExc_ConnectionError, "connection closed");
    std::optional<ReadBoxResultMsg> res;
    bool closed = false;
    {
      py::gil_scoped_release nogil;
      c_->wait_until(
          [&](const ClientView& v) {
            if (auto it = v.read_results.find(id); it != v.read_results.end()) res = it->second;
            closed = v.closed;
            return res.has_value() || closed;
          },
          ms(timeout));
    }
    if (!res) fail_or_timeout(closed, "the server did not answer the read within the timeout");
    if (!res->error.empty()) raise(PyExc_ValueError, "read_server_box: " + res->error);
    const Vec3i s = r.size();
    py::array_t<std::uint8_t> out({std::size_t{2}, std::size_t(s.y), std::size_t(s.z), std::size_t(s.x)});
    auto m = out.mutable_unchecked<4>();
    std::size_t i = 0;
    for (int y = 0; y < s.y; ++y)
      for (int z = 0; z < s.z; ++z)
        for (int x = 0; x < s.x; ++x, ++i) {
          m(0, y, z, x) = res->voxels[i].material;
          m(1, y, z, x) = res->voxels[i].occupancy;
        }
    return out;
  }

  EditFuture undo() { return sent(c_->undo()); }
  EditFuture redo() { return sent(c_->redo()); }

  void move_to(const Vec3& position) {
    ClientStateMsg s = state();
    s.position = point_of(position, "position");
    if (!c_->set_state(s)) raise(PyExc_ConnectionError, "connection closed");
  }
  Vec3 position() const {
    const Vec3f p = state().position;
    return {p.x, p.y, p.z};
  }
  std::vector<std::string> materials() const {
    const auto w = c_->welcome();
    return w ? w->materials : std::vector<std::string>{};
  }
  bool closed() const { return c_->closed(); }
  std::string disconnect_reason() const { return c_->disconnect_reason(); }
  void close() {
    py::gil_scoped_release nogil;
    c_->disconnect();
  }

 private:
  ClientStateMsg state() const { return c_->last_state().value_or(ClientStateMsg{}); }
  std::vector<Vec3i> full_chunks(const WelcomeMsg& w) const {
    const ClientStateMsg s = state();
    const std::int32_t full =
        std::min({s.full_res_radius == 0 ? w.default_full_res_radius : s.full_res_radius, w.max_full_res_radius,
                  s.view_distance == 0 ? w.default_view_distance : s.view_distance, w.max_view_distance});
    return chunks_in_view(s.position, full, w.bounds());
  }
  // Under the client's lock (a wait_until predicate): touches only v.
  static bool held_full(const ClientView& v, const std::vector<Vec3i>& chunks) {
    if (!v.welcomed) return false;
    for (const Vec3i cp : chunks) {
      const ChunkCoverage* c = v.replica.coverage(cp);
      if (c == nullptr || c->state == CoverageState::kMip) return false;
    }
    return true;
  }
  [[noreturn]] void fail_or_timeout(bool closed, const std::string& what) const {
    if (closed) raise(PyExc_ConnectionError, "connection closed: " + c_->disconnect_reason());
    raise(PyExc_TimeoutError, what);
  }
  std::string material_name(Material m) const {
    const auto names = materials();
    return m < names.size() ? names[m] : std::to_string(m);
  }
  Material material_of(const py::object& m) const {
    const auto names = materials();
    if (py::isinstance<py::int_>(m)) {
      const long id = m.cast<long>();
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
  static float radius_of(double r) {
    if (!(r > 0) || r > kMaxSphereRadius) raise(PyExc_ValueError, "radius must be in (0, 32]");
    return static_cast<float>(r);
  }
  EditFuture sent(std::uint32_t id) {
    if (id == 0) raise(PyExc_ConnectionError, "the edit could not be sent (connection closed or queue full)");
    return EditFuture(c_, id);
  }

  std::shared_ptr<Client> c_;
};

}  // namespace
}  // namespace terrane::python

PYBIND11_MODULE(terrane, m) {
  using namespace terrane::python;
  namespace py = pybind11;
  m.doc() = "Terrane: connect to a terrane-server, query its world and edit it (the client library, for scripts).";
  py::register_exception<EditRejected>(m, "EditRejected", PyExc_RuntimeError);

  py::class_<EditFuture>(m, "EditFuture", "The outcome of one edit.")
      .def_property_readonly("id", &EditFuture::id)
      .def("done", &EditFuture::done, "True once the server answered.")
      .def("result", &EditFuture::result, py::arg("timeout") = 30.0,
           "Wait for the answer: True when applied and stored; raises EditRejected(reason), TimeoutError or "
           "ConnectionError.");

  py::class_<PyClient>(m, "Client", "A connection to a terrane-server with a replica of what it streams.")
      .def("wait_ready", &PyClient::wait_ready, py::arg("timeout") = 30.0, "Wait for the server's Welcome.")
      .def("wait_loaded", &PyClient::wait_loaded, py::arg("timeout") = 60.0,
           "Wait until every chunk within the full-resolution radius is held at full resolution.")
      .def_property_readonly("loaded", &PyClient::loaded, "The full-resolution region is held now.")
      .def("verify", &PyClient::verify, py::arg("timeout") = 60.0,
           "Compare every full-resolution chunk with the server's region hash; how many differ (0: all match).")
      .def("voxel", &PyClient::voxel, py::arg("position"), "(material name, occupancy) at an integer position.")
      .def("read_box", &PyClient::read_box, py::arg("min"), py::arg("max"),
           "The replica's voxels in [min, max) as a uint8 array of shape (2, y, z, x): materials, occupancies.")
      .def("fill_box", &PyClient::fill_box, py::arg("min"), py::arg("max"), py::arg("material"),
           py::arg("occupancy") = 255, "Fill [min, max) with a material (name or id; Air clears).")
      .def("fill_sphere", &PyClient::fill_sphere, py::arg("center"), py::arg("radius"), py::arg("material"))
      .def("dig", &PyClient::dig, py::arg("center"), py::arg("radius"))
      .def("paint", &PyClient::paint, py::arg("center"), py::arg("radius"), py::arg("material"))
      .def("write_box", &PyClient::write_box, py::arg("min"), py::arg("voxels"),
           "Write a uint8 array of shape (2, y, z, x) (materials, occupancies) at min; at most 32^3 voxels.")
      .def("raycast", &PyClient::raycast, py::arg("origin"), py::arg("direction"), py::arg("max_distance") = 256.0,
           "The first solid voxel along a ray: ((x, y, z), normal, distance, material) or None.")
      .def("ground", &PyClient::ground, py::arg("x"), py::arg("z"),
           "The y just above the highest solid voxel of a column the replica holds, or None.")
      .def("read_server_box", &PyClient::read_server_box, py::arg("min"), py::arg("max"), py::arg("timeout") = 30.0,
           "The server's voxels of [min, max) (at most 32^3) as a (2, y, z, x) uint8 array.")
      .def("undo", &PyClient::undo)
      .def("redo", &PyClient::redo)
      .def("move_to", &PyClient::move_to, py::arg("position"), "Move (the server streams around the new place).")
      .def_property_readonly("position", &PyClient::position)
      .def_property_readonly("materials", &PyClient::materials, "The world's material names, by id.")
      .def_property_readonly("closed", &PyClient::closed)
      .def_property_readonly("disconnect_reason", &PyClient::disconnect_reason)
      .def("close", &PyClient::close)
      .def("__enter__", [](PyClient& c) -> PyClient& { return c; }, py::return_value_policy::reference)
      .def("__exit__", [](PyClient& c, const py::object&, const py::object&, const py::object&) { c.close(); });

  m.def(
      "connect",
      [](const std::string& address, const std::string& name, const std::string& token, std::optional<Vec3> position,
         int view_distance, int full_res_radius, bool reconnect) {
        return std::make_unique<PyClient>(address, name, token, position, view_distance, full_res_radius, reconnect);
      },
      py::arg("address"), py::arg("name") = "python", py::arg("token") = "", py::arg("position") = py::none(),
      py::arg("view_distance") = 128, py::arg("full_res_radius") = 48, py::arg("reconnect") = false,
      "Connect to HOST:PORT; position None starts at the server's spawn.");
}
