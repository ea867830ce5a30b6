#include "server/cluster/cluster_node.h"

#include "server/base/log.h"

namespace terrane {

ClusterNode::ClusterNode(const ClusterOptions& options, PostgresStore& store)
    : url_(options.store_url), server_id_(options.server_id), lease_(options.lease), store_(store) {}

StoreResult<std::unique_ptr<ClusterNode>> ClusterNode::open(const ClusterOptions& options, PostgresStore& store,
                                                            LeaseKeeper::LostFn on_lost, DatabaseCounters* database) {
  std::unique_ptr<ClusterNode> node(new ClusterNode(options, store));
  node->database_ = database;
  // Writes are fenced by this server's leases (STORE_POSTGRESQL.md): a
  // region another server holds is never written, and a lease lost (this
  // server paused or cut off past it) makes the next write fail, which
  // stops the server as any failed commit does.
  auto keeper = LeaseKeeper::open(node->url_, node->server_id_, LeaseTimes::of(node->lease_), std::move(on_lost),
                                 database);
  if (!keeper) return keeper.error();
  node->leases_ = std::move(*keeper);
  auto control = ClusterControl::open(node->url_, *node->leases_, database);
  if (!control) return control.error();
  node->control_ = std::move(*control);
  // Only leases held: the world owner claims a region (and reads it again)
  // before it applies anything there, so a write never takes back a region
  // this server lost or handed over.
  store.set_lease_source(node->leases_->held_source(), node->lease_);
  store.count_retries_in(database);
  return node;
}

ClusterNode::~ClusterNode() {
  stop_listening();
  stop_control();
}

StoreResult<std::vector<std::uint32_t>> ClusterNode::others_running() const {
  auto cluster = ClusterStore::open(url_);
  if (!cluster) return cluster.error();
  auto ids = (*cluster)->running(lease_);
  if (!ids) return ids.error();
  std::erase(*ids, server_id_);
  return ids;
}

StoreResult<Ok> ClusterNode::listen(ChangeListener::Handlers handlers) {
  auto listener = ChangeListener::open(url_, server_id_, std::move(handlers), database_);
  if (!listener) return listener.error();
  changes_ = std::move(*listener);
  return Ok{};
}

void ClusterNode::start(std::string address) { leases_->advertise(std::move(address), &directory_); }

void ClusterNode::stop_listening() { changes_.reset(); }

void ClusterNode::stop_control() {
  if (control_) control_->stop();
}

void ClusterNode::release() {
  if (auto released = leases_->release_all(); !released)
    server_log().warn("leases not released (they run out in {} ms): {}", lease_.count(), released.error().message);
}

}  // namespace terrane
