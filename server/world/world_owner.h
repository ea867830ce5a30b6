// WorldOwner: the world strand and the API to it. It owns no world state
// itself: it makes the strand's owners, picks the authority once, and
// hands each call to the owner it concerns, on the strand.
//
//   RequestQueue  clients' comings and goings and streaming's requests
//                 (join, leave, moved, want, release, want_horizon,
//                 holds_full), drained in slices of kRequestSlice
//   FanOut        the clients as the world knows them, who holds what,
//                 presence; tells holders of new versions
//   HorizonCache  horizon images made and kept
//   Residency     the chunk versions held: wants, grants, loads, coarse
//                 images, estimates, lightening and unloading
//   Authority     whether this server may write a box now: LocalAuthority
//                 (SQLite), or SharedAuthority (a PostgreSQL world several
//                 servers share: leases, forwarded edits, other servers'
//                 changes)
//   Tick          the tick: the edit queue, undo histories, commits,
//                 acknowledgements, reads and hashes
//
// The world applies edits and publishes versions; it does no per-client
// streaming and no encoding (replicators do both on their own strands,
// from the versions they are handed).
//
// Streaming's requests wait in one queue of their own, in the order
// called: a tick, a commit's acknowledgements or an edit posted meanwhile
// runs between two slices instead of behind every request a thousand
// moving clients queued (one queue, so a client's requests never pass its
// join). The world's copy of a client's position so trails a directly
// posted edit by that queue's wait (the stream gate keeps it near 20 ms):
// only undo and redo are checked against it, and a step at the very edge
// of the full-resolution region during a move may be refused, with its
// reason. How long each request waited is reported (on_request_wait: the
// stream gate, which then holds streaming back).
//
// Threading: the public methods may be called from any thread and post to
// the strand (or queue a request for it); WorldClient callbacks are made on
// the strand.
#pragma once

#include <asio.hpp>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "common/world/world.h"
#include "server/base/chunk_version.h"
#include "server/base/cluster_options.h"
#include "server/storage/postgres_store.h"
#include "server/storage/storage.h"
#include "server/world/authority.h"
#include "server/world/fan_out.h"
#include "server/world/horizon_cache.h"
#include "server/world/request_queue.h"
#include "server/world/residency.h"
#include "server/world/tick.h"
#include "server/world/world_client.h"
#include "server/world/world_clock.h"
#include "server/world/world_options.h"

namespace terrane {

class WorldOwner {
 public:
  using Strand = asio::strand<asio::io_context::executor_type>;
  using RollbackResult = terrane::RollbackResult;

  // storage.leased() (set before) picks the shared world's authority, which
  // reads cluster (this server's id and the lease; unused otherwise).
  // options outlives the owner.
  WorldOwner(asio::io_context& io, World& world, Storage& storage, const WorldOptions& options,
             ServerCounters& counters, const ClusterOptions& cluster = {});

  void start();
  // Applies what is queued, stops the tick and waits for every commit.
  // Blocks; must not be called from an io thread.
  void stop();

  // identified: the name is proven the player's (its undo history then
  // outlives the session: Tick, ParkedHistories). presence_records: it
  // takes PresenceRecords (kFeaturePresenceRecords) for Presence.
  void join(ClientId id, std::string name, std::shared_ptr<WorldClient> client, bool identified = false,
            bool presence_records = false);
  void leave(ClientId id);
  void moved(ClientId id, Vec3f position, std::int32_t view_distance, std::int32_t full_res_radius);
  // Streaming's requests (queued after the join, with it).
  void want(ClientId id, std::vector<ChunkWant> chunks);
  void release(ClientId id, std::vector<Vec3i> chunks);
  // The client now holds these chunks at full resolution without asking
  // for them again (held Empty, brought within full resolution by a move):
  // their changes reach it every tick from now on, and any gathered for
  // its next mips_changed are handed over at once.
  void holds_full(ClientId id, std::vector<Vec3i> chunks);
  // Horizon images of these regions at these levels (nearest first),
  // handed over through WorldClient::horizons as each is made; each is made
  // once and kept until a chunk of its region changes.
  void want_horizon(ClientId id, std::vector<HorizonWant> wants);
  // How long each streaming request waited in its queue (0 once it is
  // empty), called on the strand. Before start().
  void on_request_wait(std::function<void(std::chrono::nanoseconds)> fn) { requests_.on_wait(std::move(fn)); }
  // The longest the strand spends on streaming requests at a time.
  static constexpr std::chrono::microseconds kRequestSlice = RequestQueue::kSlice;
  // Already checked by the client's replicator: rate, size, and that the
  // client holds the edit's chunks at full resolution.
  void edit(ClientId id, EditRequestMsg edit);
  // Chunks another server of a shared world stored, at these revisions
  // (its notices): what this server holds of them older than that is
  // brought up to date, and its holders are sent the change. A chunk held
  // with its voxels at the revision before, whose notice carries the
  // changed units, has them applied (its holders get the units, as for an
  // edit here); any other is read again (its holders get the new chunk),
  // or forgotten when nothing here holds or waits for it.
  void changed_elsewhere(std::vector<ChunkChange> changes);
  // Notices of these regions may have been missed (their write sequences
  // moved while the listener reconnected): every chunk held there, outside
  // the regions this server writes, is read again (background loads).
  void read_again_elsewhere(std::vector<Vec3i> regions);
  // This server's inbox has edits forwarded by another server (its notice):
  // they are read and applied like its own clients' edits, and answered in
  // the tick's commit.
  void inbox_has_edits();
  // The owner's answer to an edit this server forwarded.
  void answered(ForwardAnswer answer);
  // A shared world's region lease this server held is gone (the lease
  // keeper found it lost): the server stops, as after a failed commit.
  void lease_lost(Vec3i region, std::string why);
  // Rejects an edit the replicator refused, with the true state of its box.
  void refuse(ClientId id, EditRequestMsg edit, RejectReason why, std::string reason);

  // A rollback (terrane-admin rollback): log entries of one player, newest
  // first, undone in that order under the undo rule (a voxel is restored
  // only while it is still as the entry left it), limited to within when
  // given. Applied as one edit in a tick, stored and logged (as actor's),
  // fanned out like any edit; done runs on the world strand after the
  // commit.
  void rollback(std::string actor, std::vector<EditLogEntry> entries, std::optional<Region> within,
                std::function<void(RollbackResult)> done);
  // Answers every queued rollback with why (stopping, storage failed). On
  // the strand.
  void fail_rollbacks(const std::string& why);
  void read_box(ClientId id, ReadBoxMsg request);
  void hash(ClientId id, Vec3i chunk_pos);

  // done(tick, stored) runs (on the world strand) once every tick applied so
  // far is committed: every edit applied up to tick is stored (acknowledged
  // edits always are; this also covers the tick in flight); stored is false
  // once the store has failed.
  void flush(std::function<void(std::uint64_t tick, bool stored)> done);

  // Runs fn on the strand and waits (tests, tools).
  void inspect(const std::function<void(const WorldView&)>& fn);
  bool storage_failed() const { return tick_.storage_failed(); }
  // The world's options (any thread: read-only): replicators read the edit
  // rate and the mips' refresh period here.
  const WorldOptions& options() const { return options_; }

 private:
  // A request from the queue, on the strand.
  void handle(WorldRequest& r);

  const WorldOptions& options_;
  Strand strand_;
  WorldClock clock_;
  FanOut fan_out_;
  HorizonCache horizons_;
  Residency residency_;
  // Picked once: SharedAuthority when the store has leases, else
  // LocalAuthority. (Made with a reference to tick_, used only later.)
  std::unique_ptr<Authority> authority_;
  Tick tick_;
  RequestQueue requests_;  // last: its drains run on the strand until the owner goes
};

}  // namespace terrane
