// Server: the authoritative Terrane world server (asio over TCP). It only
// wires the rooms together. server/README.md has the rooms (one folder
// each: base, net, replication, world, storage, ops), the thread or strand
// that owns each, the locks with their reasons and the allowed includes
// (checked by tests/server/include_edges_test.cpp), and walks a chunk and
// an edit through them.
//
// A tick (world strand, fixed schedule): apply edits to copies of their
// chunks and publish new versions; the storage writer commits them (one
// transaction for every tick queued) while the next tick runs; after the
// commit, acks go out and each holder of a changed chunk gets the tick's
// changes in one call, answered with one UpdateBatch and the mip refreshes
// whose bytes changed (server/replication/replicator.h).
//
// Counters are atomics, readable from any thread. stop() (any thread but an
// io thread) closes the acceptor, applies what is queued, waits for every
// commit, closes every session and joins the threads: the world is saved.
#pragma once

#include <asio.hpp>
#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <unordered_map>
#include <vector>

#include "common/world/world.h"
#include "common/world/world_lock.h"
#include "server/net/client_session.h"
#include "server/ops/access.h"
#include "server/ops/admin.h"
#include "server/ops/http_endpoint.h"
#include "server/base/options.h"
#include "server/replication/replicator.h"
#include "server/cluster/change_listener.h"
#include "server/cluster/cluster_control.h"
#include "server/cluster/lease_keeper.h"
#include "server/storage/storage.h"
#include "server/world/world_owner.h"

namespace terrane {

class Server {
 public:
  // Opens (or creates) the world and binds the listening socket. Nothing
  // runs until start().
  static FileResult<std::unique_ptr<Server>> create(const ServerOptions& options);
  ~Server();
  Server(const Server&) = delete;
  Server& operator=(const Server&) = delete;

  void start();
  // Idempotent; see the note above.
  void stop();

  std::uint16_t port() const { return port_; }
  // The metrics endpoint's port (0 without --metrics).
  std::uint16_t metrics_port() const { return metrics_ ? metrics_->port() : 0; }
  // Prometheus text (what /metrics serves) and the health rule (/health).
  std::string metrics_text() const;
  // Whether streaming yields now (and holding it paused: tests, operators).
  StreamGate& stream_gate() { return *stream_gate_; }
  Health health() const;
  const std::string& address() const { return options_.bind_address; }
  const ServerCounters& counters() const { return counters_; }
  const StorageCounters& storage_counters() const { return storage_->counters(); }
  const ServerOptions& options() const { return options_; }
  // True once a tick's changes could not be saved (the server stopped serving).
  bool storage_failed() const { return world_owner_->storage_failed(); }

  // Runs fn on the world strand and waits for it (tests, tools). Must not be
  // called from an io thread.
  void inspect(const std::function<void(const WorldView&)>& fn);

 private:
  explicit Server(const ServerOptions& options);
  // Where clients start: above the generated surface at the origin, or for
  // worlds without a generator above the centre of the stored chunks.
  static Vec3f find_spawn(World& world);
  void do_accept();
  AdminHooks admin_hooks();
  void schedule_shutdown(std::uint32_t seconds, bool restart, const std::string& reason);
  // The world of options_: a directory (made when missing) or a PostgreSQL
  // database (made when it holds none; leases_ set up for its writes).
  FileResult<std::unique_ptr<World>> open_world();
  void notify_all(const ServerNoticeMsg& notice);
  void log_stats();
  void arm_stats();

  ServerOptions options_;
  ServerCounters counters_;
  // The test seam of UpdateBatches: set only by the --test-*-updates
  // options (null when serving for real).
  std::unique_ptr<UpdateFaults> faults_;
  // Who writes which region of a PostgreSQL world, published by the lease
  // keeper's thread (so it outlives it) and read by the replicators.
  ClusterDirectory cluster_;
  // A PostgreSQL world's leases (null for SQLite): the writer's lease
  // source, so it outlives the world and storage below.
  std::unique_ptr<LeaseKeeper> leases_;
  // A PostgreSQL world's control thread (null for SQLite): the claims,
  // forwards and inbox reads Storage passes on; outlives storage_.
  std::unique_ptr<ClusterControl> control_;
  // A world directory's one-writer lock (common/world/world_lock.h), held
  // for the server's life; declared before the world so it outlives every
  // write. Not held for a PostgreSQL world (leases fence its writers).
  WorldLock world_lock_;
  std::unique_ptr<World> world_;
  // world_'s store as the chunk store it is, for a PostgreSQL world (null
  // for SQLite): the writer of Storage::Shared.
  const PostgresStore* shared_store_ = nullptr;
  std::unique_ptr<Storage> storage_;
  asio::io_context io_;
  asio::executor_work_guard<asio::io_context::executor_type> work_;
  // The world strand runs on a thread of its own, so ticks keep their
  // schedule however many session handlers wait for the io threads.
  asio::io_context world_io_;
  asio::executor_work_guard<asio::io_context::executor_type> world_work_;
  std::thread world_thread_;
  asio::ip::tcp::acceptor acceptor_;
  asio::steady_timer stats_timer_;
  std::unique_ptr<WorldOwner> world_owner_;
  // Streaming yields to live traffic while the io threads or the world
  // strand fall behind (probes on both; stopped first in stop()).
  std::unique_ptr<StreamGate> stream_gate_;
  // A shared world's notices from the other servers, handed to the world
  // owner (stopped before it).
  std::unique_ptr<ChangeListener> changes_;
  std::unique_ptr<HttpEndpoint> metrics_;
  std::unique_ptr<AccessControl> access_;
  std::mutex admin_mutex_;  // admin_ is dropped in stop() while sessions may still ask
  std::unique_ptr<Admin> admin_;
  ClientSession::AdminFn admin_fn_;
  asio::steady_timer shutdown_timer_;
  // What the last notice tells clients when the server stops: to reconnect
  // (a SIGTERM is usually a restart) unless an operator's shutdown said
  // otherwise.
  std::atomic<bool> clients_reconnect_{true};
  std::thread shutdown_thread_;  // stops the server when no owner does (options.on_shutdown unset)
  const std::chrono::steady_clock::time_point started_at_ = std::chrono::steady_clock::now();
  WelcomeTemplate welcome_;
  // What every client session shares (the Welcome, admission, admin
  // commands, counters); set once access_ exists.
  std::optional<ClientSession::Context> session_context_;
  std::shared_ptr<const ViewTable> default_view_;  // kept made (ViewTable::get's cache may drop unused tables)
  std::vector<std::thread> threads_;
  std::uint16_t port_ = 0;
  std::atomic<bool> stopped_{false};
  std::atomic<bool> stopping_{false};
  bool started_ = false;
  std::atomic<std::uint64_t> next_id_{1};

  // Live sessions, for stop() and the client cap. Guarded by sessions_mutex_:
  // sessions are added by the acceptor and removed on their own strands.
  std::mutex sessions_mutex_;
  struct Peer {
    std::weak_ptr<Session> session;
    std::weak_ptr<ClientSession> client;
  };
  std::unordered_map<ClientId, Peer> sessions_;

  std::chrono::steady_clock::time_point stats_at_ = std::chrono::steady_clock::now();
  std::uint64_t stats_edits_ = 0, stats_sent_ = 0, stats_received_ = 0;
};

}  // namespace terrane
