#include "server/storage/postgres_store.h"

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <libpq-fe.h>
#include <poll.h>

#include <cerrno>
#include <algorithm>
#include <charconv>
#include <cstring>
#include <limits>
#include <map>
#include <optional>
#include <string_view>
#include <thread>
#include <tuple>

#include "common/codec/update_batch.h"
#include "common/world/coarse_image.h"
#include "protocol/framing.h"
#include "protocol/messages.h"
#include "server/base/log.h"

namespace terrane {

namespace {

// Serialises schema creation between servers opening one database at once.
constexpr std::int64_t kSchemaLockKey = 0x7465727261'6e65;  // "terrane"

// A write PostgreSQL rolled back to break a deadlock (or a serialization
// conflict) is tried again at once this many times before it fails.
constexpr int kConflictRetries = 3;

std::string region_text(Vec3i r) { return fmt::format("({},{},{})", r.x, r.y, r.z); }

// A lease row whose values are not what the schema allows.
StoreError bad_row(const char* what, Vec3i region) {
  return StoreError{StoreError::Kind::kDecode,
                    fmt::format("postgresql: {}: region {} has a lease row out of range", what, region_text(region))};
}

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

// One statement parameter: text, or raw bytes sent in binary format.
struct Param {
  std::string bytes;
  bool binary = false;
};
Param text(std::int64_t v) { return Param{std::to_string(v), false}; }
Param blob(std::span<const std::uint8_t> b) {
  return Param{std::string(reinterpret_cast<const char*>(b.data()), b.size()), true};
}

std::uint64_t be64(const char* p) {
  std::uint64_t v = 0;
  for (int i = 0; i < 8; ++i) v = (v << 8) | static_cast<unsigned char>(p[i]);
  return v;
}

// A chunk's coarse mip as stored in terrane_chunks.coarse: 64 voxels,
// material then occupancy, Box order (the coarse image's entry voxels).
std::vector<std::uint8_t> coarse_bytes(const CoarseVoxels& v) {
  std::vector<std::uint8_t> out;
  out.reserve(v.size() * 2);
  for (const Voxel& x : v) {
    out.push_back(x.material);
    out.push_back(x.occupancy);
  }
  return out;
}

FileError file_error(const StoreError& e) { return FileError{e.message, std::nullopt}; }

}  // namespace

struct PostgresStore::Connection {
  PGconn* conn = nullptr;
  ~Connection() {
    if (conn != nullptr) PQfinish(conn);
  }

  struct Rows {
    PGresult* res = nullptr;
    Rows() = default;
    explicit Rows(PGresult* r) : res(r) {}
    Rows(Rows&& o) noexcept : res(std::exchange(o.res, nullptr)) {}
    Rows& operator=(Rows&& o) noexcept {
      std::swap(res, o.res);
      return *this;
    }
    ~Rows() {
      if (res != nullptr) PQclear(res);
    }
    int count() const { return PQntuples(res); }
    std::string get(int row, int col) const { return PQgetvalue(res, row, col); }
    // A column read as an integer, or nullopt if it is not one (never an
    // exception: the database's answer is checked like any input).
    std::optional<std::int64_t> integer(int row, int col) const {
      const char* v = PQgetvalue(res, row, col);
      const char* end = v + std::strlen(v);
      std::int64_t out = 0;
      const auto [at, ec] = std::from_chars(v, end, out);
      if (ec != std::errc{} || at != end) return std::nullopt;
      return out;
    }
  };

  StoreError error(const char* what, PGresult* res) const {
    StoreError e;
    e.kind = PQstatus(conn) == CONNECTION_OK ? StoreError::Kind::kQuery : StoreError::Kind::kConnection;
    const char* state = res != nullptr ? PQresultErrorField(res, PG_DIAG_SQLSTATE) : nullptr;
    if (e.kind == StoreError::Kind::kQuery && state != nullptr && std::strncmp(state, "40", 2) == 0)
      e.kind = StoreError::Kind::kConflict;
    std::string detail = res != nullptr ? PQresultErrorMessage(res) : PQerrorMessage(conn);
    while (!detail.empty() && (detail.back() == '\n' || detail.back() == ' ')) detail.pop_back();
    e.message = fmt::format("postgresql: {}: {}", what, detail);
    return e;
  }

  // Runs one statement; binary_result asks for binary columns.
  StoreResult<Rows> exec(const char* what, const char* sql, const std::vector<Param>& params = {},
                         bool binary_result = false) {
    // A connection that broke (the database restarted, say) is opened again
    // before the next statement; the statement fails if that fails too.
    if (PQstatus(conn) != CONNECTION_OK) {
      PQreset(conn);
      if (PQstatus(conn) == CONNECTION_OK) set_limits();
    }
    std::vector<const char*> values;
    std::vector<int> lengths, formats;
    for (const Param& p : params) {
      values.push_back(p.bytes.data());
      lengths.push_back(static_cast<int>(p.bytes.size()));
      formats.push_back(p.binary ? 1 : 0);
    }
    PGresult* res = PQexecParams(conn, sql, static_cast<int>(params.size()), nullptr, values.data(), lengths.data(),
                                 formats.data(), binary_result ? 1 : 0);
    const ExecStatusType st = res != nullptr ? PQresultStatus(res) : PGRES_FATAL_ERROR;
    if (st != PGRES_COMMAND_OK && st != PGRES_TUPLES_OK) {
      StoreError e = error(what, res);
      if (res != nullptr) PQclear(res);
      return e;
    }
    return Rows(res);
  }

  // The session's limits (STORE_POSTGRESQL.md): a transaction left idle is
  // ended, no statement waits long for a lock. Per session: set again
  // after a reset.
  std::optional<StoreError> set_limits() {
    for (const char* limit : {"SET idle_in_transaction_session_timeout = '10s'", "SET lock_timeout = '10s'"}) {
      PGresult* r = PQexec(conn, limit);
      const bool ok = r != nullptr && PQresultStatus(r) == PGRES_COMMAND_OK;
      std::optional<StoreError> e;
      if (!ok) e = error("session limits", r);
      if (r != nullptr) PQclear(r);
      if (e) return e;
    }
    return std::nullopt;
  }

  // Ends a failed transaction (if the connection still works) and passes
  // the error on.
  StoreError abort(StoreError e) {
    if (PQstatus(conn) == CONNECTION_OK) PQclear(PQexec(conn, "ROLLBACK"));
    return e;
  }
};

Vec3i lease_region_of(Vec3i chunk_pos) { return coarse_region_of(chunk_pos); }


PostgresStore::PostgresStore(std::unique_ptr<Connection> c, std::string url, std::string shown)
    : c_(std::move(c)), url_(std::move(url)), shown_(std::move(shown)) {}

bool PostgresStore::is_url(const std::string& url) {
  return url.rfind("postgresql://", 0) == 0 || url.rfind("postgres://", 0) == 0;
}
PostgresStore::~PostgresStore() = default;

StoreResult<std::unique_ptr<PostgresStore>> PostgresStore::open(const std::string& url) {
  const std::string shown = redacted(url);  // as messages name it
  auto c = std::make_unique<Connection>();
  // Defaults first, so that the same settings in url win: a bounded connect
  // and TCP keepalives, so a dead peer is noticed in seconds, not hours.
  const char* keys[] = {"connect_timeout", "keepalives", "keepalives_idle", "keepalives_interval",
                        "keepalives_count", "dbname", nullptr};
  const char* values[] = {"10", "1", "5", "2", "3", url.c_str(), nullptr};
  c->conn = PQconnectdbParams(keys, values, /*expand_dbname=*/1);
  if (c->conn == nullptr || PQstatus(c->conn) != CONNECTION_OK) {
    std::string detail = c->conn != nullptr ? PQerrorMessage(c->conn) : "out of memory";
    while (!detail.empty() && (detail.back() == '\n' || detail.back() == ' ')) detail.pop_back();
    return StoreError{StoreError::Kind::kConnection,
                      fmt::format("postgresql: cannot connect to {}: {}", shown, detail)};
  }
  // Notices (e.g. "relation already exists, skipping") are not errors.
  PQsetNoticeProcessor(c->conn, [](void*, const char*) {}, nullptr);
  // A writer stopped inside a transaction (paused, partitioned) must not
  // hold a lease row's lock for ever: the database ends its session, which
  // rolls it back, and a takeover goes on. No statement waits long for a
  // lock either.
  if (auto e = c->set_limits()) return *e;
  // A database whose schema is this build's is used as it is: the
  // statements below take table locks even when there is nothing to make.
  if (auto current = c->exec("read schema version", "SELECT version FROM terrane_schema");
      current && current->count() == 1 && current->integer(0, 0) == kSchemaVersion) {
    std::unique_ptr<PostgresStore> store(new PostgresStore(std::move(c), url, shown));
    if (auto m = store->read_meta(); !m) return m.error();
    return store;
  }
  auto begin = c->exec("begin", "BEGIN");
  if (!begin) return begin.error();
  auto lock = c->exec("lock schema", "SELECT pg_advisory_xact_lock($1)", {text(kSchemaLockKey)});
  if (!lock) return c->abort(lock.error());
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
           "  player text NOT NULL, edit bytea NOT NULL, created_at timestamptz NOT NULL)",
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
           "  revision bigint NOT NULL, units bytea NOT NULL, PRIMARY KEY (x, y, z, revision))"}) {
    auto made = c->exec("create schema", table);
    if (!made) return c->abort(made.error());
  }
  auto version = c->exec("read schema version", "SELECT version FROM terrane_schema");
  if (!version) return c->abort(version.error());
  if (version->count() == 0) {
    auto put = c->exec("write schema version", "INSERT INTO terrane_schema (version) VALUES ($1)",
                       {text(kSchemaVersion)});
    if (!put) return c->abort(put.error());
  } else if (const auto v = version->integer(0, 0); v == 1 || v == 2 || v == 3) {
    // Servers of an older version still running would write without moving
    // the write sequences or keeping answers (1), refuse this build's
    // notices (2), or read blobs without the units kept after them (3):
    // the upgrade waits for them. A server without a lease (its clients
    // only watch) still reads and may write later: servers of versions 2
    // and 3 say they run every second (terrane_servers; empty in version 1).
    auto running = c->exec("count running servers",
                           "SELECT (SELECT count(*) FROM terrane_leases WHERE expires_at > clock_timestamp()),"
                           " (SELECT count(*) FROM terrane_servers"
                           "  WHERE seen_at > clock_timestamp() - interval '10 seconds')");
    if (!running) return c->abort(running.error());
    std::vector<std::string> still;
    if (running->integer(0, 0).value_or(0) > 0) still.push_back(running->get(0, 0) + " regions leased now");
    if (running->integer(0, 1).value_or(0) > 0)
      still.push_back(running->get(0, 1) + " servers running (seen in the last 10 s)");
    if (!still.empty())
      return c->abort(StoreError{StoreError::Kind::kQuery,
                                 fmt::format("postgresql: {} holds a Terrane schema of version {} with {}: stop its "
                                             "servers, then start this build to bring it to version {}",
                                             shown, *v, fmt::join(still, " and "), kSchemaVersion)});
    // Version 1 lacks terrane_servers, terrane_answers and the leases'
    // seq only, made above; version 2 differs in its notices only; version
    // 3 lacks terrane_chunk_units and blob_revision only (NULL: every blob
    // is at its chunk's revision), made above.
    auto put = c->exec("write schema version", "UPDATE terrane_schema SET version = $1", {text(kSchemaVersion)});
    if (!put) return c->abort(put.error());
  } else if (version->integer(0, 0) != kSchemaVersion) {
    return c->abort(StoreError{StoreError::Kind::kQuery,
                               fmt::format("postgresql: {} holds a Terrane schema of version {}; this build reads "
                                           "version {}",
                                           shown, version->get(0, 0), kSchemaVersion)});
  }
  auto commit = c->exec("commit schema", "COMMIT");
  if (!commit) return c->abort(commit.error());
  std::unique_ptr<PostgresStore> store(new PostgresStore(std::move(c), url, shown));
  if (auto m = store->read_meta(); !m) return m.error();
  return store;
}

StoreResult<RegionLease> PostgresStore::claim(Vec3i region, std::uint32_t owner, std::chrono::milliseconds lease,
                                               ClaimRule rule) {
  if (owner > kMaxServerId)
    return StoreError{StoreError::Kind::kQuery, fmt::format("server id {} is not below 2^31", owner)};
  if (rule == ClaimRule::kPreferNeighbours) {
    auto left = left_to_neighbour(region, owner);
    if (!left) return left.error();
    if (*left) return **left;
  }
  // Free, expired or the claimant's own: taken at the next epoch (a server
  // that claims again is a new incarnation: whatever its earlier self still
  // has in flight is fenced). Held by another: no row changes, and the
  // answer is empty.
  auto r = c_->exec("claim region",
                    "INSERT INTO terrane_leases AS l (rx, ry, rz, owner, epoch, expires_at)"
                    " VALUES ($1, $2, $3, $4, 1, clock_timestamp() + $5::bigint * interval '1 millisecond')"
                    " ON CONFLICT (rx, ry, rz) DO UPDATE SET"
                    "  epoch = l.epoch + 1, owner = EXCLUDED.owner, expires_at = EXCLUDED.expires_at"
                    "  WHERE l.owner = EXCLUDED.owner OR l.expires_at <= clock_timestamp()"
                    " RETURNING epoch",
                    {text(region.x), text(region.y), text(region.z), text(owner), text(lease.count())});
  if (!r) return r.error();
  if (r->count() == 1) {
    const auto epoch = r->integer(0, 0);
    if (!epoch || *epoch < 1) return bad_row("claim region", region);
    return RegionLease{region, owner, static_cast<std::uint64_t>(*epoch)};
  }
  auto who = c_->exec("read region holder",
                      "SELECT owner, epoch, expires_at FROM terrane_leases WHERE rx = $1 AND ry = $2 AND rz = $3",
                      {text(region.x), text(region.y), text(region.z)});
  if (!who) return who.error();
  const std::string holder = who->count() == 1 ? fmt::format("server {} (epoch {}) until {}", who->get(0, 0),
                                                              who->get(0, 1), who->get(0, 2))
                                               : std::string("another server");
  StoreError owned{StoreError::Kind::kOwned, fmt::format("region {} is leased to {}", region_text(region), holder), {}};
  if (who->count() == 1)
    if (const auto id = who->integer(0, 0); id && *id >= 0 && *id <= std::numeric_limits<std::int32_t>::max())
      owned.holder = static_cast<std::uint32_t>(*id);
  return owned;
}

StoreResult<std::optional<StoreError>> PostgresStore::left_to_neighbour(Vec3i region, std::uint32_t owner) {
  // Per server with a current lease in the 3 x 3 x 3 regions around (a
  // range of the primary key): how many of the region's 26 neighbours it
  // writes, and whether it writes the region itself. A preference, read
  // apart from the claim: a claim racing it only makes a territory less
  // whole.
  auto r = c_->exec("read neighbouring leases",
                    "SELECT owner,"
                    " count(*) FILTER (WHERE NOT (rx = $1::int AND ry = $2::int AND rz = $3::int)),"
                    " count(*) FILTER (WHERE rx = $1::int AND ry = $2::int AND rz = $3::int)"
                    " FROM terrane_leases WHERE expires_at > clock_timestamp()"
                    "  AND rx BETWEEN $1::int - 1 AND $1::int + 1 AND ry BETWEEN $2::int - 1 AND $2::int + 1"
                    "  AND rz BETWEEN $3::int - 1 AND $3::int + 1"
                    " GROUP BY owner",
                    {text(region.x), text(region.y), text(region.z)});
  if (!r) return r.error();
  struct Writer {
    std::int64_t id = 0, near = 0, here = 0;
  };
  std::vector<Writer> writers;
  for (int i = 0; i < r->count(); ++i) {
    Writer w{r->integer(i, 0).value_or(-1), r->integer(i, 1).value_or(-1), r->integer(i, 2).value_or(-1)};
    if (w.id < 0 || w.id > kMaxServerId || w.near < 0 || w.here < 0)
      return StoreError{StoreError::Kind::kDecode, "postgresql: read neighbouring leases: a row is not a lease count"};
    writers.push_back(w);
  }
  for (const Writer& w : writers) {
    if (w.here > 0) return std::optional<StoreError>{};  // held: by another (the claim says whom) or by owner
    if (w.id == owner && w.near > 0) return std::optional<StoreError>{};  // next to this server's own
  }
  const Writer* best = nullptr;
  for (const Writer& w : writers)
    if (w.id != owner && w.near > 0 &&
        (best == nullptr || w.near > best->near || (w.near == best->near && w.id < best->id)))
      best = &w;
  if (best == nullptr) return std::optional<StoreError>{};
  return std::optional<StoreError>{StoreError{
      StoreError::Kind::kLeft,
      fmt::format("region {} is left to server {}, which writes {} of its neighbours (this server writes none)",
                  region_text(region), best->id, best->near),
      static_cast<std::uint32_t>(best->id)}};
}

StoreResult<std::vector<RegionLease>> PostgresStore::renew(std::span<const RegionLease> leases,
                                                           std::chrono::milliseconds lease) {
  std::vector<RegionLease> kept;
  if (leases.empty()) return kept;
  // One statement for every lease of one owner (a server holds thousands
  // of regions in a big world): arrays of the regions and their epochs.
  std::map<std::uint32_t, std::vector<const RegionLease*>> by_owner;
  for (const RegionLease& l : leases) by_owner[l.owner].push_back(&l);
  for (const auto& [owner, ls] : by_owner) {
    std::vector<std::int64_t> xs, ys, zs, epochs;
    for (const RegionLease* l : ls) {
      xs.push_back(l->region.x);
      ys.push_back(l->region.y);
      zs.push_back(l->region.z);
      epochs.push_back(static_cast<std::int64_t>(l->epoch));
    }
    auto array = [](const std::vector<std::int64_t>& v) { return Param{fmt::format("{{{}}}", fmt::join(v, ",")), false}; };
    // The rows are locked first, in the order a commit checks its leases
    // (save_fenced: y, z, x), so a renewal and a commit of the same server
    // never wait for each other in a cycle (a deadlock aborts one).
    auto r = c_->exec("renew leases",
                      "WITH locked AS MATERIALIZED (SELECT l.rx, l.ry, l.rz FROM terrane_leases AS l"
                      "  JOIN unnest($1::integer[], $2::integer[], $3::integer[], $4::bigint[]) AS k(rx, ry, rz, epoch)"
                      "  ON l.rx = k.rx AND l.ry = k.ry AND l.rz = k.rz AND l.epoch = k.epoch"
                      "  WHERE l.owner = $5 AND l.expires_at > clock_timestamp()"
                      "  ORDER BY l.ry, l.rz, l.rx FOR UPDATE OF l)"
                      " UPDATE terrane_leases AS l SET expires_at = clock_timestamp() + $6::bigint * interval '1 millisecond'"
                      " FROM locked WHERE l.rx = locked.rx AND l.ry = locked.ry AND l.rz = locked.rz AND l.owner = $5"
                      " AND l.expires_at > clock_timestamp() RETURNING l.rx, l.ry, l.rz, l.epoch",
                      {array(xs), array(ys), array(zs), array(epochs), text(owner), text(lease.count())});
    if (!r) return r.error();
    for (int row = 0; row < r->count(); ++row) {
      const auto x = r->integer(row, 0), y = r->integer(row, 1), z = r->integer(row, 2), e = r->integer(row, 3);
      if (!x || !y || !z || !e) continue;
      const RegionLease got{{static_cast<int>(*x), static_cast<int>(*y), static_cast<int>(*z)}, owner,
                            static_cast<std::uint64_t>(*e)};
      for (const RegionLease* l : ls)
        if (*l == got) {
          kept.push_back(*l);
          break;
        }
    }
  }
  return kept;
}

StoreResult<Ok> PostgresStore::release(std::span<const RegionLease> leases) {
  for (const RegionLease& l : leases) {
    auto r = c_->exec("release lease",
                      "UPDATE terrane_leases SET expires_at = clock_timestamp()"
                      " WHERE rx = $1 AND ry = $2 AND rz = $3 AND owner = $4 AND epoch = $5",
                      {text(l.region.x), text(l.region.y), text(l.region.z), text(l.owner),
                       text(static_cast<std::int64_t>(l.epoch))});
    if (!r) return r.error();
  }
  return Ok{};
}

StoreResult<std::optional<RegionLease>> PostgresStore::holder(Vec3i region) {
  auto r = c_->exec("read region holder",
                    "SELECT owner, epoch FROM terrane_leases"
                    " WHERE rx = $1 AND ry = $2 AND rz = $3 AND expires_at > clock_timestamp()",
                    {text(region.x), text(region.y), text(region.z)});
  if (!r) return r.error();
  if (r->count() == 0) return std::optional<RegionLease>{};
  const auto owner = r->integer(0, 0), epoch = r->integer(0, 1);
  if (!owner || *owner < 0 || !epoch || *epoch < 1) return bad_row("read region holder", region);
  return std::optional<RegionLease>{
      RegionLease{region, static_cast<std::uint32_t>(*owner), static_cast<std::uint64_t>(*epoch)}};
}

StoreResult<std::vector<RegionSeq>> PostgresStore::region_seqs() {
  auto r = c_->exec("read region sequences", "SELECT rx, ry, rz, seq FROM terrane_leases WHERE seq > 0");
  if (!r) return r.error();
  std::vector<RegionSeq> out;
  for (int row = 0; row < r->count(); ++row) {
    const auto x = r->integer(row, 0), y = r->integer(row, 1), z = r->integer(row, 2), seq = r->integer(row, 3);
    if (!x || !y || !z || !seq || *seq < 0) continue;
    out.push_back(RegionSeq{{static_cast<int>(*x), static_cast<int>(*y), static_cast<int>(*z)},
                            static_cast<std::uint64_t>(*seq)});
  }
  return out;
}

StoreResult<Ok> PostgresStore::advertise(std::uint32_t id, const std::string& address) {
  if (id > kMaxServerId) return StoreError{StoreError::Kind::kQuery, fmt::format("server id {} is not below 2^31", id)};
  auto r = c_->exec("advertise server",
                    "INSERT INTO terrane_servers AS s (id, address, seen_at) VALUES ($1, $2, clock_timestamp())"
                    " ON CONFLICT (id) DO UPDATE SET address = EXCLUDED.address, seen_at = EXCLUDED.seen_at",
                    {text(id), Param{address, false}});
  if (!r) return r.error();
  return Ok{};
}

StoreResult<Ok> PostgresStore::withdraw(std::uint32_t id) {
  auto r = c_->exec("withdraw server", "DELETE FROM terrane_servers WHERE id = $1", {text(id)});
  if (!r) return r.error();
  return Ok{};
}

StoreResult<std::vector<std::uint32_t>> PostgresStore::running(std::chrono::milliseconds fresh) {
  auto r = c_->exec("read running servers",
                    "SELECT id FROM terrane_servers WHERE seen_at > clock_timestamp() - $1::bigint * interval '1 millisecond'",
                    {text(fresh.count())});
  if (!r) return r.error();
  std::vector<std::uint32_t> out;
  for (int row = 0; row < r->count(); ++row)
    if (const auto id = r->integer(row, 0); id && *id >= 0 && *id <= kMaxServerId) out.push_back(static_cast<std::uint32_t>(*id));
  return out;
}

StoreResult<PostgresStore::Cluster> PostgresStore::cluster(std::chrono::milliseconds fresh) {
  Cluster out;
  auto servers = c_->exec("read servers",
                          "SELECT id, address FROM terrane_servers WHERE address <> ''"
                          " AND seen_at > clock_timestamp() - $1::bigint * interval '1 millisecond'",
                          {text(fresh.count())});
  if (!servers) return servers.error();
  for (int row = 0; row < servers->count(); ++row) {
    const auto id = servers->integer(row, 0);
    // Another server's row: an address that does not parse is skipped (no
    // client is sent there), never trusted.
    auto a = parse_server_address(servers->get(row, 1), nullptr);
    if (!id || *id < 0 || *id > kMaxServerId || !a) continue;
    a->id = static_cast<std::uint32_t>(*id);
    out.servers.push_back(std::move(*a));
  }
  auto leases = c_->exec("read leases",
                         "SELECT rx, ry, rz, owner, epoch FROM terrane_leases WHERE expires_at > clock_timestamp()");
  if (!leases) return leases.error();
  for (int row = 0; row < leases->count(); ++row) {
    const auto x = leases->integer(row, 0), y = leases->integer(row, 1), z = leases->integer(row, 2),
               owner = leases->integer(row, 3), epoch = leases->integer(row, 4);
    if (!x || !y || !z || !owner || *owner < 0 || *owner > kMaxServerId || !epoch || *epoch < 1) continue;
    out.writers.push_back(RegionWriter{{static_cast<int>(*x), static_cast<int>(*y), static_cast<int>(*z)},
                                       static_cast<std::uint32_t>(*owner), static_cast<std::uint64_t>(*epoch)});
  }
  return out;
}

// The upsert's rule for keeping a chunk's blob (STORE_POSTGRESQL.md,
// "Chunks and their units"): c the stored row, $7 the most rows of units
// behind a blob (0: write the blob).
#define KEEP_UNITS \
  "(c.revision + 1 = EXCLUDED.revision AND EXCLUDED.revision - COALESCE(c.blob_revision, c.revision) <= $7)"

StoreResult<Ok> PostgresStore::save_fenced(std::span<const RegionLease> leases, std::span<const ChunkWrite> chunks,
                                           std::span<const EditLogEntry> log, bool overwrite,
                                           std::span<const ForwardAnswer> answers) {
  // The leases the chunks need, in one order for every server (lease rows
  // are locked in that order, so two writers never deadlock).
  std::map<std::tuple<int, int, int>, RegionLease> used;
  for (const ChunkWrite& w : chunks) {
    const Vec3i region = lease_region_of(w.pos);
    auto it = std::find_if(leases.begin(), leases.end(), [&](const RegionLease& l) { return l.region == region; });
    if (it == leases.end())
      return StoreError{StoreError::Kind::kFenced, fmt::format("chunk {} lies in region {}, under none of the leases given",
                                                               region_text(w.pos), region_text(region))};
    used.emplace(std::make_tuple(region.y, region.z, region.x), *it);
  }
  auto begin = c_->exec("begin", "BEGIN");
  if (!begin) return begin.error();
  // Checking a lease locks its row (as a takeover's update would) and
  // moves the region's write sequence on.
  std::vector<RegionSeq> seqs;
  for (const auto& [key, l] : used) {
    auto r = c_->exec("check lease",
                      "UPDATE terrane_leases SET seq = seq + 1 WHERE rx = $1 AND ry = $2 AND rz = $3 AND owner = $4"
                      " AND epoch = $5 AND expires_at > clock_timestamp() RETURNING seq",
                      {text(l.region.x), text(l.region.y), text(l.region.z), text(l.owner),
                       text(static_cast<std::int64_t>(l.epoch))});
    if (!r) return c_->abort(r.error());
    if (r->count() == 1)
      if (const auto seq = r->integer(0, 0); seq && *seq > 0)
        seqs.push_back(RegionSeq{l.region, static_cast<std::uint64_t>(*seq)});
    if (r->count() == 0)
      return c_->abort(StoreError{StoreError::Kind::kFenced,
                                  fmt::format("region {}: the lease of server {} at epoch {} is no longer current; "
                                              "nothing was written",
                                              region_text(l.region), l.owner, l.epoch)});
  }
  for (const ChunkWrite& w : chunks) {
    CoarseVoxels coarse{};
    if (w.coarse) {
      coarse = *w.coarse;
    } else {
      auto decoded = decode_chunk_blob(w.blob);
      if (!decoded)
        return c_->abort(StoreError{StoreError::Kind::kDecode, fmt::format("chunk {}: the blob to write: {}",
                                                                            region_text(w.pos),
                                                                            decoded.error().describe())});
      coarse = coarse_voxels(&*decoded);
    }
    std::vector<Param> params{text(w.pos.x), text(w.pos.y), text(w.pos.z), text(static_cast<std::int64_t>(w.revision)),
                              blob(w.blob), blob(coarse_bytes(coarse))};
    if (!overwrite) {
      auto r = c_->exec("write chunk",
                        "INSERT INTO terrane_chunks (x, y, z, revision, blob, coarse)"
                        " VALUES ($1, $2, $3, $4, $5, $6) ON CONFLICT (x, y, z) DO NOTHING",
                        params);
      if (!r) return c_->abort(r.error());
      continue;
    }
    // Units that take the stored revision to this one are kept in place of
    // the blob while the chunk has fewer than kMaxKeptUnits rows of them
    // (revision - blob_revision), decided against the stored row.
    // (Revisions a batch of ticks coalesced skip one: the blob is written.)
    // One statement, one round trip: the row, then its row of units if the
    // blob was kept, else the chunk's rows of units deleted.
    const bool may_keep = !w.units.empty() && w.units.size() <= kMaxKeptUnitsBytes;
    params.push_back(text(may_keep ? kMaxKeptUnits : std::int64_t{0}));
    params.push_back(blob(w.units));
    auto r = c_->exec("write chunk",
                      "WITH up AS (INSERT INTO terrane_chunks AS c (x, y, z, revision, blob, coarse)"
                      "  VALUES ($1, $2, $3, $4, $5, $6) ON CONFLICT (x, y, z) DO UPDATE SET"
                      "  revision = EXCLUDED.revision, coarse = EXCLUDED.coarse,"
                      "  blob_revision = CASE WHEN " KEEP_UNITS " THEN COALESCE(c.blob_revision, c.revision) END,"
                      "  blob = CASE WHEN " KEEP_UNITS " THEN c.blob ELSE EXCLUDED.blob END"
                      "  RETURNING blob_revision),"
                      " kept AS (INSERT INTO terrane_chunk_units (x, y, z, revision, units)"
                      "  SELECT $1::integer, $2::integer, $3::integer, $4::bigint, $8::bytea FROM up"
                      "  WHERE blob_revision IS NOT NULL"
                      "  ON CONFLICT (x, y, z, revision) DO UPDATE SET units = EXCLUDED.units)"
                      " DELETE FROM terrane_chunk_units WHERE x = $1 AND y = $2 AND z = $3"
                      "  AND NOT EXISTS (SELECT 1 FROM up WHERE blob_revision IS NOT NULL)",
                      params);
    if (!r) return c_->abort(r.error());
  }
#undef KEEP_UNITS
  for (const EditLogEntry& e : log) {
    auto r = c_->exec("write edit log",
                      "INSERT INTO terrane_edit_log (tick, time_ms, player, x0, y0, z0, x1, y1, z1, before, after)"
                      " VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11)",
                      {text(static_cast<std::int64_t>(e.tick)), text(e.time_ms), Param{e.player, false},
                       text(e.box.min.x), text(e.box.min.y), text(e.box.min.z), text(e.box.max.x), text(e.box.max.y),
                       text(e.box.max.z), blob(e.before), blob(e.after)});
    if (!r) return c_->abort(r.error());
  }
  // The news for the other servers, delivered by PostgreSQL at the commit
  // and only if it commits: each chunk written with its revision.
  for (const std::string& payload : change_notices(chunks, seqs)) {
    auto r = c_->exec("notify changes", "SELECT pg_notify($1, $2)", {Param{kChangesChannel, false}, Param{payload, false}});
    if (!r) return c_->abort(r.error());
  }
  // After the changes: the sender reads its edit's chunks again before it
  // acknowledges.
  if (auto a = answer_in_transaction(answers); !a) return c_->abort(a.error());
  auto commit = c_->exec("commit chunks", "COMMIT");
  if (!commit) return c_->abort(commit.error());
  return Ok{};
}


namespace {

// Binary columns, each checked for its length: the database's answer is
// read like any input.
std::optional<std::int32_t> be32_at(PGresult* res, int row, int col) {
  if (PQgetisnull(res, row, col) || PQgetlength(res, row, col) != 4) return std::nullopt;
  const char* p = PQgetvalue(res, row, col);
  std::uint32_t v = 0;
  for (int i = 0; i < 4; ++i) v = (v << 8) | static_cast<unsigned char>(p[i]);
  return static_cast<std::int32_t>(v);
}
std::optional<std::int64_t> be64_at(PGresult* res, int row, int col) {
  if (PQgetisnull(res, row, col) || PQgetlength(res, row, col) != 8) return std::nullopt;
  return static_cast<std::int64_t>(be64(PQgetvalue(res, row, col)));
}
std::span<const std::uint8_t> bytes_at(PGresult* res, int row, int col) {
  return {reinterpret_cast<const std::uint8_t*>(PQgetvalue(res, row, col)),
          static_cast<std::size_t>(PQgetlength(res, row, col))};
}

// The chunk position in a row's first three columns (x, y, z integers).
std::optional<Vec3i> position_at(PGresult* res, int row) {
  const auto x = be32_at(res, row, 0), y = be32_at(res, row, 1), z = be32_at(res, row, 2);
  if (!x || !y || !z) return std::nullopt;
  return Vec3i{*x, *y, *z};
}

FileError decode_failure(Vec3i pos, const DecodeError& e) {
  return FileError{fmt::format("postgresql: chunk {}: {}", region_text(pos), e.describe()), e};
}

Result<CoarseVoxels> coarse_from_bytes(std::span<const std::uint8_t> b) {
  CoarseVoxels v{};
  if (b.size() != v.size() * 2) return DecodeError{DecodeErrorCode::kTruncated, b.size(), "coarse mip length"};
  for (std::size_t i = 0; i < v.size(); ++i) {
    const Voxel x{b[2 * i], b[2 * i + 1]};
    if (x.material >= kMaterialCount) return DecodeError{DecodeErrorCode::kInvalidValue, 2 * i, "coarse mip material"};
    if (x.material == kAir && x.occupancy != 0)
      return DecodeError{DecodeErrorCode::kInvalidValue, 2 * i + 1, "coarse mip Air with occupancy"};
    v[i] = x;
  }
  return v;
}

// Brings chunk from revision `from` (its blob's) to `to` with the units in
// rows [first, end) of res (revision in column rev_col, units in units_col),
// which must be revisions from + 1 ... to, in order.
FileStatus replay_units(Vec3i pos, Chunk& chunk, std::uint64_t from, std::uint64_t to, PGresult* res, int first,
                        int rev_col, int units_col) {
  std::vector<UnitUpdate> scratch;
  std::uint64_t at = from;
  for (int i = first; i < PQntuples(res); ++i) {
    const auto rev = be64_at(res, i, rev_col);
    if (!rev || *rev < 0 || static_cast<std::uint64_t>(*rev) != at + 1 || at + 1 > to) break;
    auto applied = apply_chunk_update_batch(bytes_at(res, i, units_col), pos, chunk, scratch);
    if (!applied)
      return FileError{fmt::format("postgresql: chunk {}: its units of revision {}: {}", region_text(pos), at + 1,
                                   applied.error().describe()),
                       applied.error()};
    ++at;
  }
  if (at != to)
    return FileError{fmt::format("postgresql: chunk {}: its blob is of revision {}, and its units of revision {} "
                                 "(of {} to {}) are missing",
                                 region_text(pos), from, at + 1, from + 1, to),
                     DecodeError{DecodeErrorCode::kTruncated, 0, "a chunk's units missing"}};
  return Ok{};
}

// The parameters of a region's chunk range: x0, x1, y0, y1, z0, z1.
std::vector<Param> region_range(Vec3i region) {
  const Vec3i lo = region * kCoarseRegionChunks, hi = lo + Vec3i{kCoarseRegionChunks - 1, kCoarseRegionChunks - 1,
                                                                  kCoarseRegionChunks - 1};
  return {text(lo.x), text(hi.x), text(lo.y), text(hi.y), text(lo.z), text(hi.z)};
}

}  // namespace

StoreResult<Ok> PostgresStore::set_name(const std::string& application_name) {
  auto r = c_->exec("name connection", "SELECT set_config('application_name', $1, false)",
                    {Param{application_name, false}});
  if (!r) return r.error();
  return Ok{};
}

StoreResult<Ok> PostgresStore::listen() {
  for (const char* sql : {"LISTEN terrane_changes", "LISTEN terrane_inbox", "LISTEN terrane_answers"}) {
    auto r = c_->exec("listen for notices", sql);
    if (!r) return r.error();
  }
  return Ok{};
}

StoreResult<std::vector<PostgresStore::Notice>> PostgresStore::wait_notices(std::chrono::milliseconds timeout) {
  std::vector<Notice> out;
  const auto take = [&] {
    while (PGnotify* n = PQnotifies(c_->conn)) {
      out.push_back(Notice{n->relname, n->extra});
      PQfreemem(n);
    }
  };
  take();
  if (!out.empty()) return out;
  const int fd = PQsocket(c_->conn);
  if (fd < 0 || PQstatus(c_->conn) != CONNECTION_OK)
    return StoreError{StoreError::Kind::kConnection, "postgresql: listen for changes: the connection is gone"};
  pollfd p{fd, POLLIN, 0};
  const int ready = ::poll(&p, 1, static_cast<int>(timeout.count()));
  if (ready < 0 && errno != EINTR)
    return StoreError{StoreError::Kind::kConnection, "postgresql: listen for changes: poll failed"};
  if (ready > 0 && PQconsumeInput(c_->conn) == 0) return c_->error("listen for changes", nullptr);
  take();
  return out;
}

StoreResult<Ok> PostgresStore::answer_in_transaction(std::span<const ForwardAnswer> answers) {
  for (const ForwardAnswer& a : answers) {
    // Answered: the row goes. The answer travels in the notice, and stays
    // in terrane_answers until its sender has it (a sender whose listener
    // was reconnecting when the notice went out reads it there).
    auto r = c_->exec("answer forwarded edit", "DELETE FROM terrane_inbox WHERE id = $1", {text(a.id)});
    if (!r) return r.error();
    auto kept = c_->exec("keep answer",
                         "INSERT INTO terrane_answers (id, from_server, accepted, tick, reason, answered_at)"
                         " VALUES ($1, $2, $3, $4, $5, clock_timestamp()) ON CONFLICT (id) DO NOTHING",
                         {text(a.id), text(a.from), Param{a.accepted ? "true" : "false", false},
                          text(static_cast<std::int64_t>(a.tick)), Param{a.reason.substr(0, 256), false}});
    if (!kept) return kept.error();
    auto n = c_->exec("notify answer", "SELECT pg_notify($1, $2)",
                      {Param{kAnswersChannel, false}, Param{answer_notice(a), false}});
    if (!n) return n.error();
  }
  return Ok{};
}

template <class T>
StoreResult<T> PostgresStore::transaction(const char* what, const std::function<StoreResult<T>()>& body) {
  auto begin = c_->exec("begin", "BEGIN");
  if (!begin) return begin.error();
  auto out = body();
  if (!out) return c_->abort(out.error());
  auto commit = c_->exec(what, "COMMIT");
  if (!commit) return c_->abort(commit.error());
  return out;
}

StoreResult<std::vector<ForwardAnswer>> PostgresStore::take_answers(std::uint32_t from) {
  auto r = c_->exec("take answers",
                    "DELETE FROM terrane_answers WHERE from_server = $1 RETURNING id, accepted, tick, reason",
                    {text(from)});
  if (!r) return r.error();
  std::vector<ForwardAnswer> out;
  for (int row = 0; row < r->count(); ++row) {
    const auto id = r->integer(row, 0), tick = r->integer(row, 2);
    if (!id || *id < 1 || !tick || *tick < 0) continue;  // not a row this build wrote: left out
    out.push_back(
        ForwardAnswer{*id, from, r->get(row, 1) == "t", static_cast<std::uint64_t>(*tick), r->get(row, 3).substr(0, 256)});
  }
  return out;
}

StoreResult<Ok> PostgresStore::forget_answers(std::span<const std::int64_t> ids) {
  // Rows nobody took (a sender that stopped) go after ten minutes.
  auto r = c_->exec("forget answers",
                    "DELETE FROM terrane_answers WHERE id = ANY($1::bigint[])"
                    " OR answered_at < clock_timestamp() - interval '10 minutes'",
                    {Param{fmt::format("{{{}}}", fmt::join(ids, ",")), false}});
  if (!r) return r.error();
  return Ok{};
}

StoreResult<Ok> PostgresStore::answer(std::span<const ForwardAnswer> answers) {
  return transaction<Ok>("commit answers", [&] { return answer_in_transaction(answers); });
}

StoreResult<std::int64_t> PostgresStore::forward(std::uint32_t from, std::uint32_t to, const std::string& player,
                                                 std::span<const std::uint8_t> edit) {
  return transaction<std::int64_t>("commit forward", [&]() -> StoreResult<std::int64_t> {
    auto row = c_->exec("forward edit",
                        "INSERT INTO terrane_inbox (to_server, from_server, player, edit, created_at)"
                        " VALUES ($1, $2, $3, $4, clock_timestamp()) RETURNING id",
                        {text(to), text(from), Param{player, false}, blob(edit)});
    if (!row) return row.error();
    const auto id = row->count() == 1 ? row->integer(0, 0) : std::nullopt;
    if (!id) return StoreError{StoreError::Kind::kDecode, "postgresql: forward edit: no row id"};
    auto n = c_->exec("notify inbox", "SELECT pg_notify($1, $2)",
                      {Param{kInboxChannel, false}, Param{std::to_string(to), false}});
    if (!n) return n.error();
    return *id;
  });
}

StoreResult<Ok> PostgresStore::relay(std::int64_t id, std::uint32_t from, std::uint32_t to) {
  return transaction<Ok>("commit relay", [&]() -> StoreResult<Ok> {
    auto row = c_->exec("relay edit", "UPDATE terrane_inbox SET to_server = $3 WHERE id = $1 AND to_server = $2 RETURNING id",
                        {text(id), text(from), text(to)});
    if (!row) return row.error();
    if (row->count() != 1)
      return StoreError{StoreError::Kind::kFenced,
                        fmt::format("postgresql: relay edit: inbox row {} is no longer server {}'s", id, from)};
    auto n = c_->exec("notify inbox", "SELECT pg_notify($1, $2)",
                      {Param{kInboxChannel, false}, Param{std::to_string(to), false}});
    if (!n) return n.error();
    return Ok{};
  });
}

StoreResult<std::vector<InboxEdit>> PostgresStore::inbox(std::uint32_t to, std::int64_t after, std::size_t limit) {
  auto r = c_->exec("read inbox",
                    // A row's player and edit are read only up to what a
                    // client may send (longer: empty, so refused).
                    "SELECT id, from_server,"
                    " CASE WHEN octet_length(player) <= $4 THEN player ELSE '' END,"
                    " CASE WHEN octet_length(edit) <= $5 THEN edit ELSE ''::bytea END,"
                    " (extract(epoch from clock_timestamp() - created_at) * 1000)::bigint FROM terrane_inbox"
                    " WHERE to_server = $1 AND id > $2 ORDER BY id LIMIT $3",
                    {text(to), text(after), text(static_cast<std::int64_t>(limit)),
                     text(static_cast<std::int64_t>(kMaxClientNameBytes)),
                     text(static_cast<std::int64_t>(kDefaultMaxFrameBytes + kFrameHeaderBytes))},
                    /*binary_result=*/true);
  if (!r) return r.error();
  std::vector<InboxEdit> out;
  for (int i = 0; i < r->count(); ++i) {
    const auto id = be64_at(r->res, i, 0);
    const auto from = be32_at(r->res, i, 1);
    if (!id || !from || *from < 0)
      return StoreError{StoreError::Kind::kDecode, "postgresql: read inbox: a row does not read"};
    InboxEdit e;
    e.id = *id;
    e.from = static_cast<std::uint32_t>(*from);
    const auto name = bytes_at(r->res, i, 2), edit = bytes_at(r->res, i, 3);
    e.age_ms = std::max<std::int64_t>(0, be64_at(r->res, i, 4).value_or(0));
    e.player.assign(name.begin(), name.end());
    e.edit.assign(edit.begin(), edit.end());
    out.push_back(std::move(e));
  }
  return out;
}

StoreResult<Ok> PostgresStore::read_meta() {
  auto r = c_->exec("read world metadata", "SELECT key, value FROM terrane_meta");
  if (!r) return r.error();
  if (r->count() == 0) {
    has_world_ = false;
    return Ok{};
  }
  std::vector<std::pair<std::string, std::string>> keys;
  for (int i = 0; i < r->count(); ++i) keys.emplace_back(r->get(i, 0), r->get(i, 1));
  auto m = meta_from_keys(keys, "world " + shown_);
  if (!m) return StoreError{StoreError::Kind::kDecode, m.error().message};
  meta_ = std::move(*m);
  has_world_ = true;
  return Ok{};
}

StoreResult<Ok> PostgresStore::create_world(const WorldMeta& meta) {
  if (auto why = meta.bounds.validate(); !why.empty())
    return StoreError{StoreError::Kind::kQuery, fmt::format("world {}: {}", shown_, why)};
  auto begin = c_->exec("begin", "BEGIN");
  if (!begin) return begin.error();
  // The schema lock again: two servers making the world at once agree on
  // one metadata (the first's).
  auto lock = c_->exec("lock schema", "SELECT pg_advisory_xact_lock($1)", {text(kSchemaLockKey)});
  if (!lock) return c_->abort(lock.error());
  auto any = c_->exec("read world metadata", "SELECT 1 FROM terrane_meta LIMIT 1");
  if (!any) return c_->abort(any.error());
  if (any->count() == 0) {
    for (const auto& [k, v] : meta_to_keys(meta)) {
      auto put = c_->exec("write world metadata", "INSERT INTO terrane_meta (key, value) VALUES ($1, $2)",
                          {Param{k, false}, Param{v, false}});
      if (!put) return c_->abort(put.error());
    }
  }
  auto commit = c_->exec("commit world metadata", "COMMIT");
  if (!commit) return c_->abort(commit.error());
  return read_meta();
}

FileStatus PostgresStore::put_meta(const std::vector<std::pair<std::string, std::string>>& keys) {
  auto done = transaction<Ok>("commit world metadata", [&]() -> StoreResult<Ok> {
    for (const auto& [k, v] : keys) {
      auto put = c_->exec("write world metadata",
                          "INSERT INTO terrane_meta (key, value) VALUES ($1, $2)"
                          " ON CONFLICT (key) DO UPDATE SET value = EXCLUDED.value",
                          {Param{k, false}, Param{v, false}});
      if (!put) return put.error();
    }
    return Ok{};
  });
  if (!done) return file_error(done.error());
  return Ok{};
}

FileResult<std::unique_ptr<WorldStore>> PostgresStore::reopen() const {
  auto again = open(url_);
  if (!again) return file_error(again.error());
  (*again)->set_lease_source(leases_, retry_for_);
  return std::unique_ptr<WorldStore>(std::move(*again));
}

FileStatus PostgresStore::set_epoch(std::uint64_t epoch) {
  // One statement, above whatever is stored: servers starting at once each
  // get an epoch of their own (a client's resume token names one).
  auto r = c_->exec("write world epoch",
                    "UPDATE terrane_meta SET value = (GREATEST(value::bigint + 1, $1::bigint))::text"
                    " WHERE key = 'epoch' RETURNING value",
                    {text(static_cast<std::int64_t>(std::min<std::uint64_t>(
                        epoch, static_cast<std::uint64_t>(std::numeric_limits<std::int64_t>::max()))))});
  if (!r) return file_error(r.error());
  const auto got = r->count() == 1 ? r->integer(0, 0) : std::nullopt;
  if (!got || *got < 0) return FileError{"world " + shown_ + ": metadata key epoch missing or malformed", {}};
  meta_.epoch = static_cast<std::uint64_t>(*got);
  return Ok{};
}

FileStatus PostgresStore::set_bounds(const WorldBounds& bounds) {
  if (auto why = bounds.validate(); !why.empty()) return FileError{"world " + shown_ + ": " + why, {}};
  WorldMeta m = meta_;
  m.bounds = bounds;
  // Only the bounds' keys: another server's epoch is left as it is.
  std::vector<std::pair<std::string, std::string>> keys;
  for (auto& kv : meta_to_keys(m))
    if (kv.first == "bounds_y" || kv.first == "bounds_xz") keys.push_back(std::move(kv));
  if (auto st = put_meta(keys); !st) return st;
  meta_.bounds = bounds;
  return Ok{};
}

FileResult<std::optional<StoredChunk>> PostgresStore::load_chunk(Vec3i pos) {
  // One statement, so one snapshot: the row (revision, the blob's revision,
  // blob), then the units kept after the blob, by revision.
  auto r = c_->exec("read chunk",
                    "SELECT revision, COALESCE(blob_revision, revision), blob FROM terrane_chunks"
                    "  WHERE x = $1 AND y = $2 AND z = $3"
                    " UNION ALL"
                    " SELECT u.revision, -1, u.units FROM terrane_chunk_units u JOIN terrane_chunks c USING (x, y, z)"
                    "  WHERE u.x = $1 AND u.y = $2 AND u.z = $3 AND u.revision > c.blob_revision"
                    "  AND u.revision <= c.revision"
                    " ORDER BY 2 DESC, 1",
                    {text(pos.x), text(pos.y), text(pos.z)}, /*binary_result=*/true);
  if (!r) return file_error(r.error());
  if (r->count() == 0) return std::optional<StoredChunk>{};
  const auto revision = be64_at(r->res, 0, 0);
  const auto blob_revision = be64_at(r->res, 0, 1);
  if (!revision || *revision < 0 || !blob_revision || *blob_revision < 0 || *blob_revision > *revision)
    return decode_failure(pos, DecodeError{DecodeErrorCode::kInvalidValue, 0, "chunk revision"});
  auto chunk = decode_chunk_blob(bytes_at(r->res, 0, 2));
  if (!chunk) return decode_failure(pos, chunk.error());
  if (*blob_revision < *revision) {
    auto replayed = replay_units(pos, *chunk, static_cast<std::uint64_t>(*blob_revision),
                                 static_cast<std::uint64_t>(*revision), r->res, 1, 0, 2);
    if (!replayed) return replayed.error();
    chunk->compact();  // packed, as a decoded blob is
  }
  return std::optional<StoredChunk>{StoredChunk{static_cast<std::uint64_t>(*revision), std::move(*chunk)}};
}

FileResult<std::vector<CoarseEntry>> PostgresStore::load_coarse(Vec3i region) {
  auto r = c_->exec("read coarse mips",
                    "SELECT x, y, z, revision, coarse FROM terrane_chunks"
                    " WHERE x BETWEEN $1 AND $2 AND y BETWEEN $3 AND $4 AND z BETWEEN $5 AND $6",
                    region_range(region), /*binary_result=*/true);
  if (!r) return file_error(r.error());
  std::vector<CoarseEntry> out;
  out.reserve(static_cast<std::size_t>(r->count()));
  for (int i = 0; i < r->count(); ++i) {
    const auto pos = position_at(r->res, i);
    const auto revision = be64_at(r->res, i, 3);
    if (!pos) return FileError{fmt::format("postgresql: region {}: a chunk row's position does not read",
                                           region_text(region)), std::nullopt};
    if (!revision || *revision < 0)
      return decode_failure(*pos, DecodeError{DecodeErrorCode::kInvalidValue, 0, "chunk revision"});
    auto voxels = coarse_from_bytes(bytes_at(r->res, i, 4));
    if (!voxels) return decode_failure(*pos, voxels.error());
    out.push_back(CoarseEntry{*pos, static_cast<std::uint64_t>(*revision), *voxels});
  }
  return out;
}

namespace {
template <class Rows>
FileResult<std::vector<Vec3i>> positions(Rows& r, Vec3i region) {
  if (!r) return file_error(r.error());
  std::vector<Vec3i> out;
  for (int i = 0; i < r->count(); ++i) {
    const auto pos = position_at(r->res, i);
    if (!pos) return FileError{fmt::format("postgresql: region {}: a row's position does not read",
                                           region_text(region)), std::nullopt};
    out.push_back(*pos);
  }
  return out;
}
}  // namespace

StoreResult<std::vector<std::pair<Vec3i, std::uint64_t>>> PostgresStore::stored_revisions(Vec3i region) {
  auto r = c_->exec("read revisions",
                    "SELECT x, y, z, revision FROM terrane_chunks"
                    " WHERE x BETWEEN $1 AND $2 AND y BETWEEN $3 AND $4 AND z BETWEEN $5 AND $6",
                    region_range(region), /*binary_result=*/true);
  if (!r) return r.error();
  std::vector<std::pair<Vec3i, std::uint64_t>> out;
  for (int i = 0; i < r->count(); ++i) {
    const auto pos = position_at(r->res, i);
    const auto revision = be64_at(r->res, i, 3);
    if (!pos || !revision || *revision < 0)
      return StoreError{StoreError::Kind::kDecode, "postgresql: read revisions: a row does not read"};
    out.emplace_back(*pos, static_cast<std::uint64_t>(*revision));
  }
  return out;
}

FileResult<std::vector<Vec3i>> PostgresStore::quarantined_in(Vec3i region) {
  auto r = c_->exec("read quarantine",
                    "SELECT DISTINCT x, y, z FROM terrane_quarantine"
                    " WHERE x BETWEEN $1 AND $2 AND y BETWEEN $3 AND $4 AND z BETWEEN $5 AND $6",
                    region_range(region), /*binary_result=*/true);
  return positions(r, region);
}

FileResult<std::vector<Vec3i>> PostgresStore::stored_in(Vec3i region) {
  auto r = c_->exec("read chunk positions",
                    "SELECT x, y, z FROM terrane_chunks"
                    " WHERE x BETWEEN $1 AND $2 AND y BETWEEN $3 AND $4 AND z BETWEEN $5 AND $6",
                    region_range(region), /*binary_result=*/true);
  return positions(r, region);
}

FileStatus PostgresStore::begin_read() {
  auto r = c_->exec("begin read", "BEGIN ISOLATION LEVEL REPEATABLE READ READ ONLY");
  if (!r) return file_error(r.error());
  return Ok{};
}

void PostgresStore::end_read() { (void)c_->exec("end read", "COMMIT"); }

FileStatus PostgresStore::save_chunks(std::span<const ChunkWrite> writes, bool overwrite,
                                      std::span<const EditLogEntry> log) {
  return save(writes, overwrite, log, {});
}

FileStatus PostgresStore::save_answering(std::span<const ChunkWrite> writes, std::span<const EditLogEntry> log,
                                         std::span<const ForwardAnswer> answers) {
  return save(writes, true, log, answers);
}

FileStatus PostgresStore::save(std::span<const ChunkWrite> writes, bool overwrite, std::span<const EditLogEntry> log,
                               std::span<const ForwardAnswer> answers) {
  if (!leases_)
    return FileError{fmt::format("world {}: this connection holds no leases, and writes to a PostgreSQL world "
                                 "are fenced by them (give the server or tool a --server-id)",
                                 shown_),
                     std::nullopt};
  std::vector<Vec3i> regions;
  for (const ChunkWrite& w : writes) {
    const Vec3i r = lease_region_of(w.pos);
    if (std::find(regions.begin(), regions.end(), r) == regions.end()) regions.push_back(r);
  }
  // A database that went away (restarted, say) is waited for, up to
  // retry_for: the write is tried again on a new connection. Nothing is
  // acknowledged meanwhile, and once the leases have run out the write is
  // fenced anyway. (A commit whose answer was lost may be stored twice: the
  // chunk rows are the same, its edit log entries appear twice.) A commit
  // PostgreSQL rolled back to break a deadlock is tried again at once, a
  // few times: nothing of it was stored.
  const auto give_up = std::chrono::steady_clock::now() + retry_for_;
  int conflicts = 0;
  for (int attempt = 0;; ++attempt) {
    auto leases = (*leases_)(regions);
    StoreResult<Ok> saved =
        leases ? save_fenced(*leases, writes, log, overwrite, answers) : StoreResult<Ok>(leases.error());
    if (saved) {
      if (attempt > 0)
        server_log().info("world {}: stored after {} tries{}", shown_, attempt + 1,
                          conflicts == attempt ? "" : ": the database is back");
      return Ok{};
    }
    const StoreError::Kind kind = saved.error().kind;
    if (kind == StoreError::Kind::kConflict && ++conflicts <= kConflictRetries) {
      server_log().warn("world {}: {}; trying again", shown_, saved.error().message);
      continue;
    }
    if (kind != StoreError::Kind::kConnection || std::chrono::steady_clock::now() >= give_up)
      return file_error(saved.error());
    if (attempt == conflicts) server_log().warn("world {}: {}; trying again", shown_, saved.error().message);
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
  }
}

FileResult<std::vector<EditLogEntry>> PostgresStore::edit_log(const EditLogQuery& q) {
  std::string sql = std::string("SELECT id, tick, time_ms, player, x0, y0, z0, x1, y1, z1") +
                    (q.with_voxels ? ", before, after" : "") + " FROM terrane_edit_log WHERE time_ms >= $1";
  std::vector<Param> params{text(q.since_ms)};
  if (!q.player.empty()) {
    params.push_back(Param{q.player, false});
    sql += fmt::format(" AND player = ${}", params.size());
  }
  if (q.box) {
    const Region& b = *q.box;
    const std::size_t n = params.size();
    for (const int v : {b.max.x, b.min.x, b.max.y, b.min.y, b.max.z, b.min.z}) params.push_back(text(v));
    sql += fmt::format(" AND x0 < ${} AND x1 > ${} AND y0 < ${} AND y1 > ${} AND z0 < ${} AND z1 > ${}", n + 1, n + 2,
                       n + 3, n + 4, n + 5, n + 6);
  }
  params.push_back(text(static_cast<std::int64_t>(std::min<std::size_t>(q.limit, 1u << 30))));
  sql += fmt::format(" ORDER BY id DESC LIMIT ${}", params.size());
  auto r = c_->exec("read edit log", sql.c_str(), params, /*binary_result=*/true);
  if (!r) return file_error(r.error());
  std::vector<EditLogEntry> out;
  for (int i = 0; i < r->count(); ++i) {
    EditLogEntry e;
    const auto id = be64_at(r->res, i, 0), tick = be64_at(r->res, i, 1), time = be64_at(r->res, i, 2);
    std::optional<std::int32_t> c[6];
    for (int k = 0; k < 6; ++k) c[k] = be32_at(r->res, i, 4 + k);
    if (!id || !tick || *tick < 0 || !time || std::any_of(c, c + 6, [](const auto& v) { return !v; }))
      return FileError{"postgresql: read edit log: a row does not read", std::nullopt};
    e.id = *id;
    e.tick = static_cast<std::uint64_t>(*tick);
    e.time_ms = *time;
    const auto name = bytes_at(r->res, i, 3);
    e.player.assign(name.begin(), name.end());
    e.box = {{*c[0], *c[1], *c[2]}, {*c[3], *c[4], *c[5]}};
    if (q.with_voxels) {
      const auto before = bytes_at(r->res, i, 10), after = bytes_at(r->res, i, 11);
      e.before.assign(before.begin(), before.end());
      e.after.assign(after.begin(), after.end());
    }
    out.push_back(std::move(e));
  }
  return out;
}

FileResult<std::int64_t> PostgresStore::prune_edit_log(std::int64_t before_ms, std::uint64_t max_bytes,
                                                       std::int64_t max_rows) {
  // The oldest first: those older than before_ms, then those beyond the
  // newest max_bytes of voxels; at most max_rows.
  auto r = c_->exec(
      "prune edit log",
      "DELETE FROM terrane_edit_log WHERE id IN (SELECT id FROM ("
      "  SELECT id, time_ms, sum(octet_length(before) + octet_length(after)) OVER (ORDER BY id DESC) AS newer"
      "  FROM terrane_edit_log) t"
      " WHERE time_ms < $1 OR ($2::bigint > 0 AND newer > $2::bigint) ORDER BY id LIMIT $3)",
      {text(before_ms), text(static_cast<std::int64_t>(std::min<std::uint64_t>(max_bytes, std::numeric_limits<std::int64_t>::max()))),
       text(max_rows)});
  if (!r) return file_error(r.error());
  std::int64_t n = 0;
  const char* tuples = PQcmdTuples(r->res);
  std::from_chars(tuples, tuples + std::strlen(tuples), n);
  return n;
}

FileResult<std::optional<std::uint64_t>> PostgresStore::quarantine_chunk(Vec3i pos, const std::string& reason) {
  auto begin = c_->exec("begin", "BEGIN");
  if (!begin) return file_error(begin.error());
  // Copied inside the database: the blob moves byte for byte, however
  // damaged it is, under the row's revision (the highest moved: a chunk
  // served in its place comes above it); a blob older than that says so.
  auto moved = c_->exec("quarantine chunk",
                        "WITH gone AS (DELETE FROM terrane_chunks WHERE x = $1 AND y = $2 AND z = $3"
                        "  RETURNING x, y, z, revision, blob_revision, blob)"
                        " INSERT INTO terrane_quarantine (x, y, z, revision, blob, reason, time_s)"
                        " SELECT x, y, z, revision, blob,"
                        "  CASE WHEN blob_revision IS NULL THEN $4"
                        "  ELSE $4 || ' (the blob is of revision ' || blob_revision || ', its units after it beside it)'"
                        "  END, extract(epoch from clock_timestamp())::bigint FROM gone"
                        " RETURNING revision",
                        {text(pos.x), text(pos.y), text(pos.z), Param{reason, false}});
  if (!moved) return file_error(c_->abort(moved.error()));
  // The units kept after the blob go with it, each a row of its revision.
  auto units = c_->exec("quarantine chunk units",
                        "WITH gone AS (DELETE FROM terrane_chunk_units WHERE x = $1 AND y = $2 AND z = $3"
                        "  RETURNING x, y, z, revision, units)"
                        " INSERT INTO terrane_quarantine (x, y, z, revision, blob, reason, time_s)"
                        " SELECT x, y, z, revision, units, 'the units of revision ' || revision || ' (an update batch)',"
                        "  extract(epoch from clock_timestamp())::bigint FROM gone",
                        {text(pos.x), text(pos.y), text(pos.z)});
  if (!units) return file_error(c_->abort(units.error()));
  std::optional<std::uint64_t> revision;
  if (moved->count() == 1) {
    const auto rev = moved->integer(0, 0);
    if (!rev || *rev < 0) return file_error(c_->abort(StoreError{StoreError::Kind::kDecode, "postgresql: quarantine: revision out of range"}));
    revision = static_cast<std::uint64_t>(*rev);
  }
  auto commit = c_->exec("commit quarantine", "COMMIT");
  if (!commit) return file_error(c_->abort(commit.error()));
  return revision;
}

FileResult<std::optional<std::uint64_t>> PostgresStore::quarantined_revision(Vec3i pos) {
  auto r = c_->exec("read quarantine", "SELECT max(revision) FROM terrane_quarantine WHERE x = $1 AND y = $2 AND z = $3",
                    {text(pos.x), text(pos.y), text(pos.z)});
  if (!r) return file_error(r.error());
  if (r->count() == 0 || PQgetisnull(r->res, 0, 0)) return std::optional<std::uint64_t>{};
  const auto rev = r->integer(0, 0);
  if (!rev || *rev < 0) return decode_failure(pos, DecodeError{DecodeErrorCode::kInvalidValue, 0, "quarantined revision"});
  return std::optional<std::uint64_t>{static_cast<std::uint64_t>(*rev)};
}

FileStatus PostgresStore::for_each_chunk(
    const std::function<void(Vec3i, std::uint64_t, std::span<const std::uint8_t>)>& fn) {
  std::optional<FileError> unreadable;
  auto walked = each_chunk_row(
      [&](Vec3i pos, std::uint64_t revision, FileResult<std::span<const std::uint8_t>> blob,
          const std::optional<CoarseVoxels>&) {
        if (unreadable) return;
        if (!blob) {
          unreadable = blob.error();
          return;
        }
        fn(pos, revision, *blob);
      },
      /*with_coarse=*/false);
  if (!walked) return walked;
  if (unreadable) return *unreadable;
  return Ok{};
}

FileStatus PostgresStore::for_each_chunk_row(const RowFn& fn) { return each_chunk_row(fn, /*with_coarse=*/true); }

FileStatus PostgresStore::each_chunk_row(const RowFn& fn, bool with_coarse) {
  auto begin = c_->exec("begin", "BEGIN ISOLATION LEVEL REPEATABLE READ READ ONLY");
  if (!begin) return file_error(begin.error());
  auto cursor = c_->exec("read chunks",
                         with_coarse ? "DECLARE terrane_each CURSOR FOR SELECT x, y, z, revision, blob,"
                                       " COALESCE(blob_revision, revision), coarse FROM terrane_chunks ORDER BY x, y, z"
                                     : "DECLARE terrane_each CURSOR FOR SELECT x, y, z, revision, blob,"
                                       " COALESCE(blob_revision, revision) FROM terrane_chunks ORDER BY x, y, z");
  if (!cursor) return file_error(c_->abort(cursor.error()));
  for (;;) {
    auto r = c_->exec("read chunks", "FETCH 1000 FROM terrane_each", {}, /*binary_result=*/true);
    if (!r) return file_error(c_->abort(r.error()));
    if (r->count() == 0) break;
    for (int i = 0; i < r->count(); ++i) {
      const auto pos = position_at(r->res, i);
      const auto revision = be64_at(r->res, i, 3);
      if (!pos || !revision || *revision < 0)
        return file_error(c_->abort(StoreError{StoreError::Kind::kDecode, "postgresql: read chunks: a row does not read"}));
      std::optional<CoarseVoxels> coarse;
      if (with_coarse)
        if (auto c = coarse_from_bytes(bytes_at(r->res, i, 6)); c) coarse = *c;
      const auto blob_revision = be64_at(r->res, i, 5);
      if (!blob_revision || *blob_revision < 0 || *blob_revision > *revision)
        return file_error(c_->abort(StoreError{StoreError::Kind::kDecode, "postgresql: read chunks: a row does not read"}));
      if (*blob_revision == *revision) {
        fn(*pos, static_cast<std::uint64_t>(*revision), bytes_at(r->res, i, 4), coarse);
        continue;
      }
      // The blob is older than the chunk: its units after it make the chunk,
      // handed on as a blob of its revision (read in this transaction's
      // snapshot, as the rows are).
      auto chunk = decode_chunk_blob(bytes_at(r->res, i, 4));
      if (!chunk) {  // damaged: handed on as it is, for the caller to find so
        fn(*pos, static_cast<std::uint64_t>(*revision), bytes_at(r->res, i, 4), coarse);
        continue;
      }
      auto units = c_->exec("read chunk units",
                            "SELECT revision, units FROM terrane_chunk_units WHERE x = $1 AND y = $2 AND z = $3"
                            " AND revision > $4 AND revision <= $5 ORDER BY revision",
                            {text(pos->x), text(pos->y), text(pos->z), text(*blob_revision), text(*revision)},
                            /*binary_result=*/true);
      if (!units) return file_error(c_->abort(units.error()));
      if (auto replayed = replay_units(*pos, *chunk, static_cast<std::uint64_t>(*blob_revision),
                                       static_cast<std::uint64_t>(*revision), units->res, 0, 0, 1);
          !replayed) {
        fn(*pos, static_cast<std::uint64_t>(*revision), replayed.error(), coarse);
        continue;
      }
      const auto whole = encode_chunk_blob(*chunk);
      fn(*pos, static_cast<std::uint64_t>(*revision), std::span<const std::uint8_t>(whole), coarse);
    }
  }
  auto commit = c_->exec("end read", "COMMIT");
  if (!commit) return file_error(c_->abort(commit.error()));
  return Ok{};
}

FileStatus PostgresStore::for_each_quarantined(const std::function<void(const QuarantinedChunk&)>& fn) {
  auto r = c_->exec("read quarantine",
                    "SELECT x, y, z, revision, time_s, blob, reason FROM terrane_quarantine ORDER BY x, y, z, revision",
                    {}, /*binary_result=*/true);
  if (!r) return file_error(r.error());
  for (int i = 0; i < r->count(); ++i) {
    const auto pos = position_at(r->res, i);
    const auto revision = be64_at(r->res, i, 3), time = be64_at(r->res, i, 4);
    if (!pos || !revision || *revision < 0 || !time)
      return FileError{"postgresql: read quarantine: a row does not read", std::nullopt};
    QuarantinedChunk q;
    q.pos = *pos;
    q.revision = static_cast<std::uint64_t>(*revision);
    q.time_unix_s = *time;
    const auto b = bytes_at(r->res, i, 5), reason = bytes_at(r->res, i, 6);
    q.blob.assign(b.begin(), b.end());
    q.reason.assign(reason.begin(), reason.end());
    fn(q);
  }
  return Ok{};
}

FileResult<std::int64_t> PostgresStore::stored_chunk_count() {
  auto r = c_->exec("count chunks", "SELECT count(*) FROM terrane_chunks");
  if (!r) return file_error(r.error());
  const auto n = r->integer(0, 0);
  if (!n) return FileError{"postgresql: count chunks: the count does not read", std::nullopt};
  return *n;
}

FileResult<std::vector<std::pair<std::string, std::string>>> PostgresStore::access_entries() {
  auto r = c_->exec("read access lists", "SELECT key, value FROM terrane_access ORDER BY key");
  if (!r) return file_error(r.error());
  std::vector<std::pair<std::string, std::string>> out;
  for (int i = 0; i < r->count(); ++i) out.emplace_back(r->get(i, 0), r->get(i, 1));
  return out;
}

FileStatus PostgresStore::put_access(const std::string& key, const std::string& value) {
  auto r = c_->exec("write access lists",
                    "INSERT INTO terrane_access (key, value) VALUES ($1, $2)"
                    " ON CONFLICT (key) DO UPDATE SET value = EXCLUDED.value",
                    {Param{key, false}, Param{value, false}});
  if (!r) return file_error(r.error());
  return Ok{};
}

FileStatus PostgresStore::erase_access(const std::string& key) {
  auto r = c_->exec("write access lists", "DELETE FROM terrane_access WHERE key = $1", {Param{key, false}});
  if (!r) return file_error(r.error());
  return Ok{};
}

}  // namespace terrane
