// TickUpdate: one client's UpdateBatch for one committed tick: the changed
// 4^3 units of every chunk it holds at full resolution, joined from each
// version's update piece (encoded once per version, shared by every
// holder), in chunk order (y, z, x), so the joined batch is what one
// encoder would write; with each chunk's new revision. The frame's
// segments share the pieces' bytes (protocol/out_frame.h): it keeps their
// versions alive until it is written.
//
// Threading: the client's session strand (made and finished in one call).
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <vector>

#include "protocol/messages.h"
#include "protocol/out_frame.h"
#include "server/base/chunk_version.h"
#include "server/replication/update_faults.h"

namespace terrane {

class TickUpdate {
 public:
  // v's units go in the batch (one version per chunk).
  void add(VersionPtr v) { versions_.push_back(std::move(v)); }
  bool empty() const { return versions_.empty(); }
  // The UpdateBatch frame of tick, or nullopt when faults (the test seam;
  // null when serving for real) drop it. units: set to the units it holds.
  // codec1: the client reads only network codec version 1 (its pieces are
  // made again in version 1 and copied, not shared).
  std::optional<OutFrame> finish(std::uint64_t tick, UpdateFaults* faults, std::size_t& units, bool codec1 = false);

 private:
  std::vector<VersionPtr> versions_;
};

}  // namespace terrane
