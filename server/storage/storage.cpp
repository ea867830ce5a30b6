#include "server/storage/storage.h"

#include <algorithm>

#include <chrono>
#include <unordered_map>
#include <unordered_set>

#include "server/base/log.h"
#include "server/base/thread_role.h"

namespace terrane {

FileResult<std::unique_ptr<Storage>> Storage::open(World& world, int loader_threads, bool thread_priorities,
                                                   const Shared* shared) {
  const int n = std::max(1, loader_threads);
  std::unique_ptr<Storage> s(new Storage(world, n, thread_priorities));
  if (shared != nullptr) s->cluster_ = &shared->cluster;
  for (int i = 0; i < n; ++i) {
    auto store = world.store().reopen();
    if (!store) return store.error();
    // One read of a region's coarse image, as horizon images read it,
    // before the first client: a connection's first read prepares its statements and fills its page cache with the
    // tables' upper pages (about 10-25 ms a connection, which the first
    // view's horizon would otherwise wait for). Its answer does not matter.
    (void)(*store)->load_coarse_as_kept(Vec3i{0, 0, 0});
    s->readers_.push_back(std::move(*store));
  }
  if (shared != nullptr) {
    auto w = shared->store.reopen_chunks();
    if (!w) return FileError{w.error().message, {}};
    s->shared_writer_ = w->get();
    s->writer_store_ = std::move(*w);
  } else {
    auto w = world.store().reopen();
    if (!w) return w.error();
    s->writer_store_ = std::move(*w);
  }
  // A commit stores the chunks and the edit log; the coarse images follow
  // when the writer has nothing else to do (writer_loop).
  s->writer_store_->set_coarse_behind(true);
  s->writer_ = std::thread([p = s.get()] {
    enter_thread_role(ThreadRole::kWriter, p->thread_priorities_);
    p->writer_loop();
  });
  return s;
}

Storage::Storage(World& world, int loader_threads, bool thread_priorities)
    : world_(world),
      thread_priorities_(thread_priorities),
      loader_threads_(loader_threads),
      loaders_(static_cast<std::size_t>(loader_threads)) {}

Storage::~Storage() { stop(); }

void Storage::stop() {
  if (stopped_) return;
  stopped_ = true;
  loaders_.join();
  {
    std::lock_guard lock(jobs_mutex_);
    stopping_ = true;
  }
  jobs_cv_.notify_all();
  if (writer_.joinable()) writer_.join();
}

void Storage::load(Vec3i pos, LoadDone done, Priority priority) {
  {
    std::lock_guard lock(readers_mutex_);
    queue(priority).push_back(LoadJob{pos, std::move(done)});
  }
  post_load();
}

bool Storage::promote(Vec3i pos, Priority priority) {
  if (priority == Priority::kBackground) return false;
  std::lock_guard lock(readers_mutex_);
  auto it = std::find_if(background_loads_.begin(), background_loads_.end(),
                         [&](const LoadJob& j) { return j.pos == pos && std::holds_alternative<LoadDone>(j.what); });
  if (it == background_loads_.end()) return false;
  queue(priority).push_back(std::move(*it));
  background_loads_.erase(it);
  return true;  // its runner is already posted: whichever runner comes next takes the most urgent job
}

std::deque<Storage::LoadJob>& Storage::queue(Priority priority) {
  return priority == Priority::kUrgent ? urgent_loads_ : priority == Priority::kStream ? loads_ : background_loads_;
}

void Storage::claim(Vec3i region, ClaimRule rule, ClaimDone done) {
  if (cluster_ != nullptr) cluster_->claim(region, rule, std::move(done));
}

std::unique_ptr<WorldStore> Storage::take_reader() {
  auto store = std::move(readers_.back());
  readers_.pop_back();
  return store;
}

void Storage::give_reader(std::unique_ptr<WorldStore> store) {
  std::lock_guard lock(readers_mutex_);
  readers_.push_back(std::move(store));
}

// Only a shared world's world owner asks for these (leased()); the cluster
// room runs them on its control thread.
void Storage::forward(std::uint32_t to, std::string player, EditRequestMsg edit, std::vector<Vec3i> hand_over,
                      std::chrono::steady_clock::time_point deadline,
                      std::function<void(StoreResult<std::int64_t>)> done) {
  if (cluster_ != nullptr)
    cluster_->forward(to, std::move(player), std::move(edit), std::move(hand_over), deadline, std::move(done));
}

void Storage::take_back(std::int64_t row, std::function<void(StoreResult<bool>)> done) {
  if (cluster_ != nullptr) cluster_->take_back(row, std::move(done));
}

void Storage::relay(std::int64_t row, std::uint32_t to, std::vector<Vec3i> hand_over,
                    std::function<void(StoreResult<Ok>)> done) {
  if (cluster_ != nullptr) cluster_->relay(row, to, std::move(hand_over), std::move(done));
}

void Storage::read_inbox(std::int64_t after, std::size_t limit,
                         std::function<void(StoreResult<std::vector<InboxEdit>>)> done) {
  if (cluster_ != nullptr) cluster_->read_inbox(after, limit, std::move(done));
}

void Storage::answer(std::vector<ForwardAnswer> answers) {
  if (cluster_ != nullptr) cluster_->answer(std::move(answers));
}

void Storage::load_coarse(Vec3i region, CoarseDone done) {
  {
    std::lock_guard lock(readers_mutex_);
    loads_.push_back(LoadJob{region, std::move(done)});
  }
  post_load();
}

void Storage::load_horizon(Vec3i region, int level, HorizonDone done) {
  {
    std::lock_guard lock(readers_mutex_);
    loads_.push_back(LoadJob{region, HorizonJob{level, std::move(done)}});
  }
  post_load();
}

void Storage::post_load() {
  asio::post(loaders_, [this] {
    static thread_local const bool named = (enter_thread_role(ThreadRole::kLoader, thread_priorities_), true);
    (void)named;
    std::unique_ptr<WorldStore> store;
    LoadJob job;
    {
      std::lock_guard lock(readers_mutex_);
      auto& q = !urgent_loads_.empty() ? urgent_loads_ : !loads_.empty() ? loads_ : background_loads_;
      job = std::move(q.front());
      q.pop_front();
      store = take_reader();
    }
    const auto give_back = [&] { give_reader(std::move(store)); };
    if (const auto* h = std::get_if<HorizonJob>(&job.what)) return run_horizon(*store, job.pos, *h, give_back);
    if (const auto* coarse = std::get_if<CoarseDone>(&job.what)) return run_coarse(*store, job.pos, *coarse, give_back);
    LoadedChunk c = load_now(*store, job.pos);
    give_back();
    std::get<LoadDone>(job.what)(std::move(c));
  });
}

void Storage::run_coarse(WorldStore& store, Vec3i region, const CoarseDone& done,
                         const std::function<void()>& give_back) {
  std::vector<Vec3i> rows;
  LoadedCoarse c = read_coarse(store, region, rows);
  give_back();  // the generator's judgement below needs no connection
  if (c.ok) {
    // Only chunks with no row of any kind are the generator's: a row
    // without an entry is damaged (its load quarantines it).
    // With estimates on, every one of them is estimated from the generator
    // at the mip's resolution, sky too: judging a chunk all Air exactly
    // costs its 32 x 32 columns, more than its estimate (the background
    // generation finds out). Otherwise sky is judged exactly and the rest
    // is generated when wanted.
    const std::unordered_set<Vec3i, Vec3iHash> known(rows.begin(), rows.end());
    std::vector<Vec3i> unknown;
    for_each_region_chunk(region, [&](Vec3i cp) {
      if (known.count(cp) != 0 || !world_.meta().bounds.touches_chunk(cp)) return;
      if (!world_.generator())
        c.air.push_back(cp);  // a world without a generator is Air where nothing is stored
      else if (estimate_coarse_)
        unknown.push_back(cp);
      else if (world_.generates_air(cp))
        c.air.push_back(cp);
    });
    if (!unknown.empty()) {
      std::vector<CoarseVoxels> voxels = world_.estimate_coarse(unknown);
      c.estimates.reserve(unknown.size());
      for (std::size_t i = 0; i < unknown.size(); ++i) c.estimates.push_back(CoarseEntry{unknown[i], 0, voxels[i]});
      counters_.coarse_estimated.fetch_add(unknown.size(), std::memory_order_relaxed);
    }
  }
  done(std::move(c));
}

void Storage::run_horizon(WorldStore& store, Vec3i region, const HorizonJob& job,
                          const std::function<void()>& give_back) {
  // The coarse image as kept: one read, not past any lag (reading past it
  // decodes every chunk written since, which in a busy region held loader
  // threads that edits' loads wait for). Chunks without an entry (never
  // generated, a damaged row served generated, or written since) are
  // estimated: the image is approximate anyway.
  auto entries = store.load_coarse_as_kept(region);
  give_back();
  LoadedHorizon h;
  h.region = region;
  h.level = job.level;
  if (!entries) {
    h.error = entries.error().message;
    return job.done(std::move(h));
  }
  // Stored chunks from their mips; the rest estimated (whatever the
  // estimates setting: a distant chunk never generated is not generated
  // for its image). Chunks outside the bounds stay Air.
  HorizonBuilder b(region, job.level);
  std::array<bool, kHorizonRegionSlots> stored{};
  for (const CoarseEntry& e : *entries) {
    b.put_coarse(e.chunk_pos, e.voxels);
    stored[static_cast<std::size_t>(coarse_index(e.chunk_pos))] = true;
  }
  std::vector<Vec3i> unknown;
  for_each_region_chunk(region, [&](Vec3i cp) {
    if (!stored[static_cast<std::size_t>(coarse_index(cp))] && world_.meta().bounds.touches_chunk(cp))
      unknown.push_back(cp);
  });
  world_.estimate_horizon(unknown, b);
  h.image = encode_horizon(b, kServedCodecVersion);
  counters_.horizons_made.fetch_add(1, std::memory_order_relaxed);
  job.done(std::move(h));
}

LoadedCoarse Storage::read_coarse(WorldStore& store, Vec3i region, std::vector<Vec3i>& rows) {
  LoadedCoarse c;
  c.region = region;
  // One read transaction: the image, the quarantined and the stored rows as
  // of one moment.
  const bool snapshot = store.begin_read().ok();
  auto entries = store.load_coarse(region);
  if (entries && store.coarse_read_behind()) {
    // Behind its rows: the writer rewrites it (if only its own changes
    // waiting were missing, that costs one extra scan of the region).
    std::lock_guard lock(jobs_mutex_);
    coarse_repairs_.push_back(region);
  }
  FileResult<std::vector<Vec3i>> quarantined = std::vector<Vec3i>{}, stored = std::vector<Vec3i>{};
  if (entries) quarantined = store.quarantined_in(region);
  if (entries && quarantined) stored = store.stored_in(region);
  if (snapshot) store.end_read();
  if (!entries || !quarantined || !stored) {
    c.ok = false;
    c.error = !entries ? entries.error().message : !quarantined ? quarantined.error().message : stored.error().message;
    return c;
  }
  c.entries = std::move(*entries);
  rows = std::move(*quarantined);
  rows.insert(rows.end(), stored->begin(), stored->end());
  counters_.coarse_images_read.fetch_add(1, std::memory_order_relaxed);
  return c;
}

LoadedChunk Storage::load_now(WorldStore& store, Vec3i cp) {
  LoadedChunk out;
  out.pos = cp;
  if (!world_.meta().bounds.touches_chunk(cp)) return out;  // outside the world: Air forever
  auto stored = store.load_chunk(cp);
  if (!stored) {
    if (!stored.error().decode) {
      out.ok = false;
      out.error = "cannot be read: " + stored.error().message;
      return out;
    }
    // In a shared world only the region's writer moves a row: elsewhere
    // it may be a row its writer is replacing.
    if (cluster_ != nullptr && !cluster_->holds(lease_region_of(cp))) {
      out.ok = false;
      out.error = "does not decode (" + stored.error().message +
                  "); in a region this server does not write, so it is left for the region's server";
      return out;
    }
    // A damaged blob: move the row aside (never generate over it), then
    // serve the chunk as generated with a revision above the damaged one.
    auto moved = store.quarantine_chunk(cp, stored.error().decode->describe());
    if (!moved) {
      out.ok = false;
      out.error = stored.error().message + "; quarantine failed: " + moved.error().message;
      return out;
    }
    counters_.quarantined.fetch_add(1, std::memory_order_relaxed);
    server_log().error(
        "chunk ({},{},{}): {}; row (revision {}) moved to the quarantine table, serving the chunk as generated", cp.x,
        cp.y, cp.z, stored.error().message, moved->value_or(0));
  } else if (stored->has_value()) {
    StoredChunk& sc = **stored;
    out.revision = sc.revision;
    if (!sc.chunk.empty()) out.chunk = std::make_shared<const Chunk>(std::move(sc.chunk));
    counters_.loaded_from_store.fetch_add(1, std::memory_order_relaxed);
    return out;
  }
  // Not stored: generated. A chunk whose row was quarantined (now or by an
  // earlier run) continues its revisions above the quarantined one.
  auto floor = store.quarantined_revision(cp);
  if (!floor) {
    out.ok = false;
    out.error = "cannot read its quarantine record: " + floor.error().message;
    return out;
  }
  out.revision = floor->has_value() ? **floor + 1 : 0;
  Chunk c = world_.generate_chunk(cp);
  if (!c.empty()) out.chunk = std::make_shared<const Chunk>(std::move(c));
  out.generated = true;
  counters_.generated.fetch_add(1, std::memory_order_relaxed);
  return out;
}

void Storage::commit(std::vector<VersionPtr> versions, std::vector<EditLogEntry> log, CommitDone done,
                     std::vector<ForwardAnswer> answers, std::uint64_t tick) {
  in_flight_.fetch_add(1, std::memory_order_relaxed);
  {
    std::lock_guard lock(jobs_mutex_);
    jobs_.push_back(CommitJob{std::move(versions), std::move(log), std::move(done), std::move(answers), tick});
  }
  jobs_cv_.notify_one();
}

void Storage::writer_loop() {
  FileStatus status = Ok{};
  // The edit log's size known from the start (status, /metrics).
  edit_log_.run(*writer_store_, std::chrono::steady_clock::now());
  for (;;) {
    std::deque<CommitJob> batch;
    bool stop = false;
    {
      std::unique_lock lock(jobs_mutex_);
      // Wakes at least once a minute to prune the edit log, and while coarse
      // images wait, when the oldest may be due.
      const auto wait = writer_store_->coarse_pending() > 0 ? kCoarseCheck : std::chrono::minutes(1);
      jobs_cv_.wait_for(lock, wait, [&] { return stopping_ || !jobs_.empty(); });
      stop = jobs_.empty() && stopping_;  // stopping, nothing left
      batch.swap(jobs_);
    }
    if (stop) {
      // Everything the commits left behind, before the world is closed.
      if (status) catch_up_coarse(std::chrono::steady_clock::duration::zero(), false);
      return;
    }
    if (batch.empty()) {
      if (status) {
        edit_log_.run(*writer_store_, std::chrono::steady_clock::now());
        catch_up_coarse(kCoarseDelay, true);
      }
      continue;
    }
    // After a failure, every later tick fails too, untried: not stored,
    // whatever the outcome of the failed commit.
    FileStatus told = status;
    if (!status && status.error().outcome_unknown) {
      FileError untried = status.error();
      untried.outcome_unknown = false;
      told = untried;
    }
    if (status) {
      // One transaction for every tick queued: the latest version of each
      // chunk is what is stored.
      std::unordered_map<Vec3i, std::size_t, Vec3iHash> index;
      std::vector<ChunkWrite> writes;
      std::vector<EditLogEntry> log;
      std::vector<ForwardAnswer> answers;
      // A shared world tells the other servers each chunk's changed units
      // (they apply them to the revision before instead of reading the
      // chunk); a later version of a chunk in the batch carries its own.
      const bool tells_units = shared_writer_ != nullptr;
      for (CommitJob& job : batch) {
        for (EditLogEntry& e : job.log) log.push_back(std::move(e));
        for (ForwardAnswer& a : job.answers) answers.push_back(std::move(a));
        for (const VersionPtr& v : job.versions) {
          ChunkWrite w{v->pos(), v->revision(), v->blob(), coarse_voxels(v->chunk())};
          if (tells_units && v->changed_units().any() && v->has_voxels()) {
            const UpdatePiece* piece = &v->update_piece();
            net_codec_join_update_pieces(std::span(&piece, 1), w.units);
            w.tick = job.tick;
          }
          auto [it, fresh] = index.emplace(v->pos(), writes.size());
          if (fresh)
            writes.push_back(std::move(w));
          else if (writes[it->second].revision < w.revision)
            writes[it->second] = std::move(w);
        }
      }
      if (!writes.empty() || !log.empty() || !answers.empty()) {
        const auto t0 = std::chrono::steady_clock::now();
        // Answers exist only in a shared world: its writer is PostgreSQL's.
        status = shared_writer_ != nullptr && !answers.empty() ? shared_writer_->save_answering(writes, log, answers)
                                                               : writer_store_->save_chunks(writes, true, log);
        if (status) {
          counters_.edits_logged.fetch_add(log.size(), std::memory_order_relaxed);
          edit_log_.logged(log);
        }
        counters_.commit_duration.observe(std::chrono::steady_clock::now() - t0);
        counters_.commits.fetch_add(1, std::memory_order_relaxed);
        counters_.chunks_written.fetch_add(writes.size(), std::memory_order_relaxed);
      }
      if (status) counters_.ticks_committed.fetch_add(batch.size(), std::memory_order_relaxed);
      counters_.coarse_regions_pending.store(writer_store_->coarse_pending(), std::memory_order_relaxed);
      told = status;
    }
    for (CommitJob& job : batch) {
      in_flight_.fetch_sub(1, std::memory_order_relaxed);
      job.done(told);
    }
    // After the acks went out: a prune and a count of the edit log (at most
    // once a minute, a bounded number of rows) and the coarse images due
    // delay only the next batch.
    if (status) {
      edit_log_.run(*writer_store_, std::chrono::steady_clock::now());
      catch_up_coarse(kCoarseDelay, true);
    }
  }
}

void Storage::catch_up_coarse(std::chrono::steady_clock::duration min_age, bool yield) {
  {
    std::vector<Vec3i> repairs;
    {
      std::lock_guard lock(jobs_mutex_);
      repairs.swap(coarse_repairs_);
    }
    for (const Vec3i r : repairs) writer_store_->repair_coarse(r);
  }
  for (std::size_t before = writer_store_->coarse_pending(); before > 0;) {
    if (yield) {
      std::lock_guard lock(jobs_mutex_);
      // A tick's commit first; but changes kCoarseMaxDelay old go one slice
      // at a time between commits, so a writer that is never idle still
      // catches up.
      if (!jobs_.empty()) {
        if (min_age >= kCoarseMaxDelay) return;
        min_age = kCoarseMaxDelay;
      }
    }
    const auto t0 = std::chrono::steady_clock::now();
    auto left = writer_store_->catch_up_coarse(kCoarseRegionsPerCatchUp, min_age);
    counters_.coarse_regions_pending.store(writer_store_->coarse_pending(), std::memory_order_relaxed);
    if (!left) {
      // Derived data: the rows are stored, and loads read past the lag. The
      // store tries those regions again later; said once a minute at most.
      if (const auto now = std::chrono::steady_clock::now(); now >= next_coarse_error_) {
        server_log().error("coarse images: {} (tried again later; loads decode the chunks meanwhile)",
                           left.error().message);
        next_coarse_error_ = now + std::chrono::minutes(1);
      }
      return;
    }
    if (*left == before) return;  // none due yet
    counters_.coarse_catch_up_duration.observe(std::chrono::steady_clock::now() - t0);
    before = *left;
  }
}

}  // namespace terrane
