#include "server/server.h"

#include <filesystem>
#include <future>

#include "common/world/sqlite_store.h"
#include "server/base/log.h"
#include "server/base/thread_role.h"
#include "server/storage/postgres_store.h"

namespace terrane {

FileResult<std::unique_ptr<World>> Server::open_world() {
  if (options_.store_url.empty()) {
    // The lock comes before the first read: a second server (or a tool
    // writing the directory) must not even load chunks it could write back.
    std::error_code ec;
    std::filesystem::create_directories(options_.world_dir, ec);
    if (ec) return FileError{"world " + options_.world_dir + ": cannot create directory: " + ec.message(), {}};
    auto lock = WorldLock::take(options_.world_dir, fmt::format("terrane-server on {}:{}", options_.bind_address,
                                                                options_.port));
    if (!lock) return lock.error();
    world_lock_ = std::move(*lock);
    return SqliteStore::exists(options_.world_dir) ? World::open(options_.world_dir)
                                                   : World::create(options_.world_dir, default_world_meta());
  }
  auto store = PostgresStore::open(options_.store_url);
  if (!store) return FileError{store.error().message, {}};
  if (!(*store)->has_world()) {
    if (auto made = (*store)->create_world(default_world_meta()); !made) return FileError{made.error().message, {}};
    server_log().info("world {}: created the default generated world", (*store)->where());
  }
  // Writes are fenced by this server's leases (STORE_POSTGRESQL.md): a
  // region another server holds is never written, and a lease lost (this
  // server paused or cut off past it) makes the next write fail, which
  // stops the server as any failed commit does.
  auto keeper = LeaseKeeper::open(options_.store_url, options_.server_id, LeaseTimes::of(options_.lease),
                                  [this](const RegionLease& lost, const std::string& why) {
                                    // Leases are held only once edits run, so the world owner exists.
                                    if (world_owner_) world_owner_->lease_lost(lost.region, why);
                                  },
                                  &counters_.database);
  if (!keeper) return FileError{keeper.error().message, {}};
  leases_ = std::move(*keeper);
  auto control = ClusterControl::open(options_.store_url, *leases_, &counters_.database);
  if (!control) return FileError{control.error().message, {}};
  control_ = std::move(*control);
  // A border is the whole world's: every server must apply the same one,
  // and a running server reads it only when it starts. So a new border is
  // set only while no other server runs on the world.
  if (options_.border_set && !(*store)->meta().bounds.same_border(options_.border)) {
    auto cluster = ClusterStore::open(options_.store_url);
    if (!cluster) return FileError{"--border: " + cluster.error().message, {}};
    auto ids = (*cluster)->running(options_.lease);
    if (!ids) return FileError{"--border: " + ids.error().message, {}};
    std::string running;
    int others = 0;
    for (const std::uint32_t id : *ids)
      if (id != options_.server_id) running += fmt::format("{}server {}", others++ == 0 ? "" : ", ", id);
    if (others > 0)
      return FileError{fmt::format("--border: {} {} running on this world, and a border applies to every server: "
                                   "stop {}, start this one with --border, then start {} again",
                                   running, others > 1 ? "are" : "is", others > 1 ? "them" : "it",
                                   others > 1 ? "them" : "it"),
                       {}};
  }
  // Only leases held: the world owner claims a region (and reads it again)
  // before it applies anything there, so a write never takes back a region
  // this server lost or handed over.
  (*store)->set_lease_source(leases_->held_source(), options_.lease);
  (*store)->count_retries_in(&counters_.database);
  shared_store_ = store->get();
  return World::open(std::unique_ptr<WorldStore>(std::move(*store)));
}

FileResult<std::unique_ptr<Server>> Server::create(const ServerOptions& options) {
  if (options.auth_token.empty() && options.player_tokens.empty() && !options.allow_open &&
      !is_loopback_address(options.bind_address))
    return FileError{"refusing to serve " + options.bind_address +
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
  std::optional<Storage::Shared> shared;
  if (s->control_) shared.emplace(Storage::Shared{*s->shared_store_, *s->control_});
  auto storage = Storage::open(*s->world_, s->options_.worker_threads, s->options_.thread_priorities,
                               shared ? &*shared : nullptr);
  if (!storage) return storage.error();
  s->storage_ = std::move(*storage);
  s->storage_->set_horizon_estimates(options.horizon_estimates);
  s->storage_->set_edit_log_retention(std::chrono::hours(24) * options.edit_log_days,
                                      static_cast<std::uint64_t>(options.edit_log_mb) << 20);

  asio::error_code ec;
  const auto addr = asio::ip::make_address(options.bind_address, ec);
  if (ec) return FileError{"bad bind address " + options.bind_address + ": " + ec.message(), {}};
  const asio::ip::tcp::endpoint ep(addr, options.port);
  s->acceptor_.open(ep.protocol(), ec);
  if (!ec) s->acceptor_.set_option(asio::ip::tcp::acceptor::reuse_address(true), ec);
  if (!ec) s->acceptor_.bind(ep, ec);
  if (!ec) s->acceptor_.listen(asio::socket_base::max_listen_connections, ec);
  if (ec)
    return FileError{
        "cannot listen on " + options.bind_address + ":" + std::to_string(options.port) + ": " + ec.message(), {}};
  s->port_ = s->acceptor_.local_endpoint().port();

  s->world_owner_ = std::make_unique<WorldOwner>(s->world_io_, *s->world_, *s->storage_, s->options_, s->counters_);
  // Streaming's requests that wait too long in the world's queue hold
  // streaming back, as late probes do.
  s->world_owner_->on_request_wait([gate = s->stream_gate_.get()](std::chrono::nanoseconds waited) {
    gate->observe(StreamGate::Probe::kRequests, waited);
  });
  if (s->leases_) {
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
    auto listener = ChangeListener::open(options.store_url, options.server_id, std::move(on), &s->counters_.database);
    if (!listener) return FileError{listener.error().message, {}};
    s->changes_ = std::move(*listener);
  }
  WelcomeMsg& w = s->welcome_.welcome;
  const WorldMeta& meta = s->world_->meta();
  w.server_epoch = meta.epoch;
  w.spawn = find_spawn(*s->world_);
  w.materials = meta.materials;
  w.bounds_min_y = meta.bounds.min_y;
  w.bounds_max_y = meta.bounds.max_y;
  w.max_view_distance = s->options_.max_view_distance;
  w.max_full_res_radius = s->options_.max_full_res_radius;
  w.max_frame_bytes = static_cast<std::uint32_t>(s->options_.session.max_frame_bytes);
  w.tick_hz = s->options_.tick_hz;
  w.bounded_xz = meta.bounds.bounded_xz;
  w.bounds_min_x = meta.bounds.min_x;
  w.bounds_min_z = meta.bounds.min_z;
  w.bounds_max_x = meta.bounds.max_x;
  w.bounds_max_z = meta.bounds.max_z;
  w.default_view_distance = s->options_.default_view_distance;
  w.default_full_res_radius = s->options_.default_full_res_radius;
  // As the sessions' edit-rate buckets (replication/replicator.cpp) take them.
  w.edits_per_second = static_cast<float>(s->options_.edits_per_second);
  w.edit_burst = static_cast<std::uint32_t>(s->options_.edits_per_second * 2);
  w.server_id = s->options_.server_id;
  s->welcome_.bounds = meta.bounds;
  auto access_store = s->world_->store().reopen();
  if (!access_store) return access_store.error();
  auto access = AccessControl::open(std::move(*access_store), options.auth_token, options.player_tokens,
                                    options.admin_token);
  if (!access) return access.error();
  s->access_ = std::move(*access);
  s->admin_ = std::make_unique<Admin>(s->world_->store(), s->options_.store_url.empty() ? s->options_.world_dir : "",
                                      *s->access_, s->admin_hooks());
  s->admin_fn_ = [self = s.get()](const std::string& who, AdminRequestMsg req,
                                  std::function<void(AdminResultMsg)> reply) {
    std::lock_guard lock(self->admin_mutex_);
    if (self->admin_) return self->admin_->handle(who, std::move(req), std::move(reply));
    reply(AdminResultMsg{req.request_id, false, "the server is stopping", "{}"});
  };
  s->session_context_.emplace(ClientSession::Context{
      s->welcome_.welcome, *s->access_, s->admin_fn_, s->counters_, [self = s.get()](std::uint64_t id) {
        std::lock_guard lock(self->sessions_mutex_);
        self->sessions_.erase(id);
      }});
  if (!options.metrics_address.empty()) {
    auto hp = parse_host_port(options.metrics_address);
    if (!hp) return FileError{"--metrics: " + hp.error().message, {}};
    Server* self = s.get();
    auto http = HttpEndpoint::bind(
        hp->first, hp->second, [self] { return self->metrics_text(); }, [self] { return self->health(); });
    if (!http) return http.error();
    s->metrics_ = std::move(*http);
  }
  return s;
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
      work_(asio::make_work_guard(io_)),
      world_work_(asio::make_work_guard(world_io_)),
      acceptor_(io_),
      stats_timer_(io_),
      stream_gate_(std::make_unique<StreamGate>(options.stream_yield)),
      shutdown_timer_(io_) {
  options_.tick_hz = std::clamp<std::uint32_t>(options_.tick_hz, 1, 1000);
  options_.session.max_frame_bytes = std::min(options_.session.max_frame_bytes, kDefaultMaxFrameBytes);
  options_.default_view_distance = std::min(options_.default_view_distance, options_.max_view_distance);
  options_.default_full_res_radius = std::min(options_.default_full_res_radius, options_.max_full_res_radius);
  options_.session.counters = &counters_;
  if (options_.fault_drop_updates > 0 || options_.fault_corrupt_updates > 0)
    faults_ = std::make_unique<BudgetedUpdateFaults>(options_.fault_drop_updates, options_.fault_corrupt_updates,
                                                     counters_);
}

Server::~Server() {
  stop();
  if (shutdown_thread_.joinable()) shutdown_thread_.join();
  changes_.reset();
  world_owner_.reset();
  if (control_) control_->stop();
  if (storage_) storage_->stop();
}

void Server::start() {
  if (started_) return;
  started_ = true;
  server_log().info("world {} (epoch {}), tick {} Hz", world_->store().where(), world_->meta().epoch, options_.tick_hz);
  if (leases_) {
    server_log().info("server id {} in a shared PostgreSQL world: regions leased for {} ms", options_.server_id,
                      options_.lease.count());
    // Where the other servers send clients that stand in regions this one
    // writes (and where this one learns who writes what).
    std::string advertised = options_.advertise;
    if (advertised.empty() && !is_any_address(options_.bind_address))
      advertised = ServerAddress{options_.server_id, options_.bind_address, port_}.text();
    // (Without an address it is still known to run: a --border elsewhere
    // waits for it.)
    if (advertised.empty())
      server_log().warn("no --advertise address (bound to {}): other servers redirect no client here",
                        options_.bind_address);
    else
      server_log().info("clients are redirected here as {}{}", advertised,
                        options_.redirect_margin > 0 ? "" : " (this server redirects none: --redirect-margin 0)");
    leases_->advertise(advertised, &cluster_);
  }
  if (!options_.player_tokens.empty())
    server_log().info("authentication: per-player tokens ({} players)", options_.player_tokens.size());
  else if (!options_.auth_token.empty())
    server_log().info("authentication: shared token");
  else
    server_log().warn("authentication: none, anyone who can connect may play ({})",
                      is_loopback_address(options_.bind_address) ? "loopback only" : "--open");
  // The default view's table (its offsets nearest first), made before the
  // first client instead of on its strand (tens of milliseconds at 1,024).
  // (Capped as a replicator caps a client's radii.)
  const std::int32_t view = std::min(options_.default_view_distance, options_.max_view_distance);
  default_view_ = ViewTable::get(view, std::min({options_.default_full_res_radius, options_.max_full_res_radius, view}));
  server_log().info("listening on {}:{}", options_.bind_address, port_);
  world_thread_ = std::thread([this] {
    enter_thread_role(ThreadRole::kWorld, options_.thread_priorities);
    world_io_.run();
  });
  world_owner_->start();
  stream_gate_->start(io_, world_io_);
  if (metrics_) {
    metrics_->start();
    server_log().info("metrics on http://{}:{}/metrics", parse_host_port(options_.metrics_address)->first,
                      metrics_->port());
  }
  do_accept();
  arm_stats();
  for (int i = 0; i < std::max(1, options_.io_threads); ++i)
    threads_.emplace_back([this] {
      enter_thread_role(ThreadRole::kIo, options_.thread_priorities);
      io_.run();
    });
}

void Server::stop() {
  if (stopped_.exchange(true)) return;
  if (!started_) return;
  stopping_ = true;
  stream_gate_->stop();  // while both contexts run (its probes re-arm until then)
  {
    std::promise<void> closed;
    asio::post(acceptor_.get_executor(), [this, &closed] {
      asio::error_code ignored;
      acceptor_.close(ignored);
      stats_timer_.cancel();
      shutdown_timer_.cancel();
      closed.set_value();
    });
    closed.get_future().wait();
  }
  // The command running finishes (the world still runs, so a save can);
  // nothing queued after it runs.
  {
    std::unique_ptr<Admin> admin;
    {
      std::lock_guard lock(admin_mutex_);
      admin = std::move(admin_);
    }
  }
  changes_.reset();  // no notice reaches the world owner once it stops
  // Applies what is queued and waits for its commit: nothing acknowledged
  // is lost, and every acknowledgement is sent before the sessions close.
  world_owner_->stop();
  {
    ServerNoticeMsg bye;
    bye.kind = wire::NoticeKind::Shutdown;
    bye.reconnect = clients_reconnect_.load();
    bye.text = bye.reconnect ? "server stopping now; it restarts: reconnect" : "server stopping now";
    notify_all(bye);
    std::lock_guard lock(sessions_mutex_);
    for (auto& [id, peer] : sessions_)
      if (auto s = peer.session.lock()) s->close(CloseReason::kShutdown, "server shutting down");
  }
  if (control_) control_->stop();  // claims, forwards and answers asked before the world stopped
  storage_->stop();
  // Every commit is done: the regions are given up at once, so another
  // server takes them over without waiting for the leases to run out.
  if (leases_)
    if (auto released = leases_->release_all(); !released)
      server_log().warn("leases not released (they run out in {} ms): {}", options_.lease.count(),
                        released.error().message);
  if (metrics_) metrics_->stop();
  work_.reset();
  for (auto& t : threads_) t.join();
  threads_.clear();
  world_work_.reset();
  if (world_thread_.joinable()) world_thread_.join();
  const ServerCounters& c = counters_;
  server_log().info(
      "stopped after {} ticks; sessions {} accepted, {} closed; edits {} applied, {} rejected; streamed {} full "
      "chunks, {} mips, {} estimates, {} empty, {} horizon images ({} bytes), {} resumed; {} update batches, {} mip refreshes ({} "
      "skipped: bytes unchanged); world saved",
      c.ticks.load(), c.sessions_accepted.load(), c.net.sessions_closed(), c.edits_applied.load(),
      c.edits_rejected(), c.chunks_sent.load(), c.mips_sent.load(), c.estimates_sent.load(), c.empties_sent.load(),
      c.horizons_sent.load(), c.stream_bytes.load(),
      c.chunks_resumed.load(), c.update_batches_sent.load(), c.mip_refreshes.load(), c.refreshes_skipped.load());
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
  return render_metrics(MetricsSources{counters_, storage_->counters(), encode_counters(), storage_failed(),
                                       read_process_stats(), stream_gate_->closed_count(),
                                       stream_gate_->closed_seconds()});
}

Health Server::health() const {
  if (stopping_) return {false, "shutting down"};
  return check_health(counters_, storage_failed(), options_.tick_hz, std::chrono::steady_clock::now(),
                      leases_ ? LeaseTimes::of(options_.lease).renew : std::chrono::milliseconds(0));
}

void Server::inspect(const std::function<void(const WorldView&)>& fn) { world_owner_->inspect(fn); }

void Server::do_accept() {
  acceptor_.async_accept(asio::make_strand(io_), [this](const asio::error_code& ec, asio::ip::tcp::socket socket) {
    if (ec) {
      if (ec != asio::error::operation_aborted && acceptor_.is_open()) do_accept();
      return;
    }
    if (stopping_) return;
    const ClientId id = next_id_.fetch_add(1);
    auto rep = std::make_shared<Replicator>(id, *world_owner_, options_, counters_, welcome_, *stream_gate_,
                                            leases_ ? &cluster_ : nullptr, faults_.get());
    auto client = ClientSession::open(std::move(socket), id, options_.session, *session_context_, rep);
    const std::shared_ptr<Session> session = client->session();
    rep->attach(session);
    counters_.sessions_accepted.fetch_add(1, std::memory_order_relaxed);
    bool full = false;
    {
      std::lock_guard lock(sessions_mutex_);
      sessions_[id] = Peer{session, client};
      full = sessions_.size() > options_.max_clients;
    }
    session->start();
    if (full) session->close(CloseReason::kServerFull, "server full");
    do_accept();
  });
}

void Server::notify_all(const ServerNoticeMsg& notice) {
  const auto frame = std::make_shared<const Frame>(build_server_notice(notice));
  std::lock_guard lock(sessions_mutex_);
  for (auto& [id, peer] : sessions_) {
    auto s = peer.session.lock();
    auto c = peer.client.lock();
    if (s && c && c->info().welcomed) s->send(frame, SendClass::kControl);
  }
}

void Server::schedule_shutdown(std::uint32_t seconds, bool restart, const std::string& reason) {
  clients_reconnect_ = restart;
  ServerNoticeMsg n;
  n.kind = wire::NoticeKind::Shutdown;
  n.seconds_left = seconds;
  n.reconnect = restart;
  n.text = "server stopping in " + std::to_string(seconds) + " s" + (restart ? " and restarting" : "") +
           (reason.empty() ? std::string() : ": " + reason);
  server_log().warn("{} (asked by an operator)", n.text);
  notify_all(n);
  asio::post(io_, [this, seconds] {
    if (stopping_) return;
    shutdown_timer_.expires_after(std::chrono::seconds(seconds));
    shutdown_timer_.async_wait([this](const asio::error_code& ec) {
      if (ec || stopping_) return;
      if (options_.on_shutdown) return options_.on_shutdown();
      // No owner to ask: stop from a thread of our own (stop() joins the io
      // threads, this one among them).
      if (!shutdown_thread_.joinable()) shutdown_thread_ = std::thread([this] { stop(); });
    });
  });
}

AdminHooks Server::admin_hooks() {
  AdminHooks h;
  h.status = [this] {
    ServerStatus s;
    s.world_dir = options_.world_dir;
    s.epoch = world_->meta().epoch;
    s.uptime_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - started_at_).count();
    s.clients = counters_.clients.load();
    s.ticks = counters_.ticks.load();
    s.tick_hz = options_.tick_hz;
    s.edits_applied = counters_.edits_applied.load();
    s.edits_rejected = counters_.edits_rejected();
    s.chunks_resident = counters_.chunks_loaded.load();
    s.storage_failed = storage_failed();
    const std::uint64_t n = counters_.tick_duration.count();
    s.tick_mean_ms = n > 0 ? counters_.tick_duration.sum_seconds() * 1000 / static_cast<double>(n) : 0;
    return s;
  };
  auto each = [this](const std::function<void(Session&, const PlayerInfo&)>& fn) {
    std::lock_guard lock(sessions_mutex_);
    const auto now = std::chrono::steady_clock::now();
    for (auto& [id, peer] : sessions_) {
      auto s = peer.session.lock();
      auto c = peer.client.lock();
      if (!s || !c) continue;
      const ClientSession::Info info = c->info();
      if (!info.welcomed) continue;
      PlayerInfo p;
      p.id = id;
      p.name = info.name;
      p.address = s->address();
      p.position = info.position;
      p.admin = info.admin;
      p.connected_s = std::chrono::duration<double>(now - info.joined).count();
      p.bytes_in = s->bytes_received();
      p.bytes_out = s->bytes_sent();
      p.ping_ms = info.ping_ms;
      fn(*s, p);
    }
  };
  h.players = [each] {
    std::vector<PlayerInfo> out;
    each([&](Session&, const PlayerInfo& p) { out.push_back(p); });
    std::sort(out.begin(), out.end(), [](const PlayerInfo& a, const PlayerInfo& b) { return a.name < b.name; });
    return out;
  };
  h.close_matching = [each](const std::function<bool(const PlayerInfo&)>& match, CloseReason why,
                            const std::string& text) {
    int n = 0;
    each([&](Session& s, const PlayerInfo& p) {
      if (!match(p)) return;
      s.close(why, text);
      ++n;
    });
    return n;
  };
  h.notify_all = [this](const ServerNoticeMsg& n) { notify_all(n); };
  h.flush = [this](std::function<void(std::uint64_t, bool)> done) { world_owner_->flush(std::move(done)); };
  h.shutdown = [this](std::uint32_t seconds, bool restart, const std::string& reason) {
    schedule_shutdown(seconds, restart, reason);
  };
  h.rollback = [this](const std::string& actor, std::vector<EditLogEntry> entries, std::optional<Region> within,
                      std::function<void(bool, std::string, std::uint64_t, std::uint64_t)> done) {
    world_owner_->rollback(actor, std::move(entries), within, [done = std::move(done)](WorldOwner::RollbackResult r) {
      done(r.ok, std::move(r.error), r.tick, r.voxels_restored);
    });
  };
  return h;
}

void Server::arm_stats() {
  stats_timer_.expires_after(std::chrono::seconds(10));
  stats_timer_.async_wait([this](const asio::error_code& ec) {
    if (ec || stopping_) return;
    log_stats();
    arm_stats();
  });
}

void Server::log_stats() {
  const auto now = std::chrono::steady_clock::now();
  const double dt = std::max(1e-3, std::chrono::duration<double>(now - stats_at_).count());
  std::uint64_t sent = 0, received = 0;
  for (std::size_t t = 0; t < NetCounters::kTypes; ++t) {
    sent += counters_.net.sent_bytes[t].load(std::memory_order_relaxed);
    received += counters_.net.received_bytes[t].load(std::memory_order_relaxed);
  }
  const std::uint64_t edits = counters_.edits_applied.load(std::memory_order_relaxed);
  server_log().info("{} clients; {:.1f} edits/s; out {:.2f} MB/s, in {:.3f} MB/s; {} chunks loaded",
                    counters_.clients.load(), static_cast<double>(edits - stats_edits_) / dt,
                    static_cast<double>(sent - stats_sent_) / dt / 1e6,
                    static_cast<double>(received - stats_received_) / dt / 1e6, counters_.chunks_loaded.load());
  stats_at_ = now;
  stats_edits_ = edits;
  stats_sent_ = sent;
  stats_received_ = received;
}

}  // namespace terrane
