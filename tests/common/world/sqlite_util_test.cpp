#include "common/world/sqlite_util.h"

#include <gtest/gtest.h>

#include <sqlite3.h>

#include "tests/support/scratch_world.h"

namespace terrane {
namespace {

class SqliteUtilTest : public testing_support::ScratchWorldTest {
 protected:
  SqliteUtilTest() : ScratchWorldTest("terrane-sqlite-util") {}
  std::int64_t rows() {
    sqlite3_stmt* st = nullptr;
    EXPECT_EQ(sqlite3_prepare_v2(db_, "SELECT count(*) FROM chunks", -1, &st, nullptr), SQLITE_OK);
    EXPECT_EQ(sqlite3_step(st), SQLITE_ROW);
    const std::int64_t n = sqlite3_column_int64(st, 0);
    sqlite3_finalize(st);
    return n;
  }
};

TEST_F(SqliteUtilTest, ATransactionLeftUncommittedIsRolledBackAndACommittedOneStays) {
  {
    SqliteTransaction tx(db_);
    ASSERT_TRUE(tx.began());
    put_row({0, 0, 0}, 1, {1, 2, 3});
    EXPECT_EQ(rows(), 1);
  }
  EXPECT_EQ(rows(), 0);
  EXPECT_TRUE(sqlite3_get_autocommit(db_) != 0);
  {
    SqliteTransaction tx(db_);
    ASSERT_TRUE(tx.began());
    put_row({0, 0, 0}, 1, {1, 2, 3});
    EXPECT_TRUE(tx.commit());
  }
  EXPECT_EQ(rows(), 1);
  // One inside another cannot begin, and leaves the outer one alone.
  SqliteTransaction outer(db_);
  ASSERT_TRUE(outer.began());
  {
    SqliteTransaction inner(db_);
    EXPECT_FALSE(inner.began());
  }
  EXPECT_EQ(sqlite3_get_autocommit(db_), 0);
  EXPECT_TRUE(outer.commit());
}

TEST_F(SqliteUtilTest, ATextColumnHoldingNullReadsAsEmpty) {
  sqlite3_stmt* st = nullptr;
  ASSERT_EQ(sqlite3_prepare_v2(db_, "SELECT NULL, 'ann'", -1, &st, nullptr), SQLITE_OK);
  ASSERT_EQ(sqlite3_step(st), SQLITE_ROW);
  EXPECT_EQ(sqlite_column_string(st, 0), "");
  EXPECT_EQ(sqlite_column_string(st, 1), "ann");
  sqlite3_finalize(st);
}

}  // namespace
}  // namespace terrane
