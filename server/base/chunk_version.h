// ChunkVersion: one revision of one chunk, immutable once published, shared
// by every reader (replicators on their session strands, the storage writer,
// the world). What readers derive from it — the encoding of each level, the
// tick's 4^3 update units, the chunk hash — is computed
// once, lazily, by whichever thread asks first, and then shared.
//
// A null chunk is all Air. changed_units names the 4^3 units the tick that
// made this version changed (empty for versions loaded or generated).
// level_since[L] is the revision since which level L's voxels are what they
// are in this version: a client holding level L at a revision >= that holds
// exactly these bytes, so a refresh would tell it nothing.
//
// Thread-safety: every member is const after publication; the lazy parts
// are guarded by std::call_once.
#pragma once

#include <array>
#include <atomic>
#include <bitset>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <vector>

#include "common/codec/update_batch.h"
#include "common/voxel/chunk.h"
#include "common/world/coarse_image.h"

namespace terrane {

using UnitBits = std::bitset<kUpdateUnitsPerChunk>;

// The network codec format of every unit the server makes (chunk levels,
// patches, update pieces, horizon images): version 2, which a client that
// set kFeatureCodec2 reads; for one that did not, the units go out
// transcoded to version 1 (StreamOut, TickUpdate).
inline constexpr std::uint8_t kServedCodecVersion = kNetCodecVersion2;

// How often a level's encoding was asked for and how often it had to be
// made (the rest were served from a version's own copy): process-wide.
struct EncodeCounters {
  std::atomic<std::uint64_t> asked{0}, made{0};
};
EncodeCounters& encode_counters();

class ChunkVersion {
 public:
  ChunkVersion(Vec3i pos, std::uint64_t revision, std::shared_ptr<const Chunk> chunk, UnitBits changed_units,
               std::array<std::uint64_t, kMipLevels> level_since);
  // A version as loaded or generated: every level is current since revision.
  ChunkVersion(Vec3i pos, std::uint64_t revision, std::shared_ptr<const Chunk> chunk);
  // The mips of full without its voxels: what the world keeps of a chunk
  // nobody holds at full resolution (a few hundred bytes instead of the
  // chunk). encoded() answers levels 1..3 only; the rest needs the chunk.
  static std::shared_ptr<const ChunkVersion> mips_only(const ChunkVersion& full);
  // The version after prev (revision + 1, with voxels): chunk's voxels
  // (null or empty: all Air; packed here, so its mips are encoded once for
  // every reader), changed the units in changed; each level's level_since
  // moves on only where its voxels differ from prev's.
  static std::shared_ptr<const ChunkVersion> after(const ChunkVersion& prev, std::unique_ptr<Chunk> chunk,
                                                   UnitBits changed);
  // Only the coarsest level (4^3), as a coarse image stored it: what a
  // distant view needs, without reading the chunk. encoded() answers level
  // 3 only.
  static std::shared_ptr<const ChunkVersion> coarse_only(Vec3i pos, std::uint64_t revision, const CoarseVoxels& voxels);
  // An estimate of a never-generated chunk's coarsest level
  // (World::estimate_coarse), revision 0: like coarse_only, but never empty
  // (Empty would claim the chunk all Air at full resolution; an all-Air
  // estimate is sent as a mip) and marked estimate(), to be replaced when
  // the chunk is generated.
  static std::shared_ptr<const ChunkVersion> estimated(Vec3i pos, const CoarseVoxels& voxels);

  Vec3i pos() const { return pos_; }
  std::uint64_t revision() const { return revision_; }
  const Chunk* chunk() const { return chunk_.get(); }
  bool empty() const { return empty_; }
  // False for a mips_only, coarse_only or estimated version.
  bool has_voxels() const { return has_voxels_; }
  // True for an estimated version: its level 3 is not the chunk's mip.
  bool estimate() const { return estimate_; }
  // Whether encoded(level) can answer: every level for a chunk with its
  // voxels, 1..3 for mips_only, 3 for coarse_only.
  bool has_level(int level) const { return level >= finest_level_; }
  const UnitBits& changed_units() const { return history_ && has_voxels_ ? history_->changed_units : no_units(); }
  std::uint64_t level_since(int level) const { return level_since_[static_cast<std::size_t>(level)]; }

  // Network codec bytes: level 0 is the eight 16^3 units in unit index order
  // (a Full stream record), levels 1..3 one (32 >> L)^3 unit. The rest of
  // the methods below need has_voxels().
  std::span<const std::uint8_t> encoded(int level) const;
  // Mip patches (PROTOCOL.md, "Stream batches", kind 10): the sub-units of
  // level (1 or 2) whose voxels may differ between revision held_revision
  // and this one (bit i: sub-unit i, patch_subunit_origin), or nullopt when
  // this version cannot tell: held_revision is not older, or more than
  // kPatchHistory revisions older, or a version in between was not made by
  // after() (loaded, generated, from another server). A superset: a
  // sub-unit any changed 4^3 unit of level 0 reaches (the mips' rule is
  // local to each 2^L cube).
  static constexpr int kPatchHistory = 8;
  std::optional<std::uint64_t> changed_since(int level, std::uint64_t held_revision) const;
  // The 4^3 network codec units of level's sub-units in mask, ascending,
  // appended to out (each encoded once per version, by the first asker).
  // Precondition: has_level(level), level 1 or 2.
  void append_patch_units(int level, std::uint64_t mask, std::vector<std::uint8_t>& out) const;
  // The changed units as one update piece (precondition: changed_units()
  // is not empty), in kServedCodecVersion.
  const UpdatePiece& update_piece() const;
  // The same piece made again in codec_version (not kept: for a client
  // that reads only version 1).
  UpdatePiece make_update_piece(std::uint8_t codec_version) const;
  // protocol/messages.h chunk_hash of this chunk and revision.
  std::uint64_t hash() const;
  // The world store's blob (WORLD_FORMAT.md, "Chunk blobs"), made at each
  // call: the writer asks once per version it stores, and a version held
  // long after its commit kept a copy it never used again (a few kB for
  // every chunk edited).
  std::vector<std::uint8_t> blob() const;

 private:
  // What a version made by after() knows of the edits before it: the units
  // its tick changed and the level-1 sub-units changed since each of the
  // last patch_history revisions. Out of line, and shared by a version's
  // mips_only copy (which has no changed units: changed_units() answers
  // none without voxels): most versions (loaded, generated or coarse;
  // hundreds of thousands at a time with a thousand clients) have none.
  struct EditHistory {
    UnitBits changed_units;
    // level1_changed[k]: the level-1 sub-units changed from revision - k -
    // 1 to this one, for k < patch_history (0: no history).
    std::array<std::uint64_t, kPatchHistory> level1_changed{};
    std::uint8_t patch_history = 0;
  };
  // Bytes made once on demand and then shared: exactly their size (a
  // vector kept its growth's spare capacity, and 24 bytes of its own for
  // every level of every version, used or not).
  struct Bytes {
    std::unique_ptr<std::uint8_t[]> data;
    std::uint32_t size = 0;
    std::span<const std::uint8_t> span() const { return {data.get(), size}; }
    void assign(std::span<const std::uint8_t> bytes);
    // Keeps what encode(std::vector<std::uint8_t>&) appends, made in a
    // scratch vector of the calling thread's.
    template <class Encode>
    void make(Encode&& encode) {
      thread_local std::vector<std::uint8_t> scratch;
      scratch.clear();
      encode(scratch);
      assign(scratch);
    }
  };
  // Levels 1 and 2's sub-units, encoded: their bytes back to back and where
  // each starts (the last entry: the end).
  struct PatchUnits {
    std::vector<std::uint8_t> bytes;
    std::vector<std::uint32_t> starts;
  };
  // A version holding level 3 only, from its voxels (coarse_only, estimated).
  static std::shared_ptr<ChunkVersion> level3_only(Vec3i pos, std::uint64_t revision, const CoarseVoxels& voxels);
  static const UnitBits& no_units();

  Vec3i pos_;
  bool empty_ = true;
  bool has_voxels_ = true;
  bool estimate_ = false;
  std::uint8_t finest_level_ = 0;
  std::uint64_t revision_;
  std::shared_ptr<const Chunk> chunk_;
  std::array<std::uint64_t, kMipLevels> level_since_;
  std::shared_ptr<const EditHistory> history_;  // null: no changed units, no patch history

  mutable std::array<std::once_flag, kMipLevels> encoded_once_;
  mutable std::array<Bytes, kMipLevels> encoded_;
  mutable std::once_flag piece_once_, hash_once_;
  mutable std::array<std::once_flag, 2> patch_once_;
  // Made by the first to ask (most versions are never asked).
  mutable std::array<std::unique_ptr<PatchUnits>, 2> patch_units_;
  mutable std::unique_ptr<UpdatePiece> piece_;
  mutable std::uint64_t hash_ = 0;
};

// What every chunk held costs the world: a published version of a chunk
// nobody edited is its pointers, revisions and once-flags (the voxels and
// encodings beside it).
static_assert(sizeof(ChunkVersion) <= 256);

using VersionPtr = std::shared_ptr<const ChunkVersion>;

// The levels of next whose voxels differ from prev's (bit L set for level L;
// level 0 is the chunk itself). Either may be null (all Air).
std::array<bool, kMipLevels> levels_changed(const Chunk* prev, const Chunk* next);

}  // namespace terrane
