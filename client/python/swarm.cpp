#include "client/python/swarm.h"

#include <cmath>
#include <numbers>

namespace terrane::python {

Swarm::Swarm(int n, ConnectArgs base, double spread, int threads) {
  if (n < 1 || n > 10000) raise(PyExc_ValueError, "Swarm: n must be 1..10000");
  if (threads < 1 || threads > 64) raise(PyExc_ValueError, "Swarm: threads must be 1..64");
  if (!(spread >= 0) || spread > 1e6) raise(PyExc_ValueError, "Swarm: spread must be 0..10^6 voxels");
  if (base.position) raise(PyExc_ValueError, "Swarm: clients start around the spawn (use spread), not at a position");
  const std::string last = base.name + "-" + std::to_string(n - 1);
  if (base.name.empty() || last.size() > kMaxClientNameBytes)
    raise(PyExc_ValueError, "Swarm: names (up to '" + last + "') must be 1..64 bytes");
  pool_ = std::make_shared<IoPool>(threads);
  slot_ = std::make_shared<DispatcherSlot>();
  clients_.reserve(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) {
    ConnectArgs a = base;
    a.name = base.name + "-" + std::to_string(i);
    // A sunflower spiral: even density over a disc of radius spread.
    const double r = spread * std::sqrt((i + 0.5) / n);
    const double angle = i * std::numbers::pi * (3 - std::sqrt(5.0));
    a.spawn_offset = Vec3f{static_cast<float>(r * std::cos(angle)), 0, static_cast<float>(r * std::sin(angle))};
    a.pool = pool_;
    a.slot = slot_;
    auto c = std::make_shared<PyClient>(std::move(a));
    remember_client(c);
    clients_.push_back(std::move(c));
  }
}

Swarm::~Swarm() { close(); }

std::shared_ptr<PyClient> Swarm::at(std::ptrdiff_t i) const {
  const auto n = static_cast<std::ptrdiff_t>(clients_.size());
  if (i < 0) i += n;
  if (i < 0 || i >= n) throw py::index_error("Swarm index out of range");
  return clients_[static_cast<std::size_t>(i)];
}

namespace {
// What is left of a timeout shared by several waits.
double left(Clock::time_point deadline) {
  return std::max(0.0, std::chrono::duration<double>(deadline - Clock::now()).count());
}
}  // namespace

void Swarm::wait_ready(double timeout) {
  const auto deadline = Clock::now() + timeout_of(timeout);
  for (const auto& c : clients_) c->wait_ready(left(deadline));
}

void Swarm::wait_loaded(double timeout) {
  const auto deadline = Clock::now() + timeout_of(timeout);
  for (const auto& c : clients_) c->wait_loaded(std::nullopt, left(deadline));
}

int Swarm::verify(double timeout) {
  const auto deadline = Clock::now() + timeout_of(timeout);
  int bad = 0;
  for (const auto& c : clients_) bad += c->verify(left(deadline));
  return bad;
}

void Swarm::close() {
  for (const auto& c : clients_) c->close();
  if (auto d = slot_ ? slot_->peek() : nullptr) {
    d->stop();  // runs the clients' last callbacks (their disconnects)
    if (!d->finished()) return;  // called from a callback: they have not run yet
  }
  for (const auto& c : clients_) c->clear_handlers();
}

}  // namespace terrane::python
