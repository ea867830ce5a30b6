#include "common/world/sqlite_edit_log.h"

#include <gtest/gtest.h>

#include <string>
#include <vector>

#include <sqlite3.h>

#include "tests/support/scratch_world.h"

namespace terrane {
namespace {

// The edit log over the scratch world's connection.
class SqliteEditLogTest : public testing_support::ScratchWorldTest {
 protected:
  SqliteEditLogTest() : ScratchWorldTest("terrane-edit-log") {}
  void TearDown() override {
    log_.reset();
    ScratchWorldTest::TearDown();
  }
  SqliteEditLog& log() {
    if (!log_) log_ = std::make_unique<SqliteEditLog>(db_, dir_);
    return *log_;
  }
  // Appends in a transaction of its own, as SqliteStore::save_chunks does.
  void append(const std::vector<EditLogEntry>& entries) {
    exec("BEGIN IMMEDIATE");
    auto bytes = log().append(entries);
    ASSERT_TRUE(bytes.ok()) << bytes.error().message;
    exec("COMMIT");
    log().committed(entries.size(), *bytes);
  }
  // What a scan of the table finds.
  EditLogSize counted() {
    sqlite3_stmt* st = nullptr;
    EXPECT_EQ(sqlite3_prepare_v2(db_, "SELECT count(*), coalesce(sum(length(before) + length(after)), 0) FROM edit_log",
                                 -1, &st, nullptr),
              SQLITE_OK);
    EXPECT_EQ(sqlite3_step(st), SQLITE_ROW);
    const EditLogSize out{sqlite3_column_int64(st, 0), static_cast<std::uint64_t>(sqlite3_column_int64(st, 1))};
    sqlite3_finalize(st);
    return out;
  }
  std::unique_ptr<SqliteEditLog> log_;
};

EditLogEntry entry(std::uint64_t tick, std::int64_t ms, const std::string& who, Region box, std::size_t bytes) {
  return EditLogEntry{0, tick, ms, who, box, std::vector<std::uint8_t>(bytes, 1), std::vector<std::uint8_t>(bytes, 2)};
}

TEST_F(SqliteEditLogTest, ANewWorldHasAnEmptyLog) {
  auto listed = log().query(EditLogQuery{});
  ASSERT_TRUE(listed.ok());
  EXPECT_TRUE(listed->empty());
  EXPECT_EQ(*log().size(), (EditLogSize{0, 0}));
  EXPECT_EQ(*log().prune(1'000'000, 1, 100), 0);
  // Appending nothing makes no table either.
  append({});
  auto again = log().query(EditLogQuery{});
  ASSERT_TRUE(again.ok());
  EXPECT_TRUE(again->empty());
}

TEST_F(SqliteEditLogTest, AppendedEntriesReadBackNewestFirstWithTheirBoxesAndVoxels) {
  append({entry(1, 1000, "ann", {{0, 0, 0}, {2, 2, 2}}, 10), entry(2, 2000, "bob", {{10, 0, 10}, {12, 2, 12}}, 20)});
  append({entry(3, 3000, "ann", {{5, 5, 5}, {6, 6, 6}}, 30)});
  EditLogQuery q;
  q.player = "ann";
  q.with_voxels = true;
  auto ann = log().query(q);
  ASSERT_TRUE(ann.ok());
  ASSERT_EQ(ann->size(), 2u);
  EXPECT_EQ((*ann)[0].tick, 3u);
  EXPECT_EQ((*ann)[0].time_ms, 3000);
  EXPECT_EQ((*ann)[0].box, (Region{{5, 5, 5}, {6, 6, 6}}));
  EXPECT_EQ((*ann)[0].before, std::vector<std::uint8_t>(30, 1));
  EXPECT_EQ((*ann)[0].after, std::vector<std::uint8_t>(30, 2));
  EXPECT_EQ((*ann)[1].tick, 1u);
  EXPECT_GT((*ann)[0].id, (*ann)[1].id);
  EditLogQuery near_bob;
  near_bob.box = Region{{11, 1, 11}, {20, 20, 20}};
  auto bob = log().query(near_bob);
  ASSERT_TRUE(bob.ok());
  ASSERT_EQ(bob->size(), 1u);
  EXPECT_EQ((*bob)[0].player, "bob");
  EXPECT_TRUE((*bob)[0].before.empty());  // voxels only when asked
  EditLogQuery recent;
  recent.since_ms = 2000;
  recent.limit = 1;
  EXPECT_EQ(log().query(recent)->at(0).tick, 3u);
  EXPECT_EQ(*log().size(), (EditLogSize{3, 120}));
  EXPECT_EQ(*log().size(), counted());
}

TEST_F(SqliteEditLogTest, AnAppendRolledBackLeavesNothingAndTheSizeKeptUnchanged) {
  append({entry(1, 1000, "ann", {{0, 0, 0}, {1, 1, 1}}, 4)});
  ASSERT_EQ(*log().size(), counted());  // counted once here, then kept
  exec("BEGIN IMMEDIATE");
  ASSERT_TRUE(log().append(std::vector<EditLogEntry>{entry(2, 2000, "bob", {{0, 0, 0}, {1, 1, 1}}, 9)}).ok());
  exec("ROLLBACK");
  EXPECT_EQ(*log().size(), (EditLogSize{1, 8}));
  EXPECT_EQ(counted(), (EditLogSize{1, 8}));
  EXPECT_EQ(log().query(EditLogQuery{})->size(), 1u);
}

TEST_F(SqliteEditLogTest, PruningTakesTheOldFirstAndStopsAtEachBound) {
  std::vector<EditLogEntry> entries;
  // Ticks 0-9 at 1000 * tick ms, 2 * 10 bytes each (200 bytes in all).
  for (std::uint64_t t = 0; t < 10; ++t)
    entries.push_back(entry(t, static_cast<std::int64_t>(1000 * t), "ann", {{0, 0, 0}, {1, 1, 1}}, 10));
  append(entries);
  ASSERT_EQ(*log().size(), counted());
  // By age, at most max_rows: ticks 0-1 of the four older than 4000.
  EXPECT_EQ(*log().prune(4000, 0, 2), 2);
  EXPECT_EQ(*log().size(), counted());
  EXPECT_EQ(log().query(EditLogQuery{})->back().tick, 2u);
  // By age, unbounded rows: ticks 2-3.
  EXPECT_EQ(*log().prune(4000, 0, 10000), 2);
  EXPECT_EQ(*log().size(), (EditLogSize{6, 120}));
  // By size: the oldest go until at most 70 bytes are left (ticks 4-6).
  EXPECT_EQ(*log().prune(0, 70, 10000), 3);
  EXPECT_EQ(*log().size(), (EditLogSize{3, 60}));
  EXPECT_EQ(*log().size(), counted());
  EXPECT_EQ(log().query(EditLogQuery{})->back().tick, 7u);
  // Under both bounds already: nothing goes.
  EXPECT_EQ(*log().prune(0, 60, 10000), 0);
  EXPECT_EQ(counted(), (EditLogSize{3, 60}));
}

TEST_F(SqliteEditLogTest, TheLogSurvivesReopeningAndIsCountedAgain) {
  append({entry(1, 1000, "ann", {{0, 0, 0}, {1, 1, 1}}, 5), entry(2, 2000, "ann", {{0, 0, 0}, {1, 1, 1}}, 6)});
  log_.reset();
  ASSERT_NO_FATAL_FAILURE(reopen_db());
  EXPECT_EQ(*log().size(), (EditLogSize{2, 22}));
  EXPECT_EQ(log().query(EditLogQuery{})->front().tick, 2u);
}

TEST_F(SqliteEditLogTest, ANullPlayerInADamagedWorldReadsAsNoName) {
  append({entry(1, 1000, "ann", {{0, 0, 0}, {1, 1, 1}}, 5)});
  log_.reset();
  ASSERT_NO_FATAL_FAILURE(rewrite_schema("edit_log", "player TEXT NOT NULL", "player TEXT"));
  exec("UPDATE edit_log SET player = NULL");
  auto read = log().query(EditLogQuery{});
  ASSERT_TRUE(read.ok()) << read.error().message;
  ASSERT_EQ(read->size(), 1u);
  EXPECT_EQ(read->front().player, "");
  EXPECT_EQ(read->front().tick, 1u);
}

}  // namespace
}  // namespace terrane
