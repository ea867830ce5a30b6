#include "common/world/sqlite_quarantine.h"

#include <gtest/gtest.h>

#include <memory>
#include <random>
#include <string>
#include <vector>

#include <sqlite3.h>

#include "tests/support/scratch_world.h"

namespace terrane {
namespace {

// The quarantine over the scratch world's connection.
class SqliteQuarantineTest : public testing_support::ScratchWorldTest {
 protected:
  SqliteQuarantineTest() : ScratchWorldTest("terrane-quarantine") {}
  void SetUp() override {
    ASSERT_NO_FATAL_FAILURE(ScratchWorldTest::SetUp());
    quarantine_ = std::make_unique<SqliteQuarantine>(db_, dir_);
  }
  void TearDown() override {
    quarantine_.reset();
    ScratchWorldTest::TearDown();
  }
  // The chunks row's revision, if there is one.
  std::optional<std::uint64_t> row_revision(Vec3i pos) {
    sqlite3_stmt* st = nullptr;
    EXPECT_EQ(sqlite3_prepare_v2(db_, "SELECT revision FROM chunks WHERE cx = ? AND cy = ? AND cz = ?", -1, &st, nullptr),
              SQLITE_OK);
    sqlite3_bind_int(st, 1, pos.x);
    sqlite3_bind_int(st, 2, pos.y);
    sqlite3_bind_int(st, 3, pos.z);
    std::optional<std::uint64_t> out;
    if (sqlite3_step(st) == SQLITE_ROW) out = static_cast<std::uint64_t>(sqlite3_column_int64(st, 0));
    sqlite3_finalize(st);
    return out;
  }
  std::vector<QuarantinedChunk> listed() {
    std::vector<QuarantinedChunk> out;
    EXPECT_TRUE(quarantine_->for_each([&](const QuarantinedChunk& q) { out.push_back(q); }).ok());
    return out;
  }
  static FileStatus nothing_else() { return Ok{}; }
  std::unique_ptr<SqliteQuarantine> quarantine_;
};

std::vector<std::uint8_t> good_blob(unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> mat(1, 20);
  Box box({32, 32, 32});
  for (int y = 0; y < 10; ++y)
    for (int z = 0; z < 32; ++z)
      for (int x = 0; x < 32; ++x) box.set(x, y, z, solid(static_cast<Material>(mat(rng))));
  return encode_chunk_blob(box);
}

TEST_F(SqliteQuarantineTest, AWorldWithoutTheTableGainsItAndKeepsItsRows) {
  ASSERT_EQ(sqlite3_exec(db_, "DROP TABLE quarantine", nullptr, nullptr, nullptr), SQLITE_OK);
  EXPECT_FALSE(quarantine_->count().ok());
  ASSERT_TRUE(quarantine_->ensure_table().ok());
  EXPECT_EQ(*quarantine_->count(), 0);
  put_row({1, 2, 3}, 4, {9, 9, 9});
  ASSERT_TRUE(quarantine_->move_aside({1, 2, 3}, "bad", nothing_else).ok());
  // Again on a world that has it: nothing changes.
  ASSERT_TRUE(quarantine_->ensure_table().ok());
  EXPECT_EQ(*quarantine_->count(), 1);
}

TEST_F(SqliteQuarantineTest, MovingAsideKeepsTheBlobByteForByteThenARestoreWritesAboveIt) {
  const std::vector<std::uint8_t> bad = {1, 1, 0xff, 0x00, 0x13};
  const std::vector<std::uint8_t> good = good_blob(7);
  put_row({2, 0, -3}, 7, bad);
  put_row({0, 0, 0}, 4, good);
  int also_called = 0;
  auto moved = quarantine_->move_aside({2, 0, -3}, "truncated blob", [&] {
    ++also_called;
    return FileStatus{Ok{}};
  });
  ASSERT_TRUE(moved.ok()) << moved.error().message;
  EXPECT_EQ(*moved, std::optional<std::uint64_t>{7});
  EXPECT_EQ(also_called, 1);
  EXPECT_EQ(row_revision({2, 0, -3}), std::nullopt);  // gone from chunks
  EXPECT_EQ(row_revision({0, 0, 0}), std::optional<std::uint64_t>{4});  // the other untouched
  auto rows = listed();
  ASSERT_EQ(rows.size(), 1u);
  EXPECT_EQ(rows[0].pos, (Vec3i{2, 0, -3}));
  EXPECT_EQ(rows[0].revision, 7u);
  EXPECT_EQ(rows[0].reason, "truncated blob");
  EXPECT_EQ(rows[0].blob, bad);
  EXPECT_GT(rows[0].time_unix_s, 1700000000);  // a real clock reading (2023 or later)
  EXPECT_EQ(*quarantine_->count(), 1);
  EXPECT_EQ(*quarantine_->revision({2, 0, -3}), std::optional<std::uint64_t>{7});
  EXPECT_EQ(*quarantine_->revision({0, 0, 0}), std::nullopt);
  EXPECT_EQ(*quarantine_->in_region({0, -1, -1}), std::vector<Vec3i>{});
  EXPECT_EQ(*quarantine_->in_region({0, 0, -1}), (std::vector<Vec3i>{{2, 0, -3}}));

  // Restored (a good blob written back above the quarantined revision): the
  // quarantine row stays as it was.
  put_row({2, 0, -3}, 8, good);
  auto restored = decode_chunk_blob(good);
  ASSERT_TRUE(restored.ok());
  EXPECT_EQ(row_revision({2, 0, -3}), std::optional<std::uint64_t>{8});
  EXPECT_EQ(listed().at(0).blob, bad);
  EXPECT_EQ(*quarantine_->revision({2, 0, -3}), std::optional<std::uint64_t>{7});

  // Damaged again: a second row, the highest revision reported.
  put_row({2, 0, -3}, 9, bad);
  ASSERT_EQ(*quarantine_->move_aside({2, 0, -3}, "again", nothing_else), std::optional<std::uint64_t>{9});
  EXPECT_EQ(*quarantine_->count(), 2);
  EXPECT_EQ(*quarantine_->revision({2, 0, -3}), std::optional<std::uint64_t>{9});
  EXPECT_EQ(listed().at(1).reason, "again");  // oldest first
  EXPECT_EQ(*quarantine_->in_region({0, 0, -1}), (std::vector<Vec3i>{{2, 0, -3}}));  // each chunk once
}

TEST_F(SqliteQuarantineTest, AChunkWithNoRowMovesNothing) {
  bool also_called = false;
  auto none = quarantine_->move_aside({9, 9, 9}, "nothing there", [&] {
    also_called = true;
    return FileStatus{Ok{}};
  });
  ASSERT_TRUE(none.ok());
  EXPECT_EQ(*none, std::nullopt);
  EXPECT_FALSE(also_called);
  EXPECT_EQ(*quarantine_->count(), 0);
}

TEST_F(SqliteQuarantineTest, WhatGoesWithTheRowFailingRollsTheMoveBack) {
  put_row({5, 5, 5}, 3, {1, 2, 3});
  auto moved = quarantine_->move_aside({5, 5, 5}, "bad",
                                       [] { return FileStatus{FileError{"world x: the coarse image failed", {}}}; });
  ASSERT_FALSE(moved.ok());
  EXPECT_EQ(moved.error().message, "world x: the coarse image failed");
  EXPECT_EQ(row_revision({5, 5, 5}), std::optional<std::uint64_t>{3});
  EXPECT_EQ(*quarantine_->count(), 0);
  // The transaction is over: the next move goes through.
  ASSERT_EQ(*quarantine_->move_aside({5, 5, 5}, "bad", nothing_else), std::optional<std::uint64_t>{3});
}

TEST_F(SqliteQuarantineTest, RowsSurviveReopening) {
  put_row({-1, 0, 0}, 2, {7, 7});
  ASSERT_TRUE(quarantine_->move_aside({-1, 0, 0}, "bad", nothing_else).ok());
  quarantine_.reset();
  ASSERT_NO_FATAL_FAILURE(reopen_db());
  quarantine_ = std::make_unique<SqliteQuarantine>(db_, dir_);
  EXPECT_EQ(*quarantine_->revision({-1, 0, 0}), std::optional<std::uint64_t>{2});
  EXPECT_EQ(listed().at(0).blob, (std::vector<std::uint8_t>{7, 7}));
}

}  // namespace
}  // namespace terrane
