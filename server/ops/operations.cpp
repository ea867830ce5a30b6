#include "server/ops/operations.h"

#include <algorithm>
#include <vector>

#include "common/cli/cli.h"
#include "server/base/log.h"
#include "server/net/limits.h"

namespace terrane {

Operations::Operations(const OpsOptions& options, std::string metrics_host, asio::io_context& io,
                       SessionTable& sessions, const ServerCounters& counters, Wiring wiring)
    : metrics_host_(std::move(metrics_host)),
      tokens_file_(options.tokens_file),
      on_shutdown_(options.on_shutdown),
      sessions_(sessions),
      wiring_(std::move(wiring)),
      stats_(io, counters),
      strand_(asio::make_strand(io)),
      shutdown_timer_(strand_) {}

FileResult<std::unique_ptr<Operations>> Operations::open(const OpsOptions& options, const WorldStore& store,
                                                         const std::string& world_dir,
                                                         asio::io_context& io, SessionTable& sessions,
                                                         const ServerCounters& counters, Wiring wiring) {
  std::optional<std::pair<std::string, std::uint16_t>> metrics_at;
  if (!options.metrics_address.empty()) {
    auto hp = parse_host_port(options.metrics_address);
    if (!hp) return FileError{"--metrics: " + hp.error().message, {}};
    metrics_at = *hp;
  }
  std::unique_ptr<Operations> ops(new Operations(options, metrics_at ? metrics_at->first : "", io, sessions, counters,
                                                 std::move(wiring)));
  auto access_store = store.reopen();
  if (!access_store) return access_store.error();
  auto access = AccessControl::open(std::move(*access_store), options.auth_token, options.player_tokens,
                                    options.admin_token);
  if (!access) return access.error();
  ops->access_ = std::move(*access);
  ops->admin_ = std::make_unique<Admin>(store, world_dir, *ops->access_, ops->hooks());
  ops->admin_fn_ = [self = ops.get()](const std::string& who, AdminRequestMsg req,
                                      std::function<void(AdminResultMsg)> reply) {
    std::lock_guard lock(self->admin_m_);
    if (self->admin_) return self->admin_->handle(who, std::move(req), std::move(reply));
    reply(AdminResultMsg{req.request_id, false, "the server is stopping", "{\"error\": \"the server is stopping\"}"});
  };
  if (options.backups.every.count() > 0) {
    if (world_dir.empty())
      return FileError{"--backup-every: the world is in PostgreSQL; back it up with PostgreSQL's own tools", {}};
    ops->backups_ = std::make_unique<BackupSchedule>(options.backups, world_dir);
  }
  if (metrics_at) {
    Operations* self = ops.get();
    auto http = HttpEndpoint::bind(
        metrics_at->first, metrics_at->second,
        [self] {
          return self->wiring_.metrics() + render_health_gauge(self->health()) +
                 (self->backups_ ? render_backup_metrics(self->backups_->counters()) : std::string());
        },
        [self] { return self->health(); });
    if (!http) return http.error();
    ops->metrics_ = std::move(*http);
  }
  return ops;
}

Operations::~Operations() { join_stopping(); }

void Operations::start() {
  if (metrics_) {
    metrics_->start();
    server_log().info("metrics on http://{}:{}/metrics", metrics_host_, metrics_->port());
  }
  stats_.start();
  if (backups_) backups_->start();
}

void Operations::notify_all(const ServerNoticeMsg& notice) {
  const auto frame = std::make_shared<const Frame>(build_server_notice(notice));
  sessions_.for_each_welcomed(
      [&](std::uint64_t, Session& s, const ClientSession::Info&) { s.send(frame, SendClass::kControl); });
}

namespace {

std::string shutdown_text(std::uint32_t seconds, bool restart, const std::string& reason) {
  return "server stopping in " + std::to_string(seconds) + " s" + (restart ? " and restarting" : "") +
         (reason.empty() ? std::string() : ": " + reason);
}

}  // namespace

void Operations::schedule_shutdown(std::uint32_t seconds, bool restart, const std::string& reason) {
  clients_reconnect_ = restart;
  const auto due = std::chrono::steady_clock::now() + std::chrono::seconds(seconds);
  shutdown_due_ns_ = std::max<std::int64_t>(1, steady_ns(due));
  ServerNoticeMsg n;
  n.kind = wire::NoticeKind::Shutdown;
  n.seconds_left = seconds;
  n.reconnect = restart;
  n.text = shutdown_text(seconds, restart, reason);
  server_log().warn("{} (asked by an operator)", n.text);
  notify_all(n);
  asio::post(strand_, [this, due, reason] {
    if (stopping_) return;
    shutdown_due_ = due;
    shutdown_reason_ = reason;
    shutdown_timer_.cancel();
    arm_shutdown(++shutdown_generation_);
  });
}

void Operations::arm_shutdown(std::uint64_t generation) {
  const auto now = std::chrono::steady_clock::now();
  const auto left = std::chrono::ceil<std::chrono::seconds>(shutdown_due_ - now).count();
  std::uint32_t mark = 0;  // the next warning, 0: none before the due time
  for (const std::uint32_t w : kShutdownWarnings)
    if (static_cast<std::int64_t>(w) < left) {
      mark = w;
      break;
    }
  shutdown_timer_.expires_at(shutdown_due_ - std::chrono::seconds(mark));
  shutdown_timer_.async_wait([this, generation, mark](const asio::error_code& ec) {
    if (ec || stopping_ || generation != shutdown_generation_) return;
    if (mark > 0) {
      ServerNoticeMsg n;
      n.kind = wire::NoticeKind::Shutdown;
      n.seconds_left = mark;
      n.reconnect = clients_reconnect_;
      n.text = shutdown_text(mark, n.reconnect, shutdown_reason_);
      server_log().warn("{}", n.text);
      notify_all(n);
      return arm_shutdown(generation);
    }
    if (on_shutdown_) return on_shutdown_(clients_reconnect_.load());
    // No owner to ask: stop from a thread of our own (the server's stop
    // joins the io threads, this one among them).
    if (!stopping_thread_.joinable()) stopping_thread_ = std::thread([this] { wiring_.stop(); });
  });
}

bool Operations::cancel_shutdown() {
  if (stopping_ || shutdown_due_ns_.exchange(0) == 0) return false;
  clients_reconnect_ = true;
  asio::post(strand_, [this] {
    ++shutdown_generation_;
    shutdown_timer_.cancel();
  });
  ServerNoticeMsg n;
  n.kind = wire::NoticeKind::Say;
  n.text = "the scheduled shutdown is cancelled";
  server_log().warn("{} (asked by an operator)", n.text);
  notify_all(n);
  return true;
}

void Operations::reload() {
  std::optional<std::unordered_map<std::string, PlayerToken>> players;
  if (!tokens_file_.empty()) {
    auto tokens = load_tokens_file(tokens_file_);
    if (!tokens)
      server_log().error("reload: keeping the previous tokens: {}", tokens.error().message);
    else if (tokens->empty())
      server_log().error("reload: keeping the previous tokens: tokens file {} lists no players", tokens_file_);
    else
      players = std::move(*tokens);
  }
  auto changed = access_->reload(std::move(players));
  if (!changed) {
    server_log().error("reload: keeping the previous bans and whitelist: {}", changed.error().message);
    return;
  }
  if (changed->empty()) server_log().info("reload: nothing changed");
  for (const std::string& line : *changed) server_log().info("reload: {}", line);
}

std::optional<std::uint32_t> Operations::shutdown_in() const {
  const std::int64_t due = shutdown_due_ns_.load();
  if (due == 0) return std::nullopt;
  const std::int64_t left = due - steady_ns(std::chrono::steady_clock::now());
  return static_cast<std::uint32_t>(std::max<std::int64_t>(0, (left + 999'999'999) / 1'000'000'000));
}

Health Operations::health() const {
  Health h = wiring_.health();
  if (h.state == HealthState::kFailing) return h;
  if (const auto left = shutdown_in())
    return {HealthState::kDraining, "shutdown pending: stopping in " + std::to_string(*left) + " s"};
  return h;
}

void Operations::stop_timers() {
  stopping_ = true;
  stats_.stop();
  if (backups_) backups_->stop();
  asio::dispatch(strand_, [this] { shutdown_timer_.cancel(); });
}

void Operations::close_admin() {
  std::unique_ptr<Admin> admin;
  {
    std::lock_guard lock(admin_m_);
    admin = std::move(admin_);
  }
  // admin ends here, outside admin_m_: its command running finishes.
}

void Operations::notify_stopping() {
  ServerNoticeMsg bye;
  bye.kind = wire::NoticeKind::Shutdown;
  bye.reconnect = clients_reconnect_.load();
  bye.text = bye.reconnect ? "server stopping now; it restarts: reconnect" : "server stopping now";
  notify_all(bye);
}

void Operations::stop_metrics() {
  if (metrics_) metrics_->stop();
}

void Operations::join_stopping() {
  if (stopping_thread_.joinable() && stopping_thread_.get_id() != std::this_thread::get_id()) stopping_thread_.join();
}

AdminHooks Operations::hooks() {
  AdminHooks h;
  h.status = [this] {
    ServerStatus s = wiring_.world.status();
    s.uptime_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - started_at_).count();
    s.shutdown_in_s = shutdown_in();
    return s;
  };
  auto each = [this](const std::function<void(Session&, const PlayerInfo&)>& fn) {
    const auto now = std::chrono::steady_clock::now();
    sessions_.for_each_welcomed([&](std::uint64_t id, Session& s, const ClientSession::Info& info) {
      PlayerInfo p;
      p.id = id;
      p.name = info.name;
      p.address = s.address();
      p.position = info.position;
      p.admin = info.admin;
      p.connected_s = std::chrono::duration<double>(now - info.joined).count();
      p.bytes_in = s.bytes_received();
      p.bytes_out = s.bytes_sent();
      p.ping_ms = info.ping_ms;
      fn(s, p);
    });
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
  h.flush = wiring_.world.flush;
  h.shutdown = [this](std::uint32_t seconds, bool restart, const std::string& reason) {
    schedule_shutdown(seconds, restart, reason);
  };
  h.cancel_shutdown = [this] { return cancel_shutdown(); };
  h.rollback = wiring_.world.rollback;
  return h;
}

}  // namespace terrane
