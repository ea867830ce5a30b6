// PgConnection against a real PostgreSQL started by the test: the schema
// is made once and left alone when current, a transaction is all or
// nothing, a statement's error names it, binary columns are read with
// their lengths checked, and a connection string is shown without its
// password. A statement the database never answers (its backend stopped,
// as a partition looks from here) fails at its deadline with kConnection,
// inside a transaction too, and the next statement reopens the connection.
#include "server/storage/pg_connection.h"

#include <gtest/gtest.h>
#include <libpq-fe.h>

#include <signal.h>

#include <chrono>
#include <future>
#include <string>
#include <vector>

#include "tests/support/postgres.h"

namespace terrane {
namespace {

using testing_support::sql_value;

class PgConnectionTest : public testing_support::PostgresTest {
 protected:
  std::unique_ptr<PgConnection> open() {
    auto c = PgConnection::open(url_);
    EXPECT_TRUE(c.ok()) << (c.ok() ? "" : c.error().message);
    return c.ok() ? std::move(*c) : nullptr;
  }
};

TEST_F(PgConnectionTest, OpenMakesTheSchemaOnceAndShowsTheUrl) {
  auto a = open();
  ASSERT_TRUE(a);
  EXPECT_EQ(sql_value(url_, "SELECT version FROM terrane_schema"), std::to_string(kPgSchemaVersion));
  auto b = open();  // finds it made
  ASSERT_TRUE(b);
  EXPECT_EQ(sql_value(url_, "SELECT count(*) FROM terrane_schema"), "1");
  EXPECT_EQ(a->url(), url_);
  EXPECT_EQ(a->shown(), url_);  // no password in it: shown as it is
}

TEST_F(PgConnectionTest, ATransactionIsAllOrNothingAndAFailedStatementIsNamed) {
  auto c = open();
  ASSERT_TRUE(c);
  ASSERT_TRUE(c->exec("make table", "CREATE TABLE t (v integer PRIMARY KEY)").ok());
  auto failed = c->transaction<Ok>("commit t", [&]() -> StoreResult<Ok> {
    if (auto r = c->exec("insert one", "INSERT INTO t VALUES (1)"); !r) return r.error();
    auto twice = c->exec("insert again", "INSERT INTO t VALUES (1)");
    if (!twice) return twice.error();
    return Ok{};
  });
  ASSERT_FALSE(failed.ok());
  EXPECT_EQ(failed.error().kind, StoreError::Kind::kQuery);
  EXPECT_EQ(failed.error().message.rfind("postgresql: insert again: ", 0), 0u) << failed.error().message;
  EXPECT_EQ(sql_value(url_, "SELECT count(*) FROM t"), "0") << "rolled back whole";
  // The connection works on after the rollback.
  auto done = c->transaction<std::int64_t>("commit t", [&]() -> StoreResult<std::int64_t> {
    auto r = c->exec("insert", "INSERT INTO t VALUES ($1) RETURNING v", {pg::text(7)});
    if (!r) return r.error();
    return r->integer(0, 0).value_or(-1);
  });
  ASSERT_TRUE(done.ok()) << done.error().message;
  EXPECT_EQ(*done, 7);
  EXPECT_EQ(sql_value(url_, "SELECT count(*) FROM t"), "1");
}

TEST_F(PgConnectionTest, BinaryColumnsAreReadOnlyAtTheirLength) {
  auto c = open();
  ASSERT_TRUE(c);
  const std::vector<std::uint8_t> bytes{0, 1, 2, 255};
  auto r = c->exec("read", "SELECT 5::integer, -6::integer, 7::integer, 8::bigint, 9::integer, $1::bytea, NULL::bigint",
                   {pg::blob(bytes)}, /*binary_result=*/true);
  ASSERT_TRUE(r.ok()) << r.error().message;
  EXPECT_EQ(pg::position_at(r->res, 0), (Vec3i{5, -6, 7}));
  EXPECT_EQ(pg::be64_at(r->res, 0, 3), 8);
  EXPECT_EQ(pg::be64_at(r->res, 0, 4), std::nullopt) << "an integer is not a bigint";
  EXPECT_EQ(pg::be32_at(r->res, 0, 3), std::nullopt) << "a bigint is not an integer";
  const auto got = pg::bytes_at(r->res, 0, 5);
  EXPECT_EQ(std::vector<std::uint8_t>(got.begin(), got.end()), bytes);
  EXPECT_EQ(pg::be64_at(r->res, 0, 6), std::nullopt) << "NULL";
  // Text columns that are not integers read as none.
  auto t = c->exec("read", "SELECT '12', '1x', ''");
  ASSERT_TRUE(t.ok()) << t.error().message;
  EXPECT_EQ(t->integer(0, 0), 12);
  EXPECT_EQ(t->integer(0, 1), std::nullopt);
  EXPECT_EQ(t->integer(0, 2), std::nullopt);
}

TEST(PgRedacted, APasswordIsNeverShown) {
  EXPECT_EQ(pg::redacted("postgresql://ann:s3cret@db.example:5432/w"), "postgresql://ann:***@db.example:5432/w");
  EXPECT_EQ(pg::redacted("postgresql://ann@db.example/w"), "postgresql://ann@db.example/w");
  const std::string keywords = pg::redacted("host=db port=5432 password = 'open sesame' dbname=w");
  EXPECT_EQ(keywords.find("sesame"), std::string::npos) << keywords;
  EXPECT_NE(keywords.find("password=***"), std::string::npos) << keywords;
  EXPECT_EQ(pg::region_text({1, -2, 3}), "(1,-2,3)");
}

// The backend serving c, stopped until the guard is gone.
class StoppedBackend {
 public:
  explicit StoppedBackend(PgConnection& c) {
    auto r = c.exec("backend pid", "SELECT pg_backend_pid()");
    if (r && r->count() == 1) pid_ = static_cast<pid_t>(r->integer(0, 0).value_or(0));
    if (pid_ > 0) ::kill(pid_, SIGSTOP);
  }
  ~StoppedBackend() {
    if (pid_ > 0) ::kill(pid_, SIGCONT);
  }
  bool stopped() const { return pid_ > 0; }

 private:
  pid_t pid_ = 0;
};

TEST_F(PgConnectionTest, AStatementNeverAnsweredFailsAtItsDeadlineAndTheNextOneReopens) {
  auto c = open();
  ASSERT_TRUE(c);
  c->set_call_timeout(std::chrono::milliseconds(300));
  ASSERT_TRUE(c->exec("make table", "CREATE TABLE t (v integer PRIMARY KEY)").ok());
  {
    // (The futures outlive the stopped backend: a failed assertion lets it
    // run again before they wait for their calls.)
    std::future<StoreResult<PgConnection::Rows>> call;
    StoppedBackend stopped(*c);
    ASSERT_TRUE(stopped.stopped());
    // Without a deadline this waits for as long as the backend is stopped:
    // the bound below is only how long the test lets it try.
    call = std::async(std::launch::async, [&] { return c->exec("insert one", "INSERT INTO t VALUES (1)"); });
    ASSERT_EQ(call.wait_for(std::chrono::seconds(60)), std::future_status::ready) << "no deadline";
    auto r = call.get();
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().kind, StoreError::Kind::kConnection);
    EXPECT_NE(r.error().message.find("postgresql: insert one: no answer within 300 ms"), std::string::npos)
        << r.error().message;
  }
  // The connection was given up: the next statement opens a new one.
  ASSERT_TRUE(c->exec("insert two", "INSERT INTO t VALUES (2)").ok());
  {
    // A transaction's statements have the deadline too, and its failure
    // sends no ROLLBACK on the connection given up (which would wait as
    // long again).
    std::future<StoreResult<Ok>> t;
    StoppedBackend stopped(*c);
    ASSERT_TRUE(stopped.stopped());
    t = std::async(std::launch::async, [&] {
      return c->transaction<Ok>("commit t", [&]() -> StoreResult<Ok> {
        if (auto x = c->exec("insert four", "INSERT INTO t VALUES (4)"); !x) return x.error();
        return Ok{};
      });
    });
    ASSERT_EQ(t.wait_for(std::chrono::seconds(60)), std::future_status::ready) << "no deadline in a transaction";
    auto r = t.get();
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().kind, StoreError::Kind::kConnection);
  }
  c->set_call_timeout(std::chrono::seconds(10));
  auto again = c->exec("insert three", "INSERT INTO t VALUES (3) RETURNING v");
  ASSERT_TRUE(again.ok()) << again.error().message;
  EXPECT_EQ(again->integer(0, 0), 3);
  // A statement given up may still be applied (it was sent: the backend,
  // running again, reads it) — a caller treats its outcome as unknown. One
  // inside a transaction given up never is: the backend finds its client
  // gone before any COMMIT.
  const std::string rows = sql_value(url_, "SELECT string_agg(v::text, ',' ORDER BY v) FROM t WHERE v > 1");
  EXPECT_EQ(rows, "2,3");
}

}  // namespace
}  // namespace terrane
