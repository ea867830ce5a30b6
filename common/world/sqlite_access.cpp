#include "common/world/sqlite_access.h"

#include <sqlite3.h>

#include "common/world/sqlite_util.h"

namespace terrane {

SqliteAccess::SqliteAccess(sqlite3* db, std::string dir) : db_(db), dir_(std::move(dir)) {}

FileError SqliteAccess::error(const std::string& what) const { return sqlite_error(db_, dir_, what); }

FileResult<std::vector<std::pair<std::string, std::string>>> SqliteAccess::entries() {
  std::vector<std::pair<std::string, std::string>> out;
  if (!sqlite_table_exists(db_, "access")) return out;  // made by the first write: nothing listed
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v2(db_, "SELECT key, value FROM access ORDER BY key", -1, &st, nullptr) != SQLITE_OK) {
    sqlite3_finalize(st);
    return error("cannot read the access lists");
  }
  int rc;
  while ((rc = sqlite3_step(st)) == SQLITE_ROW)
    out.emplace_back(sqlite_column_string(st, 0), sqlite_column_string(st, 1));
  sqlite3_finalize(st);
  if (rc != SQLITE_DONE) return error("cannot read the access lists");
  return out;
}

FileStatus SqliteAccess::put(const std::string& key, const std::string& value) {
  char* err = nullptr;
  if (sqlite3_exec(db_, "CREATE TABLE IF NOT EXISTS access(key TEXT PRIMARY KEY, value TEXT NOT NULL) WITHOUT ROWID",
                   nullptr, nullptr, &err) != SQLITE_OK) {
    sqlite3_free(err);
    return error("cannot create the access table");
  }
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v2(db_, "INSERT OR REPLACE INTO access(key, value) VALUES(?, ?)", -1, &st, nullptr) != SQLITE_OK)
    return error("cannot prepare an access write");
  sqlite3_bind_text(st, 1, key.data(), static_cast<int>(key.size()), SQLITE_TRANSIENT);
  sqlite3_bind_text(st, 2, value.data(), static_cast<int>(value.size()), SQLITE_TRANSIENT);
  const int rc = sqlite3_step(st);
  sqlite3_finalize(st);
  if (rc != SQLITE_DONE) return error("cannot write the access lists");
  return Ok{};
}

FileStatus SqliteAccess::erase(const std::string& key) {
  if (!sqlite_table_exists(db_, "access")) return Ok{};  // no table: nothing to erase
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v2(db_, "DELETE FROM access WHERE key = ?", -1, &st, nullptr) != SQLITE_OK) {
    sqlite3_finalize(st);
    return error("cannot write the access lists");
  }
  sqlite3_bind_text(st, 1, key.data(), static_cast<int>(key.size()), SQLITE_TRANSIENT);
  const int rc = sqlite3_step(st);
  sqlite3_finalize(st);
  if (rc != SQLITE_DONE) return error("cannot write the access lists");
  return Ok{};
}

}  // namespace terrane
