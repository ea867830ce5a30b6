// PostgresStore: a world kept in PostgreSQL, so that several servers can
// share it (server/storage/STORE_POSTGRESQL.md has the tables and the rules).
//
// It is a WorldStore (the world's metadata, chunk rows with their coarse
// mips, quarantine, edit log, access lists) plus the region leases. A
// region (8 x 8 x 8 chunks, the coarse images' regions) has at most one
// writer. That writer is the server whose lease is current, and every write
// transaction checks the lease (owner, epoch, not expired by the database's
// clock) in the same transaction, so a server that lost its lease can never
// write.
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
#include "server/storage/cluster_map.h"
#include "server/storage/notices.h"

namespace terrane {

// What a PostgresStore call can fail with.
struct StoreError {
  enum class Kind : std::uint8_t {
    kConnection,  // the database cannot be reached, or the connection broke
    kQuery,       // PostgreSQL refused a statement
    kConflict,    // PostgreSQL rolled the transaction back to break a deadlock or a serialization
                  // conflict (SQLSTATE class 40): nothing of it was done, trying again is safe
    kOwned,       // a region is leased to another server (claim)
    kLeft,        // a free region is left to the server writing its neighbours (claim, ClaimRule::kPreferNeighbours)
    kFenced,      // a write's lease is no longer current: nothing was written
    kDecode,      // a stored row does not decode
  };
  StoreError() = default;
  StoreError(Kind k, std::string m, std::optional<std::uint32_t> h = std::nullopt)
      : kind(k), message(std::move(m)), holder(h) {}
  Kind kind = Kind::kQuery;
  std::string message;
  std::optional<std::uint32_t> holder;  // kOwned: the server holding the region; kLeft: the one it is left to
};

// How a claim treats a free region (STORE_POSTGRESQL.md, "Regions and leases").
enum class ClaimRule : std::uint8_t {
  kAny,               // take it (tools, forwarded edits, rollbacks)
  kPreferNeighbours,  // leave it to a server writing a neighbour unless the claimant writes one itself
                      // (a server's clients' own edits)
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


// Edits forwarded between servers (STORE_POSTGRESQL.md, "Forwarded
// edits"): a server sends an edit in a region another server holds to that
// server's inbox (a row, and a notice on terrane_inbox naming the server);
// the owner applies it in a tick and answers in the tick's commit (the row
// deleted, and a notice on terrane_answers naming the sender).
inline constexpr const char* kInboxChannel = "terrane_inbox";
inline constexpr const char* kAnswersChannel = "terrane_answers";
struct InboxEdit {
  std::int64_t id = 0;
  std::uint32_t from = 0;  // the server that forwarded it
  std::string player;
  std::vector<std::uint8_t> edit;  // an EditRequest frame, as a client sent it
  std::int64_t age_ms = 0;         // since it was forwarded, by the database's clock
};

// Server ids (terrane-server --server-id) are below 2^31: PostgreSQL's integer.
inline constexpr std::uint32_t kMaxServerId = 2147483647;

// Where a server's writes get their leases: the leases of the regions given
// (a LeaseKeeper's ensure), or kOwned naming the holder of one of them.
using LeaseSource = std::function<StoreResult<std::vector<RegionLease>>(std::span<const Vec3i> regions)>;

class PostgresStore final : public WorldStore {
 public:
  // Connects and creates the schema if the database has none (in one
  // transaction; a schema of another version is an error naming both).
  // The world's metadata is read if the database holds a world
  // (has_world()); create_world puts one there.
  static StoreResult<std::unique_ptr<PostgresStore>> open(const std::string& url);
  ~PostgresStore() override;

  // The schema version this build reads and writes.
  // 1 to 3 are upgraded on open once none of their regions is leased (1:
  // terrane_servers and the rest added; 2: notices carry changed units,
  // which a server of version 2 refuses; 3: a chunk's blob may be older
  // than its revision, followed by its units in terrane_chunk_units, which
  // a server of version 3 would not read; so none may run beside this one).
  static constexpr int kSchemaVersion = 4;
  // Whether url names a PostgreSQL database ("postgresql://..." or
  // "postgres://...") rather than a world directory.
  static bool is_url(const std::string& url);

  bool has_world() const { return has_world_; }
  // Stores meta as the world's unless the database holds a world already
  // (another server may have made it first: its metadata wins), then reads
  // it back.
  StoreResult<Ok> create_world(const WorldMeta& meta);
  // Every write of this connection (save_chunks) asks source for the
  // leases of the regions it writes and is fenced by them. Connections
  // made by reopen() share it. Without one, writes are refused.
  // retry_for: how long a write waits for a database that cannot be
  // reached (tried again on a new connection) before it fails.
  void set_lease_source(std::shared_ptr<const LeaseSource> source,
                        std::chrono::milliseconds retry_for = std::chrono::milliseconds(0)) {
    leases_ = std::move(source);
    retry_for_ = retry_for;
  }

  // Takes the region for owner (a server id below 2^31) for the lease time,
  // at the next epoch, if it is free, its lease has expired, or owner holds
  // it already (a server that claims again is a new incarnation: writes its
  // earlier self still has in flight are fenced; renew keeps an epoch).
  // Otherwise the error is kOwned, naming the holder and when its lease
  // runs out. With kPreferNeighbours, a free region one of whose 26
  // neighbours another server writes is left to that server (error kLeft,
  // naming it) unless owner writes a neighbour too (the server writing
  // most neighbours, then the lowest id). Territories stay whole, so
  // clients cross fewer borders.
  StoreResult<RegionLease> claim(Vec3i region, std::uint32_t owner, std::chrono::milliseconds lease,
                                 ClaimRule rule = ClaimRule::kAny);
  // Extends each lease still current (same owner and epoch, not expired) by
  // lease from now; returns those it extended. A lease missing from the
  // answer is lost: its holder must stop writing the region.
  StoreResult<std::vector<RegionLease>> renew(std::span<const RegionLease> leases, std::chrono::milliseconds lease);
  // Gives the leases up (they expire at once); other servers may claim them.
  StoreResult<Ok> release(std::span<const RegionLease> leases);
  // Who holds region now (a current lease), if anyone.
  StoreResult<std::optional<RegionLease>> holder(Vec3i region);

  // Where server id takes clients ("HOST:PORT"), seen now: a lease keeper
  // calls it every renewal round. withdraw forgets it (a clean stop).
  StoreResult<Ok> advertise(std::uint32_t id, const std::string& address);
  StoreResult<Ok> withdraw(std::uint32_t id);
  // Every current lease's region and writer, and the addresses of servers
  // seen within fresh (rows that do not parse are left out).
  struct Cluster {
    std::vector<RegionWriter> writers;
    std::vector<ServerAddress> servers;
  };
  StoreResult<Cluster> cluster(std::chrono::milliseconds fresh);
  // The ids of servers seen within fresh (with an address or without).
  StoreResult<std::vector<std::uint32_t>> running(std::chrono::milliseconds fresh);

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

  // Every region's write sequence number (regions never written under a
  // lease have none: 0).
  StoreResult<std::vector<RegionSeq>> region_seqs();
  // The stored chunks of a region and their revisions.
  StoreResult<std::vector<std::pair<Vec3i, std::uint64_t>>> stored_revisions(Vec3i region);

  // Forwards an edit to server to's inbox (one transaction: the row and
  // its notice); the row's id.
  StoreResult<std::int64_t> forward(std::uint32_t from, std::uint32_t to, const std::string& player,
                                    std::span<const std::uint8_t> edit);
  // Passes the edit of inbox row id, addressed to from, on to server to
  // (one transaction: the row readdressed, its notice). Its sender and age
  // stay, so to answers the sender and refuses it once too old. kFenced if
  // the row is no longer from's (answered or passed on already).
  StoreResult<Ok> relay(std::int64_t id, std::uint32_t from, std::uint32_t to);
  // Edits for server to not answered yet with an id above after, oldest
  // first, at most limit.
  StoreResult<std::vector<InboxEdit>> inbox(std::uint32_t to, std::int64_t after, std::size_t limit);
  // Answers without writing chunks (edits refused).
  StoreResult<Ok> answer(std::span<const ForwardAnswer> answers);
  // Every answer is also kept in terrane_answers until its sender has it:
  // take_answers hands over (and deletes) those to edits server from
  // forwarded (a listener that reconnected may have missed their notices);
  // forget_answers deletes those whose notices arrived, and any older than
  // ten minutes.
  StoreResult<std::vector<ForwardAnswer>> take_answers(std::uint32_t from);
  StoreResult<Ok> forget_answers(std::span<const std::int64_t> ids);

  // Subscribes this connection to terrane_changes; wait_notices then
  // returns the payloads that arrived, waiting up to timeout for the first.
  // A broken connection is kConnection (open another and read again what
  // may have been missed).
  // (And on terrane_inbox and terrane_answers: wait_notices returns every
  // channel's payloads, each with its channel.)
  StoreResult<Ok> listen();
  // Names this connection in pg_stat_activity (operators see which server
  // and which part of it a session is).
  StoreResult<Ok> set_name(const std::string& application_name);
  struct Notice {
    std::string channel, payload;
  };
  StoreResult<std::vector<Notice>> wait_notices(std::chrono::milliseconds timeout);

  // WorldStore. Errors name the statement and PostgreSQL's message; a chunk
  // row that does not decode is an error with decode set, naming the chunk.
  const std::string& where() const override { return shown_; }
  FileResult<std::unique_ptr<WorldStore>> reopen() const override;
  const WorldMeta& meta() const override { return meta_; }
  FileStatus set_epoch(std::uint64_t epoch) override;
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
  // kPreferNeighbours' rule: the kLeft error if region is left to another
  // server, nullopt if owner may claim it.
  StoreResult<std::optional<StoreError>> left_to_neighbour(Vec3i region, std::uint32_t owner);
  // for_each_chunk(_row): the coarse column read and decoded only if asked.
  FileStatus each_chunk_row(const RowFn& fn, bool with_coarse);
  struct Connection;
  PostgresStore(std::unique_ptr<Connection> c, std::string url, std::string shown);
  StoreResult<Ok> read_meta();
  FileStatus save(std::span<const ChunkWrite> writes, bool overwrite, std::span<const EditLogEntry> log,
                  std::span<const ForwardAnswer> answers);
  // BEGIN, body, COMMIT; on any failure the transaction is rolled back.
  template <class T>
  StoreResult<T> transaction(const char* what, const std::function<StoreResult<T>()>& body);
  // Inside a transaction: the rows answered and their notices.
  StoreResult<Ok> answer_in_transaction(std::span<const ForwardAnswer> answers);
  // Writes these metadata keys (others are left as they are).
  FileStatus put_meta(const std::vector<std::pair<std::string, std::string>>& keys);

  std::unique_ptr<Connection> c_;
  std::string url_;    // as given (reopen connects with it)
  std::string shown_;  // as messages name it: the password left out
  bool has_world_ = false;
  WorldMeta meta_;
  std::shared_ptr<const LeaseSource> leases_;
  std::chrono::milliseconds retry_for_{0};
};

// The news between servers (STORE_POSTGRESQL.md, "Notices"): every fenced
// write notifies channel terrane_changes, in its transaction, of each chunk
// it wrote and the chunk's new revision, and of each region it wrote and
// the region's new sequence number (+1 per write of it). Payloads are
// text: entries "x,y,z,revision" or "x,y,z,revision,tick,UNITS" (a chunk)
// and "r,x,y,z,seq" (a region) separated by one space, at most
// kMaxChangeNoticeBytes each (more entries: more notices). UNITS is the
// base64 (RFC 4648, padded) of the update batch of the 4^3 units that
// changed from revision - 1 to revision in the writer's world tick `tick`
// (ChunkWrite::units and tick), when the write knows them and they take at
// most kMaxNoticeUnitsBytes of base64; a reader holding revision - 1
// applies them instead of reading the chunk.
inline constexpr const char* kChangesChannel = "terrane_changes";
// A chunk written with its changed units (ChunkWrite::units, taking the
// stored revision to the next) keeps its blob and gains a row of units in
// terrane_chunk_units while it has at most kMaxKeptUnits such rows, each
// of at most kMaxKeptUnitsBytes; otherwise the blob is written whole and
// the chunk's rows of units are deleted (STORE_POSTGRESQL.md, "Chunks and
// their units").
inline constexpr std::int64_t kMaxKeptUnits = 32;
inline constexpr std::size_t kMaxKeptUnitsBytes = 4096;

// The region (8 x 8 x 8 chunks) a chunk belongs to.
Vec3i lease_region_of(Vec3i chunk_pos);

}  // namespace terrane
