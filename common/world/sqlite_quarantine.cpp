#include "common/world/sqlite_quarantine.h"

#include <sqlite3.h>

#include <sstream>

#include "common/world/sqlite_util.h"

namespace terrane {

namespace {
constexpr const char* kQuarantineSchema =
    "CREATE TABLE IF NOT EXISTS quarantine(id INTEGER PRIMARY KEY,"
    " cx INTEGER NOT NULL, cy INTEGER NOT NULL, cz INTEGER NOT NULL,"
    " revision INTEGER NOT NULL, data BLOB NOT NULL, reason TEXT NOT NULL, time INTEGER NOT NULL);"
    "CREATE INDEX IF NOT EXISTS quarantine_chunk ON quarantine(cx, cy, cz);";
}  // namespace

SqliteQuarantine::SqliteQuarantine(sqlite3* db, std::string dir) : db_(db), dir_(std::move(dir)) {}

SqliteQuarantine::~SqliteQuarantine() { sqlite3_finalize(revision_stmt_); }

FileError SqliteQuarantine::error(const std::string& what) const { return sqlite_error(db_, dir_, what); }

FileStatus SqliteQuarantine::ensure_table() {
  // Look first: when the table exists (the usual case) opening stays a pure
  // read, so tools can open a world a server is writing without a write lock.
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v2(db_, "SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = 'quarantine'", -1, &st,
                         nullptr) != SQLITE_OK)
    return error("cannot read schema");
  const int rc = sqlite3_step(st);
  sqlite3_finalize(st);
  if (rc == SQLITE_ROW) return Ok{};
  if (rc != SQLITE_DONE) return error("cannot read schema");
  char* err = nullptr;
  if (sqlite3_exec(db_, kQuarantineSchema, nullptr, nullptr, &err) != SQLITE_OK) {
    std::string msg = err ? err : "?";
    sqlite3_free(err);
    return FileError{"world " + dir_ + ": cannot create the quarantine table: " + msg, {}};
  }
  return Ok{};
}

FileResult<std::optional<std::uint64_t>> SqliteQuarantine::move_aside(Vec3i pos, const std::string& reason,
                                                                      const std::function<FileStatus()>& also) {
  std::ostringstream where;
  where << "chunk (" << pos.x << ", " << pos.y << ", " << pos.z << ")";
  SqliteTransaction tx(db_);
  if (!tx.began()) return error("cannot begin quarantine of " + where.str());
  auto fail = [&](const std::string& what) { return error(what + " " + where.str()); };
  // The row is copied inside SQLite: the blob moves byte for byte, however
  // damaged it is.
  const char* kSteps[2] = {
      "INSERT INTO quarantine(cx, cy, cz, revision, data, reason, time)"
      " SELECT cx, cy, cz, revision, data, ?4, CAST(strftime('%s', 'now') AS INTEGER)"
      " FROM chunks WHERE cx = ?1 AND cy = ?2 AND cz = ?3",
      "DELETE FROM chunks WHERE cx = ?1 AND cy = ?2 AND cz = ?3"};
  std::optional<std::uint64_t> moved;
  {
    sqlite3_stmt* st = nullptr;
    if (sqlite3_prepare_v2(db_, "SELECT revision FROM chunks WHERE cx = ? AND cy = ? AND cz = ?", -1, &st, nullptr) !=
        SQLITE_OK)
      return fail("cannot prepare quarantine of");
    sqlite3_bind_int(st, 1, pos.x);
    sqlite3_bind_int(st, 2, pos.y);
    sqlite3_bind_int(st, 3, pos.z);
    const int rc = sqlite3_step(st);
    if (rc == SQLITE_ROW) moved = static_cast<std::uint64_t>(sqlite3_column_int64(st, 0));
    sqlite3_finalize(st);
    if (rc != SQLITE_ROW && rc != SQLITE_DONE) return fail("cannot read revision of");
  }
  if (!moved) return std::optional<std::uint64_t>{};
  for (const char* sql : kSteps) {
    sqlite3_stmt* st = nullptr;
    if (sqlite3_prepare_v2(db_, sql, -1, &st, nullptr) != SQLITE_OK) return fail("cannot prepare quarantine of");
    sqlite3_bind_int(st, 1, pos.x);
    sqlite3_bind_int(st, 2, pos.y);
    sqlite3_bind_int(st, 3, pos.z);
    if (sqlite3_bind_parameter_count(st) >= 4) sqlite3_bind_text(st, 4, reason.c_str(), -1, SQLITE_TRANSIENT);
    const int rc = sqlite3_step(st);
    const int changed = sqlite3_changes(db_);
    sqlite3_finalize(st);
    if (rc != SQLITE_DONE) return fail("cannot quarantine");
    if (changed != 1) return fail("quarantine moved " + std::to_string(changed) + " rows for");
  }
  // What goes with the row (its coarse entry).
  if (auto c = also(); !c) return c.error();
  if (!tx.commit()) return fail("cannot commit quarantine of");
  return moved;
}

FileResult<std::optional<std::uint64_t>> SqliteQuarantine::revision(Vec3i pos) {
  if (!revision_stmt_ &&
      sqlite3_prepare_v2(db_, "SELECT max(revision) FROM quarantine WHERE cx = ? AND cy = ? AND cz = ?", -1,
                         &revision_stmt_, nullptr) != SQLITE_OK)
    return error("cannot prepare quarantine read");
  SqliteStmtReset reset{revision_stmt_};
  sqlite3_bind_int(revision_stmt_, 1, pos.x);
  sqlite3_bind_int(revision_stmt_, 2, pos.y);
  sqlite3_bind_int(revision_stmt_, 3, pos.z);
  if (sqlite3_step(revision_stmt_) != SQLITE_ROW) return error("cannot read quarantine");
  if (sqlite3_column_type(revision_stmt_, 0) == SQLITE_NULL) return std::optional<std::uint64_t>{};
  return std::optional<std::uint64_t>{static_cast<std::uint64_t>(sqlite3_column_int64(revision_stmt_, 0))};
}

FileStatus SqliteQuarantine::for_each(const std::function<void(const QuarantinedChunk&)>& fn) {
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v2(db_, "SELECT cx, cy, cz, revision, data, reason, time FROM quarantine ORDER BY id", -1, &st,
                         nullptr) != SQLITE_OK)
    return error("cannot list quarantined chunks");
  int rc;
  while ((rc = sqlite3_step(st)) == SQLITE_ROW) {
    QuarantinedChunk q;
    q.pos = Vec3i{sqlite3_column_int(st, 0), sqlite3_column_int(st, 1), sqlite3_column_int(st, 2)};
    q.revision = static_cast<std::uint64_t>(sqlite3_column_int64(st, 3));
    const auto* data = static_cast<const std::uint8_t*>(sqlite3_column_blob(st, 4));
    const auto size = static_cast<std::size_t>(sqlite3_column_bytes(st, 4));
    if (data) q.blob.assign(data, data + size);
    q.reason = sqlite_column_string(st, 5);
    q.time_unix_s = sqlite3_column_int64(st, 6);
    fn(q);
  }
  sqlite3_finalize(st);
  if (rc != SQLITE_DONE) return error("cannot list quarantined chunks");
  return Ok{};
}

FileResult<std::int64_t> SqliteQuarantine::count() {
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v2(db_, "SELECT count(*) FROM quarantine", -1, &st, nullptr) != SQLITE_OK)
    return error("cannot count quarantined chunks");
  std::int64_t n = -1;
  if (sqlite3_step(st) == SQLITE_ROW) n = sqlite3_column_int64(st, 0);
  sqlite3_finalize(st);
  if (n < 0) return error("cannot count quarantined chunks");
  return n;
}

FileResult<std::vector<Vec3i>> SqliteQuarantine::in_region(Vec3i region) {
  return sqlite_chunks_in_region(db_, dir_, "quarantine", region);
}

}  // namespace terrane
