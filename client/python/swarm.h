// Swarm: many Python clients from one script, cheaply: they share one
// IoPool (a few io threads, as terrane-bots shares its) and one callbacks
// thread (a DispatcherSlot). It owns the pool, the slot and its clients;
// its methods run on the script's thread, waits with the GIL released.
#pragma once

#include <cstddef>
#include <memory>
#include <vector>

#include "client/python/events.h"
#include "client/python/py_client.h"

namespace terrane::python {

// n clients on one io pool of `threads` threads and one callbacks thread.
class Swarm {
 public:
  Swarm(int n, ConnectArgs base, double spread, int threads);
  ~Swarm();
  std::size_t size() const { return clients_.size(); }
  std::shared_ptr<PyClient> at(std::ptrdiff_t i) const;
  const std::vector<std::shared_ptr<PyClient>>& clients() const { return clients_; }
  void wait_ready(double timeout);
  void wait_loaded(double timeout);
  int verify(double timeout);
  void close();

 private:
  std::shared_ptr<IoPool> pool_;
  std::shared_ptr<DispatcherSlot> slot_;
  std::vector<std::shared_ptr<PyClient>> clients_;
};

}  // namespace terrane::python
