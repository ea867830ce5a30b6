#include "common/world/sqlite_access.h"

#include <gtest/gtest.h>

#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "tests/support/scratch_world.h"

namespace terrane {
namespace {

using Entries = std::vector<std::pair<std::string, std::string>>;

// The access lists over the scratch world's connection.
class SqliteAccessTest : public testing_support::ScratchWorldTest {
 protected:
  SqliteAccessTest() : ScratchWorldTest("terrane-access") {}
  void SetUp() override {
    ASSERT_NO_FATAL_FAILURE(ScratchWorldTest::SetUp());
    access_ = std::make_unique<SqliteAccess>(db_, dir_);
  }
  void TearDown() override {
    access_.reset();
    ScratchWorldTest::TearDown();
  }
  void reopen() {
    access_.reset();
    reopen_db();
    access_ = std::make_unique<SqliteAccess>(db_, dir_);
  }
  std::unique_ptr<SqliteAccess> access_;
};

TEST_F(SqliteAccessTest, BeforeTheFirstWriteThereIsNothingAndErasingIsNoError) {
  EXPECT_EQ(*access_->entries(), Entries{});
  EXPECT_TRUE(access_->erase("ban:ann").ok());
  EXPECT_EQ(*access_->entries(), Entries{});
}

TEST_F(SqliteAccessTest, EntriesRoundTripByKeyAndSurviveReopening) {
  ASSERT_TRUE(access_->put("whitelist:bob", "1").ok());
  ASSERT_TRUE(access_->put("ban:ann", "until 2030").ok());
  ASSERT_TRUE(access_->put("ban:ann", "for ever").ok());  // replaced, not added
  ASSERT_TRUE(access_->put("admin:cy", "").ok());
  EXPECT_EQ(*access_->entries(), (Entries{{"admin:cy", ""}, {"ban:ann", "for ever"}, {"whitelist:bob", "1"}}));
  reopen();
  ASSERT_EQ(access_->entries()->size(), 3u);
  ASSERT_TRUE(access_->erase("ban:ann").ok());
  ASSERT_TRUE(access_->erase("nobody").ok());
  reopen();
  EXPECT_EQ(access_->entries()->back(), (std::pair<std::string, std::string>{"whitelist:bob", "1"}));
  EXPECT_EQ(access_->entries()->size(), 2u);
}

TEST_F(SqliteAccessTest, ANullValueInADamagedWorldReadsAsEmpty) {
  ASSERT_TRUE(access_->put("ban:ann", "for ever").ok());
  access_.reset();
  ASSERT_NO_FATAL_FAILURE(rewrite_schema("access", "value TEXT NOT NULL", "value TEXT"));
  access_ = std::make_unique<SqliteAccess>(db_, dir_);
  exec("UPDATE access SET value = NULL");
  auto read = access_->entries();
  ASSERT_TRUE(read.ok()) << read.error().message;
  EXPECT_EQ(*read, (Entries{{"ban:ann", ""}}));
}

}  // namespace
}  // namespace terrane
