// Stream batches: the server's streaming of coverage and voxels, many chunks
// per frame (PROTOCOL.md, "Stream batches"). One FlatBuffers frame costs
// about 40 bytes of header, table and vector bookkeeping, which is as much
// as a typical 16^3 unit of terrain encodes to; a batch carries the records
// of many chunks in one frame, each record costing a few bytes beyond the
// network codec's own.
//
//   record := kind:u8  dx dy dz:zigzag varint  revision:varint  payload
//     kind 0 Empty     the chunk is all Air (full resolution); no payload
//     kind 1..3 Mip L  one network codec unit of (32 >> L)^3 voxels
//     kind 4 Full      eight 16^3 network codec units, unit i at offset
//                      (i & 1, (i >> 1) & 1, (i >> 2) & 1) * 16
//     kind 5 Released  the chunk left the view; no payload
//     kind 6 Estimate  one 4^3 unit, as Mip 3, estimated from the world's
//                      generator for a chunk never generated; replaced by
//                      a Mip or Empty record when the exact mip differs
//   (dx, dy, dz) is the chunk position minus the previous record's (the
//   first record's is relative to (0, 0, 0)).
//
// Thread-safety: the writer and the scratch are single-threaded objects;
// decode_stream_batch is reentrant given its own scratch.
#pragma once

#include <cstdint>
#include <functional>
#include <span>
#include <vector>

#include "common/codec/decode_error.h"
#include "common/voxel/box.h"
#include "common/voxel/vec3.h"
#include "protocol/messages.h"

namespace terrane {

enum class StreamRecordKind : std::uint8_t {
  kEmpty = 0,
  kMip1 = 1,
  kMip2 = 2,
  kMip3 = 3,
  kFull = 4,
  kReleased = 5,
  kEstimate = 6,
};

// Records in one batch at most (bounds a receiver's work per frame).
inline constexpr std::size_t kMaxStreamRecords = 4096;
// A server closes a batch once it reaches this size (far below the frame
// limit even with a worst-case Full record after it).
inline constexpr std::size_t kStreamBatchTargetBytes = 64 * 1024;

struct StreamRecord {
  StreamRecordKind kind = StreamRecordKind::kEmpty;
  Vec3i chunk_pos;
  std::uint64_t revision = 0;
  int level = 0;               // 0 for Full, 1..3 for Mip, 3 for Estimate
  const Box* voxels = nullptr; // Full: 32^3; Mip: (32 >> level)^3; else null
};

class StreamBatchWriter {
 public:
  // payload: the record's encoded units (empty for Empty and Released).
  void add(StreamRecordKind kind, Vec3i chunk_pos, std::uint64_t revision, std::span<const std::uint8_t> payload);
  bool empty() const { return records_ == 0; }
  std::size_t records() const { return records_; }
  std::size_t size_bytes() const { return bytes_.size(); }
  // The StreamBatch frame of the records so far; the writer starts over.
  Frame finish();

 private:
  std::vector<std::uint8_t> bytes_;
  Vec3i prev_{0, 0, 0};
  std::size_t records_ = 0;
};

// Scratch buffers for decoding, reusable across batches.
struct StreamDecodeScratch {
  Box unit{Vec3i{16, 16, 16}};
  Box chunk{Vec3i{32, 32, 32}};
  Box mip;
};

// Decodes every record in order and calls fn for each (the Box is valid
// during the call). Stops at the first error, from the bytes (kTruncated,
// kInvalidValue for an unknown kind, an out-of-range position or an
// over-long varint, kOverLimit beyond kMaxStreamRecords, the codec's errors)
// or from fn. Records before the error have been delivered.
Status decode_stream_batch(std::span<const std::uint8_t> records, StreamDecodeScratch& scratch,
                           const std::function<Status(const StreamRecord&)>& fn);

}  // namespace terrane
