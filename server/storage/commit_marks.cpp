#include "server/storage/commit_marks.h"

#include <random>

namespace terrane {

namespace {

// Records commit $2 of writer $1: one row, or none if it was recorded
// already (the update's WHERE fails; the row is locked all the same).
constexpr const char* kRecord =
    "INSERT INTO terrane_commits AS k (writer, seq, committed_at) VALUES ($1, $2, clock_timestamp())"
    " ON CONFLICT (writer) DO UPDATE SET seq = EXCLUDED.seq, committed_at = EXCLUDED.committed_at"
    " WHERE k.seq <> EXCLUDED.seq RETURNING 1";

}  // namespace

CommitMarks::CommitMarks() {
  // 62 random bits, never 0: no two connections draw the same in practice.
  std::random_device seed;
  std::mt19937_64 bits((static_cast<std::uint64_t>(seed()) << 32) ^ seed());
  writer_ = static_cast<std::int64_t>((bits() >> 2) | 1);
}

StoreResult<bool> CommitMarks::record(PgConnection& c, std::int64_t commit) const {
  auto r = c.exec("record commit", kRecord, {pg::text(writer_), pg::text(commit)});
  if (!r) return r.error();
  return r->count() == 1;
}

StoreResult<bool> CommitMarks::stored(PgConnection& c, std::int64_t commit) const {
  auto begin = c.exec("begin", "BEGIN");
  if (!begin) return begin.error();
  auto recorded = record(c, commit);
  (void)c.abort(StoreError{});  // only asked: rolled back
  if (!recorded) return recorded.error();
  return !*recorded;
}

void CommitMarks::forget_old(PgConnection& c) {
  if (forgotten_) return;
  forgotten_ = c.exec("forget old commits",
                      "DELETE FROM terrane_commits WHERE committed_at < clock_timestamp() - interval '1 hour'")
                   .ok();
}

}  // namespace terrane
