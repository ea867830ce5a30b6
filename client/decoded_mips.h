// DecodedMips: the voxels of mip records and horizon images, kept once
// for all the replicas of one process that hold equal voxels.
//
// A process running many clients (the terrane-bots load test) receives
// the same mip of a chunk version once per client whose view holds it at
// that level, and the same horizon image once per client that sees the
// region from afar; kept per client, those copies were most of a bot's
// memory. A replica never changes a mip or an image in place (a record
// replaces it whole; updates apply to full-resolution chunks only), so
// replicas can hold them as one immutable box.
//
// Found by a key the caller derives from the record (a hash of its bytes:
// equal bytes decode to equal voxels), and taken only when the voxels are
// equal too: nothing is trusted across clients but that comparison, so a
// replica holds exactly what its own record says (boxes whose keys are
// equal but voxels differ are kept side by side).
// Weak: a box lives as long as some replica holds it; the table forgets
// the dead ones when it is rebuilt (at 3/4 full), so it is bounded by what
// the replicas hold. The table is flat (open addressing, linear probing):
// a process's bots intern every mip they receive, and a node map's
// lookups cost as much as the rest of applying them.
// Thread-safety: every member may be called from any thread.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <span>
#include <vector>

#include "common/voxel/box.h"

namespace terrane {

class DecodedMips {
 public:
  // The key of a record's bytes (payload) at a level (the same bytes at
  // another level are other voxels).
  static std::size_t key_of(std::span<const std::uint8_t> bytes, int level);
  // The key of voxels themselves (for records whose bytes the caller does
  // not have).
  static std::size_t key_of(const Box& voxels);

  // An immutable box equal to voxels: one kept under key whose voxels are
  // equal, else a new one, kept under key from now on.
  std::shared_ptr<const Box> intern(std::size_t key, const Box& voxels);

  struct Stats {
    std::uint64_t hits = 0, misses = 0;
    std::size_t entries = 0;  // live boxes kept
    std::size_t bytes = 0;    // their voxels and the table (heap)
  };
  Stats stats() const;

 private:
  struct Slot {
    std::size_t key = 0;
    std::weak_ptr<const Box> box;
    bool used = false;  // a box was kept here (alive or dead since)
  };
  // Keeps the live boxes only, in a table of at least twice their number.
  void rebuild();

  mutable std::mutex m_;
  std::vector<Slot> slots_;  // a power of two of them, or none
  std::size_t used_ = 0;     // slots used
  Stats stats_;
};

}  // namespace terrane
