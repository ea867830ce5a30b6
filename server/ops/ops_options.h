// The ops room's options: the access rules' tokens, the /metrics endpoint,
// what a scheduled shutdown calls and the scheduled backups. Plain data, filled by main.cpp
// (part of ServerOptions, server/server_options.h) and given to
// Operations::open.
#pragma once

#include <chrono>
#include <functional>
#include <string>
#include <unordered_map>

#include "server/net/net_options.h"

namespace terrane {

// Scheduled backups of a SQLite world (BackupSchedule, backup_schedule.h).
struct BackupOptions {
  std::chrono::milliseconds every{0};  // 0: none
  int keep = 7;                        // the newest kept in dir, at least 1
  std::string dir;                     // where they go (made when missing)
};

struct OpsOptions {
  // The operator's HTTP endpoint (/metrics, /health): "HOST:PORT", empty =
  // none; port 0 picks a free one (see metrics_port()).
  std::string metrics_address;
  // Authentication (checked at the handshake, by AccessControl): per-player
  // tokens (name -> token, from a tokens file) take precedence over one
  // shared token; with neither the server is open, which it allows only on
  // a loopback address unless allow_open says otherwise.
  std::string auth_token;
  std::unordered_map<std::string, PlayerToken> player_tokens;
  // Where player_tokens came from (read again on SIGHUP); "" = none.
  std::string tokens_file;
  // Whoever gives this token joins as an admin (terrane-admin), whatever
  // the name; empty = admins only through the tokens file's roles.
  std::string admin_token;
  bool allow_open = false;
  // Called (any thread) when an operator asked the server to stop
  // (terrane-admin shutdown) and the warning time is up; the owner of the
  // Server should stop it, as on SIGTERM. restart: the operator said
  // --restart (terrane-server then exits 75 so a supervisor restarts it).
  std::function<void(bool restart)> on_shutdown;
  // --backup-every, --backup-keep, --backup-dir.
  BackupOptions backups;
};

}  // namespace terrane
