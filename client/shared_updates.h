// SharedUpdates: the chunks that updates made of shared chunks, so the
// replicas of one process that hold one chunk apply each update to it once.
//
// A server sends every client holding a chunk at full resolution the same
// units for each of the chunk's ticks, and a process running many clients
// (the terrane-bots load test) holds that chunk once, shared
// (DecodedChunks, Grid::put_shared_chunk), until an update changes it; a
// replica that applied the update on its own copy paid the copy, the rows'
// repacking and the mips' update once per client: in a crowd, most of a
// bot's CPU. Here the first replica to apply an update to a shared chunk
// keeps the result under (that chunk, those units); every replica holding
// the same chunk object that is sent the same units takes the result as
// it is, shared again.
// Lineages: replicas that hold equal voxels in two chunk objects (one took
// the chunk's Full record as it came into view, the others made it by
// updates) would each make every later tick's result for themselves. So a
// result is also kept as its chunk's twin at its revision, and a replica
// whose base or result has an equal twin (voxel by voxel) takes the twin's
// lineage: one compare, once, instead of one make per tick.
// Nothing is trusted across clients but equality: an entry is taken only
// when its base is the very chunk object the replica holds (shared chunks
// are immutable) and its units equal the replica's own, voxel by voxel,
// or when the replica's own chunk equals the twin voxel by voxel (the
// revision only says where to look), so the result is what the replica's
// own apply would make.
// A result lives as long as some replica holds it, or while it is among
// the kKept newest results: the replicas of a process do not all apply a
// tick at once, and one that comes late, after the first has gone on to
// the next tick's, still takes the result instead of starting a lineage
// of its own. An entry whose base or result died is dropped when the
// table is full (kCapacity entries, or kMaxUnits units copied); so the
// table is bounded, and holds kKept chunks at most.
// Thread-safety: every member may be called from any thread.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <unordered_map>
#include <vector>

#include "common/codec/update_batch.h"
#include "common/voxel/chunk.h"
#include "common/voxel/vec3.h"

namespace terrane {

class SharedUpdates {
 public:
  static constexpr std::size_t kCapacity = 16384;
  static constexpr std::size_t kKept = 1024;
  // The units the entries copy, at most (a batch's units come from the
  // server: 512 a chunk at most, so entries are bounded by bytes too).
  static constexpr std::size_t kMaxUnits = 65536;

  // The key of units (one chunk's, in the batch's order) applied to base,
  // for find and add (computed once per apply).
  static std::size_t key_of(const Chunk* base, std::span<const UnitUpdate> units);
  // Where a chunk's twins are kept: its position and revision.
  struct At {
    Vec3i chunk_pos;
    std::uint64_t revision = 0;
    friend bool operator==(const At&, const At&) = default;
  };

  // What units made of base, if a replica applied them to this same base,
  // or to base's twin at `at` (base's position and revision) and base
  // equals it; else null. key: key_of(base, units).
  std::shared_ptr<const Chunk> find(std::size_t key, const std::shared_ptr<const Chunk>& base,
                                    std::span<const UnitUpdate> units, std::optional<At> at = std::nullopt);
  // Keeps result as what units made of base (key: key_of(base, units)),
  // and returns the chunk the caller is to hold: result, the result
  // another replica kept for this very base and these units meanwhile (two
  // replicas that applied the same tick at once on two threads then hold
  // one chunk again, and their next ticks find each other's results), or
  // the twin kept at `at` (the result's position and revision) when its
  // voxels equal result's. result may be null: the chunk became all Air,
  // and nothing is kept.
  std::shared_ptr<const Chunk> add(std::size_t key, const std::shared_ptr<const Chunk>& base,
                                   std::span<const UnitUpdate> units, const std::shared_ptr<const Chunk>& result,
                                   std::optional<At> at = std::nullopt);

  struct Stats {
    std::uint64_t hits = 0, misses = 0;
    std::uint64_t adopted = 0;  // of the misses: results made at once by two replicas, one kept for both
    std::uint64_t twins = 0;    // lineages joined: a base or a result found equal to its twin
    std::size_t entries = 0;
    std::size_t bytes = 0;  // the entries, their units and the kept results' share (heap)
  };
  Stats stats() const;

 private:
  struct Entry {
    std::weak_ptr<const Chunk> base;
    std::vector<UnitUpdate> units;
    std::weak_ptr<const Chunk> result;
  };
  struct AtHash {
    std::size_t operator()(const At& a) const noexcept;
  };
  // The entry for key if it is for this very base and these units (under m_).
  const Entry* entry_for(std::size_t key, const std::shared_ptr<const Chunk>& base,
                         std::span<const UnitUpdate> units) const;
  // Keeps result as what units made of base, under key (under m_; the
  // table bounded first).
  void remember(std::size_t key, const std::shared_ptr<const Chunk>& base, std::span<const UnitUpdate> units,
                const std::shared_ptr<const Chunk>& result);
  // Drops the entries and twins whose chunks died (under m_).
  void drop_dead();

  mutable std::mutex m_;
  // By key (one entry per key: of two whose keys are equal, the newer is kept).
  std::unordered_map<std::size_t, Entry> entries_;
  // One result per position and revision, the first kept (at most
  // kCapacity: the dead are dropped, then all, as entries_).
  std::unordered_map<At, std::weak_ptr<const Chunk>, AtHash> twins_;
  std::size_t units_held_ = 0;  // the entries' units, in all
  // The kKept newest results, oldest first (kept_next_ the slot to fill).
  std::vector<std::shared_ptr<const Chunk>> kept_;
  std::size_t kept_next_ = 0;
  Stats stats_;
};

}  // namespace terrane
