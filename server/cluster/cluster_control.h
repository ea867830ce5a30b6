// ClusterControl: the cluster room's control thread and its connection
// (a ClusterStore), which carry out what the world owner asks of the other
// servers through Storage (ClusterLink): claims, forwarded and relayed
// edits (a forward's deadline written by the database's clock as the
// lease keeper last read it), edits taken back, inbox reads and refusals. An edit waits on each of them, so they
// run on a thread of their own, never behind the loads (thousands may be
// queued while clients join), in the order asked.
//
// Threading: the ClusterLink methods may be called from any thread; their
// work and its done callbacks run on the control thread (post from there
// to where the result belongs). stop() waits for the work queued and must
// not be called from the control thread.
#pragma once

#include <asio.hpp>
#include <chrono>
#include <functional>
#include <memory>
#include <string>

#include "server/base/rate_limit.h"
#include "server/cluster/cluster_store.h"
#include "server/cluster/lease_keeper.h"
#include "server/storage/cluster_link.h"

namespace terrane {

class ClusterControl final : public ClusterLink {
 public:
  // url: the world's database; keeper: this server's leases (claims and
  // hand-overs go through it), which must outlive this. counters (may be
  // null; must outlive this): inbox_failing follows each inbox read.
  static StoreResult<std::unique_ptr<ClusterControl>> open(const std::string& url, LeaseKeeper& keeper,
                                                           DatabaseCounters* counters = nullptr);
  ~ClusterControl() override;
  ClusterControl(const ClusterControl&) = delete;
  ClusterControl& operator=(const ClusterControl&) = delete;
  // Runs what is queued, then ends the thread; later calls are dropped.
  void stop();

  std::uint32_t server_id() const override { return keeper_.owner(); }
  bool holds(Vec3i region) const override { return keeper_.holds(region); }
  void claim(Vec3i region, ClaimRule rule, std::function<void(RegionClaim)> done) override;
  void forward(std::uint32_t to, std::string player, EditRequestMsg edit, std::vector<Vec3i> hand_over,
               std::chrono::steady_clock::time_point deadline,
               std::function<void(StoreResult<std::int64_t>)> done) override;
  void take_back(std::int64_t row, std::function<void(StoreResult<bool>)> done) override;
  void relay(std::int64_t row, std::uint32_t to, std::vector<Vec3i> hand_over,
             std::function<void(StoreResult<Ok>)> done) override;
  void read_inbox(std::int64_t after, std::size_t limit,
                  std::function<void(StoreResult<std::vector<InboxEdit>>)> done) override;
  void answer(std::vector<ForwardAnswer> answers) override;

 private:
  ClusterControl(LeaseKeeper& keeper, std::unique_ptr<ClusterStore> store, DatabaseCounters* counters);
  // Runs fn(store_) on the control thread.
  void post(std::function<void(ClusterStore&)> fn);

  LeaseKeeper& keeper_;
  DatabaseCounters* const counters_;  // may be null
  std::unique_ptr<ClusterStore> store_;  // the control thread's
  RateLimitedLog claim_log_{1};          // claims the database failed (its own words), once a second at most
  asio::thread_pool thread_{1};
};

}  // namespace terrane
