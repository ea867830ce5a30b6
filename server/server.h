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
//
// The Server owns the order its parts start and stop in, and wires them:
//
//   create  world (its directory's lock, or a PostgreSQL world's
//           ClusterNode), Storage, the listening socket, the WorldOwner,
//           the node's listener, Operations (access, admin, /metrics)
//   start   the node advertises; the world thread, the world owner, the
//           stream gate's probes, /metrics and the stats line, accepts,
//           the io threads
//   stop    stream gate; accepts and timers; the admin room; the node's
//           listener; the world owner (what is queued is applied and
//           committed); the notice to all and every session closed; the
//           node's control thread; storage; the node's leases released;
//           /metrics; the io threads, then the world thread
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>

#include "common/world/world.h"
#include "common/world/world_lock.h"
#include "server/base/context_threads.h"
#include "server/cluster/cluster_node.h"
#include "server/net/client_session.h"
#include "server/net/listener.h"
#include "server/net/session_table.h"
#include "server/ops/operations.h"
#include "server/replication/replicator.h"
#include "server/server_options.h"
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
  // SIGHUP: the tokens file, bans and whitelist read again
  // (Operations::reload). Any thread.
  void reload() { ops_->reload(); }

  std::uint16_t port() const { return listener_.port(); }
  // The metrics endpoint's port (0 without --metrics).
  std::uint16_t metrics_port() const { return ops_->metrics_port(); }
  // Prometheus text (what /metrics serves) and the health rule (/health).
  std::string metrics_text() const;
  // Whether streaming yields now (and holding it paused: tests, operators).
  StreamGate& stream_gate() { return *stream_gate_; }
  Health health() const;
  const std::string& address() const { return options_.net.bind_address; }
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
  // The Welcome every client is sent, as options_ and the world make it.
  void make_welcome();
  // A connection accepted (its strand): its session and replicator, in the
  // table; false once stopping (the socket is dropped, none accepted after).
  bool accept(asio::ip::tcp::socket socket);
  // The world's part of the operators' commands: status, flush, rollback.
  // The world's directory or PostgreSQL URL; its border ("no border", or
  // "border x X0..X1, z Z0..Z1").
  std::string where() const;
  std::string border_text() const;
  // A player welcomed as name in session id, the join_order-th join: ends
  // name's sessions that joined before; false when name joined again since
  // (the caller's session is the older one and ends).
  bool replace_older_sessions(std::uint64_t id, const std::string& name, std::uint64_t join_order);
  AdminHooks world_hooks();
  // The world of options_: a directory (made when missing) or a PostgreSQL
  // database (made when it holds none; cluster_ opened for its writes).
  FileResult<std::unique_ptr<World>> open_world();
  // --border on a PostgreSQL world: refused while other servers run on it.
  FileStatus check_border_alone(const WorldMeta& meta);
  void log_totals() const;

  ServerOptions options_;
  ServerCounters counters_;
  // The test seam of UpdateBatches: set only by the --test-*-updates
  // options (null when serving for real).
  std::unique_ptr<UpdateFaults> faults_;
  // A PostgreSQL world's leases, control thread, notices and map of
  // writers (null for SQLite): the writer's lease source and Storage's
  // link, so it outlives the world and storage below.
  std::unique_ptr<ClusterNode> cluster_;
  // A world directory's one-writer lock (common/world/world_lock.h), held
  // for the server's life; declared before the world so it outlives every
  // write. Not held for a PostgreSQL world (leases fence its writers).
  WorldLock world_lock_;
  std::unique_ptr<World> world_;
  std::unique_ptr<Storage> storage_;
  // The sessions' and replicators' threads (terrane-io).
  ContextThreads io_;
  // The world strand runs on a thread of its own, so ticks keep their
  // schedule however many session handlers wait for the io threads.
  ContextThreads world_io_;
  Listener listener_;
  std::unique_ptr<WorldOwner> world_owner_;
  // Streaming yields to live traffic while the io threads or the world
  // strand fall behind (probes on both; stopped first in stop()).
  std::unique_ptr<StreamGate> stream_gate_;
  WelcomeTemplate welcome_;
  // The live sessions (the client cap; closed by stop()).
  SessionTable sessions_;
  // Operators' commands, access rules, /metrics, the stats line, a
  // scheduled shutdown and the notices to all (made once the world is).
  std::unique_ptr<Operations> ops_;
  // What every client session shares (the Welcome, admission, admin
  // commands, counters); set once ops_ exists.
  std::optional<ClientSession::Context> session_context_;
  std::shared_ptr<const ViewTable> default_view_;  // kept made (ViewTable::get's cache may drop unused tables)
  std::shared_ptr<const ViewTable> widest_view_;   // --max-view-distance's, the same
  // stop() runs once, and only after start(); stopping_ is read by the
  // acceptor and health() on other threads.
  std::atomic<bool> stopping_{false};
  bool started_ = false;
};

}  // namespace terrane
