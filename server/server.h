// Server: the authoritative Terrane world server (asio over TCP).
//
// Threading (the whole story):
//   - io threads (ServerOptions::io_threads) run one asio::io_context.
//   - Each Session runs on its own strand: socket I/O, frame verification,
//     message parsing, Pong replies (server/session.h).
//   - The world owner strand owns everything about the world: the World and
//     its store (one SQLite connection), the ChunkCache (Grid + revisions),
//     the peer table (per-client interest, what each client holds), the
//     pending edits and the tick timer. Sessions post parsed messages to it;
//     it posts frames back through Session::send. Nothing here takes a lock.
//   - A worker pool (ServerOptions::worker_threads) generates chunks missing
//     from the store and posts them back to the owner strand.
//   - Counters are atomics, readable from any thread.
// stop() (any thread but an io thread) closes the acceptor and every
// session, waits for the workers and io threads, and leaves the world saved:
// edits are persisted at the tick that applies them.
//
// Tick (every 1/tick_hz s, on the owner strand): apply the tick's edits in
// arrival order, persist every changed chunk in one transaction, then send
// EditAck to the editors and broadcast: one UpdateBatch per changed chunk
// (encoded once, the same bytes to every client holding it at full
// resolution) and the refreshed mip to clients holding a mip. Then stream.
//
// Streaming (server/streaming.cpp): per client, the chunks within its view
// distance, nearest first. First pass: every chunk gets its coarsest form
// (Coverage Empty, or the 4^3 mip). Second pass, nearest first: mip 2/1 by
// distance, and inside the full-resolution radius the eight 16^3 ChunkData
// units then Coverage Full. Chunks leaving the view get Coverage Released.
// A client's queue is only topped up to stream_window_bytes (again each time
// it drains, and every tick), so updates wait behind at most that much
// streaming data; edit acks and rejects go ahead of it (SendClass::kControl).
#pragma once

#include <asio.hpp>
#include <atomic>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <unordered_map>
#include <vector>

#include "common/world.h"
#include "protocol/messages.h"
#include "protocol/stream_batch.h"
#include "server/chunk_cache.h"
#include "server/edits.h"
#include "server/limits.h"
#include "server/session.h"

namespace terrane {

struct ServerOptions {
  std::string world_dir;                // created with default_world_meta() when missing
  std::string bind_address = "127.0.0.1";
  std::uint16_t port = 0;               // 0: any free port (see port())
  std::uint32_t tick_hz = 20;
  std::int32_t max_view_distance = 1024;   // voxels; client requests are capped to this
  std::int32_t max_full_res_radius = 256;  // voxels
  std::int32_t default_view_distance = 1024;   // until the client sends ClientState
  std::int32_t default_full_res_radius = 128;
  std::size_t max_clients = 1024;
  std::size_t stream_window_bytes = 512 * 1024;
  std::size_t max_edits_queued_per_client = 64;
  // Chunks a resuming client may claim (Holdings) in all.
  std::size_t max_claims_per_client = 65536;
  // Presence: how often (0 = never) and how many of the nearest clients.
  std::uint32_t presence_hz = 2;
  std::size_t presence_max_entries = 32;
  // Each client is sent the hash of one of its full-resolution chunks this
  // often (0 = only on request).
  std::uint32_t hash_push_ms = 1000;
  // Encoded chunk and mip frames kept for reuse across clients.
  std::size_t encode_cache_bytes = 64u << 20;
  // Loaded chunks kept even when no client holds them; beyond this, chunks
  // nobody holds are unloaded (about once a second).
  std::size_t resident_chunks = 4096;
  SessionLimits session;
  int io_threads = 1;
  int worker_threads = 2;
  // Authentication (checked at the handshake): per-player tokens (name ->
  // token, from a tokens file) take precedence over one shared token; with
  // neither the server is open, which it allows only on a loopback address
  // unless allow_open says otherwise.
  std::string auth_token;
  std::unordered_map<std::string, std::string> player_tokens;
  bool allow_open = false;
  // Per-client limits (0 = unlimited where a rate). A flood of edits beyond
  // the burst (edits_per_second * 2) or a move faster than max_speed (plus
  // kSpeedSlackVoxels) disconnects the client; an edit over
  // max_edit_voxels is rejected.
  double edits_per_second = 20;
  std::int64_t max_edit_voxels = kMaxEditVolume;
  double max_speed = 256;                    // voxels per second
  double outbound_bytes_per_second = 32 << 20;  // streaming; updates are never held back
  // Undo and redo history kept per client, in bytes (oldest steps go first).
  std::size_t history_bytes_per_client = 4u << 20;
  // Called (on the owner strand) when the server cannot go on, e.g. the
  // store refused a tick's changes; the owner of the Server should stop it.
  std::function<void()> on_fatal;
  // Test-only fault: silently skip sending this many UpdateBatch frames
  // (the client's revision still advances on the server's books).
  int fault_drop_updates = 0;
  // Test-only fault: send this many UpdateBatch frames with one voxel wrong.
  int fault_corrupt_updates = 0;
};

// Movement allowed beyond max_speed * elapsed time between two positions
// (network jitter bunches ClientState messages together).
inline constexpr double kSpeedSlackVoxels = 48;

struct ServerCounters {
  std::atomic<std::uint64_t> sessions_accepted{0};
  std::atomic<std::uint64_t> sessions_closed{0};
  std::atomic<std::uint64_t> ticks{0};
  std::atomic<std::uint64_t> edits_applied{0};
  std::atomic<std::uint64_t> edits_rejected{0};
  std::atomic<std::uint64_t> chunks_sent{0};     // full-resolution chunks (8 units each)
  std::atomic<std::uint64_t> mips_sent{0};
  std::atomic<std::uint64_t> empties_sent{0};
  std::atomic<std::uint64_t> update_batches_sent{0};
  std::atomic<std::uint64_t> updates_dropped_by_fault{0};
  std::atomic<std::uint64_t> updates_corrupted_by_fault{0};
  std::atomic<std::uint64_t> stream_bytes{0};    // ChunkData/MipData/Coverage bytes queued
  std::atomic<std::uint64_t> presence_sent{0};
  std::atomic<std::uint64_t> hashes_pushed{0};
  std::atomic<std::uint64_t> chunks_unloaded{0};
  std::atomic<std::uint64_t> encode_cache_hits{0};
  std::atomic<std::uint64_t> encode_cache_misses{0};
  std::atomic<std::uint64_t> limit_violations{0};
  std::atomic<std::uint64_t> auth_failures{0};
  std::atomic<std::uint64_t> chunks_resumed{0};  // claimed by a resuming client, still current, not resent
  TrafficCounters traffic;
};

class Server {
 public:
  // Opens (or creates) the world and binds the listening socket. Nothing
  // runs until start().
  static FileResult<std::unique_ptr<Server>> create(const ServerOptions& options);
  ~Server();
  Server(const Server&) = delete;
  Server& operator=(const Server&) = delete;

  void start();
  // Idempotent; see the threading note above.
  void stop();

  std::uint16_t port() const { return port_; }
  const std::string& address() const { return options_.bind_address; }
  const ServerCounters& counters() const { return counters_; }
  const ServerOptions& options() const { return options_; }
  // True once a tick's changes could not be saved (the server stopped serving).
  bool storage_failed() const { return storage_failed_flag_.load(); }

  // Runs fn on the owner strand with the authoritative cache and waits for
  // it (tests, tools). Must not be called from an io thread.
  void inspect(const std::function<void(const ChunkCache&)>& fn);

 private:
  enum class HeldKind : std::uint8_t { kEmpty, kMip, kFull };
  struct Held {
    HeldKind kind = HeldKind::kEmpty;
    int level = 0;  // kMip: 1..3
    std::uint64_t revision = 0;
  };
  // The owner strand's view of one client.
  // One step of a client's edit history: a box and its voxels before and
  // after (byte RLE, as the storage article keeps undo data).
  struct HistoryEntry {
    Region box;
    std::vector<std::uint8_t> before, after;
    std::size_t bytes() const { return before.size() + after.size() + sizeof(HistoryEntry); }
  };
  struct Peer {
    std::shared_ptr<Session> session;
    std::deque<HistoryEntry> undo, redo;
    std::size_t history_bytes = 0;
    std::string name;
    bool welcomed = false;
    ClientStateMsg state;
    // The plan: chunks in view, nearest first, and the two pass cursors.
    bool plan_valid = false;
    Vec3i plan_chunk;
    std::int32_t plan_view = -1, plan_full = -1;
    std::vector<Vec3i> plan;
    std::size_t coarse = 0, refine = 0;
    std::unordered_map<Vec3i, Held, Vec3iHash> held;
    std::vector<Vec3i> hash_requests;
    std::size_t edits_queued = 0;
    std::vector<PresenceEntryMsg> presence;  // last sent
    std::size_t hash_cursor = 0;             // next plan index for pushed hashes
    // Streaming records not yet sent. Every owner-strand handler that adds
    // records flushes them before it returns, so data frames sent directly
    // (updates, hashes, read results) keep their order after them.
    StreamBatchWriter batch;
    // What a resuming client says it still holds (Holdings): adopted without
    // sending when the revision is still current, released when out of view.
    std::unordered_map<Vec3i, Held, Vec3iHash> claims;
    TokenBucket edit_rate;
    TokenBucket outbound;
    bool moved = false;  // a position was reported (the first one is where the client joins)
    std::chrono::steady_clock::time_point moved_at;
  };
  struct PendingEdit {
    std::uint64_t peer_id;
    EditRequestMsg edit;
  };

  explicit Server(const ServerOptions& options);
  // Where clients start: above the generated surface at the origin, or for
  // worlds without a generator above the centre of the stored chunks.
  static Vec3f find_spawn(World& world);

  // server.cpp: lifecycle, accept, handshake
  void do_accept();
  void on_inbound(std::uint64_t id, InboundMessage msg);  // owner strand
  void on_session_closed(std::uint64_t id, const std::string& reason);
  void on_hello(Peer& peer, const HelloMsg& hello);
  void arm_tick();
  void on_tick();
  void schedule_pump();
  void log_stats();  // one summary line (every 10 s and at stop)

  // streaming.cpp: interest management
  void on_client_state(Peer& peer, const ClientStateMsg& state);
  void replan(Peer& peer);
  void pump(Peer& peer);
  void pump_stream(Peer& peer);  // pump's streaming passes; the caller flushes
  void pump_all();
  int desired_level(const Peer& peer, Vec3i chunk_pos) const;
  void send_coarse(Peer& peer, Vec3i chunk_pos);
  void on_holdings(Peer& peer, const HoldingsMsg& h);
  // Adopts peer's claim on chunk_pos if still current; true if adopted.
  bool adopt_claim(Peer& peer, Vec3i chunk_pos);
  void send_level(Peer& peer, Vec3i chunk_pos, int level);
  // Appends a record to the client's stream batch (sent by flush_stream,
  // or at once when the batch is full).
  void stream(Peer& peer, StreamRecordKind kind, Vec3i chunk_pos, std::uint64_t revision,
              std::span<const std::uint8_t> payload = {});
  void flush_stream(Peer& peer);
  // Interest counts: how many clients hold each chunk (chunks nobody holds
  // may be unloaded).
  void hold(Peer& peer, Vec3i chunk_pos, Held h);
  void release(Vec3i chunk_pos);
  void unload_unwatched();
  struct EncodeKey {
    Vec3i chunk_pos;
    int level;
    friend bool operator==(const EncodeKey&, const EncodeKey&) = default;
  };
  struct EncodeKeyHash {
    std::size_t operator()(const EncodeKey& k) const noexcept {
      return Vec3iHash{}(k.chunk_pos) ^ (static_cast<std::size_t>(k.level) * 0x9E3779B97F4A7C15ull);
    }
  };
  // A chunk's encoded voxels at one level and revision: level 0 holds the
  // eight 16^3 units in unit index order, mip levels one unit.
  struct EncodedChunk {
    std::uint64_t revision = 0;
    std::vector<std::uint8_t> payload;
  };
  const EncodedChunk& encoded(Vec3i chunk_pos, int level);

  void serve_hash_requests(Peer& peer);
  std::uint64_t chunk_hash(Vec3i chunk_pos);

  // edits.cpp: edits, persistence, broadcast
  void on_edit(Peer& peer, EditRequestMsg edit);
  void reject_edit(Peer& peer, const EditRequestMsg& edit, const std::string& reason);
  // Applies the top of peer's undo (or redo) history; false with *why set
  // when there is nothing to apply or it lies outside the full-resolution
  // region.
  bool apply_history(Peer& peer, bool redo, ChangedUnits& changed, std::string* why);
  void push_history(Peer& peer, std::deque<HistoryEntry>& to, HistoryEntry e);
  std::vector<std::uint8_t> snapshot(const Region& box);  // byte RLE of the box's voxels
  bool holds_full(const Peer& peer, const Region& region) const;

  // queries.cpp: read box, presence, region hashes
  void on_read_box(Peer& peer, const ReadBoxMsg& req);
  void send_presence();
  void push_region_hashes();
  void apply_edits();

  ServerOptions options_;
  ServerCounters counters_;
  std::unique_ptr<World> world_;
  asio::io_context io_;
  asio::executor_work_guard<asio::io_context::executor_type> work_;
  ChunkCache::Strand owner_;
  asio::ip::tcp::acceptor acceptor_;
  asio::steady_timer tick_timer_;
  asio::thread_pool workers_;
  std::unique_ptr<ChunkCache> cache_;
  std::vector<std::thread> threads_;
  std::uint16_t port_ = 0;
  std::atomic<bool> stopped_{false};
  bool started_ = false;

  // Owner strand only.
  std::unordered_map<std::uint64_t, Peer> peers_;
  std::deque<PendingEdit> edits_;
  std::uint64_t tick_ = 0;
  std::uint64_t next_session_id_ = 1;
  bool pump_scheduled_ = false;
  std::chrono::steady_clock::time_point stats_at_ = std::chrono::steady_clock::now();
  std::uint64_t stats_edits_ = 0, stats_sent_ = 0, stats_received_ = 0;
  bool stopping_ = false;
  bool storage_failed_ = false;
  std::atomic<bool> storage_failed_flag_{false};
  int faults_left_ = 0;
  int corruptions_left_ = 0;
  Vec3f spawn_;
  std::unordered_map<Vec3i, std::pair<std::uint64_t, std::uint64_t>, Vec3iHash> hash_cache_;  // revision, hash
  std::unordered_map<Vec3i, std::uint32_t, Vec3iHash> interest_;
  std::unordered_map<EncodeKey, EncodedChunk, EncodeKeyHash> encode_cache_;
  std::deque<EncodeKey> encode_order_;
  std::size_t encode_cache_bytes_ = 0;
};

}  // namespace terrane
