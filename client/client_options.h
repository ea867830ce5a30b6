// ClientOptions: how a Client connects, what it first asks to see, and how
// it rides out drops and Redirects (client/client.h); NetworkEmulation: an
// optional slow downstream link. Plain data, copied by each owner that
// reads it (the connection, the movement); no thread of its own.
#pragma once

#include <asio.hpp>
#include <chrono>
#include <cstdint>
#include <memory>
#include <string>

#include "client/chunk_cache.h"
#include "client/decoded_chunks.h"
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
  // Hello.features: what this client takes beyond version 2's messages
  // (the library applies every feature it knows; tests clear bits).
  std::uint32_t features = kFeatureMipPatches | kFeaturePresenceRecords | kFeatureOuterHorizon | kFeatureCodec2;
  std::chrono::milliseconds connect_timeout{5000};
  // A Ping goes out this often so an idle client is not timed out.
  std::chrono::milliseconds keepalive{5000};
  // The connection counts as lost (reconnecting if allowed, as on a drop)
  // when nothing has come from the server for this long: a paused or
  // partitioned server is noticed, not waited out. A reconnect's
  // connection that stays silent this long before its first frame closes
  // for good (the server accepts connections but does not answer: hung).
  // The server pings every 5 s and answers each Ping. Checked at each
  // keepalive, which goes at least twice per silence_timeout; 0 = never.
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
  // How the replica's full-resolution chunks hold their mips
  // (Chunk::Mips): kept (the default; the viewer reads them for its LOD),
  // or derived when read, for clients that never read them (terrane-bots).
  Chunk::Mips full_chunk_mips = Chunk::Mips::kKept;
  // Chunks kept across sessions and processes (client/chunk_cache.h; null:
  // none). A world whose Welcome names it (world_id) is joined from what
  // the cache holds of the first view: the replica is filled from it and
  // the chunks are claimed (Holdings) before the first ClientState, so only
  // what changed is sent. The files are read and decoded on the cache's
  // own threads; positions set meanwhile (set_state) go after the claims.
  // disconnect() saves the replica to it. Shared by the clients of a process.
  std::shared_ptr<ChunkCache> chunk_cache;
  NetworkEmulation emulation;
};

}  // namespace terrane
