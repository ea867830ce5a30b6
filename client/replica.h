// Replica: a client's copy of the part of the world the server sent it.
//
// Per 32^3 chunk it tracks coverage — what it knows and at which
// resolution — so Air is never confused with "not received":
//   - none:     nothing known (never sent, or released);
//   - Empty:    known all Air (at full resolution);
//   - Mip L:    the (32 >> L)^3 mip of the chunk, L in 1..3; or L in 4..5
//               from its region's horizon image (approximate, kept once per
//               8^3-chunk region, replaced by the chunk's own record; never
//               claimed, hashed or edited);
//   - Full:     every voxel, at the revision the server stated.
// Full-resolution voxels live in a Grid; per chunk, one entry holds its
// coverage, its mip voxels (a Box) and its cached region hash.
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
#include "common/codec/update_batch.h"
#include "common/voxel/box.h"
#include "common/voxel/grid.h"
#include "common/voxel/vec3_map.h"
#include "common/world/horizon.h"
#include "protocol/messages.h"
#include "protocol/stream_batch.h"

namespace terrane {

enum class CoverageState : std::uint8_t { kEmpty, kMip, kFull };

struct ChunkCoverage {
  CoverageState state = CoverageState::kEmpty;
  int level = 0;  // kMip: 1..3, or 4..5 from a horizon image; otherwise 0
  std::uint64_t revision = 0;
  // kMip level 3 from an Estimate record: the server's estimate for a chunk
  // never generated, not yet its mip (never claimed in Holdings).
  bool estimate = false;
};

// resolution_at(): -1 nothing known, 0 full resolution (or known Air),
// 1..5 the mip level held.
inline constexpr int kNoResolution = -1;

class Replica {
 public:
  Replica();

  // Full records' chunks are looked up in, and added to, shared (a cache
  // shared with the process's other replicas; null: none).
  void share_decoded(std::shared_ptr<DecodedChunks> shared) { shared_ = std::move(shared); }

  Status apply_chunk_data(const ChunkDataMsg& m);
  // A decoded StreamBatch record (protocol/stream_batch.h).
  void apply_stream_record(const StreamRecord& r);
  // A Horizon record (precondition: r.kind is kHorizon): the chunks of its
  // mask with no coverage are covered by the region's image from now on
  // (a horizon image never replaces anything); appends each to covered.
  void apply_horizon(const StreamRecord& r, std::vector<Vec3i>& covered);
  Status apply_mip_data(const MipDataMsg& m);
  void apply_coverage(const CoverageMsg& m);
  // Applies the units of chunks held at full resolution (others are
  // ignored) and takes the batch's revisions. Returns the units applied.
  // Errors: the codec's, or kInvalidValue for a unit of a chunk the batch
  // lists no revision for. With changed set, appends per chunk applied the
  // voxel box its units cover.
  Result<std::size_t> apply_update_batch(const UpdateBatchMsg& m, std::vector<Region>* changed = nullptr);

  // --- queries ---------------------------------------------------------------
  // Valid until the replica changes.
  const ChunkCoverage* coverage(Vec3i chunk_pos) const;
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
  // Region hash (protocol/messages.h) of a chunk held at full resolution
  // (Full or Empty); nullopt otherwise.
  std::optional<std::uint64_t> hash(Vec3i chunk_pos) const;
  std::optional<std::uint64_t> revision(Vec3i chunk_pos) const;
  // The (32 >> L)^3 voxels of a chunk held as mip level L (coverage kMip)
  // into out, and true; false (out unchanged) otherwise.
  bool read_mip(Vec3i chunk_pos, Box& out) const;

  std::size_t chunk_count(CoverageState state) const;
  // Chunks held as estimates now.
  std::size_t estimate_count() const;
  // Mip records that brought a chunk's level again with the very voxels
  // held at that level (a refresh that told nothing; the server avoids them).
  std::uint64_t redundant_mips() const { return redundant_mips_; }
  std::size_t chunk_count() const { return chunks_.size() + horizon_chunks_; }
  const Grid& grid() const { return grid_; }
  template <class F>
  void for_each_coverage(F&& f) const {
    for (const auto& [pos, e] : chunks_) f(pos, e.coverage);
    for (const auto& [region, h] : horizons_)
      for_each_region_chunk(region, [&](Vec3i cp) {
        if (h.covers.test(static_cast<std::size_t>(coarse_index(cp)))) f(cp, h.coverage);
      });
  }

 private:
  // What the replica has of one chunk (beside its voxels in grid_ when
  // Full): one entry, so a record costs one lookup.
  struct Entry {
    ChunkCoverage coverage;
    // coverage kMip: the (32 >> level)^3 voxels of the chunk's own record
    // (apart, so the table's slots stay small: a replica's tables are
    // read far more than its mips).
    std::unique_ptr<Box> mip;
    // Its region hash, computed since the chunk last changed (a hash is a
    // pass over 32^3 voxels; a client checks the same unchanged chunks
    // again and again).
    mutable std::optional<std::uint64_t> hash;
  };
  // A region's horizon image and the chunks it still covers (those with no
  // coverage of their own), which share one coverage value.
  struct Horizon {
    ChunkCoverage coverage;
    Box image;
    std::bitset<kHorizonRegionSlots> covers;
  };
  // The voxels a chunk's mip is read from: a box, the chunk's corner in it
  // and the level (box null: no mip held).
  struct MipView {
    const Box* box = nullptr;
    Vec3i origin;
    int level = 0;
  };
  MipView mip_view(Vec3i chunk_pos) const;
  const Horizon* horizon_of(Vec3i chunk_pos) const;
  // The chunk is no longer covered by its region's image (it has coverage
  // of its own now, or none).
  void forget_horizon(Vec3i chunk_pos);
  // The 16^3 units of a chunk on its way to full resolution, gathered so the
  // chunk is packed once when Coverage Full arrives (writing units into a
  // packed chunk one by one repacks it each time).
  struct Pending {
    Box voxels;
    std::uint8_t received = 0;  // bit per unit: (uz*2+uy)*2+ux order of unit index
  };
  static constexpr std::size_t kMaxPendingChunks = 64;

  void write_unit(Vec3i unit_pos, const Box& unit);
  void flush_pending(Vec3i chunk_pos);
  // A chunk's voxels, coverage or revision changed: its cached hash is
  // gone, and its region's horizon image no longer covers it. Every write
  // of grid_ or of an entry calls it (or, holding the entry, entry_changed()).
  void voxels_changed(Vec3i chunk_pos) {
    if (auto it = chunks_.find(chunk_pos); it != chunks_.end()) it->second.hash.reset();
    if (!horizons_.empty()) forget_horizon(chunk_pos);
  }
  void entry_changed(Vec3i chunk_pos, Entry& e) {
    e.hash.reset();
    if (!horizons_.empty()) forget_horizon(chunk_pos);
  }

  Grid grid_;
  Vec3iMap<Entry> chunks_;  // every chunk with coverage of its own
  Vec3iMap<Pending> pending_;
  Vec3iMap<Horizon> horizons_;     // by region
  std::size_t horizon_chunks_ = 0;  // chunks covered by horizons_
  Box unit_scratch_;
  std::vector<UnitUpdate> update_scratch_;
  std::uint64_t redundant_mips_ = 0;
  std::shared_ptr<DecodedChunks> shared_;
};

}  // namespace terrane
