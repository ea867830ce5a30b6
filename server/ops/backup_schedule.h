// BackupSchedule: a SQLite world's scheduled backups (terrane-server
// --backup-every, --backup-keep, --backup-dir). It owns its thread
// (terrane-backup), which waits until a backup is due or it is stopped,
// copies the world with SQLite's online backup (SqliteStore::backup_to:
// consistent while the server writes, made in NAME.partial and renamed, so
// a failed one leaves nothing) to DIR/world-YYYYMMDDTHHMMSS.mmmZ (UTC, so
// names sort by time), and then removes the oldest of those beyond keep.
// Nothing else in DIR is touched. Each backup and removal is logged;
// successes, failures and the last success's time are its counters, read
// by /metrics (terrane_backup_*, render_backup_metrics).
//
// Threading: start() and stop() on the thread that starts and stops the
// server; backup_once() on the schedule's thread (or a test's, with no
// schedule running); the counters from any thread. m_ guards stopping_,
// with a condition variable: the thread sleeps until the next backup is
// due or it is told to stop.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "server/ops/ops_options.h"

namespace terrane {

// What /metrics says of the schedule. Written by its thread.
struct BackupCounters {
  std::atomic<std::uint64_t> made{0};
  std::atomic<std::uint64_t> failed{0};
  std::atomic<std::int64_t> last_success_unix_ms{0};  // 0: none yet
};

class BackupSchedule {
 public:
  // world_dir: the SQLite world's directory (reopened for each backup).
  BackupSchedule(BackupOptions options, std::string world_dir);
  ~BackupSchedule();
  BackupSchedule(const BackupSchedule&) = delete;
  BackupSchedule& operator=(const BackupSchedule&) = delete;

  // The first backup is due options.every after start().
  void start();
  // No backup from now on; waits for one under way to finish.
  void stop();

  // One backup now, then the retention: the new backup's path, or "" when
  // it failed (logged and counted, *error says why when given).
  std::string backup_once(std::string* error = nullptr);

  const BackupCounters& counters() const { return counters_; }
  const BackupOptions& options() const { return options_; }

  // The scheduled backups in dir (the names this schedule gives, whole
  // ones only), oldest first.
  static std::vector<std::string> backups_in(const std::string& dir);

 private:
  void run();

  const BackupOptions options_;
  const std::string world_dir_;
  BackupCounters counters_;
  std::mutex m_;
  std::condition_variable wake_;
  bool stopping_ = false;  // guarded by m_
  std::thread thread_;
};

// The schedule's counters in Prometheus' text format:
// terrane_backups_total, terrane_backup_failures_total and
// terrane_backup_last_success_timestamp_seconds (0 before the first).
std::string render_backup_metrics(const BackupCounters& c);

}  // namespace terrane
