#include "common/world/sqlite_util.h"

#include <sqlite3.h>

#include <utility>

#include "common/world/coarse_image.h"

namespace terrane {

FileError sqlite_error(sqlite3* db, const std::string& dir, const std::string& what) {
  return FileError{"world " + dir + ": " + what + (db ? std::string(": ") + sqlite3_errmsg(db) : ""), {}};
}

SqliteStmtReset::~SqliteStmtReset() {
  sqlite3_reset(s);
  sqlite3_clear_bindings(s);
}

SqliteTransaction::SqliteTransaction(sqlite3* db)
    : db_(db), open_(sqlite3_exec(db, "BEGIN IMMEDIATE", nullptr, nullptr, nullptr) == SQLITE_OK) {}

SqliteTransaction::~SqliteTransaction() {
  if (open_) sqlite3_exec(db_, "ROLLBACK", nullptr, nullptr, nullptr);
}

bool SqliteTransaction::commit() {
  if (sqlite3_exec(db_, "COMMIT", nullptr, nullptr, nullptr) != SQLITE_OK) return false;
  open_ = false;
  return true;
}

std::int64_t sqlite_memory_used() {
  sqlite3_int64 now = 0, peak = 0;
  if (sqlite3_status64(SQLITE_STATUS_MEMORY_USED, &now, &peak, 0) != SQLITE_OK) return 0;
  return now;
}

std::string sqlite_column_string(sqlite3_stmt* st, int column) {
  const auto* text = reinterpret_cast<const char*>(sqlite3_column_text(st, column));
  return text != nullptr ? std::string(text) : std::string();
}

bool sqlite_table_exists(sqlite3* db, const char* name) {
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v2(db, "SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = ?", -1, &st, nullptr) !=
      SQLITE_OK)
    return false;
  sqlite3_bind_text(st, 1, name, -1, SQLITE_STATIC);
  const bool yes = sqlite3_step(st) == SQLITE_ROW;
  sqlite3_finalize(st);
  return yes;
}

FileResult<std::vector<Vec3i>> sqlite_chunks_in_region(sqlite3* db, const std::string& dir, const char* table,
                                                       Vec3i region, std::vector<std::uint64_t>* revisions) {
  sqlite3_stmt* st = nullptr;
  // cx and cy as lists, so the (cx, cy, cz) index is used for all three
  // (a range on cx alone would scan an 8-wide slab of the whole world).
  const Vec3i lo = region * kCoarseRegionChunks;
  std::string sql = revisions != nullptr ? "SELECT cx, cy, cz, revision FROM " : "SELECT DISTINCT cx, cy, cz FROM ";
  sql.append(table);
  for (const auto& [column, first] : {std::pair<const char*, int>{" WHERE cx IN (", lo.x}, {") AND cy IN (", lo.y}}) {
    sql.append(column);
    for (int i = 0; i < kCoarseRegionChunks; ++i) {
      if (i > 0) sql.push_back(',');
      sql.append(std::to_string(first + i));
    }
  }
  sql.append(") AND cz BETWEEN ?1 AND ?2");
  const auto read_error = [&] {
    std::string what = "cannot read the ";
    what.append(table).append(" table");
    return sqlite_error(db, dir, what);
  };
  if (sqlite3_prepare_v2(db, sql.c_str(), -1, &st, nullptr) != SQLITE_OK) return read_error();
  sqlite3_bind_int(st, 1, lo.z);
  sqlite3_bind_int(st, 2, lo.z + kCoarseRegionChunks - 1);
  std::vector<Vec3i> out;
  int rc;
  while ((rc = sqlite3_step(st)) == SQLITE_ROW) {
    out.push_back(Vec3i{sqlite3_column_int(st, 0), sqlite3_column_int(st, 1), sqlite3_column_int(st, 2)});
    if (revisions != nullptr) revisions->push_back(static_cast<std::uint64_t>(sqlite3_column_int64(st, 3)));
  }
  sqlite3_finalize(st);
  if (rc != SQLITE_DONE) return read_error();
  return out;
}

}  // namespace terrane
