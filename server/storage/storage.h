// Storage: the world store, off the world strand.
//
//   Loads run on a loader pool: each load reads the chunk's row on a
//   connection of its own (the world's WorldStore reopened: SQLite in WAL
//   mode and PostgreSQL both let readers run beside the writer) and
//   decodes it, or generates a chunk that was never stored. A
//   damaged blob is moved, in one transaction, to the quarantine table and
//   the chunk is served as generated at the quarantined revision + 1, so
//   revisions only grow and later saves write a fresh row. A row SQLite
//   cannot read at all is reported as a failure: nothing says the data is
//   bad, so it is neither quarantined nor generated over.
//
//   Commits run on one writer thread with its own connection: each tick's
//   changed chunk versions are queued, and the writer takes every tick
//   queued by then and stores them in one transaction (a group commit),
//   then reports each tick in order. The coarse images of the chunks
//   written follow in transactions of their own when no commit waits, a
//   region's changes held about a second so repeated edits share one
//   rewrite (WorldStore::set_coarse_behind: loads read past the lag). After a failed commit every later tick
//   fails too: the world in memory is ahead of the disk, and the server
//   stops rather than serve what it could lose.
//
//   In a world shared by several servers (PostgreSQL), the claims,
//   forwarded edits, inbox reads and answers the world owner asks for are
//   passed on to the cluster room (ClusterLink: its control thread).
//
// Threading: load() and commit() may be called from any thread; their
// callbacks run on a loader thread and the writer thread: post from there
// to where the result belongs. stop() waits for queued work (commits are
// never dropped) and must not be called from a storage thread.
#pragma once

#include <asio.hpp>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <variant>
#include <vector>

#include "common/world/horizon.h"
#include "common/world/world.h"
#include "server/base/counters.h"
#include "server/base/chunk_version.h"
#include "server/storage/cluster_link.h"
#include "server/storage/edit_log_upkeep.h"
#include "server/storage/postgres_store.h"

namespace terrane {

struct LoadedChunk {
  Vec3i pos;
  std::uint64_t revision = 0;
  std::shared_ptr<const Chunk> chunk;  // null: all Air
  bool ok = true;                      // false: the row could not be read (error says why)
  bool generated = false;
  std::string error;
};

// A region's coarse image (common/world/coarse_image.h): one entry per stored chunk.
struct LoadedCoarse {
  Vec3i region;
  std::vector<CoarseEntry> entries;
  // Chunks of the region never stored that the generator makes all Air
  // (sky; every one of a world without a generator), at revision 0: known
  // exactly without generating them.
  std::vector<Vec3i> air;
  // The region's other chunks never stored, their coarsest mip estimated
  // from the generator (World::estimate_coarse), revision 0: a distant view
  // is served these until the chunks are generated for real. Empty when
  // estimates are off.
  std::vector<CoarseEntry> estimates;
  bool ok = true;  // false: the image could not be read or is damaged (error says why)
  std::string error;
};

// A region's horizon image (common/world/horizon.h), made from its coarse
// image and, for chunks never stored, estimates at the image's resolution.
struct LoadedHorizon {
  Vec3i region;
  int level = kHorizonFarLevel;
  HorizonPtr image;  // null when the coarse image could not be read (error says why)
  std::string error;
};

struct StorageCounters {
  std::atomic<std::uint64_t> loaded_from_store{0};
  std::atomic<std::uint64_t> coarse_images_read{0};
  std::atomic<std::uint64_t> generated{0};
  std::atomic<std::uint64_t> coarse_estimated{0};  // chunks' coarsest mips estimated (LoadedCoarse::estimates)
  std::atomic<std::uint64_t> horizons_made{0};     // horizon images (LoadedHorizon)
  std::atomic<std::uint64_t> quarantined{0};
  std::atomic<std::uint64_t> commits{0};           // transactions
  std::atomic<std::uint64_t> ticks_committed{0};   // ticks carried by them
  std::atomic<std::uint64_t> chunks_written{0};
  std::atomic<std::uint64_t> edits_logged{0};
  std::atomic<std::uint64_t> log_entries_pruned{0};
  // The edit log's size (entries, bytes of voxels) as the writer knows it.
  EditLogFigure edit_log;
  DurationHistogram commit_duration;               // wall time inside each transaction
  // Coarse images written after the commits (Storage::catch_up_coarse):
  // each transaction's wall time, and the regions still waiting.
  DurationHistogram coarse_catch_up_duration;
  std::atomic<std::uint64_t> coarse_regions_pending{0};
};

class Storage {
 public:
  using LoadDone = std::function<void(LoadedChunk)>;
  using CoarseDone = std::function<void(LoadedCoarse)>;
  using HorizonDone = std::function<void(LoadedHorizon)>;
  using CommitDone = std::function<void(const FileStatus&)>;

  // A world shared by several servers (PostgreSQL): its chunk store, which
  // the writer opens again as what it is (its commits answer forwarded
  // edits and tell the other servers each chunk's changed units), and the
  // cluster room, which claims regions, forwards edits and reads the
  // inbox. Both outlive the Storage.
  struct Shared {
    const PostgresStore& store;
    ClusterLink& cluster;
  };
  // world: shared for its metadata and generator (thread-safe); its store
  // is opened again (WorldStore::reopen) once per loader and once for the
  // writer.
  // thread_priorities: the writer and loader threads at their roles'
  // niceness (server/base/thread_role.h).
  // shared: set for a shared world (null: SQLite, every region is this
  // server's).
  static FileResult<std::unique_ptr<Storage>> open(World& world, int loader_threads, bool thread_priorities = true,
                                                   const Shared* shared = nullptr);
  // The edit log keeps entries this long (0: for ever) and at most this many
  // bytes of voxels (0: no bound); the writer prunes it about once a minute
  // (EditLogUpkeep). Any thread.
  void set_edit_log_retention(std::chrono::seconds max_age, std::uint64_t max_bytes) {
    edit_log_.set_retention(max_age, max_bytes);
  }
  // Whether a coarse image's read estimates the region's chunks never
  // stored (LoadedCoarse::estimates). Call before the first load.
  void set_horizon_estimates(bool on) { estimate_coarse_ = on; }
  ~Storage();
  Storage(const Storage&) = delete;
  Storage& operator=(const Storage&) = delete;

  // Which loads go first: urgent ones (an edit or a full-resolution request
  // waits on them), then the stream's (a view's coarser chunks and coarse
  // images), then background ones (chunks whose estimates are to be
  // replaced), only when nothing else waits.
  enum class Priority : std::uint8_t { kUrgent, kStream, kBackground };
  void load(Vec3i pos, LoadDone done, Priority priority = Priority::kStream);
  // Moves a queued background load of pos to priority's queue: true if one
  // was queued (not started yet), so no second load is needed.
  bool promote(Vec3i pos, Priority priority);
  // Reads a region's coarse image (queued with the other loads).
  void load_coarse(Vec3i region, CoarseDone done);
  // Makes a region's horizon image (queued with the stream's loads, behind
  // the urgent ones that edits and full resolution wait on).
  void load_horizon(Vec3i region, int level, HorizonDone done);
  // The loader threads (Residency keeps as many estimates' replacements
  // under way).
  int loader_threads() const { return loader_threads_; }
  // Whether the world is shared by several servers (Shared given).
  bool leased() const { return cluster_ != nullptr; }
  // Claims region's lease for this server if it does not hold it (on the
  // cluster room's control thread), then lists its stored chunks
  // (RegionClaim says why).
  using Claimed = RegionClaim;
  using ClaimDone = std::function<void(Claimed)>;
  void claim(Vec3i region, ClaimRule rule, ClaimDone done);
  // Forwarded edits (a shared world; on the cluster room's control
  // thread): sends one to server to's inbox (done gets the inbox row's
  // id; ClusterLink::forward), takes one back whose wait ran out, takes
  // this server's inbox past after, and answers edits refused without a
  // commit.
  // hand_over: regions of this server's the edit also writes, released
  // first (nothing of them in flight), so that server can take them.
  // deadline: when the sender's wait for the answer runs out.
  void forward(std::uint32_t to, std::string player, EditRequestMsg edit, std::vector<Vec3i> hand_over,
               std::chrono::steady_clock::time_point deadline, std::function<void(StoreResult<std::int64_t>)> done);
  void take_back(std::int64_t row, std::function<void(StoreResult<bool>)> done);
  // Passes a forwarded edit (this server's inbox row) on to server to,
  // releasing hand_over first as forward does.
  void relay(std::int64_t row, std::uint32_t to, std::vector<Vec3i> hand_over, std::function<void(StoreResult<Ok>)> done);
  void read_inbox(std::int64_t after, std::size_t limit, std::function<void(StoreResult<std::vector<InboxEdit>>)> done);
  void answer(std::vector<ForwardAnswer> answers);
  // log: the tick's edits for the edit log, and answers: the forwarded
  // edits it applied, stored in the same transaction.
  // tick: the world tick that made the versions (a shared world's notices
  // name it with their units).
  void commit(std::vector<VersionPtr> versions, std::vector<EditLogEntry> log, CommitDone done,
              std::vector<ForwardAnswer> answers = {}, std::uint64_t tick = 0);
  void stop();

  const StorageCounters& counters() const { return counters_; }
  // Commits queued or being written.
  std::size_t commits_in_flight() const { return in_flight_.load(std::memory_order_relaxed); }

 private:
  Storage(World& world, int loader_threads, bool thread_priorities);
  LoadedChunk load_now(WorldStore& store, Vec3i pos);
  // A region's coarse image; rows gets the region's chunks that have a row
  // (stored or quarantined).
  LoadedCoarse read_coarse(WorldStore& store, Vec3i region, std::vector<Vec3i>& rows);
  void writer_loop();
  // Writes the coarse images the commits left behind (set_coarse_behind),
  // those pending at least min_age, a few regions per transaction; with
  // yield, only while no commit waits.
  void catch_up_coarse(std::chrono::steady_clock::duration min_age, bool yield);
  // A region's image changes wait this long, so a region edited again and
  // again is rewritten about once a second instead of on every tick; the
  // writer looks every kCoarseCheck while any wait.
  static constexpr std::chrono::milliseconds kCoarseDelay{1000};
  // Changes this old are written even while commits queue (a slice per batch).
  static constexpr std::chrono::milliseconds kCoarseMaxDelay{10000};
  static constexpr std::chrono::milliseconds kCoarseCheck{100};
  static constexpr std::size_t kCoarseRegionsPerCatchUp = 8;
  std::chrono::steady_clock::time_point next_coarse_error_{};

  struct CommitJob {
    std::vector<VersionPtr> versions;
    std::vector<EditLogEntry> log;
    CommitDone done;
    std::vector<ForwardAnswer> answers;
    std::uint64_t tick = 0;
  };
  // A reader connection borrowed (take_reader under readers_mutex_) and
  // given back.
  std::unique_ptr<WorldStore> take_reader();
  void give_reader(std::unique_ptr<WorldStore> store);
  bool estimate_coarse_ = true;
  // A shared world's cluster room (null: SQLite). Set once by open().
  ClusterLink* cluster_ = nullptr;

  World& world_;
  StorageCounters counters_;
  // The edit log's pruning and size, on the writer thread.
  EditLogUpkeep edit_log_{counters_.edit_log, counters_.log_entries_pruned};
  const bool thread_priorities_;
  const int loader_threads_;
  asio::thread_pool loaders_;
  // Loader connections, borrowed for one load at a time, and the queued
  // loads (urgent first). Guarded by readers_mutex_: loads on the pool's
  // threads share them. Each queued load posts one runner to the pool.
  std::mutex readers_mutex_;
  std::vector<std::unique_ptr<WorldStore>> readers_;
  struct HorizonJob {
    int level = 0;
    HorizonDone done;
  };
  struct LoadJob {
    Vec3i pos;  // a chunk, or the region of a coarse or horizon image
    std::variant<LoadDone, CoarseDone, HorizonJob> what;  // the kind of load, and where its answer goes
  };
  void run_coarse(WorldStore& store, Vec3i region, const CoarseDone& done, const std::function<void()>& give_back);
  void run_horizon(WorldStore& store, Vec3i region, const HorizonJob& job, const std::function<void()>& give_back);
  void post_load();
  std::deque<LoadJob>& queue(Priority priority);  // under readers_mutex_
  std::deque<LoadJob> urgent_loads_, loads_, background_loads_;

  std::unique_ptr<WorldStore> writer_store_;
  // writer_store_ itself, as the chunk store it is, in a shared world (set
  // once by open(); null for SQLite).
  PostgresStore* shared_writer_ = nullptr;
  // The hand-off from the world strand to the writer thread. Guarded by
  // jobs_mutex_ (the writer sleeps on jobs_cv_ when there is nothing to do).
  std::mutex jobs_mutex_;
  std::condition_variable jobs_cv_;
  std::deque<CommitJob> jobs_;
  std::vector<Vec3i> coarse_repairs_;  // regions loads found behind their rows
  bool stopping_ = false;
  std::atomic<std::size_t> in_flight_{0};
  std::thread writer_;
  bool stopped_ = false;
};

}  // namespace terrane
