// PgConnection: one libpq connection to a Terrane database, shared by the
// chunk store (PostgresStore, this room) and the cluster store
// (server/cluster/cluster_store.h): the connect with its defaults and
// session limits, the schema made or upgraded on open, statements run with
// their errors named, the transaction helper, and the readers of binary
// columns (STORE_POSTGRESQL.md has the tables and the rules).
//
// Connection strings are libpq's: "postgresql://HOST:PORT/DB" or
// "host=... port=... dbname=...", with a 10 s connect timeout and TCP
// keepalives unless they say otherwise. Errors name the statement that
// failed and PostgreSQL's own message; a password never appears in them.
// A session that stays inside a transaction for 10 s is ended by the
// database (rolling it back), and no statement waits over 10 s for a lock.
// Every statement has a deadline of its own (call_timeout, 10 s unless
// set): a database the network cut off (no reset, no answer) fails the
// statement with kConnection within it, whatever TCP does meanwhile.
//
// Threading: one object is one connection; use it from one thread at a
// time.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "common/codec/decode_error.h"
#include "common/voxel/vec3.h"

// libpq's handles, as libpq-fe.h names them (only the server library links
// libpq: its header stays out of this one).
typedef struct pg_conn PGconn;
typedef struct pg_result PGresult;

namespace terrane {

// What a PostgreSQL store's call (chunks or cluster) can fail with.
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
    kUnknown,     // the connection broke after a COMMIT was sent (or its answer's deadline passed):
                  // whether it took effect is not known
  };
  StoreError() = default;
  StoreError(Kind k, std::string m, std::optional<std::uint32_t> h = std::nullopt)
      : kind(k), message(std::move(m)), holder(h) {}
  Kind kind = Kind::kQuery;
  std::string message;
  std::optional<std::uint32_t> holder;  // kOwned: the server holding the region; kLeft: the one it is left to
};
template <class T>
using StoreResult = BasicResult<T, StoreError>;

// The schema version this build reads and writes.
// 1 to 4 are upgraded on open once none of their regions is leased (1:
// terrane_servers and the rest added; 2: notices carry changed units,
// which a server of version 2 refuses; 3: a chunk's blob may be older
// than its revision, followed by its units in terrane_chunk_units, which
// a server of version 3 would not read; 4: forwarded edits carry a
// deadline and are taken once, which a server of version 4 would neither
// write nor respect, and each writer's last commit is recorded in
// terrane_commits so that a commit tried again after its answer was lost
// is not stored twice; so none may run beside this one).
inline constexpr int kPgSchemaVersion = 5;
// Serialises schema creation (and a world's first metadata) between
// servers opening one database at once: a transaction's advisory lock.
inline constexpr std::int64_t kPgSchemaLockKey = 0x7465727261'6e65;  // "terrane"

// Statement parameters and binary columns (free functions, used by both
// stores' statements).
namespace pg {

// One statement parameter: text, or raw bytes sent in binary format.
struct Param {
  std::string bytes;
  bool binary = false;
};
inline Param text(std::int64_t v) { return Param{std::to_string(v), false}; }
Param blob(std::span<const std::uint8_t> b);

// Binary columns, each checked for its length: the database's answer is
// read like any input.
std::optional<std::int32_t> be32_at(PGresult* res, int row, int col);
std::optional<std::int64_t> be64_at(PGresult* res, int row, int col);
std::span<const std::uint8_t> bytes_at(PGresult* res, int row, int col);
// The chunk position in a row's first three columns (x, y, z integers).
std::optional<Vec3i> position_at(PGresult* res, int row);
// The parameters of a region's chunk range: x0, x1, y0, y1, z0, z1.
std::vector<Param> region_range(Vec3i region);
// "(x,y,z)", as messages name chunks and regions.
std::string region_text(Vec3i r);
// A connection string as it may be logged: the password replaced by ***.
std::string redacted(const std::string& url);

}  // namespace pg

class PgConnection {
 public:
  // Connects (libpq's defaults first: a bounded connect, TCP keepalives),
  // sets the session's limits, and makes the schema if the database has
  // none (in one transaction; an older version is upgraded once no server
  // of it runs; another version is an error naming both).
  static StoreResult<std::unique_ptr<PgConnection>> open(const std::string& url);
  ~PgConnection();
  PgConnection(const PgConnection&) = delete;
  PgConnection& operator=(const PgConnection&) = delete;

  // A statement's answer (owning the PGresult).
  struct Rows {
    PGresult* res = nullptr;
    Rows() = default;
    explicit Rows(PGresult* r) : res(r) {}
    Rows(Rows&& o) noexcept;
    Rows& operator=(Rows&& o) noexcept;
    ~Rows();
    int count() const;
    std::string get(int row, int col) const;
    // A column read as an integer, or nullopt if it is not one (never an
    // exception: the database's answer is checked like any input).
    std::optional<std::int64_t> integer(int row, int col) const;
  };

  // Runs one statement; binary_result asks for binary columns. A
  // connection that broke is opened again first. A statement not answered
  // within call_timeout fails with kConnection and gives the connection up
  // (the next statement opens it again; the database rolls back whatever
  // the session had open when it notices).
  StoreResult<Rows> exec(const char* what, const char* sql, const std::vector<pg::Param>& params = {},
                         bool binary_result = false);
  // The error of a statement (res may be null: the connection's).
  StoreError error(const char* what, PGresult* res) const;
  // Ends a failed transaction (if the connection still works) and passes
  // the error on.
  StoreError abort(StoreError e);
  // BEGIN, body, COMMIT (named what); on any failure the transaction is
  // rolled back. A COMMIT whose answer was lost is kUnknown (it may have
  // been committed); a failure before it is as reported (nothing done).
  template <class T>
  StoreResult<T> transaction(const char* what, const std::function<StoreResult<T>()>& body) {
    auto begin = exec("begin", "BEGIN");
    if (!begin) return begin.error();
    auto out = body();
    if (!out) return abort(out.error());
    auto commit = exec(what, "COMMIT");
    if (!commit) return abort(unanswered_commit(commit.error()));
    return out;
  }
  // The error of a COMMIT that was sent: a lost connection is kUnknown
  // (the database may have committed before it broke).
  static StoreError unanswered_commit(StoreError e) {
    if (e.kind == StoreError::Kind::kConnection) e.kind = StoreError::Kind::kUnknown;
    return e;
  }
  // The deadline of each statement, its answer included (10 s unless set).
  void set_call_timeout(std::chrono::milliseconds t) { call_timeout_ = t; }
  std::chrono::milliseconds call_timeout() const { return call_timeout_; }
  // The raw connection (notices: PQnotifies, PQsocket).
  PGconn* raw() const { return conn_; }
  // Test seam: asked with each statement once it has been answered; true
  // loses the answer: the statement is done in the database, and here it
  // fails with kConnection and the connection is given up, as when the
  // network fails just after the database answered.
  void set_lose_answer(std::function<bool(const char* sql)> lose) { lose_answer_ = std::move(lose); }
  // The url as given, and as messages name it (the password left out).
  const std::string& url() const { return url_; }
  const std::string& shown() const { return shown_; }

 private:
  PgConnection(PGconn* conn, std::string url, std::string shown);
  // The session's limits (STORE_POSTGRESQL.md): a transaction left idle is
  // ended, no statement waits long for a lock. Per session: set again
  // after a reset.
  std::optional<StoreError> set_limits(std::chrono::steady_clock::time_point deadline);
  // Opens the connection again (libpq's reset) by deadline; false if not.
  bool reset_by(std::chrono::steady_clock::time_point deadline);
  // Makes or upgrades the schema (open).
  StoreResult<Ok> make_schema();

  // Sends one statement and waits for its answer until deadline; null with
  // *timed_out set when the deadline passed (the connection is then broken_).
  PGresult* run(const char* sql, const std::vector<pg::Param>& params, bool binary_result,
                std::chrono::steady_clock::time_point deadline, bool* timed_out);
  // Waits until the socket is ready for events (poll's) or deadline.
  bool wait_socket(short events, std::chrono::steady_clock::time_point deadline) const;

  PGconn* conn_ = nullptr;
  std::chrono::milliseconds call_timeout_{10000};
  // A statement timed out: its answer may still come, so the connection is
  // reopened before the next one, and no ROLLBACK is sent on it.
  bool broken_ = false;
  std::string url_;
  std::string shown_;
  std::function<bool(const char* sql)> lose_answer_;  // test seam (set_lose_answer)
};

}  // namespace terrane
