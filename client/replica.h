// Replica: a client's copy of the part of the world the server sent it.
//
// Per 32^3 chunk it keeps what it holds (a Holding, protocol/holding.h),
// so Air is never confused with "not received": nothing (never sent, or
// released), Empty, Mip 1..3, an Estimate, Full, or a horizon image's 2^3
// or 1 voxel (approximate, kept once per 8^3-chunk region, replaced by the
// chunk's own record; never claimed, hashed or edited).
// Full-resolution voxels live in a Grid (a chunk taken from the process's
// DecodedChunks is held shared until an update changes it here); per
// chunk, one entry (in a ChunkTable) holds its holding and its mip (a Full
// chunk's cached hash is kept apart). Mips (kept as their records' units
// until a patch changes them) and horizon images (boxes) are immutable,
// replaced whole by the next record, so the replicas of one process that
// hold equal ones share one copy (DecodedMips, through share_decoded); a
// replica on its own keeps its own.
//
// Apply functions take parsed messages (protocol/messages.h) whose voxel
// payloads are still untrusted: every decode error is returned and leaves
// the replica consistent (at worst a chunk keeps older voxels).
// Thread-safety: none; the Client guards its Replica with a mutex.
#pragma once

#include <bitset>
#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

#include "client/decoded_chunks.h"
#include "client/chunk_table.h"
#include "common/codec/update_batch.h"
#include "common/voxel/box.h"
#include "common/voxel/grid.h"
#include "common/voxel/vec3_map.h"
#include "common/world/horizon.h"
#include "protocol/messages.h"
#include "protocol/stream_batch.h"

namespace terrane {

// resolution_at(): -1 nothing known, 0 full resolution (or known Air),
// 1..5 the mip level held.
inline constexpr int kNoResolution = -1;

// A replica's heap bytes by part (Replica::memory()). Voxels shared with
// other replicas count as their share: bytes / holders.
struct ReplicaMemory {
  GridMemory full;                     // full-resolution chunks (the Grid)
  std::size_t entry_table_bytes = 0;   // per chunk held: holding, mip handle (ChunkTable); Full chunks' hashes
  std::size_t mips = 0;                // mips and estimates held
  std::size_t mip_bytes = 0;           // their voxels
  std::size_t horizon_table_bytes = 0; // per region: holding, image handle, mask
  std::size_t horizon_image_bytes = 0;
  std::size_t total() const {
    return full.total() + entry_table_bytes + mip_bytes + horizon_table_bytes + horizon_image_bytes;
  }
  ReplicaMemory& operator+=(const ReplicaMemory& o);
};

// One voxel an UpdateBatch changed, with its value before and after.
struct VoxelChange {
  Vec3i voxel_pos;
  Voxel before;
  Voxel after;
};
// What apply_update_batch records of the voxels it changes: those whose
// value differs after the batch, in the order applied, at most max (a
// batch may change a whole chunk: the record is bounded); truncated once
// more changed than were recorded.
struct VoxelChanges {
  std::size_t max = 0;
  std::vector<VoxelChange> changes;
  bool truncated = false;
};

class Replica {
 public:
  Replica();

  // Full records' chunks are looked up in, and added to, shared (a cache
  // shared with the process's other replicas; null: none), and mips and
  // horizon images are kept in its mips().
  void share_decoded(std::shared_ptr<DecodedChunks> shared) { shared_ = std::move(shared); }
  // How the chunks of Full records hold their mips (Chunk::Mips; kKept
  // unless set): kDerived for a replica that rarely reads a full chunk's
  // mips (a load test's bots), which then costs neither their making nor
  // their bytes.
  void set_full_chunk_mips(Chunk::Mips mips) { full_mips_ = mips; }

  // A decoded StreamBatch record (protocol/stream_batch.h): the chunk is
  // held in the record's form from now on (Released: not held); a Mip
  // patch changes the mip held (ignored unless patchable(r)).
  void apply_stream_record(const StreamRecord& r);
  // Whether a Mip patch record applies: its chunk is held as the mip of
  // its level (else the server broke the protocol).
  bool patchable(const StreamRecord& r) const;
  // A Horizon record (precondition: r.kind is kHorizon): the chunks of its
  // mask not held by the client are held as its Horizon form from now on
  // (a horizon image never replaces anything); appends each to covered.
  void apply_horizon(const StreamRecord& r, std::vector<Vec3i>& covered);
  // Applies the units of chunks held at full resolution (others are
  // ignored) and takes the batch's revisions. Returns the units applied.
  // Errors: the codec's, or kInvalidValue for a unit of a chunk the batch
  // lists no revision for. With changed set, appends per chunk applied the
  // voxel box its units cover. With voxels set, records each voxel whose
  // value the batch changed as it was before and is now (read in the same
  // pass that writes it; nothing recorded costs nothing).
  Result<std::size_t> apply_update_batch(const UpdateBatchMsg& m, std::vector<Region>* changed = nullptr,
                                         VoxelChanges* voxels = nullptr);

  // --- queries ---------------------------------------------------------------
  // Valid until the replica changes.
  // What the replica holds of the chunk; null when nothing.
  const Holding* holding(Vec3i chunk_pos) const;
  int resolution_at(Vec3i voxel) const;
  // The voxel at the best resolution held (a mip voxel stands for the 2^L
  // cube it covers); Air where nothing is known — check resolution_at.
  Voxel get(Vec3i voxel) const;
  // Full-resolution voxels of [min, min + out.size()); Air elsewhere.
  void read_box(Vec3i min, Box& out) const;
  // Ray cast through full-resolution data only.
  std::optional<RayHit> raycast(Vec3f origin, Vec3f direction, float max_distance) const;
  // The y just above the highest non-Air voxel of column (x, z) within
  // [min_y, max_y), reading the best resolution held; nullopt if none.
  std::optional<std::int32_t> surface_height(std::int32_t x, std::int32_t z, std::int32_t min_y,
                                             std::int32_t max_y) const;
  // Chunk hash (protocol/messages.h) of a chunk held at full resolution
  // (Full or Empty); nullopt otherwise.
  std::optional<std::uint64_t> hash(Vec3i chunk_pos) const;
  std::optional<std::uint64_t> revision(Vec3i chunk_pos) const;
  // The (32 >> L)^3 voxels of a chunk held coarser than full resolution
  // (level L of its holding) into out, and true; false (out unchanged)
  // otherwise.
  bool read_mip(Vec3i chunk_pos, Box& out) const;
  // The payload of the stream record that gives a chunk held in an exact
  // form (claimable: Full, Mip 1..3, Empty) its voxels, appended to out
  // (Full: its eight 16^3 units; a mip: its unit; Empty: nothing), and its
  // holding; nullopt (out unchanged) when the chunk is not held so. What a
  // client keeps across sessions (client/chunk_cache.h).
  std::optional<Holding> exact_payload(Vec3i chunk_pos, std::vector<std::uint8_t>& out) const;

  // Chunks held in this form.
  std::size_t chunk_count(HoldingForm form) const;
  // Chunks held as estimates now.
  std::size_t estimate_count() const;
  // Mip records that brought a chunk's level again with the very voxels
  // held at that level (a refresh that told nothing; the server avoids them).
  std::uint64_t redundant_mips() const { return redundant_mips_; }
  std::size_t chunk_count() const { return chunks_.size() + horizon_chunks_; }
  const Grid& grid() const { return grid_; }
  ReplicaMemory memory() const;
  template <class F>
  void for_each_holding(F&& f) const {
    chunks_.for_each([&](Vec3i pos, const Entry& e) { f(pos, e.holding); });
    for (const auto& entry : horizons_)
      for_each_region_chunk(entry.first, [&, &h = entry.second](Vec3i cp) {
        if (h.covers.test(static_cast<std::size_t>(coarse_index(cp)))) f(cp, h.holding);
      });
  }

 private:
  // What the replica has of one chunk (beside its voxels in grid_ when
  // Full): one entry, so a record costs one lookup.
  struct Entry {
    Holding holding;
    // A mip or an Estimate: the (32 >> level)^3 voxels of the chunk's own
    // record (kept as its unit: a bot holds thousands of mips and reads
    // few; as voxels once a patch changed it), immutable and perhaps shared
    // with other replicas (apart, so the table's slots stay small: a
    // replica's tables are read far more than its mips).
    std::shared_ptr<const MipVoxels> mip;
  };
  // A region's horizon image and the chunks it still covers (those not held
  // by a record of their own), which share one holding (Horizon4 or 5).
  struct Horizon {
    Holding holding;
    std::shared_ptr<const Box> image;  // immutable, perhaps shared
    std::bitset<kHorizonRegionSlots> covers;
  };
  // The voxels a chunk's mip is read from: a box, the chunk's corner in it
  // and the level (box null: no mip held). A mip kept as its unit is read
  // from this thread's last decoded mip: the box is valid until the next
  // mip_view on the thread.
  struct MipView {
    const Box* box = nullptr;
    Vec3i origin;
    int level = 0;
  };
  MipView mip_view(Vec3i chunk_pos) const;
  // The immutable box equal to voxels: the one the process's replicas
  // share under key, or a box of this replica's own.
  std::shared_ptr<const Box> keep(std::size_t key, const Box& voxels);
  // The same for a mip record (its unit: the payload, or its voxels
  // encoded when it came without one), and for a patched mip's voxels.
  std::shared_ptr<const MipVoxels> keep_unit(const StreamRecord& r);
  std::shared_ptr<const MipVoxels> keep_mip(const Box& voxels);
  // A record's voxels (decoded again when the decoder skipped them).
  static const Box& voxels_of(const StreamRecord& r);
  const Horizon* horizon_of(Vec3i chunk_pos) const;
  // The chunk is no longer covered by its region's image (it is held by a
  // record of its own now, or not at all).
  void forget_horizon(Vec3i chunk_pos);
  // A chunk's voxels, holding or revision changed: its cached hash is
  // gone, and its region's horizon image no longer covers it. Every write
  // of grid_ or of an entry calls it.
  void voxels_changed(Vec3i chunk_pos) {
    if (!hashes_.empty()) hashes_.erase(chunk_pos);
    if (!horizons_.empty()) forget_horizon(chunk_pos);
  }

  Grid grid_;
  ChunkTable<Entry> chunks_;  // every chunk held by a record of its own
  // The chunk hash of Full chunks, computed since the chunk last changed (a
  // hash is a pass over 32^3 voxels; a client checks the same unchanged
  // chunks again and again). Apart from the entries: a replica holds a few
  // hundred Full chunks among thousands of mips and Empty chunks (whose
  // hash is its revision's, made when asked).
  mutable Vec3iMap<std::uint64_t> hashes_;
  Vec3iMap<Horizon> horizons_;     // by region
  std::size_t horizon_chunks_ = 0;  // chunks covered by horizons_
  std::uint64_t redundant_mips_ = 0;
  std::shared_ptr<DecodedChunks> shared_;
  Chunk::Mips full_mips_ = Chunk::Mips::kKept;
};

}  // namespace terrane
