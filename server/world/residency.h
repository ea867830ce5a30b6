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
#pragma once

#include <asio.hpp>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <functional>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <utility>
#include <vector>

#include "common/voxel/grid.h"
#include "common/voxel/vec3_map.h"
#include "server/base/chunk_version.h"
#include "server/base/counters.h"
#include "server/base/options.h"
#include "server/storage/storage.h"
#include "server/world/fan_out.h"
#include "server/world/horizon_cache.h"
#include "server/world/world_client.h"
#include "server/world/world_clock.h"

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
  struct Loaded {
    VersionPtr published;  // what clients are handed
    VersionPtr current;    // what the next edit builds on (newer while a commit is in flight)
    std::uint64_t used_tick = 0;
    // An estimate (ChunkVersion::estimate) granted to a client is queued to
    // be generated for real in the background (estimates_), then loaded.
    enum class Replace : std::uint8_t { kNo, kQueued, kLoading } replace = Replace::kNo;
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

  Residency(Strand& strand, Storage& storage, const ServerOptions& options, ServerCounters& counters,
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
  bool loading(Vec3i chunk_pos) const { return loading_.count(chunk_pos) != 0; }
  // Loads that failed to read are tried again.
  void retry_unreadable();

  // The chunks of r asked for and kept loaded for a queued edit (unbusy
  // releases them).
  void reserve(const Region& r);
  void unbusy(const Region& r);
  bool busy(Vec3i chunk_pos) const { return busy_.count(chunk_pos) != 0; }

  const Loaded* find(Vec3i chunk_pos) const {
    auto it = loaded_.find(chunk_pos);
    return it == loaded_.end() ? nullptr : &it->second;
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
    auto it = loaded_.find(chunk_pos);
    return it != loaded_.end() && it->second.current->has_voxels();
  }
  std::uint64_t revision(Vec3i chunk_pos) const override { return loaded_.at(chunk_pos).current->revision(); }
  Voxel get(Vec3i voxel) const override;
  const Chunk* chunk(Vec3i chunk_pos) const override { return loaded_.at(chunk_pos).current->chunk(); }
  std::size_t loaded_count() const override { return loaded_.size() - mips_only_; }
  std::size_t estimates_waiting() const override;

 private:
  struct Waiter {
    ClientId id;
    bool full;
  };
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

  Strand& strand_;
  Storage& storage_;
  const ServerOptions& options_;
  ServerCounters& counters_;
  const WorldClock& clock_;
  FanOut& clients_;
  HorizonCache& horizons_;
  LoadWatcher* watcher_ = nullptr;
  // Chunks with their voxels, and chunks kept as mips only.
  Vec3iMap<Loaded> loaded_;
  std::size_t mips_only_ = 0;
  std::vector<Vec3i> lighten_;  // to reduce to mips, least recently used last
  // unload_unwatched's pass over loaded_, a tick's share of its slots at a time.
  struct UnloadPass {
    std::size_t next_slot = 0;  // 0: a pass begins at the next tick
    bool lighten = false;       // over resident_chunks when the pass began
    bool forget = false;        // over kMaxMipsOnly when the pass began
    std::vector<std::pair<std::uint64_t, Vec3i>> drop;  // (used tick, chunk) that may be lightened
  } unload_pass_;
  std::unordered_map<Vec3i, std::vector<Waiter>, Vec3iHash> loading_;
  // Regions whose coarse image was read (a chunk of one without an entry
  // was never stored), and the wants waiting for an image being read.
  std::unordered_set<Vec3i, Vec3iHash> regions_read_;
  std::unordered_map<Vec3i, std::vector<std::pair<Vec3i, Waiter>>, Vec3iHash> coarse_waiting_;
  std::unordered_map<Vec3i, std::string, Vec3iHash> unreadable_;  // logged once each
  // Estimates granted, to be generated for real, in the order first granted
  // (a client asks nearest first), and how many of them are loading.
  std::deque<Vec3i> estimates_;
  std::size_t replacing_ = 0;
  std::unordered_map<ClientId, std::vector<VersionPtr>> grants_;  // not yet handed over
  bool grants_scheduled_ = false;
  // Chunks queued edits will touch (never unloaded): chunk -> edits.
  std::unordered_map<Vec3i, int, Vec3iHash> busy_;
};

}  // namespace terrane
