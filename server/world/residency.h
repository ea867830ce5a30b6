// Residency: the chunk versions the world holds and their lifecycle — what
// clients want and wait for, grants and their hand-over, loads and their
// results, regions' coarse images (for chunks wanted at the coarsest level
// only), estimates and their replacement by the real chunks, lightening
// to mips and forgetting what nobody holds, and the chunks queued edits
// pin (never unloaded while pinned). Runs on the world strand; Storage's
// callbacks are posted back to it.
//
// A client asks for chunks (want); loaded ones are granted at once, the
// others when Storage has loaded or generated them, waiters in the order
// they asked. A chunk wanted only at its coarsest level (4^3) comes from
// its region's coarse image when it was stored (one read serves the
// region's 512 chunks, none decoded), as a version with that level only;
// the chunk itself is read when a finer level, an edit or a hash needs
// it. A grant registers the client as a holder (FanOut), so every later
// change reaches it, in order after the grant. Chunks nobody holds at full
// resolution, with nothing pending, are reduced to their mips beyond
// resident_chunks, least recently used first.
//
// Each chunk has one entry (ChunkState) holding its whole residency: the
// version held (none, mips only, or with voxels), the load under way
// (wanted, replacing an estimate, or unreadable until a retry reads it)
// with its waiters, whether its estimate's replacement is queued, and the
// queued edits pinning it. An entry goes when nothing is held, loading or
// pinned. The lists beside (to lighten, estimates to replace, loads to
// retry) only order work: each chunk taken from them is checked against
// its entry.
#pragma once

#include <asio.hpp>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <utility>
#include <vector>

#include "common/voxel/grid.h"
#include "common/voxel/vec3_map.h"
#include "server/base/chunk_version.h"
#include "server/base/counters.h"
#include "server/storage/storage.h"
#include "server/world/fan_out.h"
#include "server/world/horizon_cache.h"
#include "server/world/world_client.h"
#include "server/world/world_clock.h"
#include "server/world/world_options.h"

namespace terrane {

// Read access for tests and tools (Server::inspect).
class WorldView {
 public:
  virtual ~WorldView() = default;
  virtual bool loaded(Vec3i chunk_pos) const = 0;
  // Revision of a loaded chunk as applied (committed or about to be).
  virtual std::uint64_t revision(Vec3i chunk_pos) const = 0;
  virtual Voxel get(Vec3i voxel) const = 0;
  // The chunk as applied, or null when it is all Air (precondition: loaded).
  virtual const Chunk* chunk(Vec3i chunk_pos) const = 0;
  virtual std::size_t loaded_count() const = 0;
  // Estimates granted and not yet replaced: queued, or being generated (in
  // the background or for a client).
  virtual std::size_t estimates_waiting() const = 0;
};

// What Residency asks of whoever knows chunks stored newer than held (a
// shared world's authority): loads at another revision are expected of
// them, and each landed load is reported.
class LoadWatcher {
 public:
  virtual ~LoadWatcher() = default;
  virtual bool stale(Vec3i chunk_pos) const = 0;
  // A load of chunk_pos landed and was applied (or failed).
  virtual void landed(Vec3i chunk_pos) = 0;
};

class Residency : public WorldView {
 public:
  using Strand = asio::strand<asio::io_context::executor_type>;
  // The version of a chunk held.
  struct Loaded {
    VersionPtr published;  // what clients are handed
    VersionPtr current;    // what the next edit builds on (newer while a commit is in flight)
    std::uint64_t used_tick = 0;
  };
  // The chunks kept only as mips (ChunkVersion::mips_only) at most, beyond
  // which those nobody holds are forgotten.
  static constexpr std::size_t kMaxMipsOnly = 1 << 20;
  // Chunks reduced to their mips per tick at most (each costs encoding its
  // three mip levels, tens of microseconds).
  static constexpr std::size_t kLightenPerTick = 128;
  // Background loads replacing estimates at a time (per loader thread: a
  // stream or urgent load waits for at most one generation).
  static constexpr std::size_t kReplacingLoadsPerWorker = 1;

  Residency(Strand& strand, Storage& storage, const WorldOptions& options, ServerCounters& counters,
            const WorldClock& clock, FanOut& clients, HorizonCache& horizons);
  // Before the first load.
  void watch_loads(LoadWatcher& watcher) { watcher_ = &watcher; }

  // A client's wants: granted at once when loaded, else when loaded.
  void want(ClientId id, const std::vector<ChunkWant>& chunks);
  // Grants not handed over yet to id are dropped (it left).
  void leave(ClientId id) { grants_.erase(id); }
  // Hands the grants made so far to their clients.
  void flush_grants();

  // Starts loading chunk_pos unless loaded or loading; true if loaded with
  // the given level (0: its voxels), and not as an estimate when exact.
  bool request(Vec3i chunk_pos, int level = 0, bool exact = false);
  // Loads chunk_pos unless a load of it is under way.
  void load_unless_loading(Vec3i chunk_pos, Storage::Priority priority);
  bool loading(Vec3i chunk_pos) const {
    auto it = chunks_.find(chunk_pos);
    return it != chunks_.end() && it->second.load != Load::kNone;
  }
  // Loads that failed to read are tried again.
  void retry_unreadable();

  // The chunks of r asked for and kept loaded for a queued edit (unbusy
  // releases them).
  void reserve(const Region& r);
  void unbusy(const Region& r);
  bool busy(Vec3i chunk_pos) const {
    auto it = chunks_.find(chunk_pos);
    return it != chunks_.end() && it->second.busy != 0;
  }

  // The chunk's version held, or null.
  const Loaded* find(Vec3i chunk_pos) const {
    auto it = chunks_.find(chunk_pos);
    return it == chunks_.end() || it->second.held.current == nullptr ? nullptr : &it->second.held;
  }
  // Every held chunk (fn must not change what is held).
  void for_each(const std::function<void(Vec3i, const Loaded&)>& fn) const;
  // The box r of the chunks as applied, when all are held with voxels.
  bool read_current(const Region& r, Box& out) const;
  // Copies of r's chunks as applied into scratch (each once: copied).
  void copy_into(Grid& scratch, const Region& r, std::unordered_set<Vec3i, Vec3iHash>& copied) const;
  // v (of a held chunk) is what the next edit builds on; returns it.
  const VersionPtr& advance(VersionPtr v);
  // Committed versions become what clients are handed (each its chunk's
  // newest), after the grants not yet handed over (a holder hears of a
  // version after it was granted the one before).
  void publish(const std::vector<VersionPtr>& versions);
  // Drops a held chunk (another server changed it and nobody here needs
  // it): read from the store when next wanted, its region's coarse image
  // too.
  void forget(Vec3i chunk_pos);

  // Every tick: estimates' replacements started, a few chunks lightened,
  // a tick's part of the unload pass.
  void replace_estimates();
  void lighten_some();
  void unload_unwatched();

  // WorldView
  bool loaded(Vec3i chunk_pos) const override {
    const Loaded* l = find(chunk_pos);
    return l != nullptr && l->current->has_voxels();
  }
  std::uint64_t revision(Vec3i chunk_pos) const override { return held(chunk_pos).current->revision(); }
  Voxel get(Vec3i voxel) const override;
  const Chunk* chunk(Vec3i chunk_pos) const override { return held(chunk_pos).current->chunk(); }
  std::size_t loaded_count() const override { return with_voxels_; }
  std::size_t estimates_waiting() const override;

 private:
  struct Waiter {
    ClientId id;
    bool full;
  };
  // The load of a chunk under way, if any.
  enum class Load : std::uint8_t {
    kNone,
    kLoading,    // for the waiters, an edit, or to read a newer revision
    kReplacing,  // an estimate held to be replaced, in the background: nobody waits
    kUnreadable  // failed (logged once): the waiters wait, retried every second
  };
  // One chunk's residency (see the opening comment).
  struct ChunkState {
    Loaded held;  // held.current null: nothing held
    Load load = Load::kNone;
    // Its estimate, granted to a client, is in estimates_ to be generated
    // for real in the background (ChunkVersion::estimate).
    bool replace_queued = false;
    std::uint32_t busy = 0;  // queued edits touching it (never unloaded while pinned)
    // Granted once the load lands (null: none), apart so that a held
    // chunk's entry stays small: the table is scanned every second.
    std::unique_ptr<std::vector<Waiter>> waiters;

    bool vacant() const { return held.current == nullptr && load == Load::kNone && busy == 0; }
  };
  using Chunks = Vec3iMap<ChunkState>;

  const Loaded& held(Vec3i chunk_pos) const;
  // Every change of a held version's form goes through these (they keep
  // the counts of chunks held with voxels and as mips only, and the bytes
  // of the versions held).
  void hold(ChunkState& s, VersionPtr v);
  void drop(Chunks::iterator it);  // the version held, and the entry if nothing else is left
  void wait_for(Vec3i chunk_pos, Waiter w);
  // Hands chunk_pos to Storage; the result comes back to on_loaded.
  void load(Vec3i chunk_pos, Storage::Priority priority);
  void on_loaded(LoadedChunk c);
  void apply_loaded(LoadedChunk c);
  // A want of the coarsest level of a chunk not loaded: taken (true) when
  // its region's coarse image can serve it (read now or being read).
  bool want_coarse(Vec3i chunk_pos, Waiter w);
  void on_coarse_loaded(LoadedCoarse c);
  void grant(ClientId id, Vec3i chunk_pos, bool full);
  void count_loaded();
  // A held version's memory as estimated here: the version, and its
  // chunk's voxels and mips, or the mips' encodings it was made with (the
  // encodings readers ask of a version with voxels are theirs, made
  // lazily, not counted).
  static std::size_t version_bytes(const ChunkVersion& v);
  // The table of chunks and the versions held, to the server's memory by
  // part (MemoryPart::kResidency).
  void count_memory();

  Strand& strand_;
  Storage& storage_;
  const WorldOptions& options_;
  ServerCounters& counters_;
  const WorldClock& clock_;
  FanOut& clients_;
  HorizonCache& horizons_;
  LoadWatcher* watcher_ = nullptr;
  Chunks chunks_;
  std::size_t with_voxels_ = 0;  // chunks held with their voxels
  std::size_t mips_only_ = 0;    // chunks held as mips only
  std::size_t versions_bytes_ = 0;  // version_bytes of the versions held
  std::vector<Vec3i> lighten_;   // to reduce to mips, least recently used last
  // unload_unwatched's pass over chunks_, a tick's share of its slots at a time.
  struct UnloadPass {
    std::size_t next_slot = 0;  // 0: a pass begins at the next tick
    bool lighten = false;       // over resident_chunks when the pass began
    bool forget = false;        // over kMaxMipsOnly when the pass began
    std::vector<std::pair<std::uint64_t, Vec3i>> drop;  // (used tick, chunk) that may be lightened
  } unload_pass_;
  // Regions whose coarse image was read (a chunk of one without an entry
  // was never stored), and the wants waiting for an image being read.
  std::unordered_set<Vec3i, Vec3iHash> regions_read_;
  std::unordered_map<Vec3i, std::vector<std::pair<Vec3i, Waiter>>, Vec3iHash> coarse_waiting_;
  std::vector<Vec3i> retry_;  // chunks that became unreadable
  // Estimates granted, to be generated for real, in the order first granted
  // (a client asks nearest first), and how many of them are loading.
  std::deque<Vec3i> estimates_;
  std::size_t replacing_ = 0;
  std::unordered_map<ClientId, std::vector<VersionPtr>> grants_;  // not yet handed over
  bool grants_scheduled_ = false;
};

}  // namespace terrane
