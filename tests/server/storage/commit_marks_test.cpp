// CommitMarks against a real PostgreSQL started by the test: a commit's
// number is recorded once per writer, a try that finds it recorded knows
// an earlier try was stored, and asking waits for a try still under way in
// the database and then sees its outcome.
#include "server/storage/commit_marks.h"

#include <gtest/gtest.h>

#include <future>
#include <memory>
#include <string>

#include "tests/support/eventually.h"
#include "tests/support/postgres.h"

namespace terrane {
namespace {

using namespace std::chrono_literals;
using testing_support::eventually;
using testing_support::sql_value;

class CommitMarksTest : public testing_support::PostgresTest {
 protected:
  std::unique_ptr<PgConnection> connect() {
    auto c = PgConnection::open(url_);
    EXPECT_TRUE(c.ok()) << (c.ok() ? "" : c.error().message);
    return c.ok() ? std::move(*c) : nullptr;
  }
  // BEGIN, record(commit), then COMMIT (or ROLLBACK): whether it was fresh.
  static bool commit_once(PgConnection& c, const CommitMarks& m, std::int64_t commit, bool keep = true) {
    EXPECT_TRUE(c.exec("begin", "BEGIN").ok());
    auto fresh = m.record(c, commit);
    EXPECT_TRUE(fresh.ok()) << (fresh.ok() ? "" : fresh.error().message);
    EXPECT_TRUE(c.exec("end", keep ? "COMMIT" : "ROLLBACK").ok());
    return fresh.ok() && *fresh;
  }
};

TEST_F(CommitMarksTest, ACommitIsRecordedOncePerWriterAndAskingSeesIt) {
  auto c = connect();
  ASSERT_TRUE(c);
  CommitMarks a, b;
  EXPECT_NE(a.writer(), b.writer());
  EXPECT_NE(a.writer(), 0);
  const std::int64_t first = a.next();
  EXPECT_EQ(first, 1);
  EXPECT_EQ(*a.stored(*c, first), false);  // nothing recorded yet
  EXPECT_TRUE(commit_once(*c, a, first));
  EXPECT_EQ(*a.stored(*c, first), true);
  EXPECT_FALSE(commit_once(*c, a, first)) << "the same commit recorded twice";
  // Another writer's numbers are its own.
  EXPECT_EQ(*b.stored(*c, first), false);
  EXPECT_TRUE(commit_once(*c, b, b.next()));
  // A try rolled back leaves no record: the commit is not stored.
  const std::int64_t second = a.next();
  EXPECT_TRUE(commit_once(*c, a, second, /*keep=*/false));
  EXPECT_EQ(*a.stored(*c, second), false);
  EXPECT_TRUE(commit_once(*c, a, second));
  EXPECT_EQ(*a.stored(*c, second), true);
  // One row per writer, its last commit; asking wrote nothing.
  EXPECT_EQ(sql_value(url_, "SELECT count(*) FROM terrane_commits"), "2");
  EXPECT_EQ(sql_value(url_, "SELECT seq FROM terrane_commits WHERE writer = " + std::to_string(a.writer())), "2");
}

TEST_F(CommitMarksTest, AskingWaitsForATryUnderWayAndSeesItsOutcome) {
  auto first = connect(), second = connect();
  ASSERT_TRUE(first && second);
  CommitMarks m;
  for (const bool keep : {false, true}) {
    const std::int64_t commit = m.next();
    // A try under way in the database (recorded, its COMMIT not yet run),
    // as one whose connection was lost after the COMMIT was sent may be.
    ASSERT_TRUE(first->exec("begin", "BEGIN").ok());
    ASSERT_TRUE(*m.record(*first, commit));
    auto asked = std::async(std::launch::async, [&] { return m.stored(*second, commit); });
    ASSERT_TRUE(eventually([&] {
      return sql_value(url_, "SELECT count(*) FROM pg_stat_activity WHERE wait_event_type = 'Lock'") == "1";
    })) << "the question did not wait for the try under way";
    ASSERT_TRUE(first->exec("end", keep ? "COMMIT" : "ROLLBACK").ok());
    auto stored = asked.get();
    ASSERT_TRUE(stored.ok()) << stored.error().message;
    EXPECT_EQ(*stored, keep);
  }
}

TEST_F(CommitMarksTest, RowsOfWritersGoneForAnHourAreForgotten) {
  auto c = connect();
  ASSERT_TRUE(c);
  CommitMarks old, recent;
  EXPECT_TRUE(commit_once(*c, old, old.next()));
  EXPECT_TRUE(commit_once(*c, recent, recent.next()));
  ASSERT_EQ(testing_support::run_sql(url_, "UPDATE terrane_commits SET committed_at = clock_timestamp() - "
                                           "interval '61 minutes' WHERE writer = " + std::to_string(old.writer())),
            "");
  recent.forget_old(*c);
  EXPECT_EQ(sql_value(url_, "SELECT writer FROM terrane_commits"), std::to_string(recent.writer()));
}

}  // namespace
}  // namespace terrane
