// Test support: a world made by SqliteStore in a scratch directory
// (scratch_dir.h), and a connection of the test's own to it. The owners of a
// world's other tables (SqliteEditLog, SqliteQuarantine, SqliteCoarseImages,
// SqliteAccess) are tested over that connection; a fixture drops its owner
// before the connection closes (TearDown, reopen_db), since a connection with
// statements left does not close.
#pragma once

#include <gtest/gtest.h>
#include <sqlite3.h>

#include <cstdint>
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include "common/world/sqlite_store.h"
#include "common/world/world.h"
#include "tests/support/scratch_dir.h"

namespace terrane::testing_support {

class ScratchWorldTest : public ::testing::Test {
 protected:
  // prefix names the scratch directory (scratch_dir).
  explicit ScratchWorldTest(std::string prefix) : prefix_(std::move(prefix)) {}

  void SetUp() override {
    dir_ = scratch_dir(prefix_).string();
    ASSERT_TRUE(SqliteStore::create(dir_, default_world_meta()).ok());
    open_db();
  }
  void TearDown() override {
    sqlite3_close(db_);
    std::filesystem::remove_all(dir_);
  }
  // A new connection in place of the old one (which must have no statements left).
  void reopen_db() {
    sqlite3_close(db_);
    db_ = nullptr;
    open_db();
  }
  void exec(const char* sql) { ASSERT_EQ(sqlite3_exec(db_, sql, nullptr, nullptr, nullptr), SQLITE_OK) << sql; }
  // Replaces from with to in table's schema text and reopens the connection
  // (which must have no statements left): a world as a damaged or
  // hand-edited file can hold it, e.g. a NOT NULL column that takes NULL.
  void rewrite_schema(const char* table, const char* from, const char* to) {
    exec("PRAGMA writable_schema = ON");
    sqlite3_stmt* st = nullptr;
    ASSERT_EQ(sqlite3_prepare_v2(db_, "UPDATE sqlite_master SET sql = replace(sql, ?1, ?2) WHERE name = ?3", -1, &st,
                                 nullptr),
              SQLITE_OK);
    sqlite3_bind_text(st, 1, from, -1, SQLITE_STATIC);
    sqlite3_bind_text(st, 2, to, -1, SQLITE_STATIC);
    sqlite3_bind_text(st, 3, table, -1, SQLITE_STATIC);
    EXPECT_EQ(sqlite3_step(st), SQLITE_DONE);
    EXPECT_EQ(sqlite3_changes(db_), 1);
    sqlite3_finalize(st);
    exec("PRAGMA writable_schema = OFF");
    reopen_db();
  }
  // Writes a chunks row (over any there), as SqliteStore::save_chunks does.
  void put_row(Vec3i pos, std::uint64_t revision, const std::vector<std::uint8_t>& blob) {
    sqlite3_stmt* st = nullptr;
    ASSERT_EQ(sqlite3_prepare_v2(db_, "INSERT OR REPLACE INTO chunks(cx, cy, cz, revision, data) VALUES(?, ?, ?, ?, ?)",
                                 -1, &st, nullptr),
              SQLITE_OK);
    sqlite3_bind_int(st, 1, pos.x);
    sqlite3_bind_int(st, 2, pos.y);
    sqlite3_bind_int(st, 3, pos.z);
    sqlite3_bind_int64(st, 4, static_cast<sqlite3_int64>(revision));
    sqlite3_bind_blob(st, 5, blob.data(), static_cast<int>(blob.size()), SQLITE_TRANSIENT);
    EXPECT_EQ(sqlite3_step(st), SQLITE_DONE);
    sqlite3_finalize(st);
  }

  std::string dir_;
  sqlite3* db_ = nullptr;

 private:
  void open_db() {
    ASSERT_EQ(sqlite3_open((std::filesystem::path(dir_) / kWorldDatabaseName).string().c_str(), &db_), SQLITE_OK);
  }

  std::string prefix_;
};

}  // namespace terrane::testing_support
