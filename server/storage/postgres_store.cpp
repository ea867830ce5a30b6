#include "server/storage/postgres_store.h"

#include <fmt/format.h>
#include <libpq-fe.h>

#include <algorithm>
#include <charconv>
#include <cstring>
#include <limits>
#include <map>
#include <optional>
#include <string_view>
#include <tuple>

#include "common/world/coarse_image.h"

namespace terrane {

namespace {

// Serialises schema creation between servers opening one database at once.
constexpr std::int64_t kSchemaLockKey = 0x7465727261'6e65;  // "terrane"

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

PostgresStore::PostgresStore(std::unique_ptr<Connection> c) : c_(std::move(c)) {}
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
  auto begin = c->exec("begin", "BEGIN");
  if (!begin) return begin.error();
  auto lock = c->exec("lock schema", "SELECT pg_advisory_xact_lock($1)", {text(kSchemaLockKey)});
  if (!lock) return c->abort(lock.error());
  for (const char* table : {
           "CREATE TABLE IF NOT EXISTS terrane_schema (version integer NOT NULL)",
           "CREATE TABLE IF NOT EXISTS terrane_chunks ("
           "  x integer NOT NULL, y integer NOT NULL, z integer NOT NULL,"
           "  revision bigint NOT NULL, blob bytea NOT NULL, PRIMARY KEY (x, y, z))",
           "CREATE TABLE IF NOT EXISTS terrane_leases ("
           "  rx integer NOT NULL, ry integer NOT NULL, rz integer NOT NULL,"
           "  owner integer NOT NULL, epoch bigint NOT NULL, expires_at timestamptz NOT NULL,"
           "  PRIMARY KEY (rx, ry, rz))"}) {
    auto made = c->exec("create schema", table);
    if (!made) return c->abort(made.error());
  }
  auto version = c->exec("read schema version", "SELECT version FROM terrane_schema");
  if (!version) return c->abort(version.error());
  if (version->count() == 0) {
    auto put = c->exec("write schema version", "INSERT INTO terrane_schema (version) VALUES ($1)",
                       {text(kSchemaVersion)});
    if (!put) return c->abort(put.error());
  } else if (version->integer(0, 0) != kSchemaVersion) {
    return c->abort(StoreError{StoreError::Kind::kQuery,
                               fmt::format("postgresql: {} holds a Terrane schema of version {}; this build reads "
                                           "version {}",
                                           shown, version->get(0, 0), kSchemaVersion)});
  }
  auto commit = c->exec("commit schema", "COMMIT");
  if (!commit) return c->abort(commit.error());
  return std::unique_ptr<PostgresStore>(new PostgresStore(std::move(c)));
}

StoreResult<RegionLease> PostgresStore::claim(Vec3i region, std::uint32_t owner, std::chrono::milliseconds lease) {
  if (owner > static_cast<std::uint32_t>(std::numeric_limits<std::int32_t>::max()))
    return StoreError{StoreError::Kind::kQuery, fmt::format("server id {} is not below 2^31", owner)};
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
  return StoreError{StoreError::Kind::kOwned, fmt::format("region {} is leased to {}", region_text(region), holder)};
}

StoreResult<std::vector<RegionLease>> PostgresStore::renew(std::span<const RegionLease> leases,
                                                           std::chrono::milliseconds lease) {
  std::vector<RegionLease> kept;
  for (const RegionLease& l : leases) {
    auto r = c_->exec("renew lease",
                      "UPDATE terrane_leases SET expires_at = clock_timestamp() + $6::bigint * interval '1 millisecond'"
                      " WHERE rx = $1 AND ry = $2 AND rz = $3 AND owner = $4 AND epoch = $5"
                      " AND expires_at > clock_timestamp() RETURNING 1",
                      {text(l.region.x), text(l.region.y), text(l.region.z), text(l.owner),
                       text(static_cast<std::int64_t>(l.epoch)), text(lease.count())});
    if (!r) return r.error();
    if (r->count() == 1) kept.push_back(l);
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

StoreResult<Ok> PostgresStore::save_chunks(std::span<const RegionLease> leases, std::span<const ChunkWrite> chunks) {
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
  for (const auto& [key, l] : used) {
    auto r = c_->exec("check lease",
                      "SELECT 1 FROM terrane_leases WHERE rx = $1 AND ry = $2 AND rz = $3 AND owner = $4"
                      " AND epoch = $5 AND expires_at > clock_timestamp() FOR UPDATE",
                      {text(l.region.x), text(l.region.y), text(l.region.z), text(l.owner),
                       text(static_cast<std::int64_t>(l.epoch))});
    if (!r) return c_->abort(r.error());
    if (r->count() == 0)
      return c_->abort(StoreError{StoreError::Kind::kFenced,
                                  fmt::format("region {}: the lease of server {} at epoch {} is no longer current; "
                                              "nothing was written",
                                              region_text(l.region), l.owner, l.epoch)});
  }
  for (const ChunkWrite& w : chunks) {
    auto r = c_->exec("write chunk",
                      "INSERT INTO terrane_chunks (x, y, z, revision, blob) VALUES ($1, $2, $3, $4, $5)"
                      " ON CONFLICT (x, y, z) DO UPDATE SET revision = EXCLUDED.revision, blob = EXCLUDED.blob",
                      {text(w.pos.x), text(w.pos.y), text(w.pos.z), text(static_cast<std::int64_t>(w.revision)),
                       blob(w.blob)});
    if (!r) return c_->abort(r.error());
  }
  auto commit = c_->exec("commit chunks", "COMMIT");
  if (!commit) return c_->abort(commit.error());
  return Ok{};
}

StoreResult<std::optional<StoredChunk>> PostgresStore::load_chunk(Vec3i pos) {
  auto r = c_->exec("read chunk", "SELECT revision, blob FROM terrane_chunks WHERE x = $1 AND y = $2 AND z = $3",
                    {text(pos.x), text(pos.y), text(pos.z)}, /*binary_result=*/true);
  if (!r) return r.error();
  if (r->count() == 0) return std::optional<StoredChunk>{};
  if (PQgetlength(r->res, 0, 0) != 8)
    return StoreError{StoreError::Kind::kDecode, fmt::format("chunk {}: revision is not a bigint", region_text(pos))};
  StoredChunk out;
  out.revision = be64(PQgetvalue(r->res, 0, 0));
  const auto* data = reinterpret_cast<const std::uint8_t*>(PQgetvalue(r->res, 0, 1));
  auto chunk = decode_chunk_blob(std::span<const std::uint8_t>(data, static_cast<std::size_t>(PQgetlength(r->res, 0, 1))));
  if (!chunk)
    return StoreError{StoreError::Kind::kDecode, fmt::format("chunk {}: {}", region_text(pos), chunk.error().describe())};
  out.chunk = std::move(*chunk);
  return std::optional<StoredChunk>{std::move(out)};
}

}  // namespace terrane
