// SqliteAccess: a world's access lists (the operators' bans and whitelist,
// server/ops/access.h), the table "access" of world.sqlite
// (common/world/WORLD_FORMAT.md): one text value per key, the table made
// by the first write. Reads and erases before that see no entries.
// The connection is SqliteStore's, which outlives it.
// Thread-safety: the connection's owner thread (SqliteStore's).
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "common/codec/decode_error.h"

struct sqlite3;

namespace terrane {

class SqliteAccess {
 public:
  // db: an open world (not owned; outlives this); dir names it in errors.
  SqliteAccess(sqlite3* db, std::string dir);
  SqliteAccess(const SqliteAccess&) = delete;
  SqliteAccess& operator=(const SqliteAccess&) = delete;

  // Every (key, value), by key.
  FileResult<std::vector<std::pair<std::string, std::string>>> entries();
  // Sets key to value (the table made if it is not there yet).
  FileStatus put(const std::string& key, const std::string& value);
  // Removes key; nothing to do if it is not there.
  FileStatus erase(const std::string& key);

 private:
  FileError error(const std::string& what) const;

  sqlite3* db_;
  std::string dir_;
};

}  // namespace terrane
