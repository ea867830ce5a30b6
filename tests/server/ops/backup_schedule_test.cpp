// Scheduled backups (server/ops/backup_schedule.h): at a short interval the
// schedule makes backup after backup and keeps the newest N, each one a
// whole world, touching nothing else in its directory; a backup that fails is counted and
// leaves nothing; the counters reach /metrics' text.
#include "server/ops/backup_schedule.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "common/world/sqlite_store.h"
#include "common/world/world.h"
#include "tests/support/eventually.h"
#include "tests/support/scratch_dir.h"

namespace terrane {
namespace {

namespace fs = std::filesystem;

class BackupScheduleTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = testing_support::scratch_dir("terrane-backups");
    auto store = SqliteStore::create((dir_ / "world").string(), default_world_meta());
    ASSERT_TRUE(store.ok()) << store.error().message;
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

TEST_F(BackupScheduleTest, MakesABackupEachPeriodAndKeepsTheNewestN) {
  const fs::path backups = dir_ / "backups";
  fs::create_directories(backups);
  // Not a backup of the schedule's: never touched.
  fs::create_directories(backups / "manual-copy");
  BackupSchedule schedule({std::chrono::milliseconds(100), 2, backups.string()}, (dir_ / "world").string());
  schedule.start();
  // N + 1 made: the first was removed when the third was kept.
  ASSERT_TRUE(testing_support::eventually([&] { return schedule.counters().made.load() >= 3; }))
      << schedule.counters().made.load() << " made, " << schedule.counters().failed.load() << " failed";
  schedule.stop();
  const auto made = schedule.counters().made.load();
  EXPECT_EQ(schedule.counters().failed.load(), 0u);
  const auto kept = BackupSchedule::backups_in(backups.string());
  ASSERT_EQ(kept.size(), 2u) << made << " made";
  EXPECT_LT(kept[0], kept[1]);
  for (const auto& name : kept) {
    auto copy = SqliteStore::open((backups / name).string());
    EXPECT_TRUE(copy.ok()) << name << ": " << copy.error().message;
    EXPECT_FALSE(fs::exists(backups / (name + ".partial")));
  }
  EXPECT_TRUE(fs::exists(backups / "manual-copy"));
  // Nothing else was left: the kept backups and the manual copy.
  int entries = 0;
  for (const auto& e : fs::directory_iterator(backups)) (void)e, ++entries;
  EXPECT_EQ(entries, 3);
  const auto last_ms = schedule.counters().last_success_unix_ms.load();
  const auto now_ms = std::chrono::duration_cast<std::chrono::milliseconds>(
                          std::chrono::system_clock::now().time_since_epoch())
                          .count();
  EXPECT_GT(last_ms, now_ms - 60'000);
  EXPECT_LE(last_ms, now_ms);
  const std::string text = render_backup_metrics(schedule.counters());
  EXPECT_NE(text.find("terrane_backups_total " + std::to_string(made) + "\n"), std::string::npos) << text;
  EXPECT_NE(text.find("terrane_backup_failures_total 0\n"), std::string::npos) << text;
  EXPECT_NE(text.find("terrane_backup_last_success_timestamp_seconds " + std::to_string(last_ms / 1000) + "." ),
            std::string::npos)
      << text;
}

TEST_F(BackupScheduleTest, AFailedBackupIsCountedAndLeavesNothing) {
  // The backup directory cannot be made: a file stands in its way.
  const fs::path blocked = dir_ / "blocked";
  std::ofstream(blocked) << "a file";
  BackupSchedule schedule({std::chrono::milliseconds(100), 2, (blocked / "backups").string()},
                          (dir_ / "world").string());
  std::string why;
  EXPECT_EQ(schedule.backup_once(&why), "");
  EXPECT_NE(why.find("cannot create"), std::string::npos) << why;
  EXPECT_EQ(schedule.counters().failed.load(), 1u);
  EXPECT_EQ(schedule.counters().made.load(), 0u);
  EXPECT_EQ(schedule.counters().last_success_unix_ms.load(), 0);
  // A world that is not there: counted too, and no directory is left.
  BackupSchedule missing({std::chrono::milliseconds(100), 2, (dir_ / "b2").string()}, (dir_ / "none").string());
  EXPECT_EQ(missing.backup_once(&why), "");
  EXPECT_EQ(missing.counters().failed.load(), 1u);
  EXPECT_TRUE(BackupSchedule::backups_in((dir_ / "b2").string()).empty());
  EXPECT_NE(render_backup_metrics(missing.counters()).find("terrane_backup_failures_total 1\n"), std::string::npos);
}

}  // namespace
}  // namespace terrane
