// PostgresStore: a world's chunks kept in PostgreSQL, so that several
// servers can share it (server/storage/STORE_POSTGRESQL.md has the tables
// and the rules).
//
// It is a WorldStore (the world's metadata, chunk rows with their coarse
// mips and the units kept after their blobs, quarantine, edit log, access
// lists) whose writes are fenced by region leases. A region (8 x 8 x 8
// chunks, the coarse images' regions) has at most one writer. That writer
// is the server whose lease is current, and every write transaction checks
// the lease (owner, epoch, not expired by the database's clock) in the same
// transaction, so a server that lost its lease can never write. The leases
// themselves, the servers' addresses, forwarded edits and notices are the
// cluster room's (server/cluster/cluster_store.h), on connections of its own.
//
// Connections are PgConnection's (pg_connection.h: libpq's connection
// strings, a bounded connect, session limits, errors that name the
// statement and never a password).
//
// Threading: one object is one connection; use it from one thread at a
// time (open one per thread, as the SQLite store does).
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "common/codec/decode_error.h"
#include "common/voxel/vec3.h"
#include "common/world/coarse_image.h"
#include "common/world/world_store.h"
#include "server/base/counters.h"
#include "server/storage/cluster_link.h"
#include "server/storage/commit_marks.h"
#include "server/storage/cluster_map.h"  // ServerAddress, parse_server_address: terrane-server's options
#include "server/storage/notices.h"
#include "server/storage/pg_connection.h"
#include "server/storage/pg_world_meta.h"

namespace terrane {

class PostgresStore final : public WorldStore {
 public:
  // Connects and creates the schema if the database has none (in one
  // transaction; a schema of another version is an error naming both).
  // The world's metadata is read if the database holds a world
  // (has_world()); create_world puts one there.
  static StoreResult<std::unique_ptr<PostgresStore>> open(const std::string& url);
  ~PostgresStore() override;

  // The schema version this build reads and writes (pg_connection.h).
  static constexpr int kSchemaVersion = kPgSchemaVersion;
  // Whether url names a PostgreSQL database ("postgresql://..." or
  // "postgres://...") rather than a world directory.
  static bool is_url(const std::string& url);

  bool has_world() const { return meta_.has_world(); }
  // Stores meta as the world's unless the database holds a world already
  // (another server may have made it first: its metadata wins), then reads
  // it back.
  StoreResult<Ok> create_world(const WorldMeta& meta);
  // Every write of this connection (save_chunks) asks source for the
  // leases of the regions it writes and is fenced by them. Connections
  // made by reopen() share it. Without one, writes are refused.
  // retry_for: how long a write waits for a database that cannot be
  // reached (tried again on a new connection) before it fails. A write
  // tried again after its commit's answer was lost finds out whether that
  // commit was stored, and is not stored twice; one that cannot find out
  // fails with FileError::outcome_unknown (STORE_POSTGRESQL.md, "Fencing").
  // Only the commits of save_chunks and save_answering are marked so
  // (save_fenced is one try).
  void set_lease_source(std::shared_ptr<const LeaseSource> source,
                        std::chrono::milliseconds retry_for = std::chrono::milliseconds(0)) {
    leases_ = std::move(source);
    retry_for_ = retry_for;
  }
  // Where writes count the commits being tried again (the database out of
  // reach): counters must outlive this store and the stores reopen() makes,
  // which share it. Null: not counted.
  void count_retries_in(DatabaseCounters* counters) { database_counters_ = counters; }

  // The connection (tests: its seams).
  PgConnection& connection() { return *c_; }

  // Another connection to the same world, as the chunk store it is (the
  // lease source shared): a shared world's writer (server/storage/
  // storage.h). reopen() hands it on as a WorldStore.
  StoreResult<std::unique_ptr<PostgresStore>> reopen_chunks() const;

  // Stores the chunks and the log entries in one transaction, fenced. Every
  // chunk's region must be under one of leases, and every lease used must
  // still be current when the transaction checks it (it locks the lease
  // rows, so a takeover waits for the commit and then sees the chunks).
  // Otherwise kFenced and nothing is written. A chunk outside every given
  // lease is kFenced too. overwrite = false leaves chunks already stored.
  // answers: forwarded edits this write applied (or refused), answered in
  // the same transaction.
  StoreResult<Ok> save_fenced(std::span<const RegionLease> leases, std::span<const ChunkWrite> chunks,
                              std::span<const EditLogEntry> log = {}, bool overwrite = true,
                              std::span<const ForwardAnswer> answers = {});
  // save_chunks with answers to forwarded edits in its transaction.
  FileStatus save_answering(std::span<const ChunkWrite> writes, std::span<const EditLogEntry> log,
                            std::span<const ForwardAnswer> answers);

  // WorldStore. Errors name the statement and PostgreSQL's message; a chunk
  // row that does not decode is an error with decode set, naming the chunk.
  const std::string& where() const override { return c_->shown(); }
  FileResult<std::unique_ptr<WorldStore>> reopen() const override;
  const WorldMeta& meta() const override { return meta_.meta(); }
  FileStatus set_epoch(std::uint64_t epoch) override;
  FileResult<std::uint64_t> name_world(std::uint64_t candidate) override;
  FileStatus set_bounds(const WorldBounds& bounds) override;
  FileResult<std::optional<StoredChunk>> load_chunk(Vec3i pos) override;
  FileResult<std::vector<CoarseEntry>> load_coarse(Vec3i region) override;
  FileResult<std::vector<Vec3i>> quarantined_in(Vec3i region) override;
  FileResult<std::vector<Vec3i>> stored_in(Vec3i region) override;
  FileStatus begin_read() override;
  void end_read() override;
  // Fenced by the lease source's leases (save_fenced).
  FileStatus save_chunks(std::span<const ChunkWrite> writes, bool overwrite = true,
                         std::span<const EditLogEntry> log = {}) override;
  FileResult<std::vector<EditLogEntry>> edit_log(const EditLogQuery& q) override;
  FileResult<std::int64_t> prune_edit_log(std::int64_t before_ms, std::uint64_t max_bytes,
                                          std::int64_t max_rows = 10000) override;
  // Counted at each call: one scan of the table, which every server of the
  // world writes (so no figure kept here would stay true).
  FileResult<EditLogSize> edit_log_size() override;
  FileResult<std::optional<std::uint64_t>> quarantine_chunk(Vec3i pos, const std::string& reason) override;
  FileResult<std::optional<std::uint64_t>> quarantined_revision(Vec3i pos) override;
  // Reads the rows a thousand at a time (a cursor), so memory stays bounded.
  FileStatus for_each_chunk(
      const std::function<void(Vec3i, std::uint64_t, std::span<const std::uint8_t>)>& fn) override;
  // The same, with each row's coarse mip column (nullopt if it does not
  // decode), in one read-only snapshot: terrane-world check. A chunk whose
  // units kept after its blob do not make it (one missing or not
  // decoding) comes as that error, and the walk goes on. (for_each_chunk
  // stops there and returns it.)
  using RowFn = std::function<void(Vec3i, std::uint64_t, FileResult<std::span<const std::uint8_t>>,
                                   const std::optional<CoarseVoxels>&)>;
  FileStatus for_each_chunk_row(const RowFn& fn);
  // Every quarantined row, by chunk and revision.
  FileStatus for_each_quarantined(const std::function<void(const QuarantinedChunk&)>& fn);
  FileResult<std::int64_t> stored_chunk_count() override;
  FileResult<std::vector<std::pair<std::string, std::string>>> access_entries() override;
  FileStatus put_access(const std::string& key, const std::string& value) override;
  FileStatus erase_access(const std::string& key) override;

 private:
  // for_each_chunk(_row): the coarse column read and decoded only if asked.
  FileStatus each_chunk_row(const RowFn& fn, bool with_coarse);
  explicit PostgresStore(std::unique_ptr<PgConnection> c);
  FileStatus save(std::span<const ChunkWrite> writes, bool overwrite, std::span<const EditLogEntry> log,
                  std::span<const ForwardAnswer> answers);
  // What one try of a marked commit learnt: whether the database answered
  // the question "was this commit stored?" (asked), and its answer.
  struct CommitCheck {
    bool asked = false;
    bool stored = false;
  };
  // save_fenced's transaction. commit != 0: this connection's commit
  // number, recorded in the same transaction (commits_); if it is
  // recorded already (an earlier try was stored) nothing is written and
  // check->stored is set.
  StoreResult<Ok> write_fenced(std::span<const RegionLease> leases, std::span<const ChunkWrite> chunks,
                               std::span<const EditLogEntry> log, bool overwrite,
                               std::span<const ForwardAnswer> answers, std::int64_t commit, CommitCheck* check);

  std::unique_ptr<PgConnection> c_;  // with the url as given (reopen connects with it) and as shown
  PgWorldMeta meta_;  // terrane_meta as this connection last read or wrote it
  std::shared_ptr<const LeaseSource> leases_;
  std::chrono::milliseconds retry_for_{0};
  DatabaseCounters* database_counters_ = nullptr;
  CommitMarks commits_;  // save's commits, recorded so that a try after a lost answer is not stored twice
};

// A chunk written with its changed units (ChunkWrite::units, taking the
// stored revision to the next) keeps its blob and gains a row of units in
// terrane_chunk_units while it has at most kMaxKeptUnits such rows, each
// of at most kMaxKeptUnitsBytes; otherwise the blob is written whole and
// the chunk's rows of units are deleted (STORE_POSTGRESQL.md, "Chunks and
// their units").
inline constexpr std::int64_t kMaxKeptUnits = 32;
inline constexpr std::size_t kMaxKeptUnitsBytes = 4096;

// Inside a transaction on c: forwarded edits answered, each inbox row
// deleted, its answer kept in terrane_answers until its sender has it and
// notified on terrane_answers. A fenced write answers the edits it applied
// so; the cluster store answers refused ones so, without chunks.
StoreResult<Ok> answer_forwarded(PgConnection& c, std::span<const ForwardAnswer> answers);

}  // namespace terrane
