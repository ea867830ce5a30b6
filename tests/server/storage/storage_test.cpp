// Storage: loads off the caller's thread (stored, generated, quarantined),
// group commits of several ticks in one transaction, and a failed commit
// failing every later tick.
#include "server/storage/storage.h"

#include <gtest/gtest.h>
#include <sqlite3.h>
#include <unistd.h>

#include <filesystem>
#include <future>
#include <map>
#include <tuple>

#include "common/world/sqlite_store.h"
#include "tests/support/gated_store.h"
#include "tests/support/scratch_dir.h"

namespace terrane {
namespace {

namespace fs = std::filesystem;

class StorageTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = testing_support::scratch_dir("terrane-storage");
    auto w = World::create(dir_.string(), default_world_meta());
    ASSERT_TRUE(w.ok()) << w.error().message;
    world_ = std::move(*w);
    auto s = Storage::open(*world_, 2);
    ASSERT_TRUE(s.ok()) << s.error().message;
    storage_ = std::move(*s);
  }
  void TearDown() override {
    storage_.reset();
    world_.reset();
    fs::remove_all(dir_);
  }
  LoadedChunk load(Vec3i cp) {
    std::promise<LoadedChunk> p;
    storage_->load(cp, [&](LoadedChunk c) { p.set_value(std::move(c)); });
    return p.get_future().get();
  }
  static VersionPtr version(Vec3i cp, std::uint64_t rev, Material m) {
    Chunk c;
    c.modify(Region{{0, 0, 0}, {32, 4, 32}}, [&](Vec3i, Voxel) { return solid(m); });
    return std::make_shared<const ChunkVersion>(cp, rev, std::make_shared<const Chunk>(std::move(c)));
  }

  fs::path dir_;
  std::unique_ptr<World> world_;
  std::unique_ptr<Storage> storage_;
};

TEST_F(StorageTest, LoadsGenerateWhatWasNeverStoredAndReadWhatWas) {
  const Vec3i cp{0, 0, 0};
  LoadedChunk g = load(cp);
  ASSERT_TRUE(g.ok) << g.error;
  EXPECT_TRUE(g.generated);
  EXPECT_EQ(g.revision, 0u);
  const Chunk want = world_->generate_chunk(cp);
  ASSERT_EQ(g.chunk == nullptr, want.empty());
  if (g.chunk) {
    EXPECT_EQ(g.chunk->get({5, 5, 5}), want.get({5, 5, 5}));
  }

  std::promise<FileStatus> done;
  storage_->commit({version(cp, 9, materials::kBrick)}, {}, [&](const FileStatus& st) { done.set_value(st); });
  ASSERT_TRUE(done.get_future().get().ok());
  LoadedChunk s = load(cp);
  ASSERT_TRUE(s.ok) << s.error;
  EXPECT_FALSE(s.generated);
  EXPECT_EQ(s.revision, 9u);
  ASSERT_NE(s.chunk, nullptr);
  EXPECT_EQ(s.chunk->get({1, 1, 1}), solid(materials::kBrick));
  EXPECT_EQ(storage_->counters().loaded_from_store.load(), 1u);
  EXPECT_EQ(storage_->counters().generated.load(), 1u);
}

TEST_F(StorageTest, TicksQueuedBehindABusyWriterCommitTogether) {
  // Another connection holds the write lock: the writer's first transaction
  // waits, the ticks queued meanwhile go in one transaction after it.
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open((dir_ / kWorldDatabaseName).string().c_str(), &db), SQLITE_OK);
  sqlite3_busy_timeout(db, 10000);  // a connection opening beside it may hold a lock for a moment
  ASSERT_EQ(sqlite3_exec(db, "BEGIN EXCLUSIVE", nullptr, nullptr, nullptr), SQLITE_OK) << sqlite3_errmsg(db);
  constexpr int kTicks = 6;
  std::vector<std::promise<FileStatus>> done(kTicks);
  std::vector<int> order;
  std::mutex m;
  for (int t = 0; t < kTicks; ++t)
    storage_->commit({version({t, 0, 0}, 1, materials::kRock), version({0, 0, 0}, static_cast<std::uint64_t>(t + 1), materials::kSand)}, {},
                     [&, t](const FileStatus& st) {
                       {
                         std::lock_guard lock(m);
                         order.push_back(t);
                       }
                       done[static_cast<std::size_t>(t)].set_value(st);
                     });
  ASSERT_EQ(sqlite3_exec(db, "ROLLBACK", nullptr, nullptr, nullptr), SQLITE_OK);
  sqlite3_close(db);
  for (auto& d : done) EXPECT_TRUE(d.get_future().get().ok());
  EXPECT_EQ(order, (std::vector<int>{0, 1, 2, 3, 4, 5})) << "ticks are reported in order";
  EXPECT_EQ(storage_->counters().ticks_committed.load(), static_cast<std::uint64_t>(kTicks));
  EXPECT_LT(storage_->counters().commits.load(), static_cast<std::uint64_t>(kTicks));
  EXPECT_EQ(storage_->commits_in_flight(), 0u);
  // The newest revision of a chunk written by several ticks is what is stored.
  LoadedChunk c = load({0, 0, 0});
  EXPECT_EQ(c.revision, static_cast<std::uint64_t>(kTicks));
}

TEST_F(StorageTest, ACommitsCoarseImagesFollowItAndAreReadPastMeanwhile) {
  // Two chunks of region 0 committed: the commit writes no image, a coarse
  // read right after sees both at their revisions, and stopping writes the
  // images (nothing waits for their delay).
  std::promise<FileStatus> done;
  storage_->commit({version({0, 0, 0}, 3, materials::kBrick), version({2, 1, 0}, 5, materials::kSand)}, {},
                   [&](const FileStatus& st) { done.set_value(st); });
  ASSERT_TRUE(done.get_future().get().ok());
  std::promise<LoadedCoarse> read;
  storage_->load_coarse({0, 0, 0}, [&](LoadedCoarse c) { read.set_value(std::move(c)); });
  const LoadedCoarse c = read.get_future().get();
  ASSERT_TRUE(c.ok) << c.error;
  std::map<std::tuple<int, int, int>, std::uint64_t> revisions;
  for (const CoarseEntry& e : c.entries) revisions[{e.chunk_pos.x, e.chunk_pos.y, e.chunk_pos.z}] = e.revision;
  EXPECT_EQ(revisions, (std::map<std::tuple<int, int, int>, std::uint64_t>{{{0, 0, 0}, 3}, {{2, 1, 0}, 5}}));
  for (const CoarseEntry& e : c.entries) {
    if (e.chunk_pos == Vec3i{0, 0, 0}) {
      EXPECT_EQ(e.voxels[0].material, materials::kBrick);
    }
  }
  storage_->stop();
  EXPECT_EQ(storage_->counters().coarse_regions_pending.load(), 0u);
  EXPECT_GE(storage_->counters().coarse_catch_up_duration.count(), 1u);
  auto& store = dynamic_cast<SqliteStore&>(world_->store());
  std::map<std::tuple<int, int, int>, std::uint64_t> stored;
  ASSERT_TRUE(store.for_each_coarse([&](Vec3i, const std::vector<CoarseEntry>& entries) {
                     for (const CoarseEntry& e : entries) stored[{e.chunk_pos.x, e.chunk_pos.y, e.chunk_pos.z}] = e.revision;
                   }).ok());
  EXPECT_EQ(stored, revisions) << "the images as stored, once the writer stopped";
}

TEST_F(StorageTest, ACoarseImageALoadFindsBehindItsRowsIsRewritten) {
  // What a writer killed before catching up leaves: a row newer than its
  // region's image.
  {
    auto other = world_->store().reopen();
    ASSERT_TRUE(other.ok());
    (*other)->set_coarse_behind(true);
    Chunk c;
    c.modify(Region{{0, 0, 0}, {32, 8, 32}}, [&](Vec3i, Voxel) { return solid(materials::kRock); });
    ASSERT_TRUE((*other)->save_chunks(std::vector<ChunkWrite>{{{1, 0, 1}, 4, encode_chunk_blob(c)}}).ok());
  }  // gone without catching up
  std::promise<LoadedCoarse> read;
  storage_->load_coarse({0, 0, 0}, [&](LoadedCoarse c) { read.set_value(std::move(c)); });
  const LoadedCoarse c = read.get_future().get();
  ASSERT_TRUE(c.ok) << c.error;
  ASSERT_EQ(c.entries.size(), 1u);
  EXPECT_EQ(c.entries[0].revision, 4u);
  EXPECT_EQ(c.entries[0].voxels[0].material, materials::kRock);
  storage_->stop();  // the repair the load asked for is written by then
  auto& store = dynamic_cast<SqliteStore&>(world_->store());
  std::vector<CoarseEntry> stored;
  ASSERT_TRUE(store.for_each_coarse([&](Vec3i, const std::vector<CoarseEntry>& entries) {
                     stored.insert(stored.end(), entries.begin(), entries.end());
                   }).ok());
  ASSERT_EQ(stored.size(), 1u);
  EXPECT_EQ(stored[0], c.entries[0]);
}

TEST_F(StorageTest, AFailedCommitFailsEveryLaterTick) {
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open((dir_ / kWorldDatabaseName).string().c_str(), &db), SQLITE_OK);
  sqlite3_busy_timeout(db, 10000);  // a connection opening beside it may hold a lock for a moment
  ASSERT_EQ(sqlite3_exec(db, "BEGIN EXCLUSIVE", nullptr, nullptr, nullptr), SQLITE_OK) << sqlite3_errmsg(db);
  std::promise<FileStatus> first;
  storage_->commit({version({1, 0, 0}, 1, materials::kRock)}, {}, [&](const FileStatus& st) { first.set_value(st); });
  const FileStatus st = first.get_future().get();  // after the store's busy timeout
  EXPECT_FALSE(st.ok());
  ASSERT_EQ(sqlite3_exec(db, "ROLLBACK", nullptr, nullptr, nullptr), SQLITE_OK);
  sqlite3_close(db);
  std::promise<FileStatus> later;
  storage_->commit({version({2, 0, 0}, 1, materials::kRock)}, {}, [&](const FileStatus& s) { later.set_value(s); });
  EXPECT_FALSE(later.get_future().get().ok()) << "the disk is behind the world: nothing more is committed";
  LoadedChunk c = load({2, 0, 0});
  EXPECT_TRUE(c.generated) << "never stored";
}

TEST_F(StorageTest, ADamagedRowIsQuarantinedAndServedAsGeneratedAboveItsRevision) {
  const Vec3i cp{0, 0, 0};
  std::vector<ChunkWrite> w{{cp, 4, {1, 1, 0xFF, 0xFF}}};
  ASSERT_TRUE(world_->store().save_chunks(w).ok());
  LoadedChunk c = load(cp);
  ASSERT_TRUE(c.ok) << c.error;
  EXPECT_TRUE(c.generated);
  EXPECT_EQ(c.revision, 5u);
  EXPECT_EQ(storage_->counters().quarantined.load(), 1u);
  auto n = dynamic_cast<SqliteStore&>(world_->store()).quarantined_count();
  ASSERT_TRUE(n.ok());
  EXPECT_EQ(*n, 1);
}

TEST_F(StorageTest, TicksBehindACommitOfUnknownOutcomeAreToldTheyWereNotStored) {
  // A store whose commit lost its answer and could not find out since:
  // that tick's outcome is unknown, but the ticks behind it are never
  // tried, so they are not stored (a refusal, not "unknown").
  storage_.reset();
  world_.reset();
  auto gate = std::make_shared<testing_support::StoreGate>(std::unordered_set<Vec3i, Vec3iHash>{});
  auto store = SqliteStore::open(dir_.string());
  ASSERT_TRUE(store.ok()) << store.error().message;
  auto w = World::open(std::make_unique<testing_support::GatedStore>(std::move(*store), gate));
  ASSERT_TRUE(w.ok()) << w.error().message;
  world_ = std::move(*w);
  auto s = Storage::open(*world_, 1);
  ASSERT_TRUE(s.ok()) << s.error().message;
  storage_ = std::move(*s);
  FileError unanswered{"commit chunks: the connection was lost; the commit may have been stored", std::nullopt};
  unanswered.outcome_unknown = true;
  gate->fail_saves(unanswered);
  std::promise<FileStatus> first, later;
  storage_->commit({version({1, 0, 0}, 1, materials::kRock)}, {}, [&](const FileStatus& st) { first.set_value(st); });
  const FileStatus unknown = first.get_future().get();
  ASSERT_FALSE(unknown.ok());
  EXPECT_TRUE(unknown.error().outcome_unknown);
  storage_->commit({version({2, 0, 0}, 1, materials::kRock)}, {}, [&](const FileStatus& st) { later.set_value(st); });
  const FileStatus untried = later.get_future().get();
  ASSERT_FALSE(untried.ok());
  EXPECT_FALSE(untried.error().outcome_unknown) << untried.error().message;
}

}  // namespace
}  // namespace terrane
