// Client: connects to a terrane-server, handshakes, keeps a Replica of what
// the server streams, sends client state and edits, and verifies chunks
// against the server's chunk hashes.
//
// Threading: by default the Client owns one io thread (started by
// connect()). With ClientOptions::io_context set, it owns no thread: its
// handlers run on a strand of that shared io_context, which the application
// runs on a pool of its own (many clients, few threads: the bots). Either
// way the io side — the owned thread or the strand — does all socket I/O,
// verifies and parses every frame (bytes from the server are treated as
// hostile: any bad frame closes the connection) and applies it to the
// Replica; one client's handlers never run concurrently. The Replica and
// the other shared state sit behind one mutex because the application
// queries them from its own threads; the io side holds it only while
// applying one frame. Callbacks run on the io side without the lock held:
// they may call any Client method except disconnect() and wait_until().
// Every public method is thread-safe. In shared mode connect(),
// disconnect() and wait_until() block, so they must not be called from the
// shared io_context's threads, and the io_context must be running while
// they wait and must outlive the Client.
//
// Connection states (io thread):
//
//   connect() --> [linked] --drop, or Disconnect "server shutting down"-->
//                    ^        (reconnect on)                             |
//                    |                                                   v
//                    +---- Welcome again <-- Hello, Holdings, state <-- [waiting: backoff]
//   [linked] --Disconnect with another reason, protocol error,
//              disconnect(), or reconnect attempts used up--> [closed]
//   [linked] --Redirect--> [leaving: sends held until every edit written is
//              answered, at most redirect_wait] --> Hello (resume token),
//              Holdings, state at the server named --> [linked]
//              (a connection that fails there: as a drop)
//
// While waiting, sends are queued (up to max_send_queue_bytes) and go out
// after the new handshake; the replica stays as it was.
#pragma once

#include <asio.hpp>
#include <array>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <thread>
#include <unordered_map>
#include <unordered_set>

#include "client/replica.h"
#include "protocol/framing.h"
#include "protocol/messages.h"

namespace terrane {

// Optional emulation of a slow downstream link (server -> client), applied
// where bytes leave the socket: each read is delivered to the frame parser
// after the link has carried it at bandwidth_bytes_per_s (a single
// bottleneck queue, first in first out) plus a fixed one-way latency. The
// client stops reading the socket while more than about one
// bandwidth-delay product (at least 64 KiB) waits, so a capped link pushes
// back on the server through TCP as a real one would. Upstream (client ->
// server) bytes are not delayed. Zero fields disable each part.
struct NetworkEmulation {
  std::chrono::milliseconds latency{0};
  std::uint64_t bandwidth_bytes_per_s = 0;
  bool active() const { return latency.count() > 0 || bandwidth_bytes_per_s > 0; }
};

struct ClientOptions {
  std::string host = "127.0.0.1";
  std::uint16_t port = 0;
  std::string name = "client";
  std::string auth_token;
  // Sent right after Hello. With start_at_spawn the position is replaced by
  // the Welcome's spawn point when it arrives (and sent again).
  ClientStateMsg state{{0, 0, 0}, 256, 64};
  bool start_at_spawn = true;
  // False: never send a ClientState, so the server streams nothing (tools
  // such as terrane-admin that only speak to the server).
  bool stream = true;
  // With start_at_spawn: the first position is the spawn plus this (the
  // server limits movement speed after the first position).
  Vec3f spawn_offset{0, 0, 0};
  std::uint32_t protocol_version = kProtocolVersion;  // tests: speak another version
  std::chrono::milliseconds connect_timeout{5000};
  // A Ping goes out this often so an idle client is not timed out.
  std::chrono::milliseconds keepalive{5000};
  // The connection counts as lost (reconnecting if allowed, as on a drop)
  // when nothing has come from the server for this long: a paused or
  // partitioned server is noticed, not waited out. The server pings every
  // 5 s and answers each Ping. Checked at each keepalive; 0 = never.
  std::chrono::milliseconds silence_timeout{15000};
  // Outbound bytes queued at most; sends beyond it fail.
  std::size_t max_send_queue_bytes = 4u << 20;
  // Reconnect when the connection drops without a reason, or because the
  // server shut down: with backoff from reconnect_min doubling to
  // reconnect_max, up to reconnect_attempts tries in a row (0 = forever).
  // The replica is kept and offered to the server (Holdings), so chunks
  // still current are not downloaded again. Edits sent but not answered
  // when the connection dropped are reported rejected with reason
  // kEditOutcomeUnknown: they may or may not have been applied.
  bool reconnect = false;
  std::chrono::milliseconds reconnect_min{100};
  std::chrono::milliseconds reconnect_max{5000};
  int reconnect_attempts = 0;
  // Follow a Redirect (a world shared by several servers): go on at the
  // server named, keeping the replica (Holdings), once every edit written
  // to this one is answered or redirect_wait has passed (edits then
  // unanswered are reported with kEditOutcomeUnknown; reads and hash
  // requests unanswered are dropped: ask again). Edits made meanwhile wait
  // and go to the new server. If the new server cannot be resolved or
  // reached within connect_timeout, the client goes back to the old one
  // (resuming likewise; with reconnect on, with its backoff) and follows
  // no Redirect there for a minute. false: stay (the server serves the
  // session on after a grace).
  bool follow_redirects = true;
  std::chrono::milliseconds redirect_wait{5000};
  // Shared mode (see the threading note): run on this io_context instead of
  // an owned thread. Not owned.
  asio::io_context* io_context = nullptr;
  // Chunks packed from Full records, shared with the process's other
  // clients (null: each packs its own). Many clients in one process
  // receive the same records (client/decoded_chunks.h).
  std::shared_ptr<DecodedChunks> shared_chunks;
  NetworkEmulation emulation;
};

inline constexpr std::size_t kMaxNotices = 32;
inline constexpr const char* kEditOutcomeUnknown = "connection lost before the answer; outcome unknown";

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

struct ClientCounters {
  std::uint64_t frames_in = 0;  // frames handled (by_message_type counts them by type, length header included)
  std::uint64_t bytes_in = 0;  // read from the socket (with emulation: before the emulated link delivers them)
  std::uint64_t chunk_units = 0;  // 16^3 units of Full records applied (8 a record)
  std::uint64_t mips = 0;
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
  std::uint64_t presence_updates = 0;
  std::uint64_t read_results = 0;
  std::uint64_t frames_out = 0;
  std::uint64_t bytes_out = 0;  // written to the socket
  // Indexed by wire::Body (message_type_name()).
  std::array<MessageTypeCounters, kMessageTypeCount> by_message_type{};
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

struct EditOutcome {
  bool accepted = false;
  std::uint64_t tick = 0;
  std::string reason;  // rejections
  // Rejections decided against the world also carry its true state over the
  // edit's box (empty box otherwise), for clients that predicted the edit.
  Region state_box;
  std::vector<Voxel> state;
};

// One UpdateBatch as applied to the replica: its tick, the chunks it
// touched with their new revisions, and per chunk held at full resolution
// the voxel box its changed units cover.
struct UpdateInfo {
  std::uint64_t tick = 0;
  std::vector<ChunkRevisionMsg> revisions;
  std::vector<Region> changed;
};

struct ClientCallbacks {
  std::function<void(const WelcomeMsg&)> on_welcome;
  // What the replica holds of a chunk changed: its holding now (a record
  // of its own, or a horizon image's), or null when released.
  std::function<void(Vec3i chunk_pos, const Holding* now)> on_holding;
  std::function<void(std::uint32_t edit_id, const EditOutcome&)> on_edit_result;
  // A ChunkHash arrived and was compared with the replica's chunk.
  std::function<void(Vec3i chunk_pos, bool match)> on_hash_checked;
  // The same event with the revisions compared (runs after on_hash_checked).
  std::function<void(const HashCheck&)> on_chunk_hash;
  // An UpdateBatch was applied to the replica: the tick it belongs to and
  // the chunks it touched with their new revisions.
  std::function<void(std::uint64_t tick, const std::vector<ChunkRevisionMsg>& revisions)> on_update_batch;
  // The same event with the changed voxel boxes (runs after on_update_batch).
  std::function<void(const UpdateInfo&)> on_update;
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
};

class Client {
 public:
  explicit Client(ClientOptions options, ClientCallbacks callbacks = {});
  ~Client();
  Client(const Client&) = delete;
  Client& operator=(const Client&) = delete;

  // Connects (blocking up to connect_timeout), queues Hello and the initial
  // ClientState and starts the io thread (shared mode: starts reading on
  // the strand). Returns false with *error set if the connection cannot be
  // made. Call once.
  bool connect(std::string* error);
  // Sends Disconnect, closes the socket and joins the io thread (shared
  // mode: waits until none of the client's handlers is pending). Idempotent;
  // concurrent callers all return once it is done.
  void disconnect();

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
  // An operator's command (the session's token must have the admin role);
  // the answer arrives as ClientView::admin_results[id] and on_admin_result.
  // 0 if it could not be sent.
  std::uint32_t admin(const std::string& command, const std::vector<std::string>& args = {});
  std::vector<ServerNoticeMsg> notices() const;
  // The state last sent (position, view), once there is one.
  std::optional<ClientStateMsg> last_state() const;
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
  struct Outbound {
    Frame frame;
    wire::Body type;
    std::uint32_t edit_id = 0;  // an EditRequest's
    bool skip = false;          // cut off mid-write by a Redirect: not sent again
  };
  // Bytes read from the socket, waiting for the emulated link.
  struct Delayed {
    std::chrono::steady_clock::time_point deliver_at;
    std::vector<std::uint8_t> bytes;
  };
  // Counts one pending handler of this client (shared mode waits for none).
  class OpGuard;

  bool connect_shared(const asio::ip::tcp::resolver::results_type& endpoints, std::string* error);
  void start_io();  // io side: first writes, reads and timers
  void do_read();
  bool feed(std::span<const std::uint8_t> bytes);  // io side; false once closed
  void delay_bytes(std::size_t n);
  void arm_delivery();
  void arm_keepalive();
  void handle_frame(std::span<const std::uint8_t> body);
  bool send(Frame frame, wire::Body type, std::uint32_t edit_id = 0);
  std::uint32_t send_edit(EditRequestMsg e);  // assigns the edit id
  void do_write();
  void close_locked_io(const std::string& reason);  // io side
  // io side: the connection ended; reconnects or closes for good.
  void connection_lost(const std::string& reason, bool server_said);
  void schedule_reconnect();
  void start_session();  // io side: Hello (+ Holdings, state) and the read loop
  // io side: a Redirect is pending; follows it once nothing written waits
  // for an answer (or at redirect_wait).
  void follow_when_ready();
  void follow_redirect();
  // io side: ends this connection's socket and timers (a new one follows).
  void drop_socket();
  // Under mutex_: every edit sent and not answered gets the outcome
  // unknown (recorded, and returned for on_edit_result).
  std::vector<std::pair<std::uint32_t, EditOutcome>> settle_unanswered();
  ClientView view() const;

  ClientOptions options_;
  ClientCallbacks callbacks_;
  std::unique_ptr<asio::io_context> own_io_;  // null in shared mode
  asio::io_context& io_;
  asio::strand<asio::io_context::executor_type> strand_;
  asio::ip::tcp::socket socket_;   // on strand_
  asio::steady_timer keepalive_;   // on strand_
  // When this connection last read a byte (strand_): silence_timeout.
  std::chrono::steady_clock::time_point last_heard_{};
  asio::steady_timer delivery_;    // on strand_
  std::thread thread_;
  bool started_ = false;           // connect() succeeded (caller's thread)
  std::once_flag disconnect_once_;
  std::atomic<int> pending_ops_{0};
  std::mutex ops_mutex_;           // only to wait for pending_ops_ == 0
  std::condition_variable ops_done_;
  FrameReader reader_;
  std::vector<std::uint8_t> read_buf_;
  std::deque<Outbound> send_queue_;  // io side
  bool writing_ = false;             // io side
  std::deque<Delayed> delayed_;      // io side (emulation)
  std::size_t delayed_bytes_ = 0;    // io side
  bool read_paused_ = false;         // io side
  bool delivery_armed_ = false;      // io side
  std::chrono::steady_clock::time_point link_free_{};  // io side
  std::atomic<std::size_t> queued_bytes_{0};
  std::atomic<std::uint32_t> next_edit_id_{1};
  std::atomic<bool> io_closed_{false};
  std::atomic<bool> leaving_{false};      // disconnect() was called
  std::uint64_t generation_ = 0;          // io thread: bumps per connection; stale handlers return
  asio::ip::tcp::resolver::results_type endpoints_;  // io thread
  asio::steady_timer reconnect_timer_;
  std::chrono::milliseconds backoff_{0};  // io thread
  int attempts_ = 0;                      // io thread
  bool resumed_ = false;                  // io thread: this connection is a reconnect
  bool linked_ = false;                   // io thread: a connected socket to write to
  std::optional<RedirectMsg> redirect_;   // io thread: to follow
  asio::steady_timer redirect_timer_;     // on strand_
  bool redirect_timer_armed_ = false;     // io thread
  std::string resume_token_;              // io thread: for the next Hello
  std::unordered_set<std::uint32_t> edits_on_wire_;  // io thread: written, not answered
  // io thread: a Redirect target that could not be reached, not followed
  // again until then.
  static constexpr std::chrono::seconds kUnreachableFor{60};
  std::string unreachable_;
  std::chrono::steady_clock::time_point unreachable_until_{};

  // Guarded by mutex_ (shared with the application's threads).
  mutable std::mutex mutex_;
  std::condition_variable changed_;
  Replica replica_;
  ClientCounters counters_;
  std::optional<WelcomeMsg> welcome_;
  bool closed_ = false;
  std::string disconnect_reason_;
  std::unordered_map<std::uint32_t, EditOutcome> edits_;
  std::unordered_map<Vec3i, bool, Vec3iHash> hash_checks_;
  std::unordered_map<std::uint32_t, ReadBoxResultMsg> read_results_;
  std::unordered_map<std::uint32_t, AdminResultMsg> admin_results_;
  std::deque<ServerNoticeMsg> notices_;
  // The server said it stops without coming back: do not reconnect.
  bool server_not_returning_ = false;
  std::unordered_set<std::uint32_t> unanswered_edits_;
  std::optional<ClientStateMsg> last_state_;
  std::vector<PresenceEntryMsg> presence_;
  StreamDecodeScratch stream_scratch_;  // io thread
  std::vector<Vec3i> horizon_covered_;  // io thread: a Horizon record's chunks newly covered
  std::atomic<std::uint32_t> next_request_id_{1};
};

}  // namespace terrane
