// Operations: what the server does for its operators. It owns the access
// rules (AccessControl: tokens, bans, whitelist), the admin room (Admin,
// its thread) and the function sessions hand operators' commands to, the
// /metrics and /health endpoint (HttpEndpoint, its threads), the periodic
// stats line (StatsLog), scheduled backups (BackupSchedule, its thread), a scheduled shutdown (its timer, its warnings at
// intervals, its cancellation, whether clients are told to reconnect, the
// thread that stops a server nobody else stops), the health it reports
// (draining while a shutdown is pending) and the notices to every client. The world's part of the admin commands
// (status, flush, rollback) and the metrics' text come from the Server.
//
// Threading: the admin function and notify_all() run on any thread (the
// sessions' strands, the admin thread); the shutdown timer runs on a strand
// of its own on the io threads; the rest on the thread that starts and
// stops the server. admin_m_ guards admin_, which close_admin() drops while
// sessions may still hand it commands (a post would leave a command queued
// behind a room already gone).
#pragma once

#include <asio.hpp>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

#include "common/world/world_store.h"
#include "server/base/counters.h"
#include "server/net/client_session.h"
#include "server/net/session_table.h"
#include "server/ops/access.h"
#include "server/ops/admin.h"
#include "server/ops/backup_schedule.h"
#include "server/ops/http_endpoint.h"
#include "server/ops/metrics.h"
#include "server/ops/ops_options.h"
#include "server/ops/stats_log.h"

namespace terrane {

// Seconds before a scheduled shutdown at which every client is warned
// again (besides when it is scheduled).
inline constexpr std::uint32_t kShutdownWarnings[] = {600, 300, 120, 60, 30, 10, 5};

class Operations {
 public:
  // What the rest of the server answers, wired by the Server.
  struct Wiring {
    // The world's part of the admin commands: status (its uptime is filled
    // here), flush and rollback. The other hooks are the operations' own.
    AdminHooks world;
    std::function<std::string()> metrics;  // /metrics
    std::function<Health()> health;        // /health
    // Stops the server, when a scheduled shutdown is due and
    // options.on_shutdown is unset; run on a thread of the operations' own.
    std::function<void()> stop;
  };

  // store: the world's (reopened for the access rules; the admin room's).
  // world_dir: a SQLite world's directory, which the admin room's backup
  // copies ("" for a PostgreSQL world). io: the io threads' context (the
  // timers); sessions and counters outlive the operations. Fails on a
  // store that does not reopen, bad tokens, a --metrics address that
  // does not parse or bind, or scheduled backups of a PostgreSQL world.
  static FileResult<std::unique_ptr<Operations>> open(const OpsOptions& options, const WorldStore& store,
                                                      const std::string& world_dir,
                                                      asio::io_context& io, SessionTable& sessions,
                                                      const ServerCounters& counters, Wiring wiring);
  ~Operations();
  Operations(const Operations&) = delete;
  Operations& operator=(const Operations&) = delete;

  // For the sessions' Context: admission and operators' commands.
  const Admitter& admitter() const { return *access_; }
  const ClientSession::AdminFn& admin() const { return admin_fn_; }
  // The metrics endpoint's port (0 without --metrics).
  std::uint16_t metrics_port() const { return metrics_ ? metrics_->port() : 0; }

  // Serves /metrics (with --metrics), starts the stats line and the
  // scheduled backups.
  void start();
  // Sends notice to every welcomed client (control class).
  void notify_all(const ServerNoticeMsg& notice);
  // Tells every client the server stops in seconds, warns them again at
  // kShutdownWarnings seconds before, and stops it then. A later call
  // replaces a pending one.
  void schedule_shutdown(std::uint32_t seconds, bool restart, const std::string& reason);
  // Cancels a pending shutdown and tells every client; false if none was.
  bool cancel_shutdown();
  // SIGHUP: reads the tokens file again (a bad one keeps the previous
  // tokens and the log says why, naming file and line) and the bans and
  // whitelist from the store; logs what changed. Sessions already joined
  // stay. Any thread.
  void reload();
  // Seconds until a pending shutdown (nullopt: none). Any thread.
  std::optional<std::uint32_t> shutdown_in() const;
  // /health: the server's (wiring.health), draining while a shutdown is
  // pending unless it is failing. Any thread.
  Health health() const;

  // The steps of the server's stop(), in order:
  // no shutdown scheduled or due, no stats line and no scheduled backup
  // from now on (one under way finishes);
  void stop_timers();
  // the command running finishes (the world still runs, so a save can);
  // the rest, and any asked later, are refused;
  void close_admin();
  // every client is told the server stops (and whether to reconnect);
  void notify_stopping();
  // /metrics and /health end.
  void stop_metrics();
  // Waits for the thread a due shutdown stops the server on (not from it).
  void join_stopping();

 private:
  Operations(const OpsOptions& options, std::string metrics_host, asio::io_context& io, SessionTable& sessions,
             const ServerCounters& counters, Wiring wiring);
  AdminHooks hooks();
  // On strand_: waits for the next warning or the due time of the
  // shutdown numbered generation.
  void arm_shutdown(std::uint64_t generation);

  const std::string metrics_host_;
  const std::string tokens_file_;  // options.tokens_file
  const std::function<void(bool restart)> on_shutdown_;  // options.on_shutdown
  SessionTable& sessions_;
  Wiring wiring_;
  const std::chrono::steady_clock::time_point started_at_ = std::chrono::steady_clock::now();
  std::unique_ptr<AccessControl> access_;
  std::mutex admin_m_;  // guards admin_
  std::unique_ptr<Admin> admin_;
  ClientSession::AdminFn admin_fn_;
  std::unique_ptr<HttpEndpoint> metrics_;
  StatsLog stats_;
  std::unique_ptr<BackupSchedule> backups_;  // with --backup-every, a SQLite world
  asio::strand<asio::io_context::executor_type> strand_;  // the shutdown timer's
  asio::steady_timer shutdown_timer_;
  // The pending shutdown, on strand_: when it is due, whether it restarts,
  // why, and its number (a timer's wake-up for an older one is ignored).
  std::chrono::steady_clock::time_point shutdown_due_;
  std::string shutdown_reason_;
  std::uint64_t shutdown_generation_ = 0;
  // Its due time for other threads (health, status): steady-clock
  // nanoseconds, 0 = none pending.
  std::atomic<std::int64_t> shutdown_due_ns_{0};
  std::atomic<bool> stopping_{false};
  // What the last notice tells clients when the server stops: to reconnect
  // (a SIGTERM is usually a restart) unless an operator's shutdown said
  // otherwise.
  std::atomic<bool> clients_reconnect_{true};
  std::thread stopping_thread_;  // stops the server when no owner does (options.on_shutdown unset)
};

}  // namespace terrane
