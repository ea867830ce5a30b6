#include "server/storage/pg_connection.h"

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <libpq-fe.h>

#include <poll.h>

#include <cerrno>
#include <charconv>
#include <cstring>
#include <utility>

#include "common/world/coarse_image.h"

namespace terrane {

namespace pg {

Param blob(std::span<const std::uint8_t> b) {
  return Param{std::string(reinterpret_cast<const char*>(b.data()), b.size()), true};
}

std::optional<std::int32_t> be32_at(PGresult* res, int row, int col) {
  if (PQgetisnull(res, row, col) || PQgetlength(res, row, col) != 4) return std::nullopt;
  const char* p = PQgetvalue(res, row, col);
  std::uint32_t v = 0;
  for (int i = 0; i < 4; ++i) v = (v << 8) | static_cast<unsigned char>(p[i]);
  return static_cast<std::int32_t>(v);
}

std::optional<std::int64_t> be64_at(PGresult* res, int row, int col) {
  if (PQgetisnull(res, row, col) || PQgetlength(res, row, col) != 8) return std::nullopt;
  const char* p = PQgetvalue(res, row, col);
  std::uint64_t v = 0;
  for (int i = 0; i < 8; ++i) v = (v << 8) | static_cast<unsigned char>(p[i]);
  return static_cast<std::int64_t>(v);
}

std::span<const std::uint8_t> bytes_at(PGresult* res, int row, int col) {
  return {reinterpret_cast<const std::uint8_t*>(PQgetvalue(res, row, col)),
          static_cast<std::size_t>(PQgetlength(res, row, col))};
}

std::optional<Vec3i> position_at(PGresult* res, int row) {
  const auto x = be32_at(res, row, 0), y = be32_at(res, row, 1), z = be32_at(res, row, 2);
  if (!x || !y || !z) return std::nullopt;
  return Vec3i{*x, *y, *z};
}

std::vector<Param> region_range(Vec3i region) {
  const Vec3i lo = region * kCoarseRegionChunks, hi = lo + Vec3i{kCoarseRegionChunks - 1, kCoarseRegionChunks - 1,
                                                                  kCoarseRegionChunks - 1};
  return {text(lo.x), text(hi.x), text(lo.y), text(hi.y), text(lo.z), text(hi.z)};
}

std::string region_text(Vec3i r) { return fmt::format("({},{},{})", r.x, r.y, r.z); }

// A connection string as it may be logged: the password replaced by ***.
std::string redacted(const std::string& url) {
  std::string out = url;
  if (const auto scheme = out.find("://"); scheme != std::string::npos) {
    const auto at = out.find('@', scheme + 3);
    const auto slash = out.find('/', scheme + 3);
    if (at != std::string::npos && (slash == std::string::npos || at < slash)) {
      const auto colon = out.find(':', scheme + 3);
      if (colon != std::string::npos && colon < at) out.replace(colon + 1, at - colon - 1, "***");
    }
  }
  if (out.find("password") == std::string::npos) return out;
  // Anything else that names a password: rebuilt from libpq's own parse,
  // the password left out (quoting and spaces around '=' as libpq reads them).
  char* err = nullptr;
  PQconninfoOption* opts = PQconninfoParse(url.c_str(), &err);
  if (err != nullptr) PQfreemem(err);
  if (opts == nullptr) return "(a connection string that does not parse)";
  std::string rebuilt;
  for (const PQconninfoOption* o = opts; o->keyword != nullptr; ++o) {
    if (o->val == nullptr || *o->val == '\0') continue;
    if (!rebuilt.empty()) rebuilt += ' ';
    rebuilt += o->keyword;
    rebuilt += '=';
    rebuilt += std::string_view(o->keyword) == "password" ? std::string("***") : std::string(o->val);
  }
  PQconninfoFree(opts);
  return rebuilt;
}

}  // namespace pg

PgConnection::Rows::Rows(Rows&& o) noexcept : res(std::exchange(o.res, nullptr)) {}
PgConnection::Rows& PgConnection::Rows::operator=(Rows&& o) noexcept {
  std::swap(res, o.res);
  return *this;
}
PgConnection::Rows::~Rows() {
  if (res != nullptr) PQclear(res);
}
int PgConnection::Rows::count() const { return PQntuples(res); }
std::string PgConnection::Rows::get(int row, int col) const { return PQgetvalue(res, row, col); }
std::optional<std::int64_t> PgConnection::Rows::integer(int row, int col) const {
  const char* v = PQgetvalue(res, row, col);
  const char* end = v + std::strlen(v);
  std::int64_t out = 0;
  const auto [at, ec] = std::from_chars(v, end, out);
  if (ec != std::errc{} || at != end) return std::nullopt;
  return out;
}

PgConnection::PgConnection(PGconn* conn, std::string url, std::string shown)
    : conn_(conn), url_(std::move(url)), shown_(std::move(shown)) {}

PgConnection::~PgConnection() {
  if (conn_ != nullptr) PQfinish(conn_);
}

StoreResult<std::unique_ptr<PgConnection>> PgConnection::open(const std::string& url) {
  std::string shown = pg::redacted(url);  // as messages name it
  // Defaults first, so that the same settings in url win: a bounded connect
  // and TCP keepalives, so a dead peer is noticed in seconds, not hours.
  const char* keys[] = {"connect_timeout", "keepalives", "keepalives_idle", "keepalives_interval",
                        "keepalives_count", "dbname", nullptr};
  const char* values[] = {"10", "1", "5", "2", "3", url.c_str(), nullptr};
  std::unique_ptr<PgConnection> c(new PgConnection(PQconnectdbParams(keys, values, /*expand_dbname=*/1), url, shown));
  if (c->conn_ == nullptr || PQstatus(c->conn_) != CONNECTION_OK) {
    std::string detail = c->conn_ != nullptr ? PQerrorMessage(c->conn_) : "out of memory";
    while (!detail.empty() && (detail.back() == '\n' || detail.back() == ' ')) detail.pop_back();
    return StoreError{StoreError::Kind::kConnection,
                      fmt::format("postgresql: cannot connect to {}: {}", shown, detail)};
  }
  // Notices (e.g. "relation already exists, skipping") are not errors.
  PQsetNoticeProcessor(c->conn_, [](void*, const char*) {}, nullptr);
  // A writer stopped inside a transaction (paused, partitioned) must not
  // hold a lease row's lock for ever: the database ends its session, which
  // rolls it back, and a takeover goes on. No statement waits long for a
  // lock either.
  if (auto e = c->set_limits(std::chrono::steady_clock::now() + c->call_timeout_)) return *e;
  if (auto made = c->make_schema(); !made) return made.error();
  return c;
}

StoreResult<Ok> PgConnection::make_schema() {
  // A database whose schema is this build's is used as it is: the
  // statements below take table locks even when there is nothing to make.
  if (auto current = exec("read schema version", "SELECT version FROM terrane_schema");
      current && current->count() == 1 && current->integer(0, 0) == kPgSchemaVersion)
    return Ok{};
  auto begin = exec("begin", "BEGIN");
  if (!begin) return begin.error();
  auto lock = exec("lock schema", "SELECT pg_advisory_xact_lock($1)", {pg::text(kPgSchemaLockKey)});
  if (!lock) return abort(lock.error());
  for (const char* table : {
           "CREATE TABLE IF NOT EXISTS terrane_schema (version integer NOT NULL)",
           "CREATE TABLE IF NOT EXISTS terrane_meta (key text PRIMARY KEY, value text NOT NULL)",
           "CREATE TABLE IF NOT EXISTS terrane_chunks ("
           "  x integer NOT NULL, y integer NOT NULL, z integer NOT NULL,"
           "  revision bigint NOT NULL, blob bytea NOT NULL, coarse bytea NOT NULL, PRIMARY KEY (x, y, z))",
           "CREATE TABLE IF NOT EXISTS terrane_quarantine ("
           "  id bigserial PRIMARY KEY, x integer NOT NULL, y integer NOT NULL, z integer NOT NULL,"
           "  revision bigint NOT NULL, blob bytea NOT NULL, reason text NOT NULL, time_s bigint NOT NULL)",
           "CREATE INDEX IF NOT EXISTS terrane_quarantine_chunk ON terrane_quarantine (x, y, z)",
           "CREATE TABLE IF NOT EXISTS terrane_edit_log ("
           "  id bigserial PRIMARY KEY, tick bigint NOT NULL, time_ms bigint NOT NULL, player text NOT NULL,"
           "  x0 integer NOT NULL, y0 integer NOT NULL, z0 integer NOT NULL,"
           "  x1 integer NOT NULL, y1 integer NOT NULL, z1 integer NOT NULL,"
           "  before bytea NOT NULL, after bytea NOT NULL)",
           "CREATE INDEX IF NOT EXISTS terrane_edit_log_player ON terrane_edit_log (player, id)",
           "CREATE INDEX IF NOT EXISTS terrane_edit_log_time ON terrane_edit_log (time_ms)",
           "CREATE TABLE IF NOT EXISTS terrane_access (key text PRIMARY KEY, value text NOT NULL)",
           "CREATE TABLE IF NOT EXISTS terrane_inbox ("
           "  id bigserial PRIMARY KEY, to_server integer NOT NULL, from_server integer NOT NULL,"
           "  player text NOT NULL, edit bytea NOT NULL, created_at timestamptz NOT NULL,"
           "  expires_at timestamptz NOT NULL DEFAULT '-infinity', taken boolean NOT NULL DEFAULT false)",
           "CREATE INDEX IF NOT EXISTS terrane_inbox_to ON terrane_inbox (to_server, id)",
           "CREATE TABLE IF NOT EXISTS terrane_leases ("
           "  rx integer NOT NULL, ry integer NOT NULL, rz integer NOT NULL,"
           "  owner integer NOT NULL, epoch bigint NOT NULL, expires_at timestamptz NOT NULL,"
           "  seq bigint NOT NULL DEFAULT 0, PRIMARY KEY (rx, ry, rz))",
           // Version 2: where each server takes clients (redirects), and
           // answers to forwarded edits kept until their sender read them.
           "CREATE TABLE IF NOT EXISTS terrane_servers ("
           "  id integer PRIMARY KEY, address text NOT NULL, seen_at timestamptz NOT NULL)",
           "CREATE TABLE IF NOT EXISTS terrane_answers ("
           "  id bigint PRIMARY KEY, from_server integer NOT NULL, accepted boolean NOT NULL, tick bigint NOT NULL,"
           "  reason text NOT NULL, answered_at timestamptz NOT NULL)",
           "CREATE INDEX IF NOT EXISTS terrane_answers_from ON terrane_answers (from_server)",
           "ALTER TABLE terrane_leases ADD COLUMN IF NOT EXISTS seq bigint NOT NULL DEFAULT 0",
           // Version 4: a chunk's blob may be of an older revision
           // (blob_revision; NULL: the chunk's revision), its units since
           // then kept beside it.
           "ALTER TABLE terrane_chunks ADD COLUMN IF NOT EXISTS blob_revision bigint",
           "CREATE TABLE IF NOT EXISTS terrane_chunk_units ("
           "  x integer NOT NULL, y integer NOT NULL, z integer NOT NULL,"
           "  revision bigint NOT NULL, units bytea NOT NULL, PRIMARY KEY (x, y, z, revision))",
           // Version 5: a forwarded edit's deadline, by the database's
           // clock, and whether its addressee took it (rows of version 4
           // get a deadline long past: never taken, swept); each writing
           // connection's last commit, so that a commit tried again after
           // its answer was lost is not stored twice.
           "ALTER TABLE terrane_inbox ADD COLUMN IF NOT EXISTS expires_at timestamptz NOT NULL DEFAULT '-infinity'",
           "ALTER TABLE terrane_inbox ADD COLUMN IF NOT EXISTS taken boolean NOT NULL DEFAULT false",
           "CREATE TABLE IF NOT EXISTS terrane_commits ("
           "  writer bigint PRIMARY KEY, seq bigint NOT NULL, committed_at timestamptz NOT NULL)"}) {
    auto made = exec("create schema", table);
    if (!made) return abort(made.error());
  }
  auto version = exec("read schema version", "SELECT version FROM terrane_schema");
  if (!version) return abort(version.error());
  if (version->count() == 0) {
    auto put = exec("write schema version", "INSERT INTO terrane_schema (version) VALUES ($1)",
                    {pg::text(kPgSchemaVersion)});
    if (!put) return abort(put.error());
  } else if (const auto v = version->integer(0, 0); v == 1 || v == 2 || v == 3 || v == 4) {
    // Servers of an older version still running would write without moving
    // the write sequences or keeping answers (1), refuse this build's
    // notices (2), read blobs without the units kept after them (3), or
    // forward edits without a deadline and apply them however late (4):
    // the upgrade waits for them. A server without a lease (its clients
    // only watch) still reads and may write later: servers of versions 2
    // to 4 say they run every second (terrane_servers; empty in version 1).
    auto running = exec("count running servers",
                        "SELECT (SELECT count(*) FROM terrane_leases WHERE expires_at > clock_timestamp()),"
                        " (SELECT count(*) FROM terrane_servers"
                        "  WHERE seen_at > clock_timestamp() - interval '10 seconds')");
    if (!running) return abort(running.error());
    std::vector<std::string> still;
    if (running->integer(0, 0).value_or(0) > 0) still.push_back(running->get(0, 0) + " regions leased now");
    if (running->integer(0, 1).value_or(0) > 0)
      still.push_back(running->get(0, 1) + " servers running (seen in the last 10 s)");
    if (!still.empty())
      return abort(StoreError{StoreError::Kind::kQuery,
                              fmt::format("postgresql: {} holds a Terrane schema of version {} with {}: stop its "
                                          "servers, then start this build to bring it to version {}",
                                          shown_, *v, fmt::join(still, " and "), kPgSchemaVersion)});
    // Version 1 lacks terrane_servers, terrane_answers and the leases'
    // seq only, made above; version 2 differs in its notices only; version
    // 3 lacks terrane_chunk_units and blob_revision only (NULL: every blob
    // is at its chunk's revision); version 4 lacks the inbox's expires_at
    // and taken and terrane_commits only; all made above.
    auto put = exec("write schema version", "UPDATE terrane_schema SET version = $1", {pg::text(kPgSchemaVersion)});
    if (!put) return abort(put.error());
  } else if (version->integer(0, 0) != kPgSchemaVersion) {
    return abort(StoreError{StoreError::Kind::kQuery,
                            fmt::format("postgresql: {} holds a Terrane schema of version {}; this build reads "
                                        "version {}",
                                        shown_, version->get(0, 0), kPgSchemaVersion)});
  }
  auto commit = exec("commit schema", "COMMIT");
  if (!commit) return abort(commit.error());
  return Ok{};
}

StoreError PgConnection::error(const char* what, PGresult* res) const {
  StoreError e;
  e.kind = PQstatus(conn_) == CONNECTION_OK ? StoreError::Kind::kQuery : StoreError::Kind::kConnection;
  const char* state = res != nullptr ? PQresultErrorField(res, PG_DIAG_SQLSTATE) : nullptr;
  if (e.kind == StoreError::Kind::kQuery && state != nullptr && std::strncmp(state, "40", 2) == 0)
    e.kind = StoreError::Kind::kConflict;
  std::string detail = res != nullptr ? PQresultErrorMessage(res) : PQerrorMessage(conn_);
  while (!detail.empty() && (detail.back() == '\n' || detail.back() == ' ')) detail.pop_back();
  e.message = fmt::format("postgresql: {}: {}", what, detail);
  return e;
}

StoreResult<PgConnection::Rows> PgConnection::exec(const char* what, const char* sql,
                                                   const std::vector<pg::Param>& params, bool binary_result) {
  // A connection that broke (the database restarted, say) or was given up
  // is opened again before the next statement; the statement fails if that
  // fails too.
  // One deadline covers both.
  const auto deadline = std::chrono::steady_clock::now() + call_timeout_;
  if (broken_ || PQstatus(conn_) != CONNECTION_OK) {
    broken_ = false;
    if (!reset_by(deadline) || set_limits(deadline))
      return StoreError{StoreError::Kind::kConnection,
                        fmt::format("postgresql: {}: cannot reach the database again within {} ms", what,
                                    call_timeout_.count())};
  }
  bool timed_out = false;
  PGresult* res = run(sql, params, binary_result, deadline, &timed_out);
  if (timed_out)
    return StoreError{StoreError::Kind::kConnection,
                      fmt::format("postgresql: {}: no answer within {} ms (the connection is given up)", what,
                                  call_timeout_.count())};
  if (lose_answer_ && lose_answer_(sql)) {
    if (res != nullptr) PQclear(res);
    broken_ = true;
    return StoreError{StoreError::Kind::kConnection,
                      fmt::format("postgresql: {}: the connection was lost before the answer (a test's)", what)};
  }
  const ExecStatusType st = res != nullptr ? PQresultStatus(res) : PGRES_FATAL_ERROR;
  if (st != PGRES_COMMAND_OK && st != PGRES_TUPLES_OK) {
    StoreError e = error(what, res);
    if (res != nullptr) PQclear(res);
    return e;
  }
  return Rows(res);
}

bool PgConnection::reset_by(std::chrono::steady_clock::time_point deadline) {
  // libpq's non-blocking reconnect, so that a database the network cut off
  // costs the deadline, not the connect timeout.
  if (PQresetStart(conn_) == 0) return false;
  PostgresPollingStatusType st = PGRES_POLLING_WRITING;
  for (;;) {
    if (st == PGRES_POLLING_OK) return true;
    if (st == PGRES_POLLING_FAILED) return false;
    if (!wait_socket(st == PGRES_POLLING_READING ? POLLIN : POLLOUT, deadline)) {
      broken_ = true;  // half open: start again next time
      return false;
    }
    st = PQresetPoll(conn_);
  }
}

bool PgConnection::wait_socket(short events, std::chrono::steady_clock::time_point deadline) const {
  for (;;) {
    const auto left = std::chrono::ceil<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0) return false;
    pollfd p{PQsocket(conn_), events, 0};
    if (p.fd < 0) return true;  // no socket: the libpq call that follows reports it
    const int n = ::poll(&p, 1, static_cast<int>(std::min<std::int64_t>(left.count(), 1 << 30)));
    if (n > 0) return true;
    if (n < 0 && errno != EINTR) return true;  // reported by the libpq call that follows
  }
}

PGresult* PgConnection::run(const char* sql, const std::vector<pg::Param>& params, bool binary_result,
                            std::chrono::steady_clock::time_point deadline, bool* timed_out) {
  std::vector<const char*> values;
  std::vector<int> lengths, formats;
  for (const pg::Param& p : params) {
    values.push_back(p.bytes.data());
    lengths.push_back(static_cast<int>(p.bytes.size()));
    formats.push_back(p.binary ? 1 : 0);
  }
  // Non-blocking, so that neither sending a large statement nor waiting for
  // its answer can outlast the deadline.
  PQsetnonblocking(conn_, 1);
  if (PQsendQueryParams(conn_, sql, static_cast<int>(params.size()), nullptr, values.data(), lengths.data(),
                        formats.data(), binary_result ? 1 : 0) == 0)
    return nullptr;  // the connection's error
  auto give_up = [&]() -> PGresult* {
    broken_ = true;
    *timed_out = true;
    return nullptr;
  };
  for (;;) {
    const int f = PQflush(conn_);
    if (f == 0) break;
    if (f < 0) return nullptr;
    if (!wait_socket(POLLIN | POLLOUT, deadline)) return give_up();
    if (PQconsumeInput(conn_) == 0) return nullptr;
  }
  // As PQexec: the last result, or the first error.
  PGresult* out = nullptr;
  for (;;) {
    while (PQisBusy(conn_) != 0) {
      if (!wait_socket(POLLIN, deadline)) {
        if (out != nullptr) PQclear(out);
        return give_up();
      }
      if (PQconsumeInput(conn_) == 0) {
        if (out != nullptr) PQclear(out);
        return nullptr;
      }
    }
    PGresult* r = PQgetResult(conn_);
    if (r == nullptr) break;
    if (out != nullptr && PQresultStatus(out) != PGRES_COMMAND_OK && PQresultStatus(out) != PGRES_TUPLES_OK) {
      PQclear(r);  // keep the first error
      continue;
    }
    if (out != nullptr) PQclear(out);
    out = r;
  }
  return out;
}

std::optional<StoreError> PgConnection::set_limits(std::chrono::steady_clock::time_point deadline) {
  for (const char* limit : {"SET idle_in_transaction_session_timeout = '10s'", "SET lock_timeout = '10s'"}) {
    bool timed_out = false;
    PGresult* r = run(limit, {}, false, deadline, &timed_out);
    if (timed_out)
      return StoreError{StoreError::Kind::kConnection,
                        fmt::format("postgresql: session limits: no answer within {} ms", call_timeout_.count())};
    const bool ok = r != nullptr && PQresultStatus(r) == PGRES_COMMAND_OK;
    std::optional<StoreError> e;
    if (!ok) e = error("session limits", r);
    if (r != nullptr) PQclear(r);
    if (e) return e;
  }
  return std::nullopt;
}

StoreError PgConnection::abort(StoreError e) {
  if (!broken_ && PQstatus(conn_) == CONNECTION_OK) {
    bool timed_out = false;
    if (PGresult* r = run("ROLLBACK", {}, false, std::chrono::steady_clock::now() + call_timeout_, &timed_out))
      PQclear(r);
  }
  return e;
}

}  // namespace terrane
