// Client: the facade an application uses to talk to a terrane-server: it
// wires the owners together and answers queries. It owns what the server's
// messages leave behind (the Welcome, counters, notices, presence, hash
// checks, read and admin results) and guards its owners' state:
//   Connection   (client/connection.h): socket, handshake, framing,
//                keepalive, reconnect and Redirects; the io side.
//   Replica      (client/replica.h): the holdings and voxels received.
//   EditTracker  (client/edit_tracker.h): edit ids, outstanding edits and
//                their outcomes.
//   Movement     (client/movement.h): position, view distance,
//                full-resolution radius; the ClientState frames.
//
// Threading: the Connection's io side (its own thread, or a strand of
// ClientOptions::io_context: many clients, few threads, the bots) verifies
// and parses every frame (bytes from the server are treated as hostile: any
// bad frame closes the connection) and applies it; one client's handlers
// never run concurrently. The Replica, the EditTracker, the Movement and
// the results sit behind one mutex because the application queries them
// from its own threads; the io side holds it only while applying one
// frame. Callbacks run on the io side without the lock held: they may call
// any Client method except disconnect() and wait_until(). Every public
// method is thread-safe. In shared mode connect(), disconnect() and
// wait_until() block, so they must not be called from the shared
// io_context's threads, and the io_context must be running while they wait
// and must outlive the Client. The connection's states are drawn in
// client/connection.h; while it waits to reconnect the replica stays as it
// was.
#pragma once

#include <array>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <unordered_map>
#include <unordered_set>

#include "client/client_options.h"
#include "client/connection.h"
#include "client/edit_tracker.h"
#include "client/movement.h"
#include "client/replica.h"
#include "client/view_coverage.h"
#include "protocol/framing.h"
#include "protocol/messages.h"
#include "protocol/presence_records.h"

namespace terrane {

inline constexpr std::size_t kMaxNotices = 32;

// Frames and bytes (length header included) of one message type.
struct MessageTypeCounters {
  std::uint64_t frames_in = 0;
  std::uint64_t bytes_in = 0;
  std::uint64_t frames_out = 0;
  std::uint64_t bytes_out = 0;
};
inline constexpr std::size_t kMessageTypeCount = static_cast<std::size_t>(wire::Body::MAX) + 1;
// The message type's name ("StreamBatch"); "NONE" counts frames that did not
// verify (inbound) or raw bytes (send_raw).
const char* message_type_name(std::size_t type);

// What the bytes a client receives are for: its byte budget. A frame's
// bytes (length header included) go to one cause, a StreamBatch's to the
// causes of its records, each record its own bytes and the frame's own
// bytes (header, table) to the cause with most of the batch's record bytes.
enum class ByteCause : std::uint8_t {
  kStream,     // StreamBatch records giving a chunk a form it did not hold (the view moved or is
               // being refined: new chunks, finer forms, horizon images, Released)
  kRefresh,    // StreamBatch records sending a chunk again in the form it holds (it changed:
               // a mip at its level, a Full or Empty chunk sent whole)
  kUpdate,     // UpdateBatch: the 4^3 units of edits to chunks held at full resolution
  kPresence,   // Presence
  kHash,       // ChunkHash
  kKeepalive,  // Ping and Pong
  kOther,      // the rest: Welcome, EditAck and EditReject, ReadBoxResult, notices, admin
};
inline constexpr std::size_t kByteCauseCount = 7;
// "stream", "refresh", "update", "presence", "hash", "keepalive", "other".
const char* byte_cause_name(std::size_t cause);

struct ClientCounters {
  std::uint64_t frames_in = 0;  // frames handled (by_message_type counts them by type, length header included)
  std::uint64_t bytes_in = 0;  // read from the socket (with emulation: before the emulated link delivers them)
  std::uint64_t chunk_units = 0;  // 16^3 units of Full records applied (8 a record)
  std::uint64_t mips = 0;
  std::uint64_t mip_patches = 0;  // Mip patch records: changed sub-units of a mip held
  std::uint64_t estimates = 0;  // of mips: Estimate records (a chunk's coarsest mip estimated)
  std::uint64_t horizon_chunks = 0;  // chunks first seen through a region's horizon image (not in mips)
  std::uint64_t empty_records = 0;
  std::uint64_t full_records = 0;
  std::uint64_t released = 0;
  std::uint64_t update_batches = 0;
  std::uint64_t units_updated = 0;
  std::uint64_t edits_acked = 0;
  std::uint64_t edits_rejected = 0;
  std::uint64_t hash_matches = 0;
  std::uint64_t hash_mismatches = 0;
  std::uint64_t protocol_errors = 0;
  std::uint64_t pongs = 0;
  // The last keepalive Ping's round trip (-1 before the first answer): from
  // queuing the Ping to handling its Pong, so it counts what waits on both
  // sides (this client's queue and reading, the server's) besides the wire.
  double last_round_trip_ms = -1;
  std::uint64_t reconnects = 0;
  std::uint64_t redirects = 0;  // Redirects followed
  // Chunks the first session took from ClientOptions::chunk_cache (and
  // claimed), and those disconnect() saved to it.
  std::uint64_t cache_chunks_loaded = 0;
  std::uint64_t cache_chunks_saved = 0;
  std::uint64_t presence_updates = 0;
  std::uint64_t read_results = 0;
  std::uint64_t frames_out = 0;
  std::uint64_t bytes_out = 0;  // written to the socket
  // Indexed by wire::Body (message_type_name()).
  std::array<MessageTypeCounters, kMessageTypeCount> by_message_type{};
  // Bytes received by what they were for, indexed by ByteCause (they add
  // up to the bytes of every frame handled).
  std::array<std::uint64_t, kByteCauseCount> bytes_in_by_cause{};
};

// The outcome of one ChunkHash, with what the comparison saw: a client
// that only wants the verdict can use on_hash_checked instead.
struct HashCheck {
  Vec3i chunk_pos;
  std::uint64_t server_revision = 0;
  std::optional<std::uint64_t> replica_revision;  // nullopt: chunk not held
  bool replica_full = false;  // held at full resolution (Full or Empty)
  bool match = false;         // full, same revision, same hash
};

// One UpdateBatch as applied to the replica: its tick, the chunks it
// touched with their new revisions, and per chunk held at full resolution
// the voxel box its changed units cover. With capture_voxel_changes on,
// also the voxels it changed with their values before and after (bounded
// per batch; truncated says some were left out).
struct UpdateInfo {
  std::uint64_t tick = 0;
  std::vector<ChunkRevisionMsg> revisions;
  std::vector<Region> changed;
  bool voxels_recorded = false;  // capture_voxel_changes was on for this batch
  std::vector<VoxelChange> voxels;
  bool voxels_truncated = false;
};

// One chunk's holding change (ClientCallbacks::on_holdings): what the
// replica holds of it now, or nullopt when it was released.
struct HoldingChange {
  Vec3i chunk_pos;
  std::optional<Holding> now;
};

struct ClientCallbacks {
  std::function<void(const WelcomeMsg&)> on_welcome;
  // What the replica holds of a chunk changed: its holding now (a record
  // of its own, or a horizon image's), or null when released.
  std::function<void(Vec3i chunk_pos, const Holding* now)> on_holding;
  // The same changes, once per stream batch (a cache load, a replica
  // dropped for another world's), in on_holding's order and after it when
  // both are set: a handler with a lock of its own takes it once a batch,
  // not once a chunk (a horizon image covers up to 512 chunks, a view of
  // 2,048 about 160,000).
  std::function<void(std::span<const HoldingChange>)> on_holdings;
  std::function<void(std::uint32_t edit_id, const EditOutcome&)> on_edit_result;
  // A ReadBoxResult was stored (ClientView::read_results[request_id]).
  std::function<void(std::uint32_t request_id)> on_read_result;
  // A ChunkHash arrived and was compared with the replica's chunk.
  std::function<void(Vec3i chunk_pos, bool match)> on_hash_checked;
  // The same event with the revisions compared (runs after on_hash_checked).
  std::function<void(const HashCheck&)> on_chunk_hash;
  // An UpdateBatch was applied to the replica: the tick it belongs to and
  // the chunks it touched with their new revisions.
  std::function<void(std::uint64_t tick, const std::vector<ChunkRevisionMsg>& revisions)> on_update_batch;
  // The same event with the changed voxel boxes (runs after on_update_batch).
  std::function<void(const UpdateInfo&)> on_update;
  // A StreamBatch made chunks held at full resolution (Full or Empty) that
  // were not before (nothing, a mip, an estimate or a horizon image): their
  // positions, once per batch. A chunk sent again while held in full is not
  // in it.
  std::function<void(const std::vector<Vec3i>& chunk_positions)> on_chunks_loaded;
  // A Presence arrived: the other clients in view, nearest first.
  std::function<void(const std::vector<PresenceEntryMsg>&)> on_presence;
  std::function<void(const std::string& reason)> on_disconnected;
  // The connection dropped and a reconnect is being tried (reason as for
  // on_disconnected), and when it succeeded (after the new Welcome).
  std::function<void(const std::string& reason)> on_connection_lost;
  std::function<void()> on_reconnected;
  // A Redirect is being followed (the new connection is being made; its
  // Welcome comes with on_reconnected).
  std::function<void(const RedirectMsg&)> on_redirected;
  // A notice from the server's operators: a message (Say) or a shutdown
  // warning (Shutdown, with the seconds left and whether it restarts).
  std::function<void(const ServerNoticeMsg&)> on_notice;
  std::function<void(const AdminResultMsg&)> on_admin_result;
  // A keepalive Ping was answered: its round trip (counters' last_round_trip_ms).
  std::function<void(double ms)> on_round_trip;
};

// What wait_until's predicate sees (under the Client's lock).
struct ClientView {
  const Replica& replica;
  const ClientCounters& counters;
  bool welcomed;
  bool closed;
  const std::string& disconnect_reason;
  const std::unordered_map<std::uint32_t, EditOutcome>& edits;
  const std::unordered_map<Vec3i, bool, Vec3iHash>& hash_checks;  // last verification per chunk
  const std::unordered_map<std::uint32_t, ReadBoxResultMsg>& read_results;  // by request id
  const std::vector<PresenceEntryMsg>& presence;                            // latest
  const std::deque<ServerNoticeMsg>& notices;  // the latest kMaxNotices, oldest first
  const std::unordered_map<std::uint32_t, AdminResultMsg>& admin_results;  // by request id
  // The current connection's Welcome has come: false from a drop or a
  // Redirect until the next Welcome (welcomed stays true: the replica and
  // the old Welcome are kept meanwhile).
  bool linked;
  // Welcomes received over the client's life (each resumed session adds one).
  std::uint64_t sessions;
  // Chunks claimed in this session's Holdings (a resumed session) that the
  // server has neither streamed again nor hashed since: each may be stale
  // until it does. A ChunkHashRequest for one is answered once the server
  // has confirmed or replaced it (PROTOCOL.md "Resuming after a reconnect").
  const std::unordered_set<Vec3i, Vec3iHash>& unconfirmed;
  // A first session's chunk cache is being loaded (ClientOptions::
  // chunk_cache): the position, and the claims of what it holds, wait for
  // it; the chunks loaded then join the replica, claimed (unconfirmed).
  bool cache_loading;
};

class Client : private ConnectionHandler {
 public:
  explicit Client(ClientOptions options, ClientCallbacks callbacks = {});
  ~Client() override;
  Client(const Client&) = delete;
  Client& operator=(const Client&) = delete;

  // Connects (blocking up to connect_timeout), queues Hello and the initial
  // ClientState and starts the io side (the owned thread, or reading on the
  // strand in shared mode). Returns false with *error set if the
  // connection cannot be made. Call once.
  bool connect(std::string* error);
  // Sends Disconnect, closes the socket and joins the io thread (shared
  // mode: waits until none of the client's handlers is pending), then saves
  // the replica to ClientOptions::chunk_cache (save_cache). Idempotent;
  // concurrent callers all return once it is done.
  void disconnect();
  // Saves the replica's chunks held in exact forms (but those whose hash did
  // not match the server's) to ClientOptions::chunk_cache under the world's
  // id (client/chunk_cache.h), once a session. False when there is no
  // cache, the world names no id (or no Welcome came), it was saved already
  // or a file could not be written. Disk work under the client's lock: call
  // it once the client is disconnected (disconnect() does).
  bool save_cache();

  bool set_state(const ClientStateMsg& state);
  // Edits return their edit id (the outcome arrives as an ack or reject), or
  // 0 when the send queue is full or the client is closed.
  std::uint32_t fill_box(const Region& box, Voxel v);
  std::uint32_t fill_sphere(Vec3f center, float radius, Material material);
  std::uint32_t dig(Vec3f center, float radius);
  std::uint32_t paint(Vec3f center, float radius, Material material);
  // strength in (0, 1]: how far each voxel moves toward its neighbourhood mean.
  std::uint32_t smooth(Vec3f center, float radius, float strength = 0.5f);
  // voxels in Box order; 0 if the box is over kMaxRawBoxVolume or sizes differ.
  std::uint32_t write_box(const Region& box, std::span<const Voxel> voxels);
  // Asks the server for the raw voxels of box (at most kMaxRawBoxVolume);
  // returns the request id (0 on failure). The answer appears in
  // ClientView::read_results; the voxels are the server's state as of the
  // data received before it, so they match a correct replica.
  std::uint32_t request_read_box(const Region& box);
  // Undo / redo this client's own edits on the server (per connection,
  // bounded history). Undo restores only voxels still as this client left
  // them; a voxel another client changed since keeps that change.
  std::uint32_t undo();
  std::uint32_t redo();
  bool request_chunk_hash(Vec3i chunk_pos);
  // From now on each on_update's UpdateInfo carries the voxels its batch
  // changed, before and after, at most max_per_batch of them (0: none,
  // the default; recording costs a comparison per voxel written).
  void capture_voxel_changes(std::size_t max_per_batch);
  // An operator's command (the session's token must have the admin role);
  // the answer arrives as ClientView::admin_results[id] and on_admin_result.
  // 0 if it could not be sent.
  std::uint32_t admin(const std::string& command, const std::vector<std::string>& args = {});
  std::vector<ServerNoticeMsg> notices() const;
  // The state last sent (position, view), once there is one.
  std::optional<ClientStateMsg> last_state() const;
  // The view the server streams for it (nullopt before the Welcome or a
  // state), and how much of that view the replica holds.
  std::optional<StreamedView> streamed_view() const;
  std::optional<ViewCoverage> coverage() const;
  bool ping(std::uint64_t nonce);
  // Sends raw bytes as they are (tests: malformed frames).
  bool send_raw(Frame bytes);

  // Blocks until pred(view) holds (checked after every frame and on close)
  // or the timeout passes; returns whether it held.
  bool wait_until(const std::function<bool(const ClientView&)>& pred, std::chrono::milliseconds timeout);

  // --- queries (each takes the lock once) ---------------------------------------
  Voxel get(Vec3i voxel) const;
  void read_box(Vec3i min, Box& out) const;
  int resolution_at(Vec3i voxel) const;
  std::optional<RayHit> raycast(Vec3f origin, Vec3f direction, float max_distance) const;
  std::optional<std::int32_t> surface_height(std::int32_t x, std::int32_t z) const;
  std::optional<WelcomeMsg> welcome() const;
  ClientCounters counters() const;
  bool closed() const;
  std::string disconnect_reason() const;
  // Other clients in view, nearest first, as of the latest Presence.
  std::vector<PresenceEntryMsg> presence() const;
  // Runs fn(const Replica&) under the lock.
  template <class F>
  auto with_replica(F&& fn) const {
    std::lock_guard lock(mutex_);
    return fn(replica_);
  }

 private:
  // ConnectionHandler (io side).
  std::vector<Outbound> session_frames(SessionStart start) override;
  void on_bytes_read(std::size_t n) override;
  void on_frame(std::span<const std::uint8_t> body) override;
  void on_framing_error() override;
  void on_written(const Outbound& sent) override;
  bool awaiting_answers() override;
  void on_reconnecting(const std::string& reason) override;
  void on_redirected(const RedirectMsg& to, std::uint32_t cut_edit) override;
  void on_closed(const std::string& reason) override;

  // io side, under the lock: a StreamBatch's records into the replica
  // (those before a bad one stay applied); *after reports the holdings
  // changed, to run without the lock.
  // frame_bytes: the frame's bytes (length header included), counted by
  // cause with its records'.
  Status apply_stream_batch(const wire::StreamBatch& batch, std::size_t frame_bytes, std::function<void()>* after);
  std::uint32_t send_edit(EditRequestMsg e);  // assigns the edit id
  // Edits given an outcome at once: reported (io side, without the lock).
  void report(const SettledEdits& settled);
  ClientView client_view() const;
  // Under the lock, on a first session's Welcome: starts loading the view's
  // regions of w's world from ClientOptions::chunk_cache on the cache's
  // threads, into a replica of its own (loaded_cache below); false when
  // there is nothing to load (no world id, no position yet).
  bool start_cache_load(const WelcomeMsg& w);
  // Io side, once the load is done: unless another session began since
  // (which sent claims and a position of its own), the replica is the
  // loaded one; its claims, then the held-back position, are sent and the
  // callbacks told of every chunk loaded.
  void loaded_cache(Replica loaded, std::size_t chunks, std::uint64_t session);
  // Under the lock: the replica's claimable holdings as Holdings frames
  // (region claims), each chunk noted unconfirmed.
  std::vector<Frame> claim_frames();
  // Whether a holding change is told anyone (on_holding or on_holdings),
  // and the telling (without the lock).
  bool tells_holdings() const { return callbacks_.on_holding || callbacks_.on_holdings; }
  void tell_holdings(std::span<const HoldingChange> changes) const;
  // A new replica as the options ask: the process's shared decoded chunks,
  // how full chunks hold their mips.
  void set_up(Replica& r) const;

  ClientOptions options_;
  ClientCallbacks callbacks_;

  // Guarded by mutex_ (shared with the application's threads).
  mutable std::mutex mutex_;
  std::condition_variable changed_;
  Replica replica_;
  EditTracker edits_;
  Movement movement_;
  ClientCounters counters_;
  std::optional<WelcomeMsg> welcome_;
  bool closed_ = false;
  std::string disconnect_reason_;
  std::unordered_map<Vec3i, bool, Vec3iHash> hash_checks_;
  std::unordered_map<std::uint32_t, ReadBoxResultMsg> read_results_;
  std::unordered_map<std::uint32_t, AdminResultMsg> admin_results_;
  std::uint32_t next_request_id_ = 1;
  std::deque<ServerNoticeMsg> notices_;
  // The server said it stops without coming back: do not reconnect.
  bool server_not_returning_ = false;
  std::vector<PresenceEntryMsg> presence_;
  PresenceList presence_list_;  // as the session's PresenceRecords made it
  bool linked_ = false;                               // ClientView::linked
  std::uint64_t sessions_ = 0;                        // ClientView::sessions
  std::unordered_set<Vec3i, Vec3iHash> unconfirmed_;  // ClientView::unconfirmed
  std::size_t voxel_change_cap_ = 0;                  // capture_voxel_changes
  bool cache_saved_ = false;  // this session's replica went to ClientOptions::chunk_cache (save_cache)
  bool state_held_ = false;   // positions wait for the chunk cache's load (start_cache_load)

  std::vector<Vec3i> horizon_covered_;  // io side: a Horizon record's chunks newly covered
  // Last: goes first, so no handler runs on the rest once it is gone.
  Connection connection_;
};

}  // namespace terrane
