// ClusterStore: what the servers sharing one PostgreSQL world keep there
// besides the chunks (server/storage/STORE_POSTGRESQL.md): the region
// leases (claims, renewals, releases; at most one writer per region), where
// each server takes clients, the forwarded edits' inbox and answers, and
// the notices between servers. The chunks themselves are the chunk store's
// (server/storage/postgres_store.h), whose fenced writes check these
// leases in their own transactions.
//
// Connections are PgConnection's (server/storage/pg_connection.h): open()
// makes or upgrades the schema as the chunk store's does.
//
// Threading: one object is one connection; use it from one thread at a
// time. Its users each open their own: the control thread
// (cluster_control.h), the lease keeper (claims, and its renewal thread),
// the change listener's thread.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "server/storage/cluster_link.h"
#include "server/storage/cluster_map.h"
#include "server/storage/notices.h"
#include "server/storage/pg_connection.h"

namespace terrane {

// The database's clock as one statement read it (clock_timestamp(), in
// microseconds since 1970), and when this server had the answer (its
// steady clock). The database read its clock before the answer came, so at
// any later local time t the database's clock is at least
// at_us + (t - received): a lower bound that needs no agreement between the
// machines' clocks, only that both run at the same rate (they drift by
// parts per million; a database clock stepped back breaks it).
struct DatabaseClock {
  std::int64_t at_us = 0;
  std::chrono::steady_clock::time_point received{};
  std::int64_t at_least_at(std::chrono::steady_clock::time_point t) const {
    return at_us + std::chrono::duration_cast<std::chrono::microseconds>(t - received).count();
  }
};

class ClusterStore {
 public:
  static StoreResult<std::unique_ptr<ClusterStore>> open(const std::string& url);
  // The deadline of each of its statements (PgConnection::set_call_timeout).
  void set_call_timeout(std::chrono::milliseconds t);
  ~ClusterStore();
  ClusterStore(const ClusterStore&) = delete;
  ClusterStore& operator=(const ClusterStore&) = delete;

  // Takes the region for owner (a server id below 2^31) for the lease time,
  // at the next epoch, if it is free, its lease has expired, or owner holds
  // it already (a server that claims again is a new incarnation: writes its
  // earlier self still has in flight are fenced; renew keeps an epoch).
  // Otherwise the error is kOwned, naming the holder and when its lease
  // runs out. With kPreferNeighbours, a free region one of whose 26
  // neighbours another server writes is left to that server (error kLeft,
  // naming it) unless owner writes a neighbour too (the server writing
  // most neighbours, then the lowest id). Territories stay whole, so
  // clients cross fewer borders.
  StoreResult<RegionLease> claim(Vec3i region, std::uint32_t owner, std::chrono::milliseconds lease,
                                 ClaimRule rule = ClaimRule::kAny);
  // Extends each lease still current (same owner and epoch, not expired) by
  // lease from now; returns those it extended. A lease missing from the
  // answer is lost: its holder must stop writing the region. With clock,
  // the same statement also reads the database's clock into it (one
  // statement even without leases).
  StoreResult<std::vector<RegionLease>> renew(std::span<const RegionLease> leases, std::chrono::milliseconds lease,
                                              DatabaseClock* clock = nullptr);
  // Gives the leases up (they expire at once); other servers may claim them.
  StoreResult<Ok> release(std::span<const RegionLease> leases);
  // Who holds region now (a current lease), if anyone.
  StoreResult<std::optional<RegionLease>> holder(Vec3i region);

  // Where server id takes clients ("HOST:PORT"), seen now: a lease keeper
  // calls it every renewal round. withdraw forgets it (a clean stop).
  StoreResult<Ok> advertise(std::uint32_t id, const std::string& address);
  StoreResult<Ok> withdraw(std::uint32_t id);
  // Every current lease's region and writer, and the addresses of servers
  // seen within fresh (rows that do not parse are left out).
  struct Cluster {
    std::vector<RegionWriter> writers;
    std::vector<ServerAddress> servers;
  };
  StoreResult<Cluster> cluster(std::chrono::milliseconds fresh);
  // The ids of servers seen within fresh (with an address or without).
  StoreResult<std::vector<std::uint32_t>> running(std::chrono::milliseconds fresh);

  // Every region's write sequence number (regions never written under a
  // lease have none: 0).
  StoreResult<std::vector<RegionSeq>> region_seqs();
  // The stored chunks of a region and their revisions (what a server that
  // claimed it reads again).
  StoreResult<std::vector<std::pair<Vec3i, std::uint64_t>>> stored_revisions(Vec3i region);

  // Forwards an edit to server to's inbox (one transaction: the row and
  // its notice); the row's id. expires_us: its deadline by the database's
  // clock (microseconds since 1970), after which nobody takes it. kUnknown
  // if the COMMIT's answer was lost (the row may be there).
  StoreResult<std::int64_t> forward(std::uint32_t from, std::uint32_t to, const std::string& player,
                                    std::span<const std::uint8_t> edit, std::int64_t expires_us);
  // Passes the edit of inbox row id, which from took, on to server to (one
  // transaction: the row readdressed and no longer taken, its notice). Its
  // sender and deadline stay, so to answers the sender and takes it only
  // in time. kFenced if the row is no longer from's (answered or passed on
  // already); kUnknown if the COMMIT's answer was lost.
  StoreResult<Ok> relay(std::int64_t id, std::uint32_t from, std::uint32_t to);
  // Takes the edits for server to not taken yet, with an id above after and
  // their deadline not passed, oldest first, at most limit: each is marked
  // taken in the same statement, so "taken" and "too late" are decided
  // once, by the database's clock, and a row is taken once. (The first page,
  // after = 0, also deletes to's rows whose deadline passed ten minutes
  // ago: never taken, or taken by an earlier run of to that never
  // answered.)
  StoreResult<std::vector<InboxEdit>> inbox(std::uint32_t to, std::int64_t after, std::size_t limit);
  // The sender of inbox row id takes it back (its wait ran out): true if
  // the row was there and not taken (deleted: the edit is never applied),
  // false if it was taken (its addressee has it: an answer comes, or none
  // if that server stopped) or is gone (answered).
  StoreResult<bool> take_back(std::int64_t id);
  // Answers without writing chunks (edits refused). (Edits a tick applied
  // are answered in its fenced commit: PostgresStore::save_answering.)
  StoreResult<Ok> answer(std::span<const ForwardAnswer> answers);
  // Every answer is also kept in terrane_answers until its sender has it:
  // take_answers hands over (and deletes) those to edits server from
  // forwarded (a listener that reconnected may have missed their notices);
  // forget_answers deletes those whose notices arrived, and any older than
  // ten minutes.
  StoreResult<std::vector<ForwardAnswer>> take_answers(std::uint32_t from);
  StoreResult<Ok> forget_answers(std::span<const std::int64_t> ids);

  // Subscribes this connection to terrane_changes, terrane_inbox and
  // terrane_answers; wait_notices then returns every channel's payloads
  // that arrived, each with its channel, waiting up to timeout for the
  // first. A broken connection is kConnection (open another and read
  // again what may have been missed).
  StoreResult<Ok> listen();
  struct Notice {
    std::string channel, payload;
  };
  StoreResult<std::vector<Notice>> wait_notices(std::chrono::milliseconds timeout);
  // Names this connection in pg_stat_activity (operators see which server
  // and which part of it a session is).
  StoreResult<Ok> set_name(const std::string& application_name);

 private:
  explicit ClusterStore(std::unique_ptr<PgConnection> c);
  // kPreferNeighbours' rule: the kLeft error if region is left to another
  // server, nullopt if owner may claim it.
  StoreResult<std::optional<StoreError>> left_to_neighbour(Vec3i region, std::uint32_t owner);

  std::unique_ptr<PgConnection> c_;
};

}  // namespace terrane
