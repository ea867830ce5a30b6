// PgConnection against a real PostgreSQL started by the test: the schema
// is made once and left alone when current, a transaction is all or
// nothing, a statement's error names it, binary columns are read with
// their lengths checked, and a connection string is shown without its
// password.
#include "server/storage/pg_connection.h"

#include <gtest/gtest.h>
#include <libpq-fe.h>

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

}  // namespace
}  // namespace terrane
