// PgWorldMeta: a PostgreSQL world's metadata (terrane_meta: generator,
// bounds, materials, epoch, world id), as one connection last read or
// wrote it. Several servers share the table, so every write changes only
// its own keys, in one statement where servers race: each server's epoch
// is its own (set_epoch), the first server's world id wins (name_world),
// and the first maker's metadata is the world's (create).
//
// Threading: its connection's (one thread at a time); a PostgresStore owns
// one beside its connection.
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "common/world/world_store.h"
#include "server/storage/pg_connection.h"

namespace terrane {

class PgWorldMeta {
 public:
  // Whether the database holds a world (read() or create() found one).
  bool has_world() const { return has_world_; }
  const WorldMeta& meta() const { return meta_; }

  // Reads the table (no rows: no world).
  StoreResult<Ok> read(PgConnection& c);
  // Stores meta unless the database holds a world already (another server
  // may have made it first: its metadata wins), then reads it back.
  StoreResult<Ok> create(PgConnection& c, const WorldMeta& meta);
  // One statement, above whatever is stored: servers starting at once each
  // get an epoch of their own (a client's resume token names one).
  FileStatus set_epoch(PgConnection& c, std::uint64_t epoch);
  // The stored id, or candidate stored when there is none (WorldStore::name_world).
  FileResult<std::uint64_t> name_world(PgConnection& c, std::uint64_t candidate);
  // A new border: only the bounds' keys are written.
  FileStatus set_bounds(PgConnection& c, const WorldBounds& bounds);

 private:
  // Writes these keys (others are left as they are), in one transaction.
  static FileStatus put(PgConnection& c, const std::vector<std::pair<std::string, std::string>>& keys);

  bool has_world_ = false;
  WorldMeta meta_;
};

}  // namespace terrane
