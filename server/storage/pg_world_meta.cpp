#include "server/storage/pg_world_meta.h"

#include <fmt/format.h>

#include <algorithm>
#include <limits>

namespace terrane {

using pg::Param;
using pg::text;

namespace {

FileError file_error(const StoreError& e) { return FileError{e.message, std::nullopt}; }

}  // namespace

StoreResult<Ok> PgWorldMeta::read(PgConnection& c) {
  auto r = c.exec("read world metadata", "SELECT key, value FROM terrane_meta");
  if (!r) return r.error();
  if (r->count() == 0) {
    has_world_ = false;
    return Ok{};
  }
  std::vector<std::pair<std::string, std::string>> keys;
  for (int i = 0; i < r->count(); ++i) keys.emplace_back(r->get(i, 0), r->get(i, 1));
  auto m = meta_from_keys(keys, "world " + c.shown());
  if (!m) return StoreError{StoreError::Kind::kDecode, m.error().message};
  meta_ = std::move(*m);
  has_world_ = true;
  if (meta_.format_version < kWorldFormatVersion) {
    // Format 3 (world_store.h): this server writes chunk images, which a
    // format-2 server cannot read, so the world says so before it writes.
    if (auto st = put(c, {{"format_version", std::to_string(kWorldFormatVersion)}}); !st)
      return StoreError{StoreError::Kind::kQuery, st.error().message};
    meta_.format_version = kWorldFormatVersion;
  }
  return Ok{};
}

StoreResult<Ok> PgWorldMeta::create(PgConnection& c, const WorldMeta& meta) {
  if (auto why = meta.bounds.validate(); !why.empty())
    return StoreError{StoreError::Kind::kQuery, fmt::format("world {}: {}", c.shown(), why)};
  auto begin = c.exec("begin", "BEGIN");
  if (!begin) return begin.error();
  // The schema lock again: two servers making the world at once agree on
  // one metadata (the first's).
  auto lock = c.exec("lock schema", "SELECT pg_advisory_xact_lock($1)", {text(kPgSchemaLockKey)});
  if (!lock) return c.abort(lock.error());
  auto any = c.exec("read world metadata", "SELECT 1 FROM terrane_meta LIMIT 1");
  if (!any) return c.abort(any.error());
  if (any->count() == 0) {
    for (const auto& [k, v] : meta_to_keys(meta)) {
      auto put = c.exec("write world metadata", "INSERT INTO terrane_meta (key, value) VALUES ($1, $2)",
                        {Param{k, false}, Param{v, false}});
      if (!put) return c.abort(put.error());
    }
  }
  auto commit = c.exec("commit world metadata", "COMMIT");
  if (!commit) return c.abort(commit.error());
  return read(c);
}

FileStatus PgWorldMeta::put(PgConnection& c, const std::vector<std::pair<std::string, std::string>>& keys) {
  auto done = c.transaction<Ok>("commit world metadata", [&]() -> StoreResult<Ok> {
    for (const auto& [k, v] : keys) {
      auto put = c.exec("write world metadata",
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

FileStatus PgWorldMeta::set_epoch(PgConnection& c, std::uint64_t epoch) {
  auto r = c.exec("write world epoch",
                  "UPDATE terrane_meta SET value = (GREATEST(value::bigint + 1, $1::bigint))::text"
                  " WHERE key = 'epoch' RETURNING value",
                  {text(static_cast<std::int64_t>(std::min<std::uint64_t>(
                      epoch, static_cast<std::uint64_t>(std::numeric_limits<std::int64_t>::max()))))});
  if (!r) return file_error(r.error());
  const auto got = r->count() == 1 ? r->integer(0, 0) : std::nullopt;
  if (!got || *got < 0) return FileError{"world " + c.shown() + ": metadata key epoch missing or malformed", {}};
  meta_.epoch = static_cast<std::uint64_t>(*got);
  return Ok{};
}

FileResult<std::uint64_t> PgWorldMeta::name_world(PgConnection& c, std::uint64_t candidate) {
  // One statement: of servers starting at once, the first's id is kept.
  auto r = c.exec("name the world",
                  "INSERT INTO terrane_meta (key, value) VALUES ('world_id', $1)"
                  " ON CONFLICT (key) DO UPDATE SET value = CASE WHEN terrane_meta.value = '0'"
                  " THEN EXCLUDED.value ELSE terrane_meta.value END RETURNING value",
                  {Param{std::to_string(candidate), false}});
  if (!r) return file_error(r.error());
  const auto id = r->count() == 1 ? parse_world_id(r->get(0, 0)) : std::nullopt;
  if (!id || *id == 0) return FileError{"world " + c.shown() + ": metadata key world_id malformed", {}};
  meta_.world_id = *id;
  return *id;
}

FileStatus PgWorldMeta::set_bounds(PgConnection& c, const WorldBounds& bounds) {
  if (auto why = bounds.validate(); !why.empty()) return FileError{"world " + c.shown() + ": " + why, {}};
  WorldMeta m = meta_;
  m.bounds = bounds;
  // Only the bounds' keys: another server's epoch is left as it is.
  std::vector<std::pair<std::string, std::string>> keys;
  for (auto& kv : meta_to_keys(m))
    if (kv.first == "bounds_y" || kv.first == "bounds_xz") keys.push_back(std::move(kv));
  if (auto st = put(c, keys); !st) return st;
  meta_.bounds = bounds;
  return Ok{};
}

}  // namespace terrane
