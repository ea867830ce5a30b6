// Stream batches: the server's streaming of what a client holds
// (protocol/holding.h) and the voxels of it, many chunks per frame (PROTOCOL.md, "Stream batches"). One FlatBuffers frame costs
// about 40 bytes of header, table and vector bookkeeping, which is as much
// as a typical 16^3 unit of terrain encodes to; a batch carries the records
// of many chunks in one frame, each record costing a few bytes beyond the
// network codec's own.
//
//   record := kind:u8  dx dy dz:zigzag varint  revision:varint  payload
//     kinds 0..5 give the chunk the holding form of that number
//     (protocol/holding.h):
//     kind 0 Full      eight 16^3 network codec units, unit i at offset
//                      (i & 1, (i >> 1) & 1, (i >> 2) & 1) * 16
//     kind 1..3 Mip L  one network codec unit of (32 >> L)^3 voxels
//     kind 4 Empty     the chunk is all Air (full resolution); no payload
//     kind 5 Estimate  one 4^3 unit, as Mip 3, estimated from the world's
//                      generator for a chunk never generated; replaced by
//                      a Mip or Empty record when the exact mip differs
//     kinds 6, 7       never a record (the horizon forms come only from a
//                      Horizon record): a decode error
//     kind 8 Released  the chunk left the view; no payload
//     kind 10 Mip patch  the mip a client holds at level L (1 or 2), changed:
//                      level:u8, a mask of its 4^3 sub-units (level 1: 8
//                      bytes, 64 sub-units; level 2: 1 byte, 8), then one
//                      4^3 network codec unit per set bit, ascending, each
//                      replacing that sub-unit; sub-unit i is the cube at
//                      (i % s, i / (s * s), (i / s) % s) * 4, s = 4 at
//                      level 1 and 2 at level 2 (x fastest, then z, then
//                      y). Only to a client whose Hello set
//                      kFeatureMipPatches, and only for a chunk it holds
//                      as Mip L; the chunk then holds Mip L at the record's
//                      revision.
//     kind 9 Horizon   a whole 8^3-chunk region at level 4 (2^3 per chunk),
//                      5 (1 voxel per chunk) or 6 (1 voxel per 2^3 chunks,
//                      kFeatureOuterHorizon); position: the region's
//                      first chunk (multiples of 8); revision 0; payload:
//                      level:u8, masked:u8 (0: every chunk of the region;
//                      1: a 64-byte mask follows, bit i of byte i / 8 for
//                      chunk (y * 8 + z) * 8 + x), then one network codec
//                      unit of (256 >> level)^3 voxels
//                      (common/world/horizon.h). Decoded as one record:
//                      the region's image and mask; the chunks it covers
//                      are held in form Horizon4 (level 4) or Horizon5.
//   (dx, dy, dz) is the chunk position minus the previous record's (the
//   first record's is relative to (0, 0, 0)).
//
// Thread-safety: the writer and the scratch are single-threaded objects;
// decode_stream_batch is reentrant given its own scratch.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <span>
#include <vector>

#include "common/codec/decode_error.h"
#include "common/voxel/box.h"
#include "common/voxel/vec3.h"
#include "protocol/holding.h"
#include "protocol/messages.h"
#include "protocol/out_frame.h"

namespace terrane {

enum class StreamRecordKind : std::uint8_t {
  kFull = 0,
  kMip1 = 1,
  kMip2 = 2,
  kMip3 = 3,
  kEmpty = 4,
  kEstimate = 5,
  kReleased = 8,
  kHorizon = 9,
  kMipPatch = 10,
};

constexpr bool known_record_kind(std::uint8_t kind) {
  return kind <= static_cast<std::uint8_t>(StreamRecordKind::kEstimate) ||
         kind == static_cast<std::uint8_t>(StreamRecordKind::kReleased) ||
         kind == static_cast<std::uint8_t>(StreamRecordKind::kHorizon) ||
         kind == static_cast<std::uint8_t>(StreamRecordKind::kMipPatch);
}
// A Mip patch's sub-units per axis at level (1 or 2): the mip's side / 4.
constexpr int patch_side(int level) { return (32 >> level) / 4; }
// The sub-units of a Mip patch at level (1 or 2): 64 or 8.
constexpr int patch_subunits(int level) { return patch_side(level) * patch_side(level) * patch_side(level); }
// Bytes of a Mip patch's sub-unit mask at level (1 or 2): 8 or 1.
constexpr int patch_mask_bytes(int level) { return (patch_subunits(level) + 7) / 8; }
// Sub-unit i's corner in the mip (x fastest, then z, then y).
constexpr Vec3i patch_subunit_origin(int level, int i) {
  const int s = patch_side(level);
  return Vec3i{i % s, i / (s * s), (i / s) % s} * 4;
}
// Whether a record of this kind gives its chunk a holding form (kinds 0..5).
constexpr bool gives_form(StreamRecordKind kind) { return kind <= StreamRecordKind::kEstimate; }
// Whether a record of this kind carries its chunk's voxels as network codec
// units (Full, Mip, Estimate), and their level: 0 for Full, L for Mip L,
// the coarsest for an Estimate.
constexpr bool carries_units(StreamRecordKind kind) { return gives_form(kind) && kind != StreamRecordKind::kEmpty; }
constexpr int payload_level(StreamRecordKind kind) {
  return kind == StreamRecordKind::kEstimate ? kMipLevels - 1 : static_cast<int>(kind);
}
// The record kind that sends a chunk in form f (precondition: f is not a
// horizon form).
constexpr StreamRecordKind record_kind_of(HoldingForm f) { return static_cast<StreamRecordKind>(f); }

// A Horizon record's mask of the region's chunks it covers (bit i: chunk
// (y * 8 + z) * 8 + x).
using HorizonMask = std::array<std::uint8_t, 64>;
// Bit i of a mask: chunk i = coarse_index (common/world/coarse_image.h).
inline bool horizon_mask_has(const HorizonMask& m, int i) {
  return (m[static_cast<std::size_t>(i / 8)] >> (i % 8) & 1) != 0;
}
inline void horizon_mask_set(HorizonMask& m, int i) {
  m[static_cast<std::size_t>(i / 8)] |= static_cast<std::uint8_t>(1u << (i % 8));
}
inline void horizon_mask_clear(HorizonMask& m, int i) {
  m[static_cast<std::size_t>(i / 8)] &= static_cast<std::uint8_t>(~(1u << (i % 8)));
}

// Records in one batch at most (bounds a receiver's work per frame).
inline constexpr std::size_t kMaxStreamRecords = 4096;
// A server closes a batch once it reaches this size (far below the frame
// limit even with a worst-case Full record after it).
inline constexpr std::size_t kStreamBatchTargetBytes = 64 * 1024;

struct StreamRecord {
  StreamRecordKind kind = StreamRecordKind::kEmpty;
  Vec3i chunk_pos;
  std::uint64_t revision = 0;
  int level = 0;               // 0 for Full, 1..3 for Mip, 3 for Estimate, 4..6 for Horizon, 1..2 for Mip patch
  // The form the record gives its chunk (precondition: gives_form(kind)).
  HoldingForm form() const { return static_cast<HoldingForm>(kind); }
  // Full: 32^3; Mip: (32 >> level)^3; Horizon: the region's image,
  // (256 >> level)^3; Mip patch: (32 >> level)^3 of which only the
  // sub-units in patch_mask hold the record's voxels; else null.
  const Box* voxels = nullptr;
  const HorizonMask* mask = nullptr;  // Horizon: the region's chunks it covers
  // Full, Mip, Estimate: the record's encoded units, as received (equal
  // bytes decode to equal voxels: a receiver may share what it made of
  // them); valid during the call, as voxels.
  std::span<const std::uint8_t> payload;
  // The whole record's bytes as received (kind, position, revision and
  // payload), for a receiver's accounting of what its bytes were for.
  std::size_t bytes = 0;
  std::uint64_t patch_mask = 0;  // Mip patch: its sub-units (bit i: sub-unit i; never 0)
  // Full, Mip, Estimate: what the receiver made before of these very bytes
  // (KnownPayloadFn), when it did; voxels is then null and the record's
  // voxels are what was made of them (record_voxels decodes them again if
  // the receiver needs the voxels themselves).
  std::shared_ptr<const void> known = nullptr;
};

// A receiver's memory of payloads it decoded before. Given a record's kind
// and the batch's bytes from its payload on, what it made of a payload those
// bytes begin with, and that payload's length; {0, null} when none. Equal
// bytes decode to equal voxels and a payload decoded before was valid, so
// the decoder takes the length and skips decoding them again.
struct KnownPayload {
  std::size_t bytes = 0;
  std::shared_ptr<const void> made;
};
using KnownPayloadFn = std::function<KnownPayload(StreamRecordKind kind, std::span<const std::uint8_t> rest)>;

// The voxels of a Full, Mip or Estimate record, decoded from its payload
// into scratch when the decoder skipped them (r.known); r.voxels otherwise.
struct StreamDecodeScratch;
const Box& record_voxels(const StreamRecord& r, StreamDecodeScratch& scratch);

// Appends a record's kind, position (relative to prev, which becomes
// chunk_pos) and revision to out: the bytes before its payload. What
// StreamBatchWriter writes, for records kept in one buffer (a client's
// chunk cache, client/chunk_cache.h).
void put_stream_record_head(StreamRecordKind kind, Vec3i chunk_pos, std::uint64_t revision, Vec3i& prev,
                            std::vector<std::uint8_t>& out);

// Writes a batch's records as the segments of its frame (protocol/out_frame.h):
// each record's header is the writer's own bytes, and a payload given with
// its owner (the chunk version or horizon image whose immutable encoding it
// is) is shared, not copied, so a chunk streamed to many clients is one
// buffer in all their frames.
class StreamBatchWriter {
 public:
  // payload: the record's encoded units (empty for Empty and Released),
  // copied.
  void add(StreamRecordKind kind, Vec3i chunk_pos, std::uint64_t revision, std::span<const std::uint8_t> payload) {
    put_head(kind, chunk_pos, revision);
    bytes_.append(payload);
  }
  // owner: what keeps payload alive and unchanged (null: it is copied).
  template <class T>
  void add(StreamRecordKind kind, Vec3i chunk_pos, std::uint64_t revision, std::span<const std::uint8_t> payload,
           const std::shared_ptr<T>& owner) {
    put_head(kind, chunk_pos, revision);
    bytes_.append_shared(payload, owner);
  }
  // A Horizon record: region's image at level (4 or 5), for the chunks of
  // mask (null: every chunk of the region); unit and owner as payload's.
  template <class T>
  void add_horizon(Vec3i region, int level, const HorizonMask* mask, std::span<const std::uint8_t> unit,
                   const std::shared_ptr<T>& owner) {
    put_horizon_head(region, level, mask);
    bytes_.append_shared(unit, owner);
  }
  void add_horizon(Vec3i region, int level, const HorizonMask* mask, std::span<const std::uint8_t> unit) {
    put_horizon_head(region, level, mask);
    bytes_.append(unit);
  }
  // A Mip patch record: the chunk's mip at level (1 or 2) changed in the
  // sub-units of mask (non-zero, within patch_subunits(level)); units: their
  // 4^3 network codec units, one per set bit, ascending (copied).
  void add_mip_patch(Vec3i chunk_pos, std::uint64_t revision, int level, std::uint64_t mask,
                     std::span<const std::uint8_t> units);
  bool empty() const { return records_ == 0; }
  std::size_t records() const { return records_; }
  // The records' bytes so far.
  std::size_t size_bytes() const { return bytes_.size(); }
  // The StreamBatch frame of the records so far (the bytes
  // build_stream_batch makes of them); the writer starts over.
  OutFrame finish();

 private:
  // A record's kind, position and revision.
  void put_head(StreamRecordKind kind, Vec3i chunk_pos, std::uint64_t revision);
  // A Horizon record up to its unit.
  void put_horizon_head(Vec3i region, int level, const HorizonMask* mask);

  OutFrame bytes_;
  Vec3i prev_{0, 0, 0};
  std::size_t records_ = 0;
};

// Scratch buffers for decoding, reusable across batches.
struct StreamDecodeScratch {
  Box unit{Vec3i{16, 16, 16}};
  Box chunk{Vec3i{32, 32, 32}};
  Box mip;
  Box horizon;
  Box patch_unit{Vec3i{4, 4, 4}};
  HorizonMask mask{};
};

// Decodes every record in order and calls fn for each (the Box is valid
// during the call). Stops at the first error, from the bytes (kTruncated,
// kInvalidValue for an unknown kind, an out-of-range position or an
// over-long varint, kOverLimit beyond kMaxStreamRecords, the codec's errors)
// or from fn. Records before the error have been delivered.
// known (optional): payloads of Full, Mip and Estimate records the receiver
// decoded before are not decoded again (StreamRecord::known).
Status decode_stream_batch(std::span<const std::uint8_t> records, StreamDecodeScratch& scratch,
                           const std::function<Status(const StreamRecord&)>& fn,
                           const KnownPayloadFn& known = nullptr);

}  // namespace terrane
