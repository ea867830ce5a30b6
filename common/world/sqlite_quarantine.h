// SqliteQuarantine: a world's quarantine, the table "quarantine" of
// world.sqlite (common/world/WORLD_FORMAT.md): damaged chunk rows moved
// aside (coordinates, revision, the blob as it was, the reason, the time),
// kept until someone looks. The table was added to format 1 after its
// first release: ensure_table gives it to worlds made before.
// It owns its revision lookup statement; the connection is SqliteStore's,
// which outlives it.
// Thread-safety: the connection's owner thread (SqliteStore's).
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "common/world/world_store.h"

struct sqlite3;
struct sqlite3_stmt;

namespace terrane {

class SqliteQuarantine {
 public:
  // db: an open world (not owned; outlives this); dir names it in errors.
  SqliteQuarantine(sqlite3* db, std::string dir);
  ~SqliteQuarantine();
  SqliteQuarantine(const SqliteQuarantine&) = delete;
  SqliteQuarantine& operator=(const SqliteQuarantine&) = delete;

  // Makes the table if the world has none (when it has, a pure read: tools
  // can open a world a server is writing without taking the write lock).
  FileStatus ensure_table();
  // In one transaction of its own: the chunk's row moved from "chunks" into
  // the quarantine byte for byte, then also() (what else goes with the row,
  // e.g. its coarse entry; its error rolls everything back). The revision
  // moved; none (and nothing done) if the chunk has no row.
  FileResult<std::optional<std::uint64_t>> move_aside(Vec3i pos, const std::string& reason,
                                                      const std::function<FileStatus()>& also);
  // The highest revision quarantined for the chunk; none if never.
  FileResult<std::optional<std::uint64_t>> revision(Vec3i pos);
  // Calls fn for every quarantined row, oldest first.
  FileStatus for_each(const std::function<void(const QuarantinedChunk&)>& fn);
  FileResult<std::int64_t> count();
  // The chunks of a coarse region with a quarantined row (each once).
  FileResult<std::vector<Vec3i>> in_region(Vec3i region);

 private:
  FileError error(const std::string& what) const;

  sqlite3* db_;
  std::string dir_;
  sqlite3_stmt* revision_stmt_ = nullptr;
};

}  // namespace terrane
