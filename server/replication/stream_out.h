// StreamOut: the stream batch one replicator is filling (protocol/
// stream_batch.h). Records go in in order; the batch goes out as a frame
// once it reaches kStreamBatchTargetBytes or kMaxStreamRecords, or when the
// replicator flushes it. A changed mip goes in as a Mip patch (its changed
// 4^3 sub-units) when the version can tell what changed since the revision
// held and the patch is smaller than the whole mip.
//
// It sends through the callbacks it is given: can_send (the session is
// attached; until then a batch waits) and send (the frame, counted and
// queued by the owner).
//
// The units it is given are the server's (kServedCodecVersion). For a
// client that reads only network codec version 1 (set_codec1), each record's
// units go in transcoded to version 1 (copied, not shared).
// Thread-safety: one strand (the replicator's session strand).
#pragma once

#include <cstdint>
#include <functional>
#include <span>
#include <utility>
#include <vector>

#include "common/world/horizon.h"
#include "protocol/stream_batch.h"
#include "server/base/chunk_version.h"

namespace terrane {

class StreamOut {
 public:
  StreamOut(std::function<bool()> can_send, std::function<void(OutFrame)> send)
      : can_send_(std::move(can_send)), send_(std::move(send)) {}

  // Whether the client reads only version-1 units (it did not set
  // kFeatureCodec2).
  void set_codec1(bool codec1) { codec1_ = codec1; }
  // A record (payload: its encoded units, shared with owner when given).
  void record(StreamRecordKind kind, Vec3i chunk_pos, std::uint64_t revision,
              std::span<const std::uint8_t> payload = {}, const VersionPtr& owner = nullptr);
  // A Horizon record (StreamBatchWriter::add_horizon).
  template <class T>
  void horizon(Vec3i region, int level, const HorizonMask* mask, std::span<const std::uint8_t> unit,
               const std::shared_ptr<T>& owner) {
    if (codec1_) {
      batch_.add_horizon(region, level, mask, version1(horizon_side(level), 1, unit));
    } else {
      batch_.add_horizon(region, level, mask, unit, owner);
    }
    flush_if_full();
  }
  // The mip of level (1 or 2) held at revision held, changed in v, as a
  // Mip patch: true if it went in; false (nothing added) when v cannot
  // tell what changed since held or the whole mip is not larger.
  bool mip_patch(Vec3i chunk_pos, int level, std::uint64_t held, const ChunkVersion& v);
  // Sends the records so far, if any and if it can.
  void flush();
  // Bytes of the records not yet sent.
  std::size_t pending_bytes() const { return batch_.size_bytes(); }

 private:
  void flush_if_full();
  // count units of n^3 from units, as version 1, in transcoded_.
  std::span<const std::uint8_t> version1(int n, std::size_t count, std::span<const std::uint8_t> units);

  std::function<bool()> can_send_;
  std::function<void(OutFrame)> send_;
  StreamBatchWriter batch_;
  std::vector<std::uint8_t> units_;  // a patch's units, reused
  bool codec1_ = false;
  std::vector<std::uint8_t> transcoded_;  // a record's units as version 1, reused
};

}  // namespace terrane
