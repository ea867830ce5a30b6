#include "server/replication/stream_out.h"

#include <bit>

#include "server/base/log.h"

namespace terrane {

void StreamOut::record(StreamRecordKind kind, Vec3i cp, std::uint64_t revision, std::span<const std::uint8_t> payload,
                       const VersionPtr& owner) {
  if (codec1_ && !payload.empty()) {
    // Kinds 0..5 as PROTOCOL.md's "Stream batches": Full is eight 16^3
    // units, Mip L one (32 >> L)^3, Estimate one 4^3.
    const bool full = kind == StreamRecordKind::kFull;
    const int level = kind == StreamRecordKind::kEstimate ? kMipLevels - 1 : static_cast<int>(kind);
    batch_.add(kind, cp, revision, version1(full ? kChunkSize / 2 : kChunkSize >> level, full ? 8 : 1, payload));
  } else {
    batch_.add(kind, cp, revision, payload, owner);
  }
  flush_if_full();
}

std::span<const std::uint8_t> StreamOut::version1(int n, std::size_t count, std::span<const std::uint8_t> units) {
  transcoded_.clear();
  const auto used = net_codec_append_version1(n, count, units, transcoded_);
  if (!used || *used != units.size()) {
    // The server's own units: a failure is a bug. The record goes as it
    // is, so the client refuses it with a decode error (an unknown unit
    // version) rather than hold a chunk the server thinks it sent.
    server_log().error("stream record units do not make {} units of {}^3 for a version-1 client", count, n);
    return units;
  }
  return transcoded_;
}

bool StreamOut::mip_patch(Vec3i cp, int level, std::uint64_t held, const ChunkVersion& v) {
  const std::optional<std::uint64_t> mask = v.changed_since(level, held);
  if (!mask || *mask == 0) return false;
  units_.clear();
  v.append_patch_units(level, *mask, units_);
  // Level, mask and units against the whole unit.
  if (1 + static_cast<std::size_t>(patch_mask_bytes(level)) + units_.size() >= v.encoded(level).size()) return false;
  const auto units = codec1_ ? version1(4, static_cast<std::size_t>(std::popcount(*mask)), units_)
                             : std::span<const std::uint8_t>(units_);
  batch_.add_mip_patch(cp, v.revision(), level, *mask, units);
  flush_if_full();
  return true;
}

void StreamOut::flush() {
  if (batch_.empty() || !can_send_()) return;
  send_(batch_.finish());
}

void StreamOut::flush_if_full() {
  if (batch_.size_bytes() >= kStreamBatchTargetBytes || batch_.records() >= kMaxStreamRecords) flush();
}

}  // namespace terrane
