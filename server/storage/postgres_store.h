// PostgresStore: a world kept in PostgreSQL, so that several servers can
// share it (server/storage/STORE_POSTGRESQL.md has the tables and the rules).
//
// This part holds the chunk rows and the region leases. A region (8 x 8 x 8
// chunks, the coarse images' regions) has at most one writer. That writer
// is the server whose lease is current, and every write transaction checks
// the lease (owner, epoch, not expired by the database's clock) in the same
// transaction, so a server that lost its lease can never write.
//
// Connection strings are libpq's: "postgresql://HOST:PORT/DB" or
// "host=... port=... dbname=...", with a 10 s connect timeout and TCP
// keepalives unless they say otherwise. Errors name the statement that
// failed and PostgreSQL's own message; a password never appears in them.
// A session that stays inside a transaction for 10 s is ended by the
// database (rolling it back), and no statement waits over 10 s for a lock.
//
// Threading: one object is one connection; use it from one thread at a
// time (open one per thread, as the SQLite store does).
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "common/codec/decode_error.h"
#include "common/voxel/vec3.h"
#include "common/world/world_store.h"

namespace terrane {

// What a PostgresStore call can fail with.
struct StoreError {
  enum class Kind : std::uint8_t {
    kConnection,  // the database cannot be reached, or the connection broke
    kQuery,       // PostgreSQL refused a statement
    kOwned,       // a region is leased to another server (claim)
    kFenced,      // a write's lease is no longer current: nothing was written
    kDecode,      // a stored row does not decode
  };
  Kind kind = Kind::kQuery;
  std::string message;
};
template <class T>
using StoreResult = BasicResult<T, StoreError>;

// A region's lease as its holder knows it. epoch grows by one each time the
// region changes hands, so a stale holder's writes are told apart.
struct RegionLease {
  Vec3i region;
  std::uint32_t owner = 0;  // the server id
  std::uint64_t epoch = 0;
  friend bool operator==(const RegionLease&, const RegionLease&) = default;
};

class PostgresStore {
 public:
  // Connects and creates the schema if the database has none (in one
  // transaction; a schema of another version is an error naming both).
  static StoreResult<std::unique_ptr<PostgresStore>> open(const std::string& url);
  ~PostgresStore();
  PostgresStore(const PostgresStore&) = delete;
  PostgresStore& operator=(const PostgresStore&) = delete;

  // The schema version this build reads and writes.
  static constexpr int kSchemaVersion = 1;

  // Takes the region for owner (a server id below 2^31) for the lease time,
  // at the next epoch, if it is free, its lease has expired, or owner holds
  // it already (a server that claims again is a new incarnation: writes its
  // earlier self still has in flight are fenced; renew keeps an epoch).
  // Otherwise the error is kOwned, naming the holder and when its lease
  // runs out.
  StoreResult<RegionLease> claim(Vec3i region, std::uint32_t owner, std::chrono::milliseconds lease);
  // Extends each lease still current (same owner and epoch, not expired) by
  // lease from now; returns those it extended. A lease missing from the
  // answer is lost: its holder must stop writing the region.
  StoreResult<std::vector<RegionLease>> renew(std::span<const RegionLease> leases, std::chrono::milliseconds lease);
  // Gives the leases up (they expire at once); other servers may claim them.
  StoreResult<Ok> release(std::span<const RegionLease> leases);
  // Who holds region now (a current lease), if anyone.
  StoreResult<std::optional<RegionLease>> holder(Vec3i region);

  // Stores the chunks in one transaction, fenced. Every chunk's region
  // must be under one of leases, and every lease used must still be
  // current when the transaction checks it (it locks the lease rows, so a
  // takeover waits for the commit and then sees the chunks). Otherwise
  // kFenced and nothing is written. A chunk outside every given lease is
  // kFenced too.
  StoreResult<Ok> save_chunks(std::span<const RegionLease> leases, std::span<const ChunkWrite> chunks);
  // The stored chunk, or nullopt where none is stored. A blob that does not
  // decode is kDecode, naming the chunk.
  StoreResult<std::optional<StoredChunk>> load_chunk(Vec3i pos);

 private:
  struct Connection;
  explicit PostgresStore(std::unique_ptr<Connection> c);
  std::unique_ptr<Connection> c_;
};

// The region (8 x 8 x 8 chunks) a chunk belongs to.
Vec3i lease_region_of(Vec3i chunk_pos);

}  // namespace terrane
