// The server's options, shared read-only by every room: net, world,
// storage and replication (their counters: server/base/counters.h).
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <string>
#include <unordered_map>

#include "protocol/messages.h"
#include "server/base/counters.h"

namespace terrane {

// A player of the tokens file (server/net/limits.h reads it).
struct PlayerToken {
  std::string token;
  bool admin = false;  // may run terrane-admin commands
};

// One session's limits (server/net/session.h applies them).
struct SessionLimits {
  std::size_t max_frame_bytes = kDefaultMaxFrameBytes;
  // Hard cap on queued outbound bytes: a client this far behind is dropped.
  std::size_t max_queue_bytes = 16u << 20;
  std::chrono::milliseconds handshake_timeout{5000};
  std::chrono::milliseconds idle_timeout{30000};
  // A write that makes no progress for this long drops the client.
  std::chrono::milliseconds write_timeout{10000};
  std::chrono::milliseconds linger{1000};
  // A frame whose first byte arrived must be complete within this (a
  // slowloris trickling one frame forever is dropped).
  std::chrono::milliseconds frame_timeout{10000};
  // Inbound bytes per second per client (0 = unlimited) and the burst
  // allowed above it.
  double inbound_bytes_per_second = 1 << 20;
  double inbound_burst_bytes = 4 << 20;
  // SO_SNDBUF for client sockets; 0 keeps the OS default. A small buffer
  // makes a stalled reader visible sooner (and bounds kernel memory).
  int socket_send_buffer_bytes = 0;
  ServerCounters* counters = nullptr;  // not owned; may be null
};

struct ServerOptions {
  std::string world_dir;                // created with default_world_meta() when missing
  // The world in PostgreSQL instead ("postgresql://HOST:PORT/DB", with
  // world_dir empty), shared with other servers: server/storage/
  // STORE_POSTGRESQL.md. Created with default_world_meta() when the
  // database holds none.
  std::string store_url;
  std::uint32_t server_id = 0;          // this server in a PostgreSQL world (below 2^31)
  std::chrono::milliseconds lease{5000};  // a region lease's length; renewed every tenth of it
  // Where clients reach this server ("HOST:PORT"), told to the other
  // servers of a PostgreSQL world; empty: the bind address and the port
  // listened on (none when bound to every address).
  std::string advertise;
  // A client standing this many voxels or more inside a region another
  // server writes (from every face of the 256^3 region) is redirected there
  // (PROTOCOL.md, "Redirects"); 0 never. At most 128 (half a region).
  std::int32_t redirect_margin = 32;
  std::string bind_address = "127.0.0.1";
  std::uint16_t port = 0;               // 0: any free port (see port())
  // The operator's HTTP endpoint (/metrics, /health): "HOST:PORT", empty =
  // none; port 0 picks a free one (see metrics_port()).
  std::string metrics_address;
  // A world border to set (persisted in the world): nothing is generated,
  // streamed or editable beyond it. border_set with !bounded_xz removes one.
  bool border_set = false;
  WorldBounds border;
  // An edit waits for the next tick, up to one period: at 60 Hz a sixth of
  // the 100 ms an edit may take to reach every holder, at 30 Hz a third.
  // (World 1,000 on 2 cores, median of 3: fan-out p50 47.5 -> 24.2 ms,
  // p99 175.8 -> 140.0 ms from 30 to 60 Hz, the server's CPU unchanged.)
  std::uint32_t tick_hz = 60;
  std::int32_t max_view_distance = 1024;   // voxels; client requests are capped to this
  std::int32_t max_full_res_radius = 256;  // voxels
  std::int32_t default_view_distance = 1024;   // until the client sends ClientState
  std::int32_t default_full_res_radius = 128;
  std::size_t max_clients = 1024;
  std::size_t stream_window_bytes = 512 * 1024;
  // Streaming yields when work waits longer than this on the io threads or
  // the world strand (replication/stream_gate.h); 0: it never yields.
  std::chrono::milliseconds stream_yield{20};
  std::size_t max_edits_queued_per_client = 64;
  // Chunks a resuming client may claim (Holdings) in all.
  std::size_t max_claims_per_client = 65536;
  // Presence: how often (0 = never) and how many of the nearest clients.
  std::uint32_t presence_hz = 2;
  std::size_t presence_max_entries = 32;
  // Each client is sent the hash of one of its full-resolution chunks this
  // often (0 = only on request).
  std::uint32_t hash_push_ms = 1000;
  // Chunks a client holds as mips are refreshed at most this often, with
  // their newest version (0: at the tick that changed them).
  std::uint32_t mip_refresh_ms = 500;
  // Chunks kept loaded beyond those someone holds at full resolution or is
  // editing (about once a second the least recently used of the rest go;
  // they come back from the store).
  std::size_t resident_chunks = 32768;
  // A distant chunk never generated is first sent as an estimate of its
  // coarsest mip (World::estimate_coarse), then generated in the background
  // and corrected; false: generated whole before its mip is sent.
  bool horizon_estimates = true;
  // A new view's first pass: every region of it as one horizon image (2^3
  // or 1 voxel per chunk), before any chunk's own coarsest mip.
  bool horizon_images = true;
  SessionLimits session;
  int io_threads = 2;
  // Niceness by thread role (server/base/thread_role.h): the loaders below the
  // rest.
  bool thread_priorities = true;
  // Loader threads: reading stored chunks and generating missing ones.
  int worker_threads = 2;
  // Authentication (checked at the handshake): per-player tokens (name ->
  // token, from a tokens file) take precedence over one shared token; with
  // neither the server is open, which it allows only on a loopback address
  // unless allow_open says otherwise.
  std::string auth_token;
  std::unordered_map<std::string, PlayerToken> player_tokens;
  // Whoever gives this token joins as an admin (terrane-admin), whatever
  // the name; empty = admins only through the tokens file's roles.
  std::string admin_token;
  // Called (any thread) when an operator asked the server to stop
  // (terrane-admin shutdown) and the warning time is up; the owner of the
  // Server should stop it, as on SIGTERM.
  std::function<void()> on_shutdown;
  bool allow_open = false;
  // Per-client limits (0 = unlimited where a rate). A flood of edits beyond
  // the burst (edits_per_second * 2) or a move faster than max_speed (plus
  // kSpeedSlackVoxels) disconnects the client; an edit over
  // max_edit_voxels is rejected.
  double edits_per_second = 20;
  std::int64_t max_edit_voxels = kMaxEditVolume;
  double max_speed = 256;                    // voxels per second
  double outbound_bytes_per_second = 32 << 20;  // streaming; updates are never held back
  // The edit log (who changed what, for terrane-admin log and rollback)
  // keeps entries this many days and this many MiB of voxels (0: no bound).
  std::uint32_t edit_log_days = 30;
  std::uint32_t edit_log_mb = 1024;
  // Undo and redo history kept per client, in bytes (oldest steps go first).
  std::size_t history_bytes_per_client = 4u << 20;
  // Called (on the world strand) when the server cannot go on, e.g. the
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

}  // namespace terrane
