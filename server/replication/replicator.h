// Replicator: one client's replication, on its session's strand. It owns
// what the client holds and what it should hold: the view plan (a shared
// ViewTable moved to the client's chunk, updated by the shells a move
// changes), the chunks held and the level and revision of each, the queue
// of chunks to refine, outstanding requests to the world, claims of a
// resuming client, the outbound budget and pushed chunk hashes.
//
// Streaming. First, for a new plan, every region of the view that has
// chunks the client knows nothing of, as one horizon image each (2^3 per
// chunk within a quarter of the view distance up to 256 voxels, 1 voxel per
// chunk beyond up to 1,024, 1 per 2^3 chunks beyond that for a client that
// takes it; made once by the world and shared), nearest first. Then the whole view at its
// coarsest (the 4^3 mip, or Empty for all-Air chunks; with horizon images,
// chunks within full resolution at full resolution) nearest first, then
// each chunk refined to the level
// the view rule gives it, nearest first (a queue of chunks needing
// refinement, filled when a chunk arrives coarser than it should be or a
// move brings it closer). Chunks are asked of the world in batches, at most
// kMaxRequests outstanding; the world grants versions, and the replicator
// sends their encodings (computed once per version and level, shared by
// every client) as StreamBatch records while the client's window and byte
// budget allow. Chunks more than kKeepMargin beyond the view are released
// on both sides.
//
// Ticks. The world hands each committed tick's changes of chunks held at
// full resolution in one call; the replicator answers with one
// UpdateBatch: the changed 4^3 units of every such chunk, joined from
// per-version pieces. Changes of chunks held as mips the world gathers and
// hands over every mip_refresh_ms (mips_changed); they are refreshed
// together (changes in between coalesce), and only when the bytes of the
// level held changed. A chunk held Empty that a move brings within full
// resolution is told to the world as held at full resolution (holds_full).
//
// The client's session (net/client_session.h) does the handshake, pings
// and operators' commands; it hands the replicator the messages about the
// world (ClientReplica) once the client is admitted. The replicator's
// parts each own their state: ViewPlan (the plan, the coarse pass, the
// refine queue), ChunkSlots (what is known of each chunk), HorizonQueue,
// HashRotation (pushed hashes), MipSchedule (refreshes of mips),
// TickUpdate (a tick's UpdateBatch), StreamYield (the stream gate),
// Redirector (shared worlds) and MoveLimit (the speed limit).
//
// Threading: every member runs on the session's strand. The WorldClient
// methods are called on the world strand and post here. Lifetime: shared;
// kept by the world (until leave) and by the client session.
#pragma once

#include <asio.hpp>
#include <chrono>
#include <cstdint>
#include <deque>
#include <memory>
#include <string>
#include <vector>

#include "common/world/world_store.h"
#include "protocol/stream_batch.h"
#include "server/base/rate_limit.h"
#include "server/net/limits.h"
#include "server/net/client_session.h"
#include "server/net/session.h"
#include "server/replication/chunk_slot.h"
#include "server/replication/hash_rotation.h"
#include "server/replication/horizon_queue.h"
#include "server/replication/mip_schedule.h"
#include "server/replication/move_limit.h"
#include "server/replication/redirector.h"
#include "server/replication/replication_options.h"
#include "server/replication/stream_gate.h"
#include "server/replication/stream_out.h"
#include "server/replication/stream_yield.h"
#include "server/replication/tick_update.h"
#include "server/replication/update_faults.h"
#include "server/replication/view_plan.h"
#include "server/replication/view_table.h"
#include "server/storage/cluster_map.h"
#include "server/world/world_owner.h"

namespace terrane {

// What every client is told at the handshake (the parts that do not vary).
struct WelcomeTemplate {
  WelcomeMsg welcome;
  WorldBounds bounds;
};

class Replicator : public WorldClient, public ClientReplica, public std::enable_shared_from_this<Replicator> {
 public:
  // Outstanding requests to the world at most.
  static constexpr std::size_t kMaxRequests = 96;
  // A chunk held is released when it is more than this beyond the view
  // distance (in view's terms: d^2 > (view + margin)^2), not as soon as it
  // leaves the view: a client moving back and forth across a chunk's edge
  // would otherwise have the view's shell released and streamed again at
  // each crossing. Chunks are asked for only in view.
  static constexpr std::int32_t kKeepMargin = kChunkSize;

  // options: the replication room's (the edit rate and the mips' refresh
  // period are the world's: world.options()). cluster_options: this
  // server's id, the lease and the redirect margin, read by redirects.
  // cluster: who writes which region, in a world shared by several
  // servers (null: one server, no redirects). faults: the test seam of
  // UpdateBatches (null but in tests). The references outlive this.
  Replicator(ClientId id, WorldOwner& world, const ReplicationOptions& options,
             const ClusterOptions& cluster_options, ServerCounters& counters, const WelcomeTemplate& welcome,
             const StreamGate& gate, const ClusterDirectory* cluster = nullptr, UpdateFaults* faults = nullptr);
  // Before any message: the session this replicator speaks through.
  void attach(std::shared_ptr<Session> session);

  // ClientReplica (session strand).
  void join(const std::string& name, bool identified, std::uint32_t features) override;
  bool move(const ClientStateMsg& state) override;
  void edit(EditRequestMsg edit) override;
  void read_box(const ReadBoxMsg& req) override;
  void holdings(const HoldingsMsg& held) override;
  void hash_request(Vec3i chunk_pos) override;
  void drained() override;
  void closed() override;

  // WorldClient (world strand; each posts to the session strand).
  void granted(std::vector<VersionPtr> versions) override;
  void horizons(std::vector<HorizonPtr> images) override;
  void committed(std::uint64_t tick, std::vector<VersionPtr> changed) override;
  void mips_changed(std::uint64_t tick, std::vector<VersionPtr> changed) override;
  void answer(WorldAnswer answer) override;
  void close(CloseReason why, const std::string& text) override;

 private:
  void replan();
  // Asks the world for the horizon images of the new plan's regions.
  void plan_horizon();
  void on_horizons(std::vector<HorizonPtr> images);
  // One image as a Horizon record, for the chunks of its region in view
  // that the client has nothing of.
  void send_horizon(const HorizonPtr& image);
  void move_by(Vec3i d);
  void release_outside_view();
  // A chunk leaving the view: released on both sides (its claim, what is
  // held, a grant waiting to be sent), its request cancelled; appends it
  // to released when the world must be told.
  void leave(Vec3i chunk_pos, std::vector<Vec3i>& released);
  // Whether chunk_pos, held, is coarser than the plan wants it.
  bool needs_refining(Vec3i chunk_pos) const;
  // Chunks held as Empty whose change waits for the next flush of mips and
  // that a move brought within full resolution: sent whole at once, since
  // the client may now edit there and the next tick's units change the
  // revision it has not seen.
  void send_parked_near();
  // A client the Redirector sends to another server is sent a Redirect
  // there; its streaming stops (updates go on until it leaves).
  void maybe_redirect();
  // Sends v whole (Full, or Empty) and holds it at full resolution; a
  // refresh parked for the chunk is dropped.
  void send_whole(Vec3i chunk_pos, const VersionPtr& v);

  void on_granted(std::vector<VersionPtr> versions);
  // mips_due: the world's news of chunks held coarser than full
  // resolution, gathered for mip_refresh_ms (WorldClient::mips_changed):
  // refreshed now, and not newer than what is held, possibly (a chunk
  // granted again meanwhile), when it is dropped.
  void on_committed(std::uint64_t tick, std::vector<VersionPtr> changed, bool mips_due = false);
  void pump();
  void request_more();
  void send_ready();
  // v's encoding at level (a record that shares it, not a copy).
  void send_chunk(const VersionPtr& v, int level);
  void hold(Vec3i chunk_pos, Holding h, const VersionPtr& v);
  void refresh_mip(Vec3i chunk_pos, const VersionPtr& v);
  void flush_mips();
  // Flushes the refreshes of mips once due, unless streaming yields (then
  // they wait, and coalesce, kYieldAtMost past their time at most).
  void flush_mips_when_due(std::chrono::steady_clock::time_point now);
  // owner: what keeps payload alive (the version whose encoding it is),
  // so the record shares it (StreamBatchWriter).
  void stream(StreamRecordKind kind, Vec3i chunk_pos, std::uint64_t revision,
              std::span<const std::uint8_t> payload = {}, const VersionPtr& owner = nullptr) {
    out_.record(kind, chunk_pos, revision, payload, owner);
  }
  void flush_stream();
  void answer_hash(Vec3i chunk_pos);
  void arm_timer();
  void on_timer();

  const ClientId id_;
  WorldOwner& world_;
  const ReplicationOptions& options_;
  ServerCounters& counters_;
  const WelcomeTemplate& welcome_;
  UpdateFaults* const faults_;
  // Whether streaming waits for the stream gate.
  StreamYield yield_;
  // Whether the client was sent a Redirect: nothing more is streamed until
  // it leaves, or Redirector::kRedirectGrace passes.
  Redirector redirect_;
  // session_ is used on the session strand only and dropped when the
  // session closes (it and the session's callbacks keep each other alive);
  // the world strand reaches the session through weak_session_ and posts to
  // executor_.
  std::shared_ptr<Session> session_;
  std::weak_ptr<Session> weak_session_;
  asio::any_io_executor executor_;
  std::unique_ptr<asio::steady_timer> timer_;

  bool joined_ = false;
  bool mip_patches_ = false;  // refresh mips as patches (the client takes them, the server allows them)
  bool outer_horizon_ = false;  // level-6 horizon images beyond kHorizonFarMax (the client takes them)
  bool codec1_ = false;         // the client reads only network codec version 1 (no kFeatureCodec2)
  bool closed_ = false;
  std::string name_;
  ClientStateMsg state_;
  MoveLimit move_limit_;
  TokenBucket edit_rate_, outbound_;

  // The plan: the view around the client's chunk, the coarse pass's
  // cursor and the refine queue.
  ViewPlan plan_;

  // What is known of each chunk for this client (ChunkSlot): what it holds
  // of it (its own record: an Estimate's is replaced by the chunk's exact
  // mip whatever the revisions say) or has from a horizon image (released
  // when it leaves the view), the version of a chunk held Full (chunk
  // hashes, pushed and answered here), the outstanding request to the
  // world, the grant not yet sent, a resuming client's claim and the change
  // waiting for the next refresh of mips.
  ChunkSlots slots_;
  // The horizon images this plan asked for, sent nearest region first;
  // streaming's first pass waits until none is to come.
  HorizonQueue horizon_;
  // Chunks held Full with a version, for the pushed hashes in turn.
  HashRotation hashes_;
  // Granted, not yet sent (the window or budget was full), oldest first
  // (an entry left by a grant dropped since is skipped when reached).
  std::deque<Vec3i> ready_;
  std::vector<Vec3i> hash_requests_;  // for claims not yet adopted or resent
  // The stream batch being filled; it sends through the session (counted,
  // spent from outbound_).
  StreamOut out_{[this] { return session_ != nullptr; },
                 [this](OutFrame f) {
                   outbound_.spend(static_cast<double>(f.size()));
                   counters_.stream_bytes.fetch_add(f.size(), std::memory_order_relaxed);
                   session_->send(std::move(f));
                 }};
  // When and in which order the changes parked for the refresh of mips
  // (each slot's newest) go out.
  MipSchedule mips_;
  bool timer_armed_ = false;
};

}  // namespace terrane
