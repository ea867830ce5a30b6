#include "common/world/sqlite_edit_log.h"

#include <sqlite3.h>

#include <algorithm>

#include "common/world/sqlite_util.h"

namespace terrane {

namespace {
constexpr const char* kEditLogSchema =
    "CREATE TABLE IF NOT EXISTS edit_log(id INTEGER PRIMARY KEY, tick INTEGER NOT NULL, time INTEGER NOT NULL,"
    " player TEXT NOT NULL, x0 INTEGER NOT NULL, y0 INTEGER NOT NULL, z0 INTEGER NOT NULL,"
    " x1 INTEGER NOT NULL, y1 INTEGER NOT NULL, z1 INTEGER NOT NULL, before BLOB NOT NULL, after BLOB NOT NULL);"
    "CREATE INDEX IF NOT EXISTS edit_log_player ON edit_log(player, id);"
    "CREATE INDEX IF NOT EXISTS edit_log_time ON edit_log(time);";
}  // namespace

SqliteEditLog::SqliteEditLog(sqlite3* db, std::string dir) : db_(db), dir_(std::move(dir)) {}

SqliteEditLog::~SqliteEditLog() { sqlite3_finalize(insert_stmt_); }

FileError SqliteEditLog::error(const std::string& what) const { return sqlite_error(db_, dir_, what); }

FileResult<std::uint64_t> SqliteEditLog::append(std::span<const EditLogEntry> log) {
  std::uint64_t bytes = 0;
  if (log.empty()) return bytes;
  if (!insert_stmt_) {
    if (sqlite3_exec(db_, kEditLogSchema, nullptr, nullptr, nullptr) != SQLITE_OK ||
        sqlite3_prepare_v2(db_,
                           "INSERT INTO edit_log(tick, time, player, x0, y0, z0, x1, y1, z1, before, after)"
                           " VALUES(?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                           -1, &insert_stmt_, nullptr) != SQLITE_OK)
      return error("cannot prepare the edit log");
  }
  for (const EditLogEntry& l : log) {
    bytes += l.before.size() + l.after.size();
    SqliteStmtReset reset{insert_stmt_};
    sqlite3_bind_int64(insert_stmt_, 1, static_cast<sqlite3_int64>(l.tick));
    sqlite3_bind_int64(insert_stmt_, 2, l.time_ms);
    sqlite3_bind_text(insert_stmt_, 3, l.player.data(), static_cast<int>(l.player.size()), SQLITE_STATIC);
    const int c[6] = {l.box.min.x, l.box.min.y, l.box.min.z, l.box.max.x, l.box.max.y, l.box.max.z};
    for (int i = 0; i < 6; ++i) sqlite3_bind_int(insert_stmt_, 4 + i, c[i]);
    sqlite3_bind_blob(insert_stmt_, 10, l.before.data(), static_cast<int>(l.before.size()), SQLITE_STATIC);
    sqlite3_bind_blob(insert_stmt_, 11, l.after.data(), static_cast<int>(l.after.size()), SQLITE_STATIC);
    if (sqlite3_step(insert_stmt_) != SQLITE_DONE) return error("cannot write the edit log");
  }
  return bytes;
}

void SqliteEditLog::committed(std::size_t entries, std::uint64_t bytes) {
  if (!size_) return;
  size_->entries += static_cast<std::int64_t>(entries);
  size_->bytes += bytes;
}

FileResult<std::vector<EditLogEntry>> SqliteEditLog::query(const EditLogQuery& q) {
  std::vector<EditLogEntry> out;
  if (!sqlite_table_exists(db_, "edit_log")) return out;
  std::string sql = std::string("SELECT id, tick, time, player, x0, y0, z0, x1, y1, z1") +
                    (q.with_voxels ? ", before, after" : "") + " FROM edit_log WHERE time >= ?";
  if (!q.player.empty()) sql += " AND player = ?";
  if (q.box) sql += " AND x0 < ? AND x1 > ? AND y0 < ? AND y1 > ? AND z0 < ? AND z1 > ?";
  sql += " ORDER BY id DESC LIMIT ?";
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v2(db_, sql.c_str(), -1, &st, nullptr) != SQLITE_OK) {
    sqlite3_finalize(st);
    return error("cannot read the edit log");
  }
  int n = 1;
  sqlite3_bind_int64(st, n++, q.since_ms);
  if (!q.player.empty()) sqlite3_bind_text(st, n++, q.player.data(), static_cast<int>(q.player.size()), SQLITE_STATIC);
  if (q.box) {
    const Region& b = *q.box;
    for (const int v : {b.max.x, b.min.x, b.max.y, b.min.y, b.max.z, b.min.z}) sqlite3_bind_int(st, n++, v);
  }
  sqlite3_bind_int64(st, n, static_cast<sqlite3_int64>(std::min<std::size_t>(q.limit, 1u << 30)));
  int rc;
  while ((rc = sqlite3_step(st)) == SQLITE_ROW) {
    EditLogEntry e;
    e.id = sqlite3_column_int64(st, 0);
    e.tick = static_cast<std::uint64_t>(sqlite3_column_int64(st, 1));
    e.time_ms = sqlite3_column_int64(st, 2);
    e.player = sqlite_column_string(st, 3);
    e.box = {{sqlite3_column_int(st, 4), sqlite3_column_int(st, 5), sqlite3_column_int(st, 6)},
             {sqlite3_column_int(st, 7), sqlite3_column_int(st, 8), sqlite3_column_int(st, 9)}};
    if (q.with_voxels) {
      for (int c = 10; c <= 11; ++c) {
        const auto* p = static_cast<const std::uint8_t*>(sqlite3_column_blob(st, c));
        const int len = sqlite3_column_bytes(st, c);
        (c == 10 ? e.before : e.after).assign(p, p + len);
      }
    }
    out.push_back(std::move(e));
  }
  sqlite3_finalize(st);
  if (rc != SQLITE_DONE) return error("cannot read the edit log");
  return out;
}

FileResult<std::int64_t> SqliteEditLog::prune(std::int64_t before_ms, std::uint64_t max_bytes, std::int64_t max_rows) {
  if (!sqlite_table_exists(db_, "edit_log")) return std::int64_t{0};
  std::int64_t deleted = 0;
  // The size known, less what the prune by age takes (counted through the
  // time index first: only the rows it deletes are read).
  auto known = size_;
  size_.reset();  // known again below once every delete went through
  constexpr const char* kOld = " FROM edit_log WHERE id IN (SELECT id FROM edit_log WHERE time < ? ORDER BY id LIMIT ?)";
  EditLogSize old;
  for (const bool count : {true, false}) {
    if (count && !known) continue;
    sqlite3_stmt* st = nullptr;
    const std::string sql = count ? std::string("SELECT count(*), coalesce(sum(length(before) + length(after)), 0)") + kOld
                                  : std::string("DELETE") + kOld;
    if (sqlite3_prepare_v2(db_, sql.c_str(), -1, &st, nullptr) != SQLITE_OK) return error("cannot prune the edit log");
    sqlite3_bind_int64(st, 1, before_ms);
    sqlite3_bind_int64(st, 2, max_rows);
    const int rc = sqlite3_step(st);
    if (count && rc == SQLITE_ROW)
      old = {sqlite3_column_int64(st, 0), static_cast<std::uint64_t>(sqlite3_column_int64(st, 1))};
    sqlite3_finalize(st);
    if (rc != (count ? SQLITE_ROW : SQLITE_DONE)) return error("cannot prune the edit log");
  }
  deleted += sqlite3_changes(db_);
  if (known && deleted == old.entries)
    size_ = EditLogSize{known->entries - old.entries, known->bytes - std::min(known->bytes, old.bytes)};
  if (max_bytes == 0 || deleted >= max_rows) return deleted;
  auto measured = size();
  if (!measured) return measured.error();
  std::uint64_t bytes = measured->bytes;
  std::int64_t rows_left = measured->entries;
  // The oldest go first, until under the bound: read up to a thousand
  // sizes at a time, delete through the last one needed.
  while (bytes > max_bytes && deleted < max_rows) {
    sqlite3_stmt* sel = nullptr;
    if (sqlite3_prepare_v2(db_, "SELECT id, length(before) + length(after) FROM edit_log ORDER BY id LIMIT 1000", -1,
                           &sel, nullptr) != SQLITE_OK)
      return error("cannot prune the edit log");
    std::int64_t last = -1, rows = 0;
    int r;
    while (bytes > max_bytes && (r = sqlite3_step(sel)) == SQLITE_ROW) {
      last = sqlite3_column_int64(sel, 0);
      bytes -= std::min<std::uint64_t>(bytes, static_cast<std::uint64_t>(sqlite3_column_int64(sel, 1)));
      ++rows;
    }
    sqlite3_finalize(sel);
    if (rows == 0) break;
    sqlite3_stmt* del = nullptr;
    if (sqlite3_prepare_v2(db_, "DELETE FROM edit_log WHERE id <= ?", -1, &del, nullptr) != SQLITE_OK)
      return error("cannot prune the edit log");
    sqlite3_bind_int64(del, 1, last);
    const int d = sqlite3_step(del);
    sqlite3_finalize(del);
    if (d != SQLITE_DONE) {
      size_.reset();
      return error("cannot prune the edit log");
    }
    deleted += rows;
    rows_left -= rows;
    size_ = EditLogSize{rows_left, bytes};
  }
  return deleted;
}

FileResult<EditLogSize> SqliteEditLog::size() {
  if (!sqlite_table_exists(db_, "edit_log")) return EditLogSize{};
  if (size_) return *size_;
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v2(db_, "SELECT count(*), coalesce(sum(length(before) + length(after)), 0) FROM edit_log", -1,
                         &st, nullptr) != SQLITE_OK)
    return error("cannot measure the edit log");
  EditLogSize out;
  const int rc = sqlite3_step(st);
  if (rc == SQLITE_ROW)
    out = {sqlite3_column_int64(st, 0), static_cast<std::uint64_t>(sqlite3_column_int64(st, 1))};
  sqlite3_finalize(st);
  if (rc == SQLITE_ROW) size_ = out;
  return out;
}

}  // namespace terrane
