#include "server/server.h"

#include <random>
#include <filesystem>
#include <future>

#include "common/world/sqlite_store.h"
#include "common/world/sqlite_util.h"
#include "server/base/disk_space.h"
#include "server/base/log.h"
#include "server/base/thread_role.h"
#include "server/storage/postgres_store.h"

namespace terrane {

FileResult<std::unique_ptr<World>> Server::open_world() {
  if (options_.cluster.store_url.empty()) {
    // The lock comes before the first read: a second server (or a tool
    // writing the directory) must not even load chunks it could write back.
    std::error_code ec;
    const bool exists = SqliteStore::exists(options_.world_dir);
    if (!exists && !options_.create_world)
      return FileError{"no world at " + options_.world_dir +
                           " (--no-create: nothing is created; check the path, or drop --no-create for a new world)",
                       {}};
    std::filesystem::create_directories(options_.world_dir, ec);
    if (ec) return FileError{"world " + options_.world_dir + ": cannot create directory: " + ec.message(), {}};
    if (const std::uint64_t need = options_.storage.min_free_mb << 20; need > 0) {
      const auto free = free_bytes(options_.world_dir);
      if (free && *free < need)
        return FileError{fmt::format("world {}: only {} MiB free on its file system, below --min-free-mb {}: free "
                                     "some space (or lower --min-free-mb; 0 skips the check)",
                                     options_.world_dir, *free >> 20, options_.storage.min_free_mb),
                         {}};
    }
    auto lock = WorldLock::take(options_.world_dir, fmt::format("terrane-server on {}:{}", options_.net.bind_address,
                                                                options_.net.port));
    if (!lock) return lock.error();
    world_lock_ = std::move(*lock);
    if (exists) return World::open(options_.world_dir);
    server_log().warn("creating a new world at {} (none there; --no-create refuses instead)", options_.world_dir);
    return World::create(options_.world_dir, default_world_meta());
  }
  auto store = PostgresStore::open(options_.cluster.store_url);
  if (!store) return FileError{store.error().message, {}};
  if (!(*store)->has_world()) {
    if (auto made = (*store)->create_world(default_world_meta()); !made) return FileError{made.error().message, {}};
    server_log().info("world {}: created the default generated world", (*store)->where());
  }
  auto node = ClusterNode::open(options_.cluster, **store, [this](const RegionLease& lost, const std::string& why) {
    // Leases are held only once edits run, so the world owner exists.
    if (world_owner_) world_owner_->lease_lost(lost.region, why);
  }, &counters_.database);
  if (!node) return FileError{node.error().message, {}};
  cluster_ = std::move(*node);
  if (auto alone = check_border_alone((*store)->meta()); !alone) return alone.error();
  return World::open(std::unique_ptr<WorldStore>(std::move(*store)));
}

FileStatus Server::check_border_alone(const WorldMeta& meta) {
  // A border is the whole world's: every server must apply the same one,
  // and a running server reads it only when it starts. So a new border is
  // set only while no other server runs on the world.
  if (!options_.border_set || meta.bounds.same_border(options_.border)) return Ok{};
  auto ids = cluster_->others_running();
  if (!ids) return FileError{"--border: " + ids.error().message, {}};
  if (ids->empty()) return Ok{};
  std::string running;
  int others = 0;
  for (const std::uint32_t id : *ids) running += fmt::format("{}server {}", others++ == 0 ? "" : ", ", id);
  return FileError{fmt::format("--border: {} {} running on this world, and a border applies to every server: "
                               "stop {}, start this one with --border, then start {} again",
                               running, others > 1 ? "are" : "is", others > 1 ? "them" : "it",
                               others > 1 ? "them" : "it"),
                   {}};
}

FileResult<std::unique_ptr<Server>> Server::create(const ServerOptions& options) {
  if (options.ops.auth_token.empty() && options.ops.player_tokens.empty() && !options.ops.allow_open &&
      !is_loopback_address(options.net.bind_address))
    return FileError{"refusing to serve " + options.net.bind_address +
                         " without authentication: give --auth-token or --tokens-file, or --open to allow anyone",
                     {}};
  std::unique_ptr<Server> s(new Server(options));
  auto world = s->open_world();
  if (!world) return world.error();
  s->world_ = std::move(*world);
  if (options.border_set) {
    const WorldBounds b = s->world_->meta().bounds.with_border(options.border);
    if (auto st = s->world_->store().set_bounds(b); !st) return FileError{"--border: " + st.error().message, {}};
  }
  const std::uint64_t epoch = s->world_->meta().epoch + 1;
  if (auto st = s->world_->store().set_epoch(epoch); !st) return st.error();
  if (s->world_->meta().world_id == 0) {
    std::random_device rd;
    std::uint64_t id = 0;
    while (id == 0) id = (std::uint64_t{rd()} << 32) ^ rd();
    if (auto named = s->world_->store().name_world(id); !named) return named.error();
  }
  std::optional<Storage::Shared> shared;
  if (s->cluster_) shared.emplace(s->cluster_->shared());
  auto storage = Storage::open(*s->world_, s->options_.storage.worker_threads, s->options_.thread_priorities,
                               shared ? &*shared : nullptr);
  if (!storage) return storage.error();
  s->storage_ = std::move(*storage);
  s->storage_->set_horizon_estimates(options.replication.horizon_estimates);
  s->storage_->set_edit_log_retention(std::chrono::hours(24) * options.storage.edit_log_days,
                                      static_cast<std::uint64_t>(options.storage.edit_log_mb) << 20);
  if (auto bound = s->listener_.bind(options.net.bind_address, options.net.port); !bound) return bound.error();

  s->world_owner_ = std::make_unique<WorldOwner>(s->world_io_.context(), *s->world_, *s->storage_, s->options_.world,
                                                 s->counters_, s->options_.cluster);
  // Streaming's requests that wait too long in the world's queue hold
  // streaming back, as late probes do.
  s->world_owner_->on_request_wait([gate = s->stream_gate_.get()](std::chrono::nanoseconds waited) {
    gate->observe(StreamGate::Probe::kRequests, waited);
  });
  if (s->cluster_) {
    // Subscribed before any client joins: every commit of another server
    // from now on reaches what this one holds.
    WorldOwner* owner = s->world_owner_.get();
    ChangeListener::Handlers on;
    on.changes = [owner](std::vector<ChunkChange> changes) { owner->changed_elsewhere(std::move(changes)); };
    on.inbox = [owner] { owner->inbox_has_edits(); };
    on.answer = [owner](ForwardAnswer a) { owner->answered(std::move(a)); };
    on.missed = [owner](std::vector<Vec3i> regions) {
      owner->read_again_elsewhere(std::move(regions));
      owner->inbox_has_edits();
    };
    if (auto listening = s->cluster_->listen(std::move(on)); !listening)
      return FileError{listening.error().message, {}};
  }
  s->make_welcome();
  Server* self = s.get();
  Operations::Wiring wiring{s->world_hooks(), [self] { return self->metrics_text(); },
                            [self] { return self->health(); }, [self] { self->stop(); }};
  // The admin room's backups copy a SQLite world's directory.
  const std::string backup_dir = s->options_.cluster.store_url.empty() ? s->options_.world_dir : "";
  auto ops = Operations::open(s->options_.ops, s->world_->store(), backup_dir, s->io_.context(), s->sessions_,
                              s->counters_, std::move(wiring));
  if (!ops) return ops.error();
  s->ops_ = std::move(*ops);
  s->session_context_.emplace(ClientSession::Context{s->welcome_.welcome, s->ops_->admitter(), s->ops_->admin(),
                                                     s->counters_,
                                                     [self](std::uint64_t id) { self->sessions_.remove(id); },
                                                     [self](std::uint64_t id, const std::string& name,
                                                            std::uint64_t join_order) {
                                                       return self->replace_older_sessions(id, name, join_order);
                                                     }});
  return s;
}

void Server::make_welcome() {
  WelcomeMsg& w = welcome_.welcome;
  const WorldMeta& meta = world_->meta();
  w.server_epoch = meta.epoch;
  w.world_id = meta.world_id;
  w.spawn = find_spawn(*world_);
  w.materials = meta.materials;
  w.bounds_min_y = meta.bounds.min_y;
  w.bounds_max_y = meta.bounds.max_y;
  w.max_view_distance = options_.replication.max_view_distance;
  w.max_full_res_radius = options_.replication.max_full_res_radius;
  w.max_frame_bytes = static_cast<std::uint32_t>(options_.net.session.max_frame_bytes);
  w.tick_hz = options_.world.tick_hz;
  w.bounded_xz = meta.bounds.bounded_xz;
  w.bounds_min_x = meta.bounds.min_x;
  w.bounds_min_z = meta.bounds.min_z;
  w.bounds_max_x = meta.bounds.max_x;
  w.bounds_max_z = meta.bounds.max_z;
  w.default_view_distance = options_.replication.default_view_distance;
  w.default_full_res_radius = options_.replication.default_full_res_radius;
  // As the sessions' edit-rate buckets (replication/replicator.cpp) take them.
  w.edits_per_second = static_cast<float>(options_.world.edits_per_second);
  w.edit_burst = static_cast<std::uint32_t>(options_.world.edits_per_second * 2);
  w.server_id = options_.cluster.server_id;
  welcome_.bounds = meta.bounds;
}

Vec3f Server::find_spawn(World& world) {
  if (const TerrainGenerator* gen = world.generator()) {
    // The origin, or the middle of a border that leaves it out.
    const WorldBounds& b = world.meta().bounds;
    std::int32_t x = 0, z = 0;
    if (b.bounded_xz && !b.contains({0, b.min_y, 0})) {
      x = static_cast<std::int32_t>((std::int64_t{b.min_x} + b.max_x) / 2);
      z = static_cast<std::int32_t>((std::int64_t{b.min_z} + b.max_z) / 2);
    }
    return {static_cast<float>(x) + 0.5f, gen->surface_height(x, z) + 2.0f, static_cast<float>(z) + 0.5f};
  }
  // No generator (an imported world): above the ground at the centre of
  // what is stored, so clients start where the content is.
  Vec3i lo{0, 0, 0}, hi{0, 0, 0};
  bool any = false;
  (void)world.store().for_each_chunk([&](Vec3i cp, std::uint64_t, std::span<const std::uint8_t>) {
    lo = any ? min3(lo, cp) : cp;
    hi = any ? max3(hi, cp) : cp;
    any = true;
  });
  if (!any) return {0.5f, static_cast<float>(std::max(0, world.meta().bounds.min_y)), 0.5f};
  const std::int32_t x = (lo.x + hi.x + 1) * kChunkSize / 2, z = (lo.z + hi.z + 1) * kChunkSize / 2;
  const WorldBounds& b = world.meta().bounds;
  Box column({1, b.max_y - b.min_y, 1});
  std::int32_t top = b.min_y;
  if (world.read_box({x, b.min_y, z}, column))
    for (int y = column.size().y - 1; y >= 0; --y)
      if (column.get(0, y, 0).material != kAir) {
        top = b.min_y + y + 1;
        break;
      }
  return {static_cast<float>(x) + 0.5f, static_cast<float>(top) + 2.0f, static_cast<float>(z) + 0.5f};
}

Server::Server(const ServerOptions& options)
    : options_(options),
      listener_(io_.context()),
      stream_gate_(std::make_unique<StreamGate>(options.replication.stream_yield)),
      sessions_(options.net.max_clients) {
  options_.world.tick_hz = std::clamp<std::uint32_t>(options_.world.tick_hz, 1, 1000);
  options_.net.session.max_frame_bytes = std::min(options_.net.session.max_frame_bytes, kDefaultMaxFrameBytes);
  // The defaults within the caps (the Welcome states them).
  ReplicationOptions& r = options_.replication;
  r.max_view_distance = std::clamp(r.max_view_distance, 0, ReplicationOptions::kViewDistanceLimit);
  r.default_view_distance = std::min(r.default_view_distance, r.max_view_distance);
  r.default_full_res_radius = std::min(r.default_full_res_radius, r.max_full_res_radius);
  options_.net.session.counters = &counters_;
  if (options_.faults.drop_updates > 0 || options_.faults.corrupt_updates > 0)
    faults_ = std::make_unique<BudgetedUpdateFaults>(options_.faults.drop_updates, options_.faults.corrupt_updates,
                                                     counters_);
}

Server::~Server() {
  stop();
  if (ops_) ops_->join_stopping();
  if (cluster_) cluster_->stop_listening();
  world_owner_.reset();
  if (cluster_) cluster_->stop_control();
  if (storage_) storage_->stop();
}

void Server::start() {
  if (started_) return;
  started_ = true;
  server_log().info("world {} (epoch {}), tick {} Hz", world_->store().where(), world_->meta().epoch,
                    options_.world.tick_hz);
  if (cluster_) {
    server_log().info("server id {} in a shared PostgreSQL world: regions leased for {} ms", options_.cluster.server_id,
                      options_.cluster.lease.count());
    // Where the other servers send clients that stand in regions this one
    // writes (and where this one learns who writes what).
    std::string advertised = options_.cluster.advertise;
    if (advertised.empty() && !is_any_address(options_.net.bind_address))
      advertised = ServerAddress{options_.cluster.server_id, options_.net.bind_address, port()}.text();
    // (Without an address it is still known to run: a --border elsewhere
    // waits for it.)
    if (advertised.empty())
      server_log().warn("no --advertise address (bound to {}): other servers redirect no client here",
                        options_.net.bind_address);
    else
      server_log().info(
          "clients are redirected here as {}{}", advertised,
          options_.cluster.redirect_margin > 0 ? "" : " (this server redirects none: --redirect-margin 0)");
    cluster_->start(advertised);
  }
  if (!options_.ops.player_tokens.empty())
    server_log().info("authentication: per-player tokens ({} players)", options_.ops.player_tokens.size());
  else if (!options_.ops.auth_token.empty())
    server_log().info("authentication: shared token");
  else
    server_log().warn("authentication: none, anyone who can connect may play ({})",
                      is_loopback_address(options_.net.bind_address) ? "loopback only" : "--open");
  // The default view's table (its offsets nearest first), made before the
  // first client instead of on its strand (tens of milliseconds at 1,024),
  // and up to 2,048 the widest view's with the default full-resolution
  // radius (41 ms and about 15 MB at 2,048; 8 times as much at twice the
  // distance). The defaults are within the caps (the constructor); the
  // radius is capped by the view as a replicator caps a client's.
  const ReplicationOptions& r = options_.replication;
  const auto table = [&r](std::int32_t view) {
    return ViewTable::get(view, std::min(r.default_full_res_radius, view));
  };
  default_view_ = table(r.default_view_distance);
  constexpr std::int32_t kWidestViewMade = 2048;
  if (r.max_view_distance <= kWidestViewMade) widest_view_ = table(r.max_view_distance);
  server_log().info("world {}: {}", where(), border_text());
  server_log().info("listening on {}:{}", options_.net.bind_address, port());
  world_io_.run(1, ThreadRole::kWorld, options_.thread_priorities);
  world_owner_->start();
  stream_gate_->start(io_.context(), world_io_.context());
  ops_->start();
  listener_.start([this](asio::ip::tcp::socket socket) { return accept(std::move(socket)); });
  io_.run(options_.net.io_threads, ThreadRole::kIo, options_.thread_priorities);
}

void Server::stop() {
  if (!started_ || stopping_.exchange(true)) return;
  stream_gate_->stop();  // while both contexts run (its probes re-arm until then)
  ops_->stop_timers();
  {
    std::promise<void> closed;
    asio::post(io_.context(), [this, &closed] {
      listener_.close();
      closed.set_value();
    });
    closed.get_future().wait();
  }
  // The command running finishes (the world still runs, so a save can);
  // nothing queued after it runs.
  ops_->close_admin();
  if (cluster_) cluster_->stop_listening();  // no notice reaches the world owner once it stops
  // Applies what is queued and waits for its commit: nothing acknowledged
  // is lost, and every acknowledgement is sent before the sessions close.
  world_owner_->stop();
  ops_->notify_stopping();
  sessions_.close_all(CloseReason::kShutdown, "server shutting down");
  if (cluster_) cluster_->stop_control();  // claims, forwards and answers asked before the world stopped
  storage_->stop();
  // Every commit is done: the regions are given up at once, so another
  // server takes them over without waiting for the leases to run out.
  if (cluster_) cluster_->release();
  ops_->stop_metrics();
  io_.join();
  world_io_.join();
  log_totals();
}

void Server::log_totals() const {
  const ServerCounters& c = counters_;
  server_log().info(
      "stopped after {} ticks; sessions {} accepted, {} closed; edits {} applied, {} rejected; streamed {} full "
      "chunks, {} mips, {} estimates, {} empty, {} horizon images ({} bytes), {} resumed; {} update batches, {} mip refreshes ({} "
      "skipped: bytes unchanged); {}",
      c.ticks.load(), c.sessions_accepted.load(), c.net.sessions_closed(), c.edits_applied.load(),
      c.edits_rejected(), c.chunks_sent.load(), c.mips_sent.load(), c.estimates_sent.load(), c.empties_sent.load(),
      c.horizons_sent.load(), c.stream_bytes.load(),
      c.chunks_resumed.load(), c.update_batches_sent.load(), c.mip_refreshes.load(), c.refreshes_skipped.load(),
      storage_failed() ? "world NOT saved: the storage failed (the failed tick's edits were rejected)" : "world saved");
  bool header = false;
  for (std::size_t t = 1; t < NetCounters::kTypes; ++t) {
    const std::uint64_t f = c.net.sent_frames[t].load(), r = c.net.received_frames[t].load();
    if (f == 0 && r == 0) continue;
    if (!header)
      server_log().info("{:<18} {:>10} {:>14} {:>10} {:>14}", "messages by type", "frames out", "bytes out",
                        "frames in", "bytes in");
    header = true;
    server_log().info("{:<18} {:>10} {:>14} {:>10} {:>14}", wire::EnumNameBody(static_cast<wire::Body>(t)), f,
                      c.net.sent_bytes[t].load(), r, c.net.received_bytes[t].load());
  }
}

std::string Server::metrics_text() const {
  MetricsSources m{counters_, storage_->counters(), encode_counters(), storage_failed(),
                   read_process_stats(), stream_gate_->closed_count(), stream_gate_->closed_seconds()};
  if (options_.cluster.store_url.empty()) m.disk_free_bytes = free_bytes(options_.world_dir);
  // Read at each scrape: the world's meta is where a border lives (set by
  // --border in create(), before any thread reads it; fixed while running).
  m.bounds = world_->meta().bounds;
  m.store_memory_bytes = sqlite_memory_used();
  return render_metrics(m);
}

Health Server::health() const {
  if (stopping_) return {HealthState::kDraining, "shutting down"};
  return check_health(counters_, storage_failed(), options_.world.tick_hz, std::chrono::steady_clock::now(),
                      cluster_ ? LeaseTimes::of(options_.cluster.lease).renew : std::chrono::milliseconds(0));
}

void Server::inspect(const std::function<void(const WorldView&)>& fn) { world_owner_->inspect(fn); }

bool Server::accept(asio::ip::tcp::socket socket) {
  if (stopping_) return false;
  const ClientId id = sessions_.next_id();
  auto rep = std::make_shared<Replicator>(id, *world_owner_, options_.replication, options_.cluster, counters_,
                                          welcome_, *stream_gate_, cluster_ ? &cluster_->directory() : nullptr,
                                          faults_.get());
  auto client = ClientSession::open(std::move(socket), id, options_.net.session, *session_context_, rep);
  const std::shared_ptr<Session> session = client->session();
  rep->attach(session);
  counters_.sessions_accepted.fetch_add(1, std::memory_order_relaxed);
  const bool room = sessions_.add(id, client);
  session->start();
  if (!room) session->close(CloseReason::kServerFull, "server full");
  return true;
}

std::string Server::where() const {
  return options_.cluster.store_url.empty() ? options_.world_dir : options_.cluster.store_url;
}

std::string Server::border_text() const {
  const WorldBounds& b = world_->meta().bounds;
  if (!b.bounded_xz) return "no border";
  return fmt::format("border x {}..{}, z {}..{}", b.min_x, b.max_x, b.min_z, b.max_z);
}

bool Server::replace_older_sessions(std::uint64_t id, const std::string& name, std::uint64_t join_order) {
  // As Minecraft does: the player's later join wins (the older session is
  // often a dead link not yet timed out).
  const SessionTable::Replacement r = sessions_.replace_earlier_joins(
      id, name, join_order, CloseReason::kReplaced, "logged in from another location: the same player joined again");
  for (const std::uint64_t other : r.ended)
    server_log().info("session {} ('{}') replaced by session {}: the same player joined again", other, name, id);
  if (r.newer)
    server_log().info("session {} ('{}') replaced by session {}: the same player joined again", id, name, *r.newer);
  return !r.newer.has_value();
}

AdminHooks Server::world_hooks() {
  AdminHooks h;
  h.status = [this] {
    ServerStatus s;
    s.world_dir = where();
    s.version = TERRANE_VERSION_STRING;
    s.address = fmt::format("{}:{}", options_.net.bind_address, port());
    s.border = border_text();
    s.epoch = world_->meta().epoch;
    s.clients = counters_.clients.load();
    s.admin_sessions = counters_.admin_sessions.load();
    s.ticks = counters_.ticks.load();
    s.tick_hz = options_.world.tick_hz;
    s.edits_applied = counters_.edits_applied.load();
    s.edits_rejected = counters_.edits_rejected();
    s.chunks_resident = counters_.chunks_loaded.load();
    s.storage_failed = storage_failed();
    s.edit_log = storage_->counters().edit_log.get();  // the writer's figure: no store touched here
    const std::uint64_t n = counters_.tick_duration.count();
    s.tick_mean_ms = n > 0 ? counters_.tick_duration.sum_seconds() * 1000 / static_cast<double>(n) : 0;
    return s;
  };
  h.flush = [this](std::function<void(std::uint64_t, bool)> done) { world_owner_->flush(std::move(done)); };
  h.rollback = [this](const std::string& actor, std::vector<EditLogEntry> entries, std::optional<Region> within,
                      std::function<void(bool, std::string, std::uint64_t, std::uint64_t)> done) {
    world_owner_->rollback(actor, std::move(entries), within, [done = std::move(done)](WorldOwner::RollbackResult r) {
      done(r.ok, std::move(r.error), r.tick, r.voxels_restored);
    });
  };
  return h;
}

}  // namespace terrane
