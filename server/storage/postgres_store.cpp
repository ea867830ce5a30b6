#include "server/storage/postgres_store.h"

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <libpq-fe.h>

#include <algorithm>
#include <cstdlib>
#include <limits>
#include <map>
#include <optional>
#include <string_view>
#include <thread>
#include <tuple>
#include <utility>

#include "common/codec/update_batch.h"
#include "common/world/coarse_image.h"
#include "server/base/log.h"

namespace terrane {

using pg::be32_at;
using pg::be64_at;
using pg::blob;
using pg::bytes_at;
using pg::Param;
using pg::position_at;
using pg::region_range;
using pg::region_text;
using pg::text;

namespace {

// A write PostgreSQL rolled back to break a deadlock (or a serialization
// conflict) is tried again at once this many times before it fails.
constexpr int kConflictRetries = 3;
// A write that found the database gone is tried again this often (a
// refused connection costs little): it is acknowledged this soon at most
// after the database is back.
constexpr auto kConnectionRetry = std::chrono::milliseconds(100);

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

PostgresStore::PostgresStore(std::unique_ptr<PgConnection> c) : c_(std::move(c)) {}

bool PostgresStore::is_url(const std::string& url) {
  return url.rfind("postgresql://", 0) == 0 || url.rfind("postgres://", 0) == 0;
}
PostgresStore::~PostgresStore() = default;

StoreResult<std::unique_ptr<PostgresStore>> PostgresStore::open(const std::string& url) {
  auto c = PgConnection::open(url);  // with the schema made or upgraded
  if (!c) return c.error();
  std::unique_ptr<PostgresStore> store(new PostgresStore(std::move(*c)));
  if (auto m = store->meta_.read(*store->c_); !m) return m.error();
  return store;
}

// The upsert's rule for keeping a chunk's blob (STORE_POSTGRESQL.md,
// "Chunks and their units"): c the stored row, $7 the most rows of units
// behind a blob (0: write the blob).
#define KEEP_UNITS \
  "(c.revision + 1 = EXCLUDED.revision AND EXCLUDED.revision - COALESCE(c.blob_revision, c.revision) <= $7)"

StoreResult<Ok> PostgresStore::save_fenced(std::span<const RegionLease> leases, std::span<const ChunkWrite> chunks,
                                           std::span<const EditLogEntry> log, bool overwrite,
                                           std::span<const ForwardAnswer> answers) {
  return write_fenced(leases, chunks, log, overwrite, answers, 0, nullptr);
}

StoreResult<Ok> PostgresStore::write_fenced(std::span<const RegionLease> leases, std::span<const ChunkWrite> chunks,
                                            std::span<const EditLogEntry> log, bool overwrite,
                                            std::span<const ForwardAnswer> answers, std::int64_t commit,
                                            CommitCheck* check) {
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
  if (commit != 0) {
    // An earlier try of this commit whose answer was lost may have been
    // stored: if so, it is not written again.
    auto fresh = commits_.record(*c_, commit);
    if (!fresh) return c_->abort(fresh.error());
    check->asked = true;
    if (!*fresh) {
      check->stored = true;
      (void)c_->abort(StoreError{});
      return Ok{};
    }
  }
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
  if (auto a = answer_forwarded(*c_, answers); !a) return c_->abort(a.error());
  auto done = c_->exec("commit chunks", "COMMIT");
  if (!done) return c_->abort(PgConnection::unanswered_commit(done.error()));
  return Ok{};
}

namespace {

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

}  // namespace

StoreResult<Ok> answer_forwarded(PgConnection& c, std::span<const ForwardAnswer> answers) {
  for (const ForwardAnswer& a : answers) {
    // Answered: the row goes. The answer travels in the notice, and stays
    // in terrane_answers until its sender has it (a sender whose listener
    // was reconnecting when the notice went out reads it there).
    auto r = c.exec("answer forwarded edit", "DELETE FROM terrane_inbox WHERE id = $1", {text(a.id)});
    if (!r) return r.error();
    auto kept = c.exec("keep answer",
                       "INSERT INTO terrane_answers (id, from_server, accepted, tick, reason, answered_at)"
                       " VALUES ($1, $2, $3, $4, $5, clock_timestamp()) ON CONFLICT (id) DO NOTHING",
                       {text(a.id), text(a.from), Param{a.accepted ? "true" : "false", false},
                        text(static_cast<std::int64_t>(a.tick)), Param{a.reason.substr(0, 256), false}});
    if (!kept) return kept.error();
    auto n = c.exec("notify answer", "SELECT pg_notify($1, $2)",
                    {Param{kAnswersChannel, false}, Param{answer_notice(a), false}});
    if (!n) return n.error();
  }
  return Ok{};
}

StoreResult<Ok> PostgresStore::create_world(const WorldMeta& meta) { return meta_.create(*c_, meta); }

StoreResult<std::unique_ptr<PostgresStore>> PostgresStore::reopen_chunks() const {
  auto again = open(c_->url());
  if (!again) return again.error();
  (*again)->set_lease_source(leases_, retry_for_);
  (*again)->count_retries_in(database_counters_);
  return std::move(*again);
}

FileResult<std::unique_ptr<WorldStore>> PostgresStore::reopen() const {
  auto again = reopen_chunks();
  if (!again) return file_error(again.error());
  return std::unique_ptr<WorldStore>(std::move(*again));
}

FileStatus PostgresStore::set_epoch(std::uint64_t epoch) { return meta_.set_epoch(*c_, epoch); }

FileResult<std::uint64_t> PostgresStore::name_world(std::uint64_t candidate) { return meta_.name_world(*c_, candidate); }

FileStatus PostgresStore::set_bounds(const WorldBounds& bounds) { return meta_.set_bounds(*c_, bounds); }

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
                                 c_->shown()),
                     std::nullopt};
  std::vector<Vec3i> regions;
  for (const ChunkWrite& w : writes) {
    const Vec3i r = lease_region_of(w.pos);
    if (std::find(regions.begin(), regions.end(), r) == regions.end()) regions.push_back(r);
  }
  // A database that went away (restarted, say) is waited for, up to
  // retry_for: the write is tried again on a new connection. Nothing is
  // acknowledged meanwhile, and once the leases have run out the write is
  // fenced anyway. A commit PostgreSQL rolled back to break a deadlock is
  // tried again at once, a few times: nothing of it was stored.
  // Every try records the commit's number (terrane_commits) in its
  // transaction, and first asks whether an earlier try recorded it: a try
  // whose COMMIT was sent and never answered may have been stored, and is
  // then not stored again. A commit that fails with that question open
  // has an unknown outcome, and says so.
  commits_.forget_old(*c_);
  const std::int64_t commit = commits_.next();
  const auto give_up = std::chrono::steady_clock::now() + retry_for_;
  int conflicts = 0;
  // Counted as retrying from the first failed attempt to the end (stored
  // or failed): /health says the world's changes are not being stored.
  CommitRetries retrying(database_counters_);
  bool unanswered = false;  // a try's COMMIT went unanswered, and no later try has found out since
  const auto failed = [&](const StoreError& e) {
    if (!unanswered) return file_error(e);
    FileError out{fmt::format("{}; the commit may have been stored (a try's COMMIT was sent and not answered, and "
                              "the database could not be asked since)",
                              e.message),
                  std::nullopt};
    out.outcome_unknown = true;
    return out;
  };
  for (int attempt = 0;; ++attempt) {
    auto leases = (*leases_)(regions);
    CommitCheck check;
    StoreResult<Ok> saved = leases ? write_fenced(*leases, writes, log, overwrite, answers, commit, &check)
                                   : StoreResult<Ok>(leases.error());
    if (!leases && unanswered) {
      // No lease to try again with (lost meanwhile): whether the earlier try
      // was stored can still be asked.
      auto stored = commits_.stored(*c_, commit);
      if (!stored && stored.error().kind == StoreError::Kind::kConnection) {
        saved = stored.error();  // asked again while the time lasts
      } else if (stored) {
        unanswered = false;
        if (*stored) {
          saved = Ok{};
          check.stored = true;
        }
      }
    }
    if (saved) {
      if (check.stored)
        server_log().info("world {}: commit {} was stored by an earlier try whose answer was lost; not stored again",
                          c_->shown(), commit);
      else if (attempt > 0)
        server_log().info("world {}: stored after {} tries{}", c_->shown(), attempt + 1,
                          conflicts == attempt ? "" : ": the database is back");
      return Ok{};
    }
    // A try that asked knows that no earlier try was stored (and none can
    // be any more: it waited for their transactions to end).
    if (check.asked) unanswered = false;
    if (saved.error().kind == StoreError::Kind::kUnknown) unanswered = true;
    const StoreError::Kind kind = saved.error().kind;
    if (kind == StoreError::Kind::kConflict && ++conflicts <= kConflictRetries) {
      server_log().warn("world {}: {}; trying again", c_->shown(), saved.error().message);
      continue;
    }
    const bool unreachable = kind == StoreError::Kind::kConnection || kind == StoreError::Kind::kUnknown;
    if (!unreachable || std::chrono::steady_clock::now() >= give_up) return failed(saved.error());
    retrying.start();
    if (attempt == conflicts) server_log().warn("world {}: {}; trying again", c_->shown(), saved.error().message);
    std::this_thread::sleep_for(kConnectionRetry);
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
  return static_cast<std::int64_t>(std::strtoll(PQcmdTuples(r->res), nullptr, 10));  // rows deleted ("" reads as 0)
}

FileResult<EditLogSize> PostgresStore::edit_log_size() {
  auto r = c_->exec("measure edit log",
                    "SELECT count(*), coalesce(sum(octet_length(before) + octet_length(after)), 0) FROM terrane_edit_log");
  if (!r) return file_error(r.error());
  const auto entries = r->integer(0, 0), bytes = r->integer(0, 1);
  if (!entries || !bytes || *entries < 0 || *bytes < 0) return FileError{"postgresql: measure edit log: unreadable", {}};
  return EditLogSize{*entries, static_cast<std::uint64_t>(*bytes)};
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
