// WorldOwner: the one strand that owns the world's state — the loaded
// chunk versions, the queued edits, every client's undo history, the
// interest index (who holds what) and the presence grid.
//
// It applies edits and publishes versions; it does no per-client streaming
// and no encoding (replicators do both on their own strands, from the
// versions they are handed).
//
// Tick (a fixed schedule of tick_hz, not re-armed after the work):
//   1. apply the queued edits whose chunks are loaded, in arrival order, to
//      copies of those chunks; each changed chunk becomes a new version
//      (revision + 1) that the next tick builds on;
//   2. hand the tick's versions to Storage, whose writer commits them (with
//      any other tick queued by then) in one transaction while the world
//      goes on with the next tick;
//   3. when that commit is reported: acknowledge the tick's edits, publish
//      its versions (what new readers are handed from then on) and tell each
//      holder of a changed chunk at full resolution, once per tick, which of
//      its chunks changed (InterestIndex); holders of changed chunks held
//      coarser are told every mip_refresh_ms, of all the ticks since
//      (WorldClient::mips_changed). A failed commit rejects the edits,
//      closes every client with "server storage failure", after calling
//      on_fatal.
//
// Chunks: a client asks for chunks (want); loaded ones are granted at once,
// the others when Storage has loaded or generated them. A chunk wanted only
// at its coarsest level (4^3) comes from its region's coarse image when it
// was stored (one read serves the region's 512 chunks, none decoded), as a
// version with that level only; the chunk itself is read when a finer
// level, an edit or a hash needs it. A grant registers
// the client as a holder, so every later change reaches it, in order after
// the grant. Chunks nobody holds at full resolution, with nothing pending,
// are unloaded beyond resident_chunks, least recently used first.
//
// Clients' comings and goings and streaming's requests (join, leave,
// moved, want, release, want_horizon) wait in one queue of their own, in
// the order called, which the strand drains in slices of kRequestSlice: a
// tick, a commit's acknowledgements or an edit posted meanwhile runs
// between two slices instead of behind every request a thousand moving
// clients queued. (One queue, so a client's requests never pass its join.)
// The world's copy of a client's position so trails a directly posted edit
// by that queue's wait (the stream gate keeps it near 20 ms): only undo and
// redo are checked against it, and a step at the very edge of the
// full-resolution region during a move may be refused, with its reason.
// How long each request waited is reported (on_request_wait: the stream
// gate, which then holds streaming back).
//
// In a world shared by several servers (PostgreSQL), leases, forwarded
// edits and other servers' changes are in world_owner_shared.cpp.
//
// Threading: the public methods may be called from any thread and post to
// the strand (or queue a request for it); WorldClient callbacks are made on
// the strand.
#pragma once

#include <algorithm>
#include <asio.hpp>
#include <chrono>
#include <cstdint>
#include <deque>
#include <functional>
#include <future>
#include <memory>
#include <optional>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <variant>
#include <vector>

#include "common/voxel/grid.h"
#include "common/voxel/vec3_map.h"
#include "common/world/world.h"
#include "server/base/options.h"
#include "server/base/rate_limit.h"
#include "server/net/session.h"  // SharedFrame, SendClass: the world still builds frames
#include "server/storage/postgres_store.h"
#include "server/storage/storage.h"
#include "server/base/chunk_version.h"
#include "server/world/history.h"
#include "server/world/interest.h"
#include "server/world/presence.h"
#include "server/world/authority.h"
#include "server/world/fan_out.h"
#include "server/world/horizon_cache.h"
#include "server/world/residency.h"
#include "server/world/world_clock.h"
#include "server/world/request_queue.h"
#include "server/world/world_client.h"

namespace terrane {

class WorldOwner : private EditQueue {
 public:
  using Strand = asio::strand<asio::io_context::executor_type>;

  WorldOwner(asio::io_context& io, World& world, Storage& storage, const ServerOptions& options,
             ServerCounters& counters);

  void start();
  // Applies what is queued, stops the tick and waits for every commit.
  // Blocks; must not be called from an io thread.
  void stop();

  void join(ClientId id, std::string name, std::shared_ptr<WorldClient> client);
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
  struct RollbackResult {
    bool ok = false;
    std::string error;
    std::uint64_t tick = 0;
    std::uint64_t voxels_restored = 0;
  };
  void rollback(std::string actor, std::vector<EditLogEntry> entries, std::optional<Region> within,
                std::function<void(RollbackResult)> done);
  // Answers every queued rollback with why (stopping, storage failed).
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
  bool storage_failed() const { return storage_failed_flag_.load(); }

 private:
  // A client as its edits know it: its name (the edit log's player), its
  // edits queued, its undo history.
  struct Editor {
    std::string name;
    std::size_t edits_queued = 0;
    History history;
  };
  struct Rollback {
    std::string actor;
    std::vector<EditLogEntry> entries;  // newest first
    std::optional<Region> within;
    std::function<void(RollbackResult)> done;
    std::uint64_t restored = 0;
  };
  struct PendingEdit {
    ClientId id;
    EditRequestMsg edit;
    std::string player;                  // for the edit log
    std::shared_ptr<Rollback> rollback;  // set: this is a rollback, not edit
    std::optional<Forwarded> forwarded;  // set: another server's client's edit, from this server's inbox
    // When the client's session handed it over (terrane_edit_ack_duration_seconds;
    // unset for rollbacks and forwarded edits, which are not acknowledged to a client).
    std::chrono::steady_clock::time_point received{};
  };
  struct Ack {
    ClientId id;
    std::uint32_t edit_id;
    std::chrono::steady_clock::time_point received;
  };
  using Writable = Authority::Writable;
  // EditQueue (a shared world's forwarded edits)
  void queue_forwarded(EditRequestMsg edit, std::string player, Forwarded from) override;
  void reject(ClientId id, const EditRequestMsg& edit, RejectReason why, const std::string& reason) override;

  void arm_tick();
  void on_tick();
  // One tick: the queued edits applied, as many as may be, then committed.
  void apply_edits();
  struct TickEdits;
  enum class EditStep : std::uint8_t {
    kNext,  // the edit was applied, refused, passed on or set aside: on to the next
    kStop,  // the edit waits at the queue's head (a hand-over): nothing more this tick
  };
  EditStep apply_rollback(TickEdits& t);
  EditStep apply_player_edit(TickEdits& t);
  void set_aside(TickEdits& t);  // the queue's head waits until after the tick
  void on_committed(std::uint64_t tick, const std::vector<VersionPtr>& versions, const std::vector<Ack>& acks,
                    const FileStatus& status);
  // Publishes committed versions (each its chunk's newest) and tells their
  // holders: those at full resolution at once (WorldClient::committed),
  // the others gathered for deliver_mip_news.
  void publish(std::uint64_t tick, const std::vector<VersionPtr>& versions, std::chrono::steady_clock::time_point now);
  void fatal_storage(const std::string& why);
  void retry_pending();
  World& world_;
  Storage& storage_;
  const ServerOptions& options_;
  ServerCounters& counters_;
  Strand strand_;
  void handle(WorldRequest& r);
  asio::steady_timer tick_timer_;
  std::chrono::steady_clock::time_point next_tick_;
  std::uint64_t slow_ticks_ = 0;  // longer than half a period, since the last report
  std::chrono::steady_clock::time_point next_slow_tick_report_{};

  std::unordered_map<ClientId, Editor> editors_;
  // Edits in arrival order. One that waits (chunks, a claim) holds up only
  // the edits behind it of its player or on its chunks (apply_edits).
  std::deque<PendingEdit> edits_;
  std::vector<std::pair<ClientId, ReadBoxMsg>> reads_;  // waiting for chunks
  std::vector<std::pair<ClientId, Vec3i>> hashes_;      // waiting for chunks
  WorldClock clock_;
  FanOut fan_out_;
  HorizonCache horizons_;
  Residency residency_;
  std::unique_ptr<Authority> authority_;  // SharedAuthority when the store has leases, else LocalAuthority
  std::uint64_t commits_pending_ = 0;
  std::uint64_t last_committed_tick_ = 0;
  std::vector<std::pair<std::uint64_t, std::function<void(std::uint64_t, bool)>>> flush_waiters_;
  bool storage_failed_ = false;
  std::atomic<bool> storage_failed_flag_{false};
  std::promise<void> drained_;
  bool drain_wanted_ = false;
  RequestQueue requests_;  // last: its drains run on the strand until the owner goes
};

}  // namespace terrane
