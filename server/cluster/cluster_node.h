// ClusterNode: this server's part in a shared PostgreSQL world (server/
// storage/STORE_POSTGRESQL.md): the leases it holds (LeaseKeeper, renewed
// on the keeper's thread), its control thread (ClusterControl: claims,
// forwards, relays, inbox reads), the other servers' notices
// (ChangeListener, on its thread), and who writes which region
// (ClusterDirectory, published by the keeper's thread, read by the
// replicators). A SQLite world has none: its directory's lock fences its
// one writer.
//
// Its parts start and stop in this order, the Server calling each step
// between its world owner's and its storage's:
//
//   open()            keeper (leases held only: the world owner claims) and
//                     control thread; the chunk store's lease source set
//   listen(handlers)  once the world owner exists, before any client: every
//                     commit of another server from then on reaches it
//   start(address)    each renewal round advertises where this server
//                     takes clients and publishes the map of writers to
//                     directory()
//   stop_listening()  before the world owner stops: no notice reaches it
//   stop_control()    once it stopped: what it asked of the others finishes
//   release()         once storage stopped (every commit done): the leases
//                     are given up at once, so another server takes the
//                     regions over without waiting for them to run out
//
// Threading: the steps run on the thread that creates, starts and stops the
// server; no lock of its own (its parts have theirs). directory() is read
// on any thread; the parts' callbacks run on their threads.
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "common/world/world_store.h"
#include "server/base/cluster_options.h"
#include "server/cluster/change_listener.h"
#include "server/cluster/cluster_control.h"
#include "server/cluster/lease_keeper.h"
#include "server/storage/cluster_map.h"
#include "server/storage/postgres_store.h"
#include "server/storage/storage.h"

namespace terrane {

class ClusterNode {
 public:
  // The node of a PostgreSQL world's store (options.store_url,
  // options.server_id, options.lease). store must outlive the node's use of
  // shared(); on_lost runs on the keeper's thread when a held lease is
  // lost; database (may be null) is where the keeper, the control thread,
  // the listener and the store note their links' state for /health.
  static StoreResult<std::unique_ptr<ClusterNode>> open(const ClusterOptions& options, PostgresStore& store,
                                                        LeaseKeeper::LostFn on_lost,
                                                        DatabaseCounters* database = nullptr);
  ~ClusterNode();  // the steps not taken yet, in order (release() aside: the leases then run out)
  ClusterNode(const ClusterNode&) = delete;
  ClusterNode& operator=(const ClusterNode&) = delete;

  // The ids of the other servers running on the world now (a border may be
  // set only while there are none).
  StoreResult<std::vector<std::uint32_t>> others_running() const;
  // What Storage writes through: the chunk store and the control thread.
  Storage::Shared shared() const { return Storage::Shared{store_, *control_}; }
  StoreResult<Ok> listen(ChangeListener::Handlers handlers);
  // address: where this server takes clients ("HOST:PORT"), or "" for
  // nowhere (no server redirects a client here; it is still known to run).
  void start(std::string address);
  void stop_listening();
  void stop_control();
  void release();

  // Who writes which region (null map until the first round after start()).
  const ClusterDirectory& directory() const { return directory_; }
  LeaseKeeper& leases() { return *leases_; }

 private:
  ClusterNode(const ClusterOptions& options, PostgresStore& store);

  const std::string url_;
  const std::uint32_t server_id_;
  const std::chrono::milliseconds lease_;
  PostgresStore& store_;
  // Published by the keeper's thread: declared first, so it outlives it.
  ClusterDirectory directory_;
  // The store's lease source: outlives the writes of the storage made on it.
  std::unique_ptr<LeaseKeeper> leases_;
  std::unique_ptr<ClusterControl> control_;  // takes claims through leases_
  std::unique_ptr<ChangeListener> changes_;  // null before listen() and after stop_listening()
  DatabaseCounters* database_ = nullptr;
};

}  // namespace terrane
