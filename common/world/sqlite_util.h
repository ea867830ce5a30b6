// What the owners of a world's SQLite tables share (SqliteStore and the
// owners it holds: SqliteEditLog, SqliteQuarantine, SqliteCoarseImages,
// SqliteAccess): error messages naming the world, a prepared statement's
// reset, a write transaction, a text column read, whether a table exists,
// and the chunk rows of a table within a coarse region. Free functions and
// scoped helpers over one connection, no state of their own.
// Thread-safety: that of the connection (one owner thread).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "common/codec/decode_error.h"
#include "common/voxel/chunk.h"

struct sqlite3;
struct sqlite3_stmt;

namespace terrane {

// "world <dir>: <what>: <SQLite's last error>" (the last part left out
// without a connection).
FileError sqlite_error(sqlite3* db, const std::string& dir, const std::string& what);

// RAII for one prepared statement use: reset and bindings cleared on scope exit.
struct SqliteStmtReset {
  sqlite3_stmt* s;
  ~SqliteStmtReset();
};

// Bytes SQLite holds now for every connection of this process: their page
// caches (up to 32 MiB each, sqlite_store.cpp), prepared statements and
// scratch. Any thread.
std::int64_t sqlite_memory_used();

// A text column of the current row; empty when it is NULL, which a damaged
// or hand-edited world can hold even where the schema says NOT NULL.
std::string sqlite_column_string(sqlite3_stmt* st, int column);

// One write transaction (BEGIN IMMEDIATE), rolled back when it goes out of
// scope uncommitted: an error return needs no rollback of its own, and the
// error is built (with SQLite's message) before the rollback runs.
class SqliteTransaction {
 public:
  explicit SqliteTransaction(sqlite3* db);
  ~SqliteTransaction();
  SqliteTransaction(const SqliteTransaction&) = delete;
  SqliteTransaction& operator=(const SqliteTransaction&) = delete;

  // Whether BEGIN went through (if not, there is nothing to commit or roll back).
  bool began() const { return open_; }
  // COMMIT; false if it failed (the transaction is then rolled back at scope exit).
  bool commit();

 private:
  sqlite3* db_;
  bool open_;
};

// Whether the database has a table of that name (false if it cannot tell).
bool sqlite_table_exists(sqlite3* db, const char* name);

// The chunk coordinates of table's rows within a coarse region (an index
// range scan over (cx, cy, cz)), and with revisions set, each row's
// revision (for the chunks table: one row per chunk).
FileResult<std::vector<Vec3i>> sqlite_chunks_in_region(sqlite3* db, const std::string& dir, const char* table,
                                                       Vec3i region, std::vector<std::uint64_t>* revisions = nullptr);

}  // namespace terrane
