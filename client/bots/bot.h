// One bot: a Client in shared mode (client/client.h) plus a behaviour
// (client/bots/options.h describes them), join tracking, edits at ray-cast
// targets and region-hash verification.
//
// Threading: the driver thread calls every public method; the client's
// callbacks run on the io pool. State both touch (join progress, pending
// hash checks, outstanding edits, disconnects) sits behind mutex_, which is
// never held while calling into the Client except counters() and
// with_replica() from a callback, for the join (order: Bot::mutex_, then the
// Client's lock).
#pragma once

#include <array>
#include <memory>
#include <mutex>
#include <optional>
#include <random>
#include <span>
#include <string>
#include <unordered_map>
#include <vector>

#include "client/bots/options.h"
#include "client/bots/stats.h"
#include "client/decoded_chunks.h"
#include "client/client.h"
#include "client/view_coverage.h"

namespace terrane::bots {

// Read-only run context shared by every bot.
struct RunContext {
  const BotsOptions* options = nullptr;
  WelcomeMsg welcome;
  std::int32_t view_distance = 0;    // after the server's caps
  std::int32_t full_res_radius = 0;  // after the server's caps
  Vec3f spawn;
  asio::io_context* io = nullptr;
  FanoutTracker* fanout = nullptr;
  LatencyLog* round_trips = nullptr;
  MismatchLog* mismatches = nullptr;
  std::shared_ptr<DecodedChunks> shared_chunks;  // null: --shared-chunks 0
  std::shared_ptr<ChunkCache> chunk_cache;       // null: no --chunk-cache
  Clock::time_point run_start;
};

// A bot's way of moving about (the client's own position and view are
// client/movement.h's Movement). kTeleport: jumps (options.h); kHotspot:
// flies to the spawn, lands there and stays.
enum class Gait : std::uint8_t { kIdle, kWalk, kFly, kTeleport, kHotspot };
enum class EditMode : std::uint8_t { kNone, kDig, kBuild, kBoth };

struct BotResult {
  bool connected = false;
  std::string connect_error;
  std::optional<double> join_coarse_ms, join_full_ms;
  std::uint64_t join_bytes = 0;          // received from connect until the full-resolution region was complete
  std::uint64_t join_coarse_bytes = 0;  // bytes received when the coarse view was complete
  std::uint64_t join_non_empty_voxels = 0;
  // Bytes received by cause (ByteCause) when the join completed, and the
  // seconds from then until the bot finished: its steady state.
  std::array<std::uint64_t, kByteCauseCount> join_bytes_by_cause{};
  double steady_s = 0;
  std::uint64_t hash_checked = 0, hash_unanswered = 0;
  std::uint64_t walk_steps = 0;
  // Steps refused: [0] outside the area, [1] ground not held at full resolution,
  // [2] too steep, [3] something solid in the way.
  std::array<std::uint64_t, 4> walk_blocked{};
  int checks_during_run = 0;
  double distance_moved = 0;
  std::uint64_t teleports = 0;     // jumps made (Gait::kTeleport)
  // Edits that fell due while 8 of the bot's were unanswered, not sent
  // (the only way replies hold edits back: bot.cpp kMaxOutstandingEdits).
  std::uint64_t edits_held_back = 0;
  bool at_hotspot = false;         // landed at the hotspot (Gait::kHotspot)
  bool unexpected_disconnect = false;
  std::string disconnect_reason;
  ClientCounters counters;
  std::uint32_t server_id = 0;  // the server of its last Welcome (several servers: where redirects left it)
};

class Bot {
 public:
  Bot(int index, const RunContext& ctx, Vec3f start, Gait gait, EditMode edits, std::uint64_t seed);
  ~Bot();
  Bot(const Bot&) = delete;
  Bot& operator=(const Bot&) = delete;

  // The bot's id: its number among all the scenario's bots.
  int index() const { return index_; }
  bool connect();
  // One behaviour step (every 100 ms): movement, edits, scheduled checks,
  // hash retries. active: moving and editing allowed.
  void step(Clock::time_point now, bool active);
  bool joined() const;
  std::size_t outstanding_edits() const;
  // Final verification: every chunk of the full-resolution region held.
  void start_final_check();
  bool checks_pending(Clock::time_point now);
  void finish();  // disconnect (expected) and take the final counters
  bool closed() const;
  // Nothing more to wait for in its join: joined, closed, or its connect
  // failed (counted as a connect failure; it never tries again).
  bool join_settled() const;
  ClientCounters counters() const;
  ReplicaMemory replica_memory() const;
  const BotResult& result() const { return result_; }
  bool connected() const { return result_.connected; }

 private:
  struct PendingHash {
    int attempts = 0;
    Clock::time_point sent_at;
    std::optional<Clock::time_point> retry_at;
    bool final_check = false;
  };

  // What the bot holds of chunks changed (or was released), a batch at once:
  // the fan-out tracker and join progress.
  void on_holdings(std::span<const HoldingChange> changes);
  void on_chunk_hash(const HashCheck& check);
  void on_disconnected(const std::string& reason);
  // Under mutex_: reads the join count; drops it once both join times are known.
  void check_join(Clock::time_point now);
  void count_join_voxels();
  void move(Clock::time_point now);
  void walk();
  void fly();
  void teleport(Clock::time_point now);
  void converge();
  // Whether the bot edits now: a hotspot bot only once it stands there.
  bool edits_now() const;
  void maybe_edit(Clock::time_point now);
  // write_box's voxels for box (Box order): a hut of layered materials
  // with windows (build), or air (dig).
  static std::vector<Voxel> hut_voxels(const Region& box, bool dig);
  void schedule_check(Clock::time_point now);
  void request_hash(Vec3i cp, bool final_check);  // takes mutex_
  bool held_full(Vec3i cp) const;
  bool in_area(float x, float z, float half) const;
  Vec3i voxel_at(Vec3f p) const;

  const int index_;
  const RunContext& ctx_;
  Gait gait_;
  EditMode edits_mode_;
  std::mt19937_64 rng_;
  std::unique_ptr<Client> client_;
  Vec3f pos_;
  float heading_ = 0;
  bool landed_ = false;
  int stuck_steps_ = 0;  // walk steps refused in a row
  int steps_ = 0;
  bool state_dirty_ = false;
  Clock::time_point connect_at_;
  Clock::time_point next_edit_, next_check_;
  Clock::time_point next_teleport_;
  bool over_hotspot_ = false;  // kHotspot: above the spawn, landing
  int checks_done_ = 0;
  BotResult result_;

  mutable std::mutex mutex_;
  // Join tracking: the view at the start (the bot does not move before it
  // joined), counted holding change by holding change until the bot has
  // joined and holds its whole view coarsely; then dropped.
  StreamedView join_view_;
  std::optional<ViewCoverageCounter> join_count_;
  bool joined_ = false;
  Clock::time_point joined_at_;  // when joined_ became true
  bool voxels_counted_ = false;
  std::unordered_map<Vec3i, PendingHash, Vec3iHash> pending_hash_;
  std::size_t outstanding_edits_ = 0;
  bool closing_ = false;
};

}  // namespace terrane::bots
