// Tick: the world strand's tick and the edits it applies. Owns the queue
// of edits (clients', rollbacks, those forwarded from other servers) and
// their waits, every client's edit count and undo history, the commits in
// flight and the flush waiters, the reads and hashes waiting for their
// chunks, and whether the store has failed. Runs on the world strand.
//
// Each tick (a fixed schedule of tick_hz, not re-armed after the work):
//   1. apply the queued edits whose chunks are loaded (Residency) and
//      writable (Authority), in arrival order, to copies of those chunks;
//      each changed chunk becomes a new version (revision + 1) that the
//      next tick builds on. An edit that waits holds up only the edits
//      behind it of its player or on its chunks;
//   2. hand the tick's versions to Storage, whose writer commits them (with
//      any other tick queued by then) in one transaction while the world
//      goes on with the next tick;
//   3. when that commit is reported: publish its versions (Residency) and
//      tell their holders (FanOut), then acknowledge the tick's edits. A
//      failed commit rejects the edits (saying the outcome is unknown
//      where the commit may have been stored: FileError::outcome_unknown)
//      and closes every client with "server storage failure", after
//      calling on_fatal.
// Around the edits each tick: estimates replaced, chunks lightened and
// unloaded (Residency), mip news delivered and presence sent (FanOut),
// forwarded edits settled (Authority).
#pragma once

#include <asio.hpp>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <deque>
#include <functional>
#include <future>
#include <memory>
#include <optional>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "common/world/world.h"
#include "server/base/counters.h"
#include "server/storage/storage.h"
#include "server/world/authority.h"
#include "server/world/fan_out.h"
#include "server/world/history.h"
#include "server/world/parked_histories.h"
#include "server/world/residency.h"
#include "server/world/world_client.h"
#include "server/world/world_clock.h"
#include "server/world/world_options.h"

namespace terrane {

class Tick final : public EditQueue {
 public:
  using Strand = asio::strand<asio::io_context::executor_type>;

  Tick(Strand& strand, World& world, Storage& storage, const WorldOptions& options, ServerCounters& counters,
       WorldClock& clock, Residency& residency, FanOut& clients, Authority& authority);

  // On the strand: the schedule starts now.
  void start();
  // Applies what is queued, stops the tick and waits for every commit.
  // Blocks; must not be called from the strand or an io thread.
  void stop();

  // The rest on the strand.
  // An identified player (its name proven by its own token) takes back the
  // undo history its last session left (ParkedHistories); others start
  // with none.
  void join(ClientId id, std::string name, bool identified = false);
  // An identified player's history is parked for its next session, or
  // handed to its session that joined meanwhile (the later join wins, and
  // the earlier may leave after it) if that one has none yet.
  void leave(ClientId id);
  // A client's edit (checked by its replicator), handed over at received.
  void edit(ClientId id, EditRequestMsg edit, std::chrono::steady_clock::time_point received);
  void rollback(std::string actor, std::vector<EditLogEntry> entries, std::optional<Region> within,
                std::function<void(RollbackResult)> done);
  // Answers every queued rollback with why (stopping, storage failed).
  void fail_rollbacks(const std::string& why);
  void read_box(ClientId id, const ReadBoxMsg& request);
  void hash(ClientId id, Vec3i chunk_pos);
  // done(tick, stored) once every tick applied so far is committed.
  void flush(std::function<void(std::uint64_t tick, bool stored)> done);
  // The store failed, or a lease was lost: rollbacks fail, on_fatal runs,
  // every client is closed, the tick stops.
  void fatal_storage(const std::string& why);
  // Any thread.
  bool storage_failed() const { return storage_failed_flag_.load(); }

  // EditQueue
  void queue_forwarded(EditRequestMsg edit, std::string player, Forwarded from) override;
  void reject(ClientId id, const EditRequestMsg& edit, RejectReason why, const std::string& reason) override;

 private:
  // A client as its edits know it: its name (the edit log's player), its
  // edits queued, its undo history.
  struct Editor {
    std::string name;
    std::size_t edits_queued = 0;
    History history;
    bool identified = false;
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
  struct TickEdits;
  enum class EditStep : std::uint8_t {
    kNext,  // the edit was applied, refused, passed on or set aside: on to the next
    kStop,  // the edit waits at the queue's head (a hand-over): nothing more this tick
  };

  void arm_tick();
  void on_tick();
  // One tick: the queued edits applied, as many as may be, then committed.
  void apply_edits();
  EditStep apply_rollback(TickEdits& t);
  EditStep apply_player_edit(TickEdits& t);
  void set_aside(TickEdits& t);  // the queue's head waits until after the tick
  void on_committed(std::uint64_t tick, const std::vector<VersionPtr>& versions, const std::vector<Ack>& acks,
                    const FileStatus& status);
  // Reads and hashes whose chunks have arrived are answered.
  void retry_pending();

  Strand& strand_;
  World& world_;
  Storage& storage_;
  const WorldOptions& options_;
  ServerCounters& counters_;
  WorldClock& clock_;
  Residency& residency_;
  FanOut& clients_;
  Authority& authority_;
  asio::steady_timer timer_;
  std::chrono::steady_clock::time_point next_tick_;
  std::uint64_t slow_ticks_ = 0;  // longer than half a period, since the last report
  std::chrono::steady_clock::time_point next_slow_tick_report_{};
  std::unordered_map<ClientId, Editor> editors_;
  ParkedHistories parked_;  // identified players' histories, between their sessions
  // Edits in arrival order. One that waits (chunks, a claim) holds up only
  // the edits behind it of its player or on its chunks (apply_edits).
  std::deque<PendingEdit> edits_;
  std::vector<std::pair<ClientId, ReadBoxMsg>> reads_;  // waiting for chunks
  std::vector<std::pair<ClientId, Vec3i>> hashes_;      // waiting for chunks
  std::uint64_t commits_pending_ = 0;
  std::uint64_t last_committed_tick_ = 0;
  std::vector<std::pair<std::uint64_t, std::function<void(std::uint64_t, bool)>>> flush_waiters_;
  bool storage_failed_ = false;
  std::atomic<bool> storage_failed_flag_{false};
  std::promise<void> drained_;
  bool drain_wanted_ = false;
};

}  // namespace terrane
