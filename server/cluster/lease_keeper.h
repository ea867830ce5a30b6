// LeaseKeeper: the regions one server holds in a shared PostgreSQL world,
// kept alive (server/storage/STORE_POSTGRESQL.md, "Regions and leases").
//
// ensure() claims the regions a write needs, and renews none of them itself.
// A thread of the keeper's own renews every held lease each renew period,
// on a connection of its own, so a slow write never delays a renewal; a
// round that failed (the database restarting, say) is tried again after
// the retry pause, not a whole period later. A
// lease the database no longer extends is lost: the keeper drops it and
// calls on_lost, and the owner must stop writing that region. The writes
// themselves are fenced by PostgreSQL whatever the keeper believes: the
// keeper is how a server learns early, not what keeps the data safe.
//
// Threading: ensure(), held(), database_time_at() and stop() may be called
// from any thread; on_lost runs on the keeper's thread.
#pragma once

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <thread>
#include <tuple>
#include <vector>

#include "server/base/counters.h"
#include "server/cluster/cluster_store.h"

namespace terrane {

// A database out of reach for less than lease - renew - retry - a reconnect
// costs no lease (STORE_POSTGRESQL.md, "Regions and leases"): the last
// renewal before it went away was at most a renew period earlier, and the
// first after it is back comes within a retry pause.
struct LeaseTimes {
  std::chrono::milliseconds lease{5000};  // how long a claim or renewal lasts
  std::chrono::milliseconds renew{500};   // how often every held lease is renewed
  // After a round that failed, the next is tried this soon (at most renew),
  // so that the leases are renewed as soon as the database is back. A
  // refused connection costs little; one that is not answered takes its
  // deadline, so a partition does not make this a busy loop.
  std::chrono::milliseconds retry{50};
  // A lease of this length, renewed every tenth of it.
  static LeaseTimes of(std::chrono::milliseconds lease) {
    const auto renew = std::max(std::chrono::milliseconds(1), lease / 10);
    return {lease, renew, std::min(renew, std::chrono::milliseconds(50))};
  }
};

class LeaseKeeper {
 public:
  using LostFn = std::function<void(const RegionLease& lost, const std::string& why)>;

  // url: the world's database; owner: this server's id (below 2^31).
  // counters (may be null; must outlive the keeper): where the keeper
  // notes when its last renewal round reached the database.
  static StoreResult<std::unique_ptr<LeaseKeeper>> open(const std::string& url, std::uint32_t owner,
                                                        LeaseTimes times, LostFn on_lost,
                                                        DatabaseCounters* counters = nullptr);
  ~LeaseKeeper();  // stops renewing; the leases then run out
  LeaseKeeper(const LeaseKeeper&) = delete;
  LeaseKeeper& operator=(const LeaseKeeper&) = delete;

  // The leases of regions, claiming those not held (in one order for every
  // server). Fails with kOwned (naming the holder) if another server holds
  // one of them (kLeft, by rule, if it leaves a free one to a neighbour's
  // server); the regions claimed before the failure stay held.
  StoreResult<std::vector<RegionLease>> ensure(std::span<const Vec3i> regions, ClaimRule rule = ClaimRule::kAny);
  // The leases of regions, all of them held already; claims nothing.
  // kFenced naming a region not held: a write must never take a region
  // back by itself (the world owner claims, then reads the region again).
  StoreResult<std::vector<RegionLease>> held(std::span<const Vec3i> regions) const;
  bool holds(Vec3i region) const;
  std::vector<RegionLease> held() const;
  std::uint32_t owner() const { return owner_; }
  // A lease source for a PostgresStore: the leases held only (held()), or
  // claiming those not held (ensure()). Valid while this keeper lives.
  std::shared_ptr<const LeaseSource> held_source() const;
  std::shared_ptr<const LeaseSource> claiming_source();
  // Gives these regions' leases up at once (handed to another server:
  // nothing of them may be in flight); regions not held are skipped.
  StoreResult<Ok> release(std::span<const Vec3i> regions);
  // Gives every lease up at once (a clean shutdown), then stops renewing.
  StoreResult<Ok> release_all();
  // Renewal rounds done so far (tests wait on it).
  std::uint64_t renewals() const;
  // A lower bound of the database's clock (microseconds since 1970) at
  // local time t, from the last reading (DatabaseClock: every renewal
  // round reads it, and open() once): what a forwarded edit's deadline is
  // written in. nullopt without a reading within a lease (the database out
  // of reach: then no deadline is guessed).
  std::optional<std::int64_t> database_time_at(std::chrono::steady_clock::time_point t) const;
  // From now on, every renewal round (the first at once) also tells the
  // database that this server runs and where it takes clients (address
  // "HOST:PORT", or "" for nowhere: it is then never a redirect's target)
  // and publishes to directory who writes which region (server/storage/
  // cluster_map.h). directory must outlive the keeper. release_all()
  // withdraws the row.
  void advertise(std::string address, ClusterDirectory* directory);

 private:
  LeaseKeeper(std::uint32_t owner, LeaseTimes times, LostFn on_lost, std::unique_ptr<ClusterStore> claims,
              std::unique_ptr<ClusterStore> renewals, DatabaseCounters* counters);
  void renew_loop();
  using Key = std::tuple<int, int, int>;  // (y, z, x): the claiming order
  static Key key_of(Vec3i region) { return {region.y, region.z, region.x}; }

  const std::uint32_t owner_;
  const LeaseTimes times_;
  const LostFn on_lost_;
  DatabaseCounters* const counters_;  // lease_renewed_at_ns (keeper thread); may be null
  std::mutex claims_mutex_;               // one claim at a time on claims_
  std::unique_ptr<ClusterStore> claims_;
  std::unique_ptr<ClusterStore> renewer_;  // the keeper thread's own

  // A renewal round's news of the cluster: this server's address seen now,
  // and the map of writers published (renewer_'s connection, keeper thread).
  // False when the database did not take the address.
  bool exchange_addresses(const std::string& address, ClusterDirectory* directory);

  mutable std::mutex mutex_;  // guards held_, rounds_, stopping_, address_, directory_, round_now_, clock_
  std::condition_variable wake_;
  std::map<Key, RegionLease> held_;
  std::uint64_t rounds_ = 0;
  bool stopping_ = false;
  std::string address_;
  ClusterDirectory* directory_ = nullptr;
  bool round_now_ = false;
  bool advertising_ = false;
  std::optional<DatabaseClock> clock_;  // the last reading of the database's clock
  std::shared_ptr<const ClusterMap> last_map_;  // keeper thread: the map published last
  std::thread thread_;
};

}  // namespace terrane
