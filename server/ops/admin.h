// Admin: the operators' commands (terrane-admin), spoken over the game
// protocol by sessions whose token has the admin role (AdminRequest ->
// AdminResult, protocol/PROTOCOL.md "Administration"). It runs them on a
// thread of its own, so a backup or a save never holds up a game thread,
// and reaches the rest of the server only through AdminHooks (which the
// Server wires) and AccessControl (bans, whitelist).
//
// Commands: status, players, kick, ban, unban, whitelist, say, save,
// backup, shutdown (and its --cancel, or cancel-shutdown), help (kAdminHelp). Every answer has text for people
// and a JSON object for scripts.
#pragma once

#include <asio.hpp>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "common/voxel/vec3.h"
#include "common/world/world_store.h"
#include "protocol/messages.h"
#include "server/ops/access.h"

namespace terrane {

// One connected client, as an operator sees it.
struct PlayerInfo {
  std::uint64_t id = 0;
  std::string name;
  std::string address;  // IP, as bans take it
  Vec3f position;
  bool admin = false;
  double connected_s = 0;
  std::uint64_t bytes_in = 0, bytes_out = 0;
  double ping_ms = -1;  // round trip of the server's last Ping; -1: none answered yet
};

struct ServerStatus {
  std::string world_dir;  // or the PostgreSQL URL
  std::string version, address, border;
  std::optional<std::uint32_t> shutdown_in_s;  // a pending shutdown's seconds left
  std::uint64_t epoch = 0;
  double uptime_s = 0;
  std::uint64_t clients = 0, admin_sessions = 0, ticks = 0, edits_applied = 0, edits_rejected = 0, chunks_resident = 0;
  std::uint32_t tick_hz = 0;
  bool storage_failed = false;
  double tick_mean_ms = 0;
  // The edit log's entries and voxel bytes as the storage writer last
  // counted them (nullopt: not counted yet, or the count failed).
  std::optional<EditLogSize> edit_log;
};

struct AdminHooks {
  std::function<ServerStatus()> status;
  std::function<std::vector<PlayerInfo>()> players;
  // Closes every session for which match is true; how many.
  std::function<int(const std::function<bool(const PlayerInfo&)>& match, CloseReason why, const std::string& text)>
      close_matching;
  std::function<void(const ServerNoticeMsg&)> notify_all;
  // done(tick, stored) runs (any thread) once every edit applied so far is
  // stored (stored false: the store failed).
  std::function<void(std::function<void(std::uint64_t tick, bool stored)> done)> flush;
  std::function<void(std::uint32_t seconds, bool restart, const std::string& reason)> shutdown;
  // Cancels a pending shutdown; false if none was.
  std::function<bool()> cancel_shutdown;
  // Undoes entries (newest first) as one edit by actor; done after the commit.
  std::function<void(const std::string& actor, std::vector<EditLogEntry> entries, std::optional<Region> within,
                     std::function<void(bool ok, std::string error, std::uint64_t tick, std::uint64_t voxels)> done)>
      rollback;
};

extern const char* const kAdminHelp;
// A rollback undoes at most this many logged edits at once.
inline constexpr std::size_t kMaxRollbackEdits = 20000;
// ... whose boxes cover at most this many voxels in all (the work of one tick).
inline constexpr std::int64_t kMaxRollbackVoxels = 16 << 20;

class Admin {
 public:
  using Reply = std::function<void(AdminResultMsg)>;

  // store: the world's; reopened (WorldStore::reopen) for the log and
  // rollback, so they never share the world owner's connection.
  // world_dir: a SQLite world's directory, which backup copies; "" for a
  // world in PostgreSQL (backed up with PostgreSQL's own tools).
  Admin(const WorldStore& store, std::string world_dir, AccessControl& access, AdminHooks hooks);
  ~Admin();  // finishes the command running, drops the rest
  Admin(const Admin&) = delete;
  Admin& operator=(const Admin&) = delete;

  // Any thread: queues the command; reply runs on the admin thread.
  void handle(const std::string& who, AdminRequestMsg req, Reply reply);

 private:
  AdminResultMsg run(const std::string& who, const AdminRequestMsg& req);

  const WorldStore& store_;
  const std::string world_dir_;
  AccessControl& access_;
  AdminHooks hooks_;
  // Waits (on the admin thread) until f is ready, the server stops, or the
  // timeout; false unless ready.
  template <class Future>
  bool wait_for(Future& f, std::chrono::seconds timeout);

  std::atomic<bool> stopping_{false};
  asio::io_context io_;
  asio::executor_work_guard<asio::io_context::executor_type> work_;
  std::thread thread_;
};

// "90", "90s", "15m", "2h", "7d" -> seconds; nullopt if malformed or not
// positive.
std::optional<std::int64_t> parse_duration_s(const std::string& text);

}  // namespace terrane
