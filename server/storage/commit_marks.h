// CommitMarks: the commits of one writing connection to a PostgreSQL world
// as the database records them (terrane_commits, STORE_POSTGRESQL.md,
// "Fencing"), so that a commit tried again after its answer was lost is
// not stored twice. Each connection has a writer id of its own (random)
// and numbers its commits; each try of a commit records the number in its
// own transaction, and one that finds it recorded already knows that an
// earlier try was stored. The table keeps one row per writer, its last
// commit only.
//
// Threading: owned by one PostgresStore, whose thread uses it with that
// store's connection.
#pragma once

#include <cstdint>

#include "server/storage/pg_connection.h"

namespace terrane {

class CommitMarks {
 public:
  CommitMarks();  // a writer id drawn at random
  std::int64_t writer() const { return writer_; }
  // The number of the commit about to be tried (1, 2, ...): every try of
  // it uses the same number.
  std::int64_t next() { return ++last_; }
  // Inside a transaction on c: records commit. False if it was recorded
  // already: an earlier try of it was stored, and this one must write
  // nothing. The row stays locked to the end of the transaction, so a try
  // waits for an earlier one still under way in the database (its COMMIT
  // sent, its answer lost) and then sees its outcome.
  StoreResult<bool> record(PgConnection& c, std::int64_t commit) const;
  // Whether commit was recorded (stored): asked in a transaction of its
  // own, rolled back; it waits for a try under way as record() does.
  StoreResult<bool> stored(PgConnection& c, std::int64_t commit) const;
  // Deletes the rows of writers gone (not written for an hour: no try
  // outlives that), the first time it is called; failures are left for
  // the next connection.
  void forget_old(PgConnection& c);

 private:
  std::int64_t writer_ = 0;
  std::int64_t last_ = 0;
  bool forgotten_ = false;
};

}  // namespace terrane
