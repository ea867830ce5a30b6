#include "server/ops/operations.h"

#include <algorithm>
#include <vector>

#include "common/cli/cli.h"
#include "server/base/log.h"

namespace terrane {

Operations::Operations(const OpsOptions& options, std::string metrics_host, asio::io_context& io,
                       SessionTable& sessions, const ServerCounters& counters, Wiring wiring)
    : metrics_host_(std::move(metrics_host)),
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
    reply(AdminResultMsg{req.request_id, false, "the server is stopping", "{}"});
  };
  if (metrics_at) {
    Operations* self = ops.get();
    auto http = HttpEndpoint::bind(
        metrics_at->first, metrics_at->second, [self] { return self->wiring_.metrics(); },
        [self] { return self->wiring_.health(); });
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
}

void Operations::notify_all(const ServerNoticeMsg& notice) {
  const auto frame = std::make_shared<const Frame>(build_server_notice(notice));
  sessions_.for_each_welcomed(
      [&](std::uint64_t, Session& s, const ClientSession::Info&) { s.send(frame, SendClass::kControl); });
}

void Operations::schedule_shutdown(std::uint32_t seconds, bool restart, const std::string& reason) {
  clients_reconnect_ = restart;
  ServerNoticeMsg n;
  n.kind = wire::NoticeKind::Shutdown;
  n.seconds_left = seconds;
  n.reconnect = restart;
  n.text = "server stopping in " + std::to_string(seconds) + " s" + (restart ? " and restarting" : "") +
           (reason.empty() ? std::string() : ": " + reason);
  server_log().warn("{} (asked by an operator)", n.text);
  notify_all(n);
  asio::post(strand_, [this, seconds, restart] {
    if (stopping_) return;
    shutdown_timer_.expires_after(std::chrono::seconds(seconds));
    shutdown_timer_.async_wait([this, restart](const asio::error_code& ec) {
      if (ec || stopping_) return;
      if (on_shutdown_) return on_shutdown_(restart);
      // No owner to ask: stop from a thread of our own (the server's stop
      // joins the io threads, this one among them).
      if (!stopping_thread_.joinable()) stopping_thread_ = std::thread([this] { wiring_.stop(); });
    });
  });
}

void Operations::stop_timers() {
  stopping_ = true;
  stats_.stop();
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
  h.rollback = wiring_.world.rollback;
  return h;
}

}  // namespace terrane
