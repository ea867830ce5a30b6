#include "common/world/sqlite_access.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <sqlite3.h>
#include <unistd.h>

#include "common/world/sqlite_store.h"
#include "common/world/world.h"

namespace terrane {
namespace {

namespace fs = std::filesystem;

using Entries = std::vector<std::pair<std::string, std::string>>;

// A world made by SqliteStore in a scratch directory, and a connection of
// the test's own to it: the access lists run over that connection.
class SqliteAccessTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = (fs::temp_directory_path() / ("terrane-access-" + std::to_string(::getpid()) + "-" +
                                          ::testing::UnitTest::GetInstance()->current_test_info()->name()))
               .string();
    fs::remove_all(dir_);
    ASSERT_TRUE(SqliteStore::create(dir_, default_world_meta()).ok());
    reopen();
  }
  void TearDown() override {
    access_.reset();
    sqlite3_close(db_);
    fs::remove_all(dir_);
  }
  void reopen() {
    access_.reset();
    if (db_) sqlite3_close(db_);
    ASSERT_EQ(sqlite3_open((dir_ + "/world.sqlite").c_str(), &db_), SQLITE_OK);
    access_ = std::make_unique<SqliteAccess>(db_, dir_);
  }
  std::string dir_;
  sqlite3* db_ = nullptr;
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

}  // namespace
}  // namespace terrane
