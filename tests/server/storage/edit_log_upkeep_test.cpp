// EditLogUpkeep on a world's SQLite store, as the storage writer runs it:
// the size it publishes is the log's as a count finds it, from the first
// run on and through commits and prunes; prunes follow the retention once
// a period, and a retention set later applies at the next run.
#include "server/storage/edit_log_upkeep.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <memory>
#include <vector>

#include "common/world/sqlite_store.h"
#include "common/world/world.h"
#include "tests/support/scratch_dir.h"

namespace terrane {
namespace {

using namespace std::chrono_literals;

std::int64_t unix_ms_ago(std::chrono::hours ago) {
  return std::chrono::duration_cast<std::chrono::milliseconds>(
             (std::chrono::system_clock::now() - ago).time_since_epoch())
      .count();
}

class EditLogUpkeepTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = testing_support::scratch_dir("terrane-edit-log-upkeep");
    auto store = SqliteStore::create(dir_.string(), default_world_meta());
    ASSERT_TRUE(store.ok()) << store.error().message;
    store_ = std::move(*store);
  }
  void TearDown() override {
    store_.reset();
    std::filesystem::remove_all(dir_);
  }
  // Stores n entries of `bytes` voxel bytes before (and one more after),
  // made `ago` hours back, as a commit does; returns them.
  std::vector<EditLogEntry> write(int n, std::size_t bytes, std::chrono::hours ago = 0h) {
    std::vector<EditLogEntry> log;
    for (int i = 0; i < n; ++i, ++tick_)
      log.push_back(EditLogEntry{0, tick_, unix_ms_ago(ago), "ann", {{0, 0, 0}, {1, 1, 1}},
                                 std::vector<std::uint8_t>(bytes, 1), std::vector<std::uint8_t>(bytes + 1, 2)});
    EXPECT_TRUE(store_->save_chunks({}, true, log).ok());
    return log;
  }
  EditLogSize counted() {
    auto size = store_->edit_log_size();
    EXPECT_TRUE(size.ok());
    return size.ok() ? *size : EditLogSize{-1, 0};
  }

  std::filesystem::path dir_;
  std::unique_ptr<SqliteStore> store_;
  std::uint64_t tick_ = 0;
  EditLogFigure figure_;
  std::atomic<std::uint64_t> pruned_{0};
  EditLogUpkeep upkeep_{figure_, pruned_};
  const std::chrono::steady_clock::time_point t0_ = std::chrono::steady_clock::now();
};

TEST_F(EditLogUpkeepTest, TheFigureIsTheLogsFromTheFirstRunAndGrowsWithEachCommit) {
  EXPECT_EQ(figure_.get(), std::nullopt);  // not counted yet
  upkeep_.run(*store_, t0_);
  EXPECT_EQ(figure_.get(), (EditLogSize{0, 0}));  // no log yet: empty
  write(2, 10);  // not told: the next count finds them
  upkeep_.run(*store_, t0_ + EditLogUpkeep::kPeriod);
  EXPECT_EQ(figure_.get(), (EditLogSize{2, 2 * 21}));
  upkeep_.logged(write(3, 20));
  EXPECT_EQ(figure_.get(), (EditLogSize{5, 2 * 21 + 3 * 41}));
  EXPECT_EQ(figure_.get(), counted());
  // Within the period nothing is counted again (a row written behind its
  // back stays unseen until the next count).
  write(1, 5);
  upkeep_.run(*store_, t0_ + EditLogUpkeep::kPeriod + 30s);
  EXPECT_EQ(figure_.get(), (EditLogSize{5, 2 * 21 + 3 * 41}));
  upkeep_.run(*store_, t0_ + 2 * EditLogUpkeep::kPeriod);
  EXPECT_EQ(figure_.get(), (EditLogSize{6, 2 * 21 + 3 * 41 + 11}));
}

TEST_F(EditLogUpkeepTest, PrunesFollowTheRetentionOncePerPeriodAndTheFigureFollowsThem) {
  write(4, 10, 48h);  // two days old, 21 bytes each
  write(2, 30);       // new, 61 bytes each
  upkeep_.run(*store_, t0_);  // no retention: nothing pruned
  EXPECT_EQ(figure_.get(), (EditLogSize{6, 4 * 21 + 2 * 61}));
  EXPECT_EQ(pruned_.load(), 0u);

  // Set while running: a day's entries; the first prune is due at once.
  upkeep_.set_retention(24h, 0);
  upkeep_.run(*store_, t0_ + 1s);
  EXPECT_EQ(pruned_.load(), 4u);
  EXPECT_EQ(figure_.get(), (EditLogSize{2, 2 * 61}));
  EXPECT_EQ(figure_.get(), counted());

  // The next prune waits a period.
  upkeep_.logged(write(1, 10, 48h));
  upkeep_.run(*store_, t0_ + 30s);
  EXPECT_EQ(pruned_.load(), 4u);
  EXPECT_EQ(figure_.get(), (EditLogSize{3, 2 * 61 + 21}));
  upkeep_.run(*store_, t0_ + 1s + EditLogUpkeep::kPeriod);
  EXPECT_EQ(pruned_.load(), 5u);
  EXPECT_EQ(figure_.get(), (EditLogSize{2, 2 * 61}));

  // By size: the oldest go until 100 bytes fit.
  upkeep_.set_retention(0s, 100);
  upkeep_.run(*store_, t0_ + 1s + 2 * EditLogUpkeep::kPeriod);
  EXPECT_EQ(pruned_.load(), 6u);
  EXPECT_EQ(figure_.get(), (EditLogSize{1, 61}));
  EXPECT_EQ(figure_.get(), counted());
}

TEST(EditLogFigure, IsUnknownUntilSetAndGrowsOnlyOnceKnown) {
  EditLogFigure f;
  f.add(3, 30);
  EXPECT_EQ(f.get(), std::nullopt);
  f.set(EditLogSize{1, 10});
  f.add(3, 30);
  EXPECT_EQ(f.get(), (EditLogSize{4, 40}));
  f.set(std::nullopt);  // a count failed
  EXPECT_EQ(f.get(), std::nullopt);
}

}  // namespace
}  // namespace terrane
