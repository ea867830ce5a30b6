// Wire messages shared by the server and the client: builders that produce a
// complete frame (length header + FlatBuffers Message, protocol/framing.h)
// and parsers that turn a verified Message body into plain structs after
// checking what the fields mean (coordinates in range, material < 64, radius
// and box volume bounds, string lengths). The FlatBuffers verifier (run by
// verify_message) only proves the bytes are a well-formed buffer; these
// parsers are the second gate and treat every field as hostile.
//
// Also the chunk hash, which both sides must compute identically.
// Thread-safety: every function is pure.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "common/codec/decode_error.h"
#include "common/voxel/chunk.h"
#include "common/voxel/vec3.h"
#include "common/voxel/voxel.h"
#include "common/world/world_bounds.h"
#include "protocol/framing.h"
#include "protocol/holding.h"
#include "protocol/out_frame.h"
#include "protocol/terrane_generated.h"

namespace terrane {

// --- limits (PROTOCOL.md, "Meaning checks") --------------------------------
inline constexpr std::size_t kMaxClientNameBytes = 64;
// The first byte below 0x20 or DEL in text, or npos: what text a server
// logs (a client's name, a resume token) may not hold, since a line end in
// it would forge a log line.
std::size_t control_character_at(std::string_view text);
inline constexpr std::size_t kMaxAuthTokenBytes = 256;
inline constexpr std::size_t kMaxReasonBytes = 256;
inline constexpr std::size_t kMaxAdminCommandBytes = 32;
inline constexpr std::size_t kMaxAdminArgs = 16;
inline constexpr std::size_t kMaxAdminArgBytes = 1024;
inline constexpr std::size_t kMaxNoticeBytes = 1024;
inline constexpr std::size_t kMaxResumeTokenBytes = 64;
inline constexpr std::size_t kMaxRedirectHostBytes = 253;
inline constexpr std::size_t kMaxMaterialNames = kMaterialCount;
// Voxel coordinates on the wire stay within +-2^24 so that chunk and unit
// coordinates, and positions as float, never overflow or lose whole voxels.
inline constexpr std::int32_t kMaxWireCoordinate = 1 << 24;
// One edit touches at most 64^3 voxels: bounded work per message on the
// server's owner thread (a few milliseconds).
inline constexpr std::int64_t kMaxEditVolume = 64 * 64 * 64;
inline constexpr float kMaxSphereRadius = 32.0f;
// WriteBox and ReadBox carry raw voxels (byte RLE, at most 2 bytes each):
// 32^3 voxels keep one message under 64 KiB decoded.
inline constexpr std::int64_t kMaxRawBoxVolume = 32 * 32 * 32;
// Presence entries in one message: the nearest clients in view.
inline constexpr std::size_t kMaxPresenceEntries = 64;
// View distances on the wire; the server caps them further.
inline constexpr std::int32_t kMaxWireViewDistance = 1 << 16;
// Chunk revisions in one UpdateBatch (one batch covers at most one tick).
inline constexpr std::size_t kMaxBatchRevisions = 4096;
// A Full stream record's units: eight 16^3 units of its 32^3 chunk.
inline constexpr int kFullRecordUnit = 16;

// --- message structs ---------------------------------------------------------
// Hello.features bits. A server sends a feature's messages only to a client
// that set its bit; bits it does not know are ignored.
inline constexpr std::uint32_t kFeatureMipPatches = 1u << 0;       // Mip patch stream records (kind 10)
inline constexpr std::uint32_t kFeaturePresenceRecords = 1u << 1;  // PresenceRecords instead of Presence
inline constexpr std::uint32_t kFeatureOuterHorizon = 1u << 2;     // level-6 Horizon records beyond 1,024 voxels
inline constexpr std::uint32_t kFeatureCodec2 = 1u << 3;           // network codec units of format version 2

struct HelloMsg {
  std::uint32_t protocol_version = kProtocolVersion;
  std::string client_name;
  std::string auth_token;
  std::string resume_token;  // a Redirect's token, echoed (empty on a first connection)
  std::uint32_t features = 0;  // kFeature* bits: what the client can take (PROTOCOL.md, "Features")
};

struct AdminRequestMsg {
  std::uint32_t request_id = 0;
  std::string command;
  std::vector<std::string> args;
};

struct AdminResultMsg {
  std::uint32_t request_id = 0;
  bool ok = false;
  std::string text;
  std::string json;
};

// kind may be one this build does not know (a newer server): ignore it.
struct ServerNoticeMsg {
  wire::NoticeKind kind = wire::NoticeKind::Say;
  std::string text;
  std::uint32_t seconds_left = 0;
  bool reconnect = false;
};

// Go on at another server of the same world (PROTOCOL.md, "Redirects").
struct RedirectMsg {
  std::uint32_t server_id = 0;
  std::string host;
  std::uint16_t port = 0;
  std::string token;  // echoed in the next Hello's resume_token
};

struct WelcomeMsg {
  std::uint32_t protocol_version = kProtocolVersion;
  std::uint64_t server_epoch = 0;
  Vec3f spawn;
  std::vector<std::string> materials;
  std::int32_t bounds_min_y = 0;
  std::int32_t bounds_max_y = 0;
  std::int32_t max_view_distance = 0;
  std::int32_t max_full_res_radius = 0;
  std::uint32_t max_frame_bytes = 0;
  std::uint32_t tick_hz = 0;
  bool bounded_xz = false;
  std::int32_t bounds_min_x = 0, bounds_min_z = 0, bounds_max_x = 0, bounds_max_z = 0;
  std::int32_t default_view_distance = 0, default_full_res_radius = 0;
  float edits_per_second = 0;  // 0: unlimited (or a server that does not say)
  std::uint32_t edit_burst = 0;
  std::uint32_t server_id = 0;  // in a world of several servers; 0 otherwise
  std::uint64_t world_id = 0;   // 0: the server names none (nothing kept across sessions)

  // The world's bounds as the view rule and edits take them.
  WorldBounds bounds() const {
    return WorldBounds{bounds_min_y, bounds_max_y, bounded_xz, bounds_min_x, bounds_max_x, bounds_min_z, bounds_max_z};
  }
};

struct ClientStateMsg {
  Vec3f position;
  std::int32_t view_distance = 0;    // voxels
  std::int32_t full_res_radius = 0;  // voxels
};

// Same values as wire::EditKind.
enum class EditKind : std::uint8_t {
  kFillBox = 0, kFillSphere = 1, kDig = 2, kPaint = 3, kSmooth = 4, kWriteBox = 5, kUndo = 6, kRedo = 7
};

// True for the kinds defined by a centre and radius.
constexpr bool is_sphere_edit(EditKind k) {
  return k == EditKind::kFillSphere || k == EditKind::kDig || k == EditKind::kPaint || k == EditKind::kSmooth;
}
// Undo and Redo act on the sender's own edit history; they carry no region.
constexpr bool is_history_edit(EditKind k) { return k == EditKind::kUndo || k == EditKind::kRedo; }

struct EditRequestMsg {
  std::uint32_t edit_id = 0;
  EditKind kind = EditKind::kFillBox;
  Region box;          // kFillBox, kWriteBox: half-open
  Vec3f center;        // sphere kinds
  float radius = 0;    // sphere kinds
  Material material = kAir;    // kFillBox, kFillSphere, kPaint (not Air)
  std::uint8_t occupancy = 0;  // kFillBox: the byte written (Air forces 0); kSmooth: strength
  std::vector<Voxel> voxels;   // kWriteBox: the box's voxels in Box order (decoded, validated)

  // The voxels the edit may change.
  Region bounds() const;
  // The voxels the edit reads (bounds() plus the smoothing filter's reach).
  Region reads() const;
};

struct ReadBoxMsg {
  std::uint32_t request_id = 0;
  Region box;
};
struct ReadBoxResultMsg {
  std::uint32_t request_id = 0;
  Region box;
  std::string error;                  // empty on success
  std::vector<Voxel> voxels;          // Box order, box.volume() of them on success
};
struct EditRejectMsg {
  std::uint32_t edit_id = 0;
  std::string reason;
  Region box;                 // empty when no state is attached
  std::vector<Voxel> voxels;  // the true state of box (Box order)
  bool outcome_unknown = false;  // the edit may have been applied (false: it was not)
};
struct PresenceEntryMsg {
  std::uint32_t client_id = 0;
  Vec3f position;
  std::string name = {};  // its Hello's client_name; empty from a server that sends none
  friend bool operator==(const PresenceEntryMsg&, const PresenceEntryMsg&) = default;
};

// Data messages point into the frame they were parsed from.
struct ChunkRevisionMsg {
  Vec3i chunk_pos;
  std::uint64_t revision = 0;
};
struct UpdateBatchMsg {
  std::uint64_t tick = 0;
  std::span<const std::uint8_t> data;
  std::vector<ChunkRevisionMsg> revisions;
};
struct ChunkHashMsg {
  Vec3i chunk_pos;
  std::uint64_t revision = 0;
  std::uint64_t hash = 0;
};

// One entry of Holdings: a chunk and what the client holds of it (a
// claimable form: Full, Mip 1..3 or Empty).
inline constexpr std::size_t kMaxHoldingsPerMessage = 16384;
struct HeldChunkMsg {
  Vec3i chunk_pos;
  Holding holding;
};

// --- builders: each returns one complete frame --------------------------------
// Strings longer than their limit are truncated to it (our own callers).
Frame build_hello(const HelloMsg& m);
Frame build_welcome(const WelcomeMsg& m);
Frame build_disconnect(std::string_view reason);
Frame build_admin_request(const AdminRequestMsg& m);
// text and json are cut to fit one frame (the json is then replaced by {}).
Frame build_admin_result(const AdminResultMsg& m);
Frame build_server_notice(const ServerNoticeMsg& m);
Frame build_redirect(const RedirectMsg& m);
Frame build_client_state(const ClientStateMsg& m);
Frame build_update_batch(std::uint64_t tick, std::span<const std::uint8_t> data,
                         std::span<const ChunkRevisionMsg> revisions);
// The same frame as build_update_batch(tick, data's bytes, revisions), with
// data's segments kept as they are: its shared spans are not copied.
OutFrame gather_update_batch(std::uint64_t tick, OutFrame data, std::span<const ChunkRevisionMsg> revisions);
Frame build_edit_request(const EditRequestMsg& m);
Frame build_edit_ack(std::uint32_t edit_id, std::uint64_t tick);
Frame build_edit_reject(std::uint32_t edit_id, std::string_view reason, bool outcome_unknown = false);
// A rejection with the true state of box (voxels in Box order).
Frame build_edit_reject(std::uint32_t edit_id, std::string_view reason, const Region& box, std::span<const Voxel> voxels,
                        bool outcome_unknown = false);
Frame build_read_box(std::uint32_t request_id, const Region& box);
Frame build_read_box_result(std::uint32_t request_id, const Region& box, std::span<const Voxel> voxels);
Frame build_read_box_error(std::uint32_t request_id, const Region& box, std::string_view error);
Frame build_presence(std::span<const PresenceEntryMsg> entries);
// records: encode_presence_records's bytes (protocol/presence_records.h).
Frame build_presence_records(std::span<const std::uint8_t> records);
// records: protocol/stream_batch.h (StreamBatchWriter builds them).
Frame build_stream_batch(std::span<const std::uint8_t> records);
// The same frame as build_stream_batch(records' bytes), with records'
// segments kept as they are (StreamBatchWriter::finish).
OutFrame gather_stream_batch(OutFrame records);
// At most kMaxHoldingsPerMessage entries (the rest are dropped: split larger
// holdings over several messages).
Frame build_holdings(std::span<const HeldChunkMsg> chunks);
// The same claims (any number, each chunk at most once) as region claims
// (protocol/region_claims.h): whole regions to a message, at most
// kMaxHoldingsPerMessage claims each; none for no claims.
// world_id: the world the chunks came from (Holdings.world_id; 0: unchecked).
std::vector<Frame> build_region_holdings(std::span<const HeldChunkMsg> claims, std::uint64_t world_id);
Frame build_chunk_hash(const ChunkHashMsg& m);
Frame build_chunk_hash_request(Vec3i chunk_pos);
Frame build_ping(std::uint64_t nonce);
Frame build_pong(std::uint64_t nonce);

// --- parsers: meaning checks on a verified message ------------------------------
// Each returns kInvalidValue / kOverLimit naming the field on failure.
Result<HelloMsg> parse_hello(const wire::Hello& m);
Result<WelcomeMsg> parse_welcome(const wire::Welcome& m);
Result<std::string> parse_disconnect(const wire::Disconnect& m);
Result<AdminRequestMsg> parse_admin_request(const wire::AdminRequest& m);
Result<AdminResultMsg> parse_admin_result(const wire::AdminResult& m);
Result<ServerNoticeMsg> parse_server_notice(const wire::ServerNotice& m);
Result<RedirectMsg> parse_redirect(const wire::Redirect& m);
Result<ClientStateMsg> parse_client_state(const wire::ClientState& m);
Result<EditRequestMsg> parse_edit_request(const wire::EditRequest& m);
Result<UpdateBatchMsg> parse_update_batch(const wire::UpdateBatch& m);
Result<ChunkHashMsg> parse_chunk_hash(const wire::ChunkHash& m);
Result<Vec3i> parse_chunk_hash_request(const wire::ChunkHashRequest& m);
Result<ReadBoxMsg> parse_read_box(const wire::ReadBox& m);
Result<ReadBoxResultMsg> parse_read_box_result(const wire::ReadBoxResult& m);
Result<EditRejectMsg> parse_edit_reject(const wire::EditReject& m);
Result<std::vector<PresenceEntryMsg>> parse_presence(const wire::Presence& m);
// The records' bytes (decode_presence_records reads them).
std::span<const std::uint8_t> parse_presence_records(const wire::PresenceRecords& m);
// The records of a StreamBatch (non-empty); decode them with decode_stream_batch.
Result<std::span<const std::uint8_t>> parse_stream_batch(const wire::StreamBatch& m);
// The claims of chunks, then those of regions (decode_region_claims): at
// most kMaxHoldingsPerMessage in all.
Result<std::vector<HeldChunkMsg>> parse_holdings(const wire::Holdings& m);

// True if every component lies in [-kMaxWireCoordinate, kMaxWireCoordinate].
bool wire_coordinate_ok(Vec3i voxel);
// Same for chunk coordinates (voxel range / 32).
bool wire_chunk_ok(Vec3i chunk_pos);

// --- chunk hash ------------------------------------------------------------
// 64-bit FNV-1a over the revision (8 bytes little-endian) then the 32^3
// voxels of the chunk in Box order, two bytes each (material, occupancy).
// A null chunk is all Air. Both sides hash decoded voxels, so the value does
// not depend on how the chunk travelled. (The loop is chunk_hash.h's.)
std::uint64_t chunk_hash(const Chunk* chunk, std::uint64_t revision);

}  // namespace terrane
