#include "server/replication/stream_out.h"

namespace terrane {

void StreamOut::record(StreamRecordKind kind, Vec3i cp, std::uint64_t revision, std::span<const std::uint8_t> payload,
                       const VersionPtr& owner) {
  batch_.add(kind, cp, revision, payload, owner);
  flush_if_full();
}

bool StreamOut::mip_patch(Vec3i cp, int level, std::uint64_t held, const ChunkVersion& v) {
  const std::optional<std::uint64_t> mask = v.changed_since(level, held);
  if (!mask || *mask == 0) return false;
  units_.clear();
  v.append_patch_units(level, *mask, units_);
  // Level, mask and units against the whole unit.
  if (1 + static_cast<std::size_t>(patch_mask_bytes(level)) + units_.size() >= v.encoded(level).size()) return false;
  batch_.add_mip_patch(cp, v.revision(), level, *mask, units_);
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
