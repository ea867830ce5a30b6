// SqliteEditLog: a world's edit log, the table "edit_log" of world.sqlite
// (common/world/WORLD_FORMAT.md): one row per applied edit (tick, time,
// player, box, voxels before and after), made by the first logged write.
// It owns its insert statement and the log's size once counted; the
// connection is SqliteStore's, which outlives it and owns the transactions
// (append runs inside the one that writes the edit's chunks).
// Thread-safety: the connection's owner thread (SqliteStore's).
#pragma once

#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "common/world/world_store.h"

struct sqlite3;
struct sqlite3_stmt;

namespace terrane {

class SqliteEditLog {
 public:
  // db: an open world (not owned; outlives this); dir names it in errors.
  SqliteEditLog(sqlite3* db, std::string dir);
  ~SqliteEditLog();
  SqliteEditLog(const SqliteEditLog&) = delete;
  SqliteEditLog& operator=(const SqliteEditLog&) = delete;

  // Inside the caller's transaction: the entries written (the table made
  // if it is not there yet); the bytes of their before/after voxels. On an
  // error the caller rolls back (the message is taken before).
  FileResult<std::uint64_t> append(std::span<const EditLogEntry> log);
  // After that transaction committed: the size kept counts what it added.
  void committed(std::size_t entries, std::uint64_t bytes);
  // The entries matching q, newest first (none before anything was logged).
  FileResult<std::vector<EditLogEntry>> query(const EditLogQuery& q);
  // Deletes entries older than before_ms, then the oldest until the
  // before/after bytes are at most max_bytes (0: no bound by size), at
  // most max_rows in all; how many went.
  FileResult<std::int64_t> prune(std::int64_t before_ms, std::uint64_t max_bytes, std::int64_t max_rows);
  // Entries and the bytes of their before/after voxels. Counted once (a
  // scan of the whole log), then kept by this owner's appends and prunes.
  FileResult<EditLogSize> size();

 private:
  FileError error(const std::string& what) const;

  sqlite3* db_;
  std::string dir_;
  sqlite3_stmt* insert_stmt_ = nullptr;
  // size() once counted: a prune by size once a minute scanned every row,
  // tens of milliseconds on the writer thread with a busy log, and every
  // acknowledgement waited behind it. Unknown again after a failure or a
  // prune by age that did not go as counted.
  std::optional<EditLogSize> size_;
};

}  // namespace terrane
