#include "common/world/sqlite_store.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <set>
#include <tuple>

#include <signal.h>
#include <sqlite3.h>
#include <sys/resource.h>

#include "common/codec/lz4_block.h"
#include "common/world/world.h"
#include "tests/support/scratch_dir.h"

namespace terrane {
namespace {

namespace fs = std::filesystem;

class SqliteStoreTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = testing_support::scratch_dir("terrane-store").string();
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string dir_;
};

Chunk sample_chunk(unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> mat(0, 20), occ(0, 255);
  Box box({32, 32, 32});
  for (int y = 0; y < 32; ++y)
    for (int z = 0; z < 32; ++z)
      for (int x = 0; x < 32; ++x)
        box.set(x, y, z, y < 12 ? solid(materials::kRock)
                                 : (y < 16 ? make_voxel(static_cast<Material>(mat(rng)), static_cast<std::uint8_t>(occ(rng)))
                                           : Voxel{}));
  return Chunk::from_box(box);
}

void expect_same(const Chunk& a, const Chunk& b) {
  for (int level = 0; level < kMipLevels; ++level) {
    Box ba, bb;
    a.read_level(level, ba);
    b.read_level(level, bb);
    ASSERT_EQ(ba, bb) << "level " << level;
  }
}

TEST_F(SqliteStoreTest, CreateThenOpenKeepsMetadata) {
  WorldMeta meta = default_world_meta(42);
  meta.bounds.bounded_xz = true;
  meta.bounds.min_x = -100;
  meta.bounds.max_x = 100;
  meta.bounds.min_z = -50;
  meta.bounds.max_z = 60;
  meta.epoch = 7;
  ASSERT_TRUE(SqliteStore::create(dir_, meta).ok());
  auto store = SqliteStore::open(dir_);
  ASSERT_TRUE(store.ok()) << store.error().message;
  const WorldMeta& m = (*store)->meta();
  EXPECT_EQ(m.generator, GeneratorKind::kTerrain);
  EXPECT_EQ(m.generator_params, meta.generator_params);
  EXPECT_EQ(m.materials, meta.materials);
  EXPECT_EQ(m.materials[1], "Water");
  EXPECT_TRUE(m.bounds.bounded_xz);
  EXPECT_EQ(m.bounds.max_z, 60);
  EXPECT_EQ(m.epoch, 7u);
}

TEST_F(SqliteStoreTest, CreateRefusesExistingWorldAndOpenRefusesMissingOne) {
  ASSERT_TRUE(SqliteStore::create(dir_, default_world_meta()).ok());
  auto again = SqliteStore::create(dir_, default_world_meta());
  ASSERT_FALSE(again.ok());
  EXPECT_NE(again.error().message.find("already exists"), std::string::npos);
  auto missing = SqliteStore::open(dir_ + "-nope");
  ASSERT_FALSE(missing.ok());
  EXPECT_NE(missing.error().message.find("no world here"), std::string::npos);
}

TEST_F(SqliteStoreTest, DurabilitySettingsAreWalAndSynchronousFull) {
  auto store = SqliteStore::create(dir_, default_world_meta());
  ASSERT_TRUE(store.ok());
  EXPECT_EQ(*(*store)->pragma("journal_mode"), "wal");
  EXPECT_EQ(*(*store)->pragma("synchronous"), "2");  // FULL
}

// A backup is a whole world or nothing: one that fails part-way (here a
// file-size limit, as a full disk would) leaves neither DEST nor
// DEST.partial; the next one succeeds, and DEST opens with every chunk.
TEST_F(SqliteStoreTest, AFailedBackupLeavesNoPartialDirectory) {
  auto store = SqliteStore::create(dir_, default_world_meta());
  ASSERT_TRUE(store.ok());
  std::vector<ChunkWrite> writes;
  for (unsigned i = 0; i < 40; ++i) writes.push_back({{static_cast<int>(i), 0, 0}, 1, encode_chunk_blob(sample_chunk(i))});
  ASSERT_TRUE((*store)->save_chunks(writes).ok());
  const std::string dest = dir_ + "-backups/b1";
  {
    // Writes past 64 KiB fail with EFBIG (SIGXFSZ ignored) until restored.
    struct sigaction ignore {}, old {};
    ignore.sa_handler = SIG_IGN;
    ASSERT_EQ(sigaction(SIGXFSZ, &ignore, &old), 0);
    rlimit before{};
    ASSERT_EQ(getrlimit(RLIMIT_FSIZE, &before), 0);
    rlimit small = before;
    small.rlim_cur = 64 << 10;
    ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &small), 0);
    const auto st = (*store)->backup_to(dest, nullptr);
    setrlimit(RLIMIT_FSIZE, &before);
    sigaction(SIGXFSZ, &old, nullptr);
    ASSERT_FALSE(st.ok());
    EXPECT_NE(st.error().message.find("backup " + dest), std::string::npos) << st.error().message;
  }
  EXPECT_FALSE(fs::exists(dest));
  EXPECT_FALSE(fs::exists(dest + ".partial"));
  // One killed part-way leaves DEST.partial: the next backup replaces it.
  fs::create_directories(dest + ".partial");
  std::ofstream(dest + ".partial/world.sqlite") << "half a world";
  ASSERT_TRUE((*store)->backup_to(dest + "/", nullptr).ok());
  EXPECT_FALSE(fs::exists(dest + ".partial"));
  auto copy = SqliteStore::open(dest);
  ASSERT_TRUE(copy.ok()) << copy.error().message;
  EXPECT_EQ(*(*copy)->stored_chunk_count(), 40);
  EXPECT_FALSE((*store)->backup_to(dest, nullptr).ok()) << "a second backup over a world";
  fs::remove_all(dir_ + "-backups");
}

// A world's id: none until named, then kept (a second name is not taken),
// across reopening; a backup of it has none, so its first server names it
// anew.
TEST_F(SqliteStoreTest, AWorldIsNamedOnceAndABackupIsNamedAnew) {
  auto store = SqliteStore::create(dir_, default_world_meta(1));
  ASSERT_TRUE(store.ok());
  EXPECT_EQ((*store)->meta().world_id, 0u);
  auto named = (*store)->name_world(0x1122334455667788ull);
  ASSERT_TRUE(named.ok());
  EXPECT_EQ(*named, 0x1122334455667788ull);
  auto again = (*store)->name_world(99);
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(*again, 0x1122334455667788ull);
  ASSERT_TRUE((*store)->set_epoch(5).ok());
  const std::string dest = dir_ + "-backups/b1";
  ASSERT_TRUE((*store)->backup_to(dest, nullptr).ok());
  store->reset();
  auto reopened = SqliteStore::open(dir_);
  ASSERT_TRUE(reopened.ok());
  EXPECT_EQ((*reopened)->meta().world_id, 0x1122334455667788ull);
  EXPECT_EQ((*reopened)->meta().epoch, 5u);
  auto copy = SqliteStore::open(dest);
  ASSERT_TRUE(copy.ok()) << copy.error().message;
  EXPECT_EQ((*copy)->meta().world_id, 0u);
  EXPECT_EQ((*copy)->meta().epoch, 5u);
  auto copy_named = (*copy)->name_world(7);
  ASSERT_TRUE(copy_named.ok());
  EXPECT_EQ(*copy_named, 7u);
  fs::remove_all(dir_ + "-backups");
}

TEST_F(SqliteStoreTest, ChunksRoundTripWithRevisions) {
  auto store = SqliteStore::create(dir_, default_world_meta());
  ASSERT_TRUE(store.ok());
  const Chunk a = sample_chunk(1), b = sample_chunk(2);
  std::vector<ChunkWrite> writes = {{{0, 0, 0}, 3, encode_chunk_blob(a)}, {{-5, 2, 9}, 8, encode_chunk_blob(b)}};
  ASSERT_TRUE((*store)->save_chunks(writes).ok());
  auto la = (*store)->load_chunk({0, 0, 0});
  ASSERT_TRUE(la.ok());
  ASSERT_TRUE(la->has_value());
  EXPECT_EQ((*la)->revision, 3u);
  expect_same((*la)->chunk, a);
  auto lb = (*store)->load_chunk({-5, 2, 9});
  ASSERT_TRUE(lb.ok() && lb->has_value());
  EXPECT_EQ((*lb)->revision, 8u);
  expect_same((*lb)->chunk, b);
  auto none = (*store)->load_chunk({1, 1, 1});
  ASSERT_TRUE(none.ok());
  EXPECT_FALSE(none->has_value());
  EXPECT_EQ(*(*store)->stored_chunk_count(), 2);
}

TEST_F(SqliteStoreTest, TheEditLogIsWrittenWithTheChunksAndQueriedNewestFirst) {
  auto store = SqliteStore::create(dir_, default_world_meta());
  ASSERT_TRUE(store.ok());
  // Before anything was logged the log is empty, not an error.
  auto empty = (*store)->edit_log(EditLogQuery{});
  ASSERT_TRUE(empty.ok());
  EXPECT_TRUE(empty->empty());
  auto entry = [](std::uint64_t tick, std::int64_t ms, const std::string& who, Region box, std::size_t bytes) {
    return EditLogEntry{0, tick, ms, who, box, std::vector<std::uint8_t>(bytes, 1), std::vector<std::uint8_t>(bytes, 2)};
  };
  const std::vector<EditLogEntry> log = {entry(1, 1000, "ann", {{0, 0, 0}, {2, 2, 2}}, 10),
                                         entry(2, 2000, "bob", {{10, 0, 10}, {12, 2, 12}}, 20),
                                         entry(3, 3000, "ann", {{5, 5, 5}, {6, 6, 6}}, 30)};
  const std::vector<ChunkWrite> writes = {{{0, 0, 0}, 1, encode_chunk_blob(sample_chunk(1))}};
  ASSERT_TRUE((*store)->save_chunks(writes, true, log).ok());
  EditLogQuery q;
  q.player = "ann";
  q.with_voxels = true;
  auto ann = (*store)->edit_log(q);
  ASSERT_TRUE(ann.ok());
  ASSERT_EQ(ann->size(), 2u);
  EXPECT_EQ((*ann)[0].tick, 3u);  // newest first
  EXPECT_EQ((*ann)[1].tick, 1u);
  EXPECT_EQ((*ann)[0].box, (Region{{5, 5, 5}, {6, 6, 6}}));
  EXPECT_EQ((*ann)[0].before, std::vector<std::uint8_t>(30, 1));
  EXPECT_EQ((*ann)[0].after, std::vector<std::uint8_t>(30, 2));
  EditLogQuery near_bob;
  near_bob.box = Region{{11, 1, 11}, {20, 20, 20}};
  auto b = (*store)->edit_log(near_bob);
  ASSERT_TRUE(b.ok());
  ASSERT_EQ(b->size(), 1u);
  EXPECT_EQ((*b)[0].player, "bob");
  EXPECT_TRUE((*b)[0].before.empty());  // voxels only when asked
  EditLogQuery recent;
  recent.since_ms = 2000;
  recent.limit = 1;
  EXPECT_EQ((*store)->edit_log(recent)->at(0).tick, 3u);
  EXPECT_EQ((*store)->edit_log_size()->entries, 3);
  EXPECT_EQ((*store)->edit_log_size()->bytes, 120u);
  // Pruning: by age, then the oldest until the bytes fit.
  EXPECT_EQ(*(*store)->prune_edit_log(1500, 0), 1);
  EXPECT_EQ(*(*store)->prune_edit_log(0, 60), 1);  // 100 bytes left > 60: bob's (the older) goes
  auto left = (*store)->edit_log(EditLogQuery{});
  ASSERT_EQ(left->size(), 1u);
  EXPECT_EQ(left->at(0).tick, 3u);
}

TEST_F(SqliteStoreTest, TheEditLogsSizeIsKeptThroughWritesAndPrunesAsACountWouldFindIt) {
  auto store = SqliteStore::create(dir_, default_world_meta());
  ASSERT_TRUE(store.ok());
  // What a scan of the table finds, from a connection of its own.
  const auto counted = [&] {
    sqlite3* db = nullptr;
    EXPECT_EQ(sqlite3_open((dir_ + "/world.sqlite").c_str(), &db), SQLITE_OK);
    sqlite3_stmt* st = nullptr;
    EXPECT_EQ(sqlite3_prepare_v2(db, "SELECT count(*), coalesce(sum(length(before) + length(after)), 0) FROM edit_log",
                                 -1, &st, nullptr),
              SQLITE_OK);
    EXPECT_EQ(sqlite3_step(st), SQLITE_ROW);
    const EditLogSize out{sqlite3_column_int64(st, 0), static_cast<std::uint64_t>(sqlite3_column_int64(st, 1))};
    sqlite3_finalize(st);
    sqlite3_close(db);
    return out;
  };
  std::uint64_t tick = 0;
  const auto write = [&](int entries, std::size_t bytes) {
    std::vector<EditLogEntry> log;
    for (int i = 0; i < entries; ++i, ++tick)
      log.push_back(EditLogEntry{0, tick, static_cast<std::int64_t>(1000 * tick), "ann", {{0, 0, 0}, {1, 1, 1}},
                                 std::vector<std::uint8_t>(bytes, 1), std::vector<std::uint8_t>(bytes + 1, 2)});
    const std::vector<ChunkWrite> writes = {{{0, 0, 0}, tick, encode_chunk_blob(sample_chunk(1))}};
    ASSERT_TRUE((*store)->save_chunks(writes, true, log).ok());
  };
  write(5, 10);
  ASSERT_EQ(*(*store)->edit_log_size(), counted());  // counted once here
  write(7, 20);
  EXPECT_EQ(*(*store)->edit_log_size(), counted());
  EXPECT_EQ(*(*store)->prune_edit_log(3000, 0), 3);  // by age (time 1000 * tick): ticks 0-2
  EXPECT_EQ(*(*store)->edit_log_size(), counted());
  write(4, 30);
  // By bytes: 9 entries of 21 or 41 bytes and 4 of 61 (573 bytes); the
  // oldest go until 300 fit (ticks 3-10).
  EXPECT_EQ(*(*store)->prune_edit_log(0, 300), 8);
  EXPECT_EQ(*(*store)->edit_log_size(), counted());
  EXPECT_EQ(*(*store)->prune_edit_log(0, 0), 0);    // nothing to do
  // Both: age takes ticks 11 and 12, then bytes 13 and 14 (61 bytes left).
  EXPECT_EQ(*(*store)->prune_edit_log(13000, 100), 4);
  EXPECT_EQ(*(*store)->edit_log_size(), counted());
  EXPECT_EQ(counted(), (EditLogSize{1, 61}));
  // Kept, not counted again (a prune by size once a minute scanned the
  // whole log): a row written behind the store's back is not seen. A world
  // has one writer, the server holding it.
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open((dir_ + "/world.sqlite").c_str(), &db), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(db,
                         "INSERT INTO edit_log(tick, time, player, x0, y0, z0, x1, y1, z1, before, after) "
                         "VALUES(99, 99000, 'bob', 0, 0, 0, 1, 1, 1, zeroblob(5), zeroblob(5))",
                         nullptr, nullptr, nullptr),
            SQLITE_OK);
  sqlite3_close(db);
  EXPECT_EQ(*(*store)->edit_log_size(), (EditLogSize{1, 61}));
  EXPECT_EQ(counted(), (EditLogSize{2, 71}));
}

TEST_F(SqliteStoreTest, DamagedBlobIsReportedWithItsCoordinates) {
  auto store = SqliteStore::create(dir_, default_world_meta());
  ASSERT_TRUE(store.ok());
  std::vector<std::uint8_t> blob = encode_chunk_blob(sample_chunk(3));
  blob.resize(blob.size() / 2);
  std::vector<ChunkWrite> writes = {{{4, -1, 7}, 1, blob}};
  ASSERT_TRUE((*store)->save_chunks(writes).ok());
  auto loaded = (*store)->load_chunk({4, -1, 7});
  ASSERT_FALSE(loaded.ok());
  EXPECT_NE(loaded.error().message.find("(4, -1, 7)"), std::string::npos) << loaded.error().message;
  EXPECT_TRUE(loaded.error().decode.has_value());
}

TEST_F(SqliteStoreTest, QuarantineMovesTheRowAsideAndSavesNeverTouchIt) {
  auto store = SqliteStore::create(dir_, default_world_meta());
  ASSERT_TRUE(store.ok());
  SqliteStore& s = **store;
  std::vector<std::uint8_t> bad = encode_chunk_blob(sample_chunk(5));
  bad.resize(bad.size() / 3);
  const Chunk good = sample_chunk(6);
  std::vector<ChunkWrite> writes = {{{2, 0, -3}, 7, bad}, {{0, 0, 0}, 4, encode_chunk_blob(good)}};
  ASSERT_TRUE(s.save_chunks(writes).ok());
  ASSERT_FALSE(s.load_chunk({2, 0, -3}).ok());

  auto moved = s.quarantine_chunk({2, 0, -3}, "truncated blob");
  ASSERT_TRUE(moved.ok()) << moved.error().message;
  ASSERT_TRUE(moved->has_value());
  EXPECT_EQ(**moved, 7u);
  // Gone from chunks (the other chunk untouched), kept byte for byte aside.
  auto after = s.load_chunk({2, 0, -3});
  ASSERT_TRUE(after.ok());
  EXPECT_FALSE(after->has_value());
  EXPECT_EQ(*s.stored_chunk_count(), 1);
  EXPECT_EQ(*s.quarantined_count(), 1);
  std::vector<QuarantinedChunk> q;
  ASSERT_TRUE(s.for_each_quarantined([&](const QuarantinedChunk& c) { q.push_back(c); }).ok());
  ASSERT_EQ(q.size(), 1u);
  EXPECT_EQ(q[0].pos, (Vec3i{2, 0, -3}));
  EXPECT_EQ(q[0].revision, 7u);
  EXPECT_EQ(q[0].reason, "truncated blob");
  EXPECT_EQ(q[0].blob, bad);
  EXPECT_GT(q[0].time_unix_s, 1700000000);  // a real clock reading (2023 or later)

  // Quarantining a chunk with no row moves nothing.
  auto none = s.quarantine_chunk({9, 9, 9}, "nothing there");
  ASSERT_TRUE(none.ok());
  EXPECT_FALSE(none->has_value());
  EXPECT_EQ(*s.quarantined_count(), 1);

  // A later save of the chunk writes a fresh row; the quarantined blob stays.
  std::vector<ChunkWrite> again = {{{2, 0, -3}, 9, encode_chunk_blob(good)}};
  ASSERT_TRUE(s.save_chunks(again).ok());
  q.clear();
  ASSERT_TRUE(s.for_each_quarantined([&](const QuarantinedChunk& c) { q.push_back(c); }).ok());
  ASSERT_EQ(q.size(), 1u);
  EXPECT_EQ(q[0].blob, bad);
  EXPECT_EQ(*s.quarantined_revision({2, 0, -3}), std::optional<std::uint64_t>{7});
  EXPECT_EQ(*s.quarantined_revision({0, 0, 0}), std::nullopt);
}

TEST_F(SqliteStoreTest, QuarantinedChunkLoadsGeneratedWithItsRevisionAboveTheQuarantinedOne) {
  {
    auto world = World::create(dir_, default_world_meta());
    ASSERT_TRUE(world.ok());
    std::vector<ChunkWrite> writes = {{{1, 0, 1}, 12, {1, 1, 0xff, 0x00, 0x13}}};
    ASSERT_TRUE((*world)->store().save_chunks(writes).ok());
    ASSERT_TRUE((*world)->store().quarantine_chunk({1, 0, 1}, "bad").ok());
  }
  // Reopened: the quarantine survives and the chunk's revisions continue.
  auto world = World::open(dir_);
  ASSERT_TRUE(world.ok());
  auto c = (*world)->load_chunk({1, 0, 1});
  ASSERT_TRUE(c.ok()) << c.error().message;
  EXPECT_EQ(c->revision, 13u);
  expect_same(c->chunk, (*world)->generate_chunk({1, 0, 1}));
  Box box({4, 4, 4});
  ASSERT_TRUE((*world)->write_box({32, 0, 32}, box).ok());
  auto stored = (*world)->store().load_chunk({1, 0, 1});
  ASSERT_TRUE(stored.ok() && stored->has_value());
  EXPECT_EQ((*stored)->revision, 14u);
  EXPECT_EQ(*dynamic_cast<SqliteStore&>((*world)->store()).quarantined_count(), 1);
}

TEST_F(SqliteStoreTest, WorldsWithoutTheQuarantineTableGainItOnOpen) {
  ASSERT_TRUE(SqliteStore::create(dir_, default_world_meta()).ok());
  {
    sqlite3* db = nullptr;
    ASSERT_EQ(sqlite3_open((fs::path(dir_) / kWorldDatabaseName).string().c_str(), &db), SQLITE_OK);
    ASSERT_EQ(sqlite3_exec(db, "DROP TABLE quarantine", nullptr, nullptr, nullptr), SQLITE_OK);
    sqlite3_close(db);
  }
  auto store = SqliteStore::open(dir_);
  ASSERT_TRUE(store.ok()) << store.error().message;
  EXPECT_EQ(*(*store)->quarantined_count(), 0);
}

TEST_F(SqliteStoreTest, ReopenedStoreKeepsWalAndSynchronousFull) {
  ASSERT_TRUE(SqliteStore::create(dir_, default_world_meta()).ok());
  auto store = SqliteStore::open(dir_);
  ASSERT_TRUE(store.ok());
  // The settings the durability promise rests on, on the connection a server
  // uses (World::open opens the store this way).
  EXPECT_EQ(*(*store)->pragma("journal_mode"), "wal");
  EXPECT_EQ(*(*store)->pragma("synchronous"), "2");  // FULL
  auto world = World::open(dir_);
  ASSERT_TRUE(world.ok());
  EXPECT_EQ(*dynamic_cast<SqliteStore&>((*world)->store()).pragma("journal_mode"), "wal");
  EXPECT_EQ(*dynamic_cast<SqliteStore&>((*world)->store()).pragma("synchronous"), "2");
}

TEST(ChunkBlob, RejectsEveryTruncationAndBadHeader) {
  const std::vector<std::uint8_t> blob = encode_chunk_blob(sample_chunk(4));
  ASSERT_TRUE(decode_chunk_blob(blob).ok());
  for (std::size_t n = 0; n < blob.size(); ++n)
    EXPECT_FALSE(decode_chunk_blob(std::span(blob.data(), n)).ok()) << "prefix " << n;
  std::vector<std::uint8_t> bad = blob;
  bad[0] = 9;
  EXPECT_EQ(decode_chunk_blob(bad).error().code, DecodeErrorCode::kBadVersion);
}

TEST_F(SqliteStoreTest, WorldGeneratesUnstoredChunksAndStoresEditsWithGrowingRevision) {
  auto world = World::create(dir_, default_world_meta(5));
  ASSERT_TRUE(world.ok()) << world.error().message;
  World& w = **world;
  const Vec3i cp{0, 0, 0};
  auto generated = w.load_chunk(cp);
  ASSERT_TRUE(generated.ok());
  EXPECT_EQ(generated->revision, 0u);
  expect_same(generated->chunk, w.generate_chunk(cp));

  Box edit({3, 3, 3}, solid(materials::kBrick));
  ASSERT_TRUE(w.write_box({30, 5, 30}, edit).ok());  // spans 4 chunks (x and z cross a border)
  ASSERT_TRUE(w.write_box({30, 5, 30}, edit).ok());
  auto stored = w.load_chunk(cp);
  ASSERT_TRUE(stored.ok());
  EXPECT_EQ(stored->revision, 2u);
  Box back({3, 3, 3});
  ASSERT_TRUE(w.read_box({30, 5, 30}, back).ok());
  EXPECT_EQ(back, edit);
  EXPECT_EQ(*w.store().stored_chunk_count(), 4);
}

TEST_F(SqliteStoreTest, BoundsClipGenerationAndWrites) {
  WorldMeta meta = default_world_meta(5);
  meta.bounds.min_y = 0;
  meta.bounds.max_y = 64;
  auto world = World::create(dir_, meta);
  ASSERT_TRUE(world.ok());
  Box below({32, 32, 32});
  (*world)->generate_chunk_box({0, -1, 0}, below);
  for (const Voxel v : below.voxels()) ASSERT_EQ(v, Voxel{});
  Box edit({1, 1, 1}, solid(materials::kBrick));
  ASSERT_TRUE((*world)->write_box({0, 100, 0}, edit).ok());
  EXPECT_EQ(*(*world)->store().stored_chunk_count(), 0);
}

}  // namespace
}  // namespace terrane

namespace terrane {
namespace {
TEST_F(SqliteStoreTest, OutOfRangeBoundsAreRefusedAndLeaveNothingBehind) {
  WorldMeta meta = default_world_meta();
  meta.bounds.max_y = 1'100'000'000;
  auto bad = SqliteStore::create(dir_, meta);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().message.find("2^30"), std::string::npos) << bad.error().message;
  EXPECT_FALSE(SqliteStore::exists(dir_));
  EXPECT_TRUE(SqliteStore::create(dir_, default_world_meta()).ok());
}

TEST_F(SqliteStoreTest, SaveWithoutOverwriteKeepsStoredChunks) {
  auto store = SqliteStore::create(dir_, default_world_meta());
  ASSERT_TRUE(store.ok());
  std::vector<ChunkWrite> edited = {{{0, 0, 0}, 5, encode_chunk_blob(sample_chunk(7))}};
  ASSERT_TRUE((*store)->save_chunks(edited).ok());
  std::vector<ChunkWrite> generated = {{{0, 0, 0}, 0, encode_chunk_blob(sample_chunk(8))},
                                       {{1, 0, 0}, 0, encode_chunk_blob(sample_chunk(8))}};
  ASSERT_TRUE((*store)->save_chunks(generated, /*overwrite=*/false).ok());
  auto kept = (*store)->load_chunk({0, 0, 0});
  ASSERT_TRUE(kept.ok() && kept->has_value());
  EXPECT_EQ((*kept)->revision, 5u);
  expect_same((*kept)->chunk, sample_chunk(7));
  EXPECT_EQ(*(*store)->stored_chunk_count(), 2);
}

TEST_F(SqliteStoreTest, EmptyMaterialTableRoundTripsEmpty) {
  WorldMeta meta = default_world_meta();
  meta.materials.clear();
  ASSERT_TRUE(SqliteStore::create(dir_, meta).ok());
  auto store = SqliteStore::open(dir_);
  ASSERT_TRUE(store.ok());
  EXPECT_TRUE((*store)->meta().materials.empty());
}
}  // namespace
}  // namespace terrane

namespace terrane {
namespace {

// Every stored chunk has the coarse entry its blob implies, and no entry
// lacks a chunk (what terrane-world check verifies).
void expect_coarse_matches_chunks(SqliteStore& s) {
  std::map<std::tuple<int, int, int>, CoarseEntry> from_chunks, from_images;
  ASSERT_TRUE(s.for_each_chunk([&](Vec3i p, std::uint64_t rev, std::span<const std::uint8_t> blob) {
                 auto c = decode_chunk_blob(blob);
                 if (c) from_chunks[{p.x, p.y, p.z}] = CoarseEntry{p, rev, coarse_voxels(&*c)};
               }).ok());
  ASSERT_TRUE(s.for_each_coarse([&](Vec3i r, const std::vector<CoarseEntry>& entries) {
                 for (const CoarseEntry& e : entries) {
                   EXPECT_EQ(coarse_region_of(e.chunk_pos), r);
                   from_images[{e.chunk_pos.x, e.chunk_pos.y, e.chunk_pos.z}] = e;
                 }
               }).ok());
  EXPECT_EQ(from_images, from_chunks);
}

TEST_F(SqliteStoreTest, CoarseImagesFollowEveryWriteEraseAndQuarantine) {
  auto s = SqliteStore::create(dir_, default_world_meta(1));
  ASSERT_TRUE(s.ok());
  SqliteStore& store = **s;
  // Chunks in two regions, one on a region's negative edge.
  std::vector<ChunkWrite> writes;
  const Vec3i spots[] = {{0, 0, 0}, {7, 1, 7}, {-1, 0, 0}, {-8, -2, 3}, {8, 0, 0}};
  for (unsigned i = 0; i < 5; ++i) writes.push_back(ChunkWrite{spots[i], 1 + i, encode_chunk_blob(sample_chunk(i))});
  ASSERT_TRUE(store.save_chunks(writes).ok());
  expect_coarse_matches_chunks(store);
  auto r0 = store.load_coarse({0, 0, 0});
  ASSERT_TRUE(r0.ok());
  ASSERT_EQ(r0->size(), 2u);  // (0,0,0) and (7,1,7)
  EXPECT_EQ((*r0)[0].revision, 1u);
  EXPECT_EQ((*r0)[0].voxels, coarse_voxels(&*decode_chunk_blob(writes[0].blob)));
  EXPECT_TRUE(store.load_coarse({5, 5, 5})->empty());

  // A new revision replaces the entry; a save without overwrite keeps both.
  ASSERT_TRUE(store.save_chunks(std::vector<ChunkWrite>{{{0, 0, 0}, 9, encode_chunk_blob(sample_chunk(20))}}).ok());
  ASSERT_TRUE(store.save_chunks(std::vector<ChunkWrite>{{{0, 0, 0}, 10, encode_chunk_blob(sample_chunk(21))},
                                                        {{1, 0, 0}, 2, encode_chunk_blob(sample_chunk(22))}},
                                false)
                  .ok());
  expect_coarse_matches_chunks(store);
  EXPECT_EQ(store.load_coarse({0, 0, 0})->front().revision, 9u);
  // A chunk's coarse voxels given by the writer are taken as they are.
  const Chunk c = sample_chunk(30);
  ASSERT_TRUE(store.save_chunks(std::vector<ChunkWrite>{{{2, 0, 0}, 3, encode_chunk_blob(c), coarse_voxels(&c)}}).ok());
  expect_coarse_matches_chunks(store);

  ASSERT_TRUE(store.erase_chunk({7, 1, 7}).ok());
  expect_coarse_matches_chunks(store);
  // A damaged blob gets no entry; quarantining a chunk removes its entry.
  ASSERT_TRUE(store.save_chunks(std::vector<ChunkWrite>{{{-1, 0, 0}, 6, {1, 1, 0xff, 0x00, 0x13}}}).ok());
  expect_coarse_matches_chunks(store);
  ASSERT_TRUE(store.quarantine_chunk({-8, -2, 3}, "test").ok());
  expect_coarse_matches_chunks(store);
  EXPECT_TRUE(store.load_coarse({-1, -1, 0})->empty());
}

TEST_F(SqliteStoreTest, AFormatOneWorldGainsItsCoarseImagesWhenOpened) {
  {
    auto s = SqliteStore::create(dir_, default_world_meta(1));
    ASSERT_TRUE(s.ok());
    std::vector<ChunkWrite> writes;
    for (int i = 0; i < 40; ++i)
      writes.push_back(ChunkWrite{{i % 10 - 5, i / 20, (i * 7) % 13 - 6}, static_cast<std::uint64_t>(i + 1),
                                  encode_chunk_blob(sample_chunk(static_cast<unsigned>(i)))});
    ASSERT_TRUE((*s)->save_chunks(writes).ok());
  }
  // As the previous format left it: no coarse table, format_version 1.
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open((dir_ + "/world.sqlite").c_str(), &db), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(db, "DROP TABLE coarse; UPDATE meta SET value = '1' WHERE key = 'format_version'", nullptr,
                         nullptr, nullptr),
            SQLITE_OK);
  sqlite3_close(db);
  std::int64_t last_done = -1, last_total = -1;
  auto s = SqliteStore::open(dir_, [&](std::int64_t done, std::int64_t total) {
    EXPECT_GE(done, last_done);
    last_done = done;
    last_total = total;
  });
  ASSERT_TRUE(s.ok()) << s.error().message;
  EXPECT_EQ(last_done, 40);
  EXPECT_EQ(last_total, 40);
  EXPECT_EQ((*s)->meta().format_version, kWorldFormatVersion);
  expect_coarse_matches_chunks(**s);
  s->reset();
  // Opened again: nothing more to do.
  bool called = false;
  auto again = SqliteStore::open(dir_, [&](std::int64_t, std::int64_t) { called = true; });
  ASSERT_TRUE(again.ok());
  EXPECT_FALSE(called);
}

TEST_F(SqliteStoreTest, AFormatTwoWorldKeepsItsCodecOneBlobsAndBecomesFormatThree) {
  // A world as format 2 wrote it: codec-1 blobs (byte RLE + LZ4).
  std::vector<Chunk> chunks;
  {
    auto s = SqliteStore::create(dir_, default_world_meta(1));
    ASSERT_TRUE(s.ok());
    std::vector<ChunkWrite> writes;
    for (int i = 0; i < 12; ++i) {
      chunks.push_back(sample_chunk(static_cast<unsigned>(i)));
      Box box;
      chunks.back().read_level(0, box);
      writes.push_back(ChunkWrite{{i, 0, 0}, 1, encode_chunk_blob_byte_rle(box), coarse_voxels(&chunks.back())});
      ASSERT_EQ(writes.back().blob[1], 1) << "codec 1";
    }
    ASSERT_TRUE((*s)->save_chunks(writes).ok());
  }
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open((dir_ + "/world.sqlite").c_str(), &db), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(db, "UPDATE meta SET value = '2' WHERE key = 'format_version'", nullptr, nullptr, nullptr),
            SQLITE_OK);
  sqlite3_close(db);
  bool rebuilt = false;
  auto s = SqliteStore::open(dir_, [&](std::int64_t, std::int64_t) { rebuilt = true; });
  ASSERT_TRUE(s.ok()) << s.error().message;
  EXPECT_FALSE(rebuilt) << "format 2 -> 3 rewrites nothing";
  EXPECT_EQ((*s)->meta().format_version, 3u);
  for (int i = 0; i < 12; ++i) {
    auto got = (*s)->load_chunk({i, 0, 0});
    ASSERT_TRUE(got.ok() && got->has_value()) << i;
    expect_same((**got).chunk, chunks[static_cast<std::size_t>(i)]);
  }
  // A chunk written now is codec 2; the others keep their codec-1 blobs.
  ASSERT_TRUE((*s)->save_chunks(std::vector<ChunkWrite>{{{0, 0, 0}, 2, encode_chunk_blob(chunks[5])}}).ok());
  auto again = (*s)->load_chunk({0, 0, 0});
  ASSERT_TRUE(again.ok() && again->has_value());
  expect_same((**again).chunk, chunks[5]);
  std::map<int, int> codecs;
  ASSERT_TRUE((*s)->for_each_chunk([&](Vec3i, std::uint64_t, std::span<const std::uint8_t> blob) {
                    ++codecs[blob[1]];
                  }).ok());
  EXPECT_EQ(codecs[2], 1);
  EXPECT_EQ(codecs[1], 11);
  s->reset();
  // A format-3 world is refused by a reader of format 2 (its metadata says 3).
  db = nullptr;
  ASSERT_EQ(sqlite3_open((dir_ + "/world.sqlite").c_str(), &db), SQLITE_OK);
  sqlite3_stmt* v = nullptr;
  ASSERT_EQ(sqlite3_prepare_v2(db, "SELECT value FROM meta WHERE key = 'format_version'", -1, &v, nullptr), SQLITE_OK);
  ASSERT_EQ(sqlite3_step(v), SQLITE_ROW);
  EXPECT_STREQ(reinterpret_cast<const char*>(sqlite3_column_text(v, 0)), "3");
  sqlite3_finalize(v);
  sqlite3_close(db);
}

TEST(ChunkBlob, CodecTwoCarriesTheChunkAsItIsAndItsChecksumCatchesDamage) {
  for (unsigned seed = 0; seed < 6; ++seed) {
    const Chunk c = sample_chunk(seed);
    const auto blob = encode_chunk_blob(c);
    ASSERT_EQ(blob[0], 1);
    ASSERT_EQ(blob[1], 2);
    auto back = decode_chunk_blob(blob);
    ASSERT_TRUE(back.ok()) << back.error().detail;
    expect_same(*back, c);
    EXPECT_EQ(back->level0().heap_bytes(), c.level0().heap_bytes()) << "the same packing, not packed again";
    EXPECT_EQ(encode_chunk_blob(*back), blob);
    // Codec 1 of the same voxels decodes to the same chunk.
    Box box;
    c.read_level(0, box);
    auto old = decode_chunk_blob(encode_chunk_blob_byte_rle(box));
    ASSERT_TRUE(old.ok());
    expect_same(*old, c);
  }
  auto blob = encode_chunk_blob(sample_chunk(2));
  blob[3] ^= 0x10;  // the checksum
  auto got = decode_chunk_blob(blob);
  ASSERT_FALSE(got.ok());
  EXPECT_EQ(got.error().code, DecodeErrorCode::kInvalidValue);
  EXPECT_EQ(got.error().offset, 2u);
  blob = encode_chunk_blob(sample_chunk(2));
  blob[1] = 3;
  EXPECT_EQ(decode_chunk_blob(blob).error().offset, 1u) << "an unknown codec";
}

TEST_F(SqliteStoreTest, ADamagedCoarseImageIsMadeAgainFromItsChunksOnTheNextWrite) {
  auto s = SqliteStore::create(dir_, default_world_meta(1));
  ASSERT_TRUE(s.ok());
  ASSERT_TRUE((*s)->save_chunks(std::vector<ChunkWrite>{{{0, 0, 0}, 1, encode_chunk_blob(sample_chunk(1))},
                                                        {{3, 0, 0}, 2, encode_chunk_blob(sample_chunk(2))}})
                  .ok());
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open((dir_ + "/world.sqlite").c_str(), &db), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(db, "UPDATE coarse SET image = x'0101ff'", nullptr, nullptr, nullptr), SQLITE_OK);
  sqlite3_close(db);
  EXPECT_FALSE((*s)->load_coarse({0, 0, 0}).ok()) << "the damage is reported on read";
  // A write into the region succeeds and leaves a whole, correct image.
  ASSERT_TRUE((*s)->save_chunks(std::vector<ChunkWrite>{{{5, 0, 0}, 1, encode_chunk_blob(sample_chunk(3))}}).ok());
  expect_coarse_matches_chunks(**s);
  EXPECT_EQ((*s)->load_coarse({0, 0, 0})->size(), 3u);
}

TEST(CoarseImage, RoundTripsAndRefusesDamage) {
  const Vec3i region{-1, 0, 2};
  std::vector<CoarseEntry> entries;
  for (int i : {0, 5, 511, 64}) {
    CoarseEntry e;
    e.chunk_pos = region * kCoarseRegionChunks + Vec3i{i % 8, i / 64, (i / 8) % 8};
    e.revision = 1000u + static_cast<unsigned>(i);
    e.voxels[static_cast<std::size_t>(i % 64)] = make_voxel(materials::kBrick, 7);
    entries.push_back(e);
  }
  const auto blob = encode_coarse_image(region, entries);
  auto back = decode_coarse_image(region, blob);
  ASSERT_TRUE(back.ok());
  std::sort(entries.begin(), entries.end(),
            [](const CoarseEntry& a, const CoarseEntry& b) { return coarse_index(a.chunk_pos) < coarse_index(b.chunk_pos); });
  EXPECT_EQ(*back, entries);
  // Every truncation, and a wrong version or codec, is an error.
  for (std::size_t n = 0; n < blob.size(); ++n)
    EXPECT_FALSE(decode_coarse_image(region, std::span(blob.data(), n)).ok()) << n;
  auto bad = blob;
  bad[0] = 2;
  EXPECT_FALSE(decode_coarse_image(region, bad).ok());
  // Raw payloads with a bad index order, a bad material, Air with occupancy.
  const auto with_raw = [](std::vector<std::uint8_t> raw) {
    std::vector<std::uint8_t> out{1, 1};
    lz4_compress(raw, out);
    return out;
  };
  std::vector<std::uint8_t> two(2 + 2 * 138, 0);
  two[0] = 2;
  two[2] = 5;              // first index 5
  two[2 + 138] = 5;        // second index 5 again
  EXPECT_FALSE(decode_coarse_image(region, with_raw(two)).ok());
  std::vector<std::uint8_t> one(2 + 138, 0);
  one[0] = 1;
  one[2 + 10] = 64;        // material 64
  EXPECT_FALSE(decode_coarse_image(region, with_raw(one)).ok());
  one[2 + 10] = 0;
  one[2 + 11] = 9;         // Air with occupancy
  EXPECT_FALSE(decode_coarse_image(region, with_raw(one)).ok());
  one[2 + 11] = 0;
  EXPECT_TRUE(decode_coarse_image(region, with_raw(one)).ok());
}

}  // namespace
}  // namespace terrane

namespace terrane {
namespace {

// The coarse entries load_coarse gives for every region that has chunks
// (what a server reads), against the chunks' own.
void expect_loads_match_chunks(SqliteStore& s) {
  std::map<std::tuple<int, int, int>, CoarseEntry> from_chunks, from_loads;
  std::set<std::tuple<int, int, int>> regions;
  ASSERT_TRUE(s.for_each_chunk([&](Vec3i p, std::uint64_t rev, std::span<const std::uint8_t> blob) {
                 auto c = decode_chunk_blob(blob);
                 if (c) from_chunks[{p.x, p.y, p.z}] = CoarseEntry{p, rev, coarse_voxels(&*c)};
                 const Vec3i r = coarse_region_of(p);
                 regions.insert({r.x, r.y, r.z});
               }).ok());
  for (const auto& [rx, ry, rz] : regions) {
    auto entries = s.load_coarse({rx, ry, rz});
    ASSERT_TRUE(entries.ok()) << entries.error().message;
    for (std::size_t i = 0; i < entries->size(); ++i) {
      const CoarseEntry& e = (*entries)[i];
      if (i > 0) {
        EXPECT_LT(coarse_index((*entries)[i - 1].chunk_pos), coarse_index(e.chunk_pos)) << "in index order";
      }
      from_loads[{e.chunk_pos.x, e.chunk_pos.y, e.chunk_pos.z}] = e;
    }
  }
  EXPECT_EQ(from_loads, from_chunks);
}

TEST_F(SqliteStoreTest, CoarseImagesBehindTheChunksAreReadPastThenCaughtUp) {
  auto created = SqliteStore::create(dir_, default_world_meta(1));
  ASSERT_TRUE(created.ok());
  ASSERT_TRUE((*created)->save_chunks(std::vector<ChunkWrite>{{{0, 0, 0}, 1, encode_chunk_blob(sample_chunk(1))},
                                                              {{3, 0, 0}, 1, encode_chunk_blob(sample_chunk(2))},
                                                              {{9, 0, 0}, 1, encode_chunk_blob(sample_chunk(3))}})
                  .ok());
  // A server's writer: its images follow the chunks; a reader beside it.
  auto writer_opened = (*created)->reopen();
  ASSERT_TRUE(writer_opened.ok());
  WorldStore& writer = **writer_opened;
  writer.set_coarse_behind(true);
  SqliteStore& reader = **created;
  // A new revision, a new chunk (region 0), a decoded-free write (region 1).
  const Chunk c9 = sample_chunk(40);
  ASSERT_TRUE(writer.save_chunks(std::vector<ChunkWrite>{{{0, 0, 0}, 2, encode_chunk_blob(sample_chunk(10))},
                                                         {{5, 1, 0}, 1, encode_chunk_blob(sample_chunk(11))},
                                                         {{9, 0, 0}, 4, encode_chunk_blob(c9), coarse_voxels(&c9)}})
                  .ok());
  EXPECT_EQ(writer.coarse_pending(), 2u);
  // As stored, the images are behind: region 0 still has revision 1 and no (5, 1, 0)...
  std::map<std::tuple<int, int, int>, std::uint64_t> stored;
  ASSERT_TRUE(reader.for_each_coarse([&](Vec3i, const std::vector<CoarseEntry>& entries) {
                     for (const CoarseEntry& e : entries) stored[{e.chunk_pos.x, e.chunk_pos.y, e.chunk_pos.z}] = e.revision;
                   }).ok());
  EXPECT_EQ(stored[std::make_tuple(0, 0, 0)], 1u);
  EXPECT_EQ(stored.count({5, 1, 0}), 0u);
  // ...but every load, on either connection, reads past that.
  expect_loads_match_chunks(reader);
  expect_loads_match_chunks(dynamic_cast<SqliteStore&>(writer));
  // Nothing is due before its time; then all of it, and the images as
  // stored match the chunks.
  auto left = writer.catch_up_coarse(8, std::chrono::hours(1));
  ASSERT_TRUE(left.ok());
  EXPECT_EQ(*left, 2u);
  left = writer.catch_up_coarse(1, std::chrono::seconds(0));
  ASSERT_TRUE(left.ok());
  EXPECT_EQ(*left, 1u);  // a region per transaction asked for
  left = writer.catch_up_coarse(8, std::chrono::seconds(0));
  ASSERT_TRUE(left.ok());
  EXPECT_EQ(*left, 0u);
  expect_coarse_matches_chunks(reader);

  // A writer that stops without catching up (a crash) leaves its images
  // behind; loads after a restart still match the chunks and say so.
  ASSERT_TRUE(writer.save_chunks(std::vector<ChunkWrite>{{{3, 0, 0}, 7, encode_chunk_blob(sample_chunk(12))},
                                                         {{1, 2, 3}, 1, encode_chunk_blob(sample_chunk(13))},
                                                         {{9, 0, 0}, 8, encode_chunk_blob(sample_chunk(15))}})
                  .ok());
  writer_opened->reset();
  created->reset();
  auto reopened = SqliteStore::open(dir_);
  ASSERT_TRUE(reopened.ok());
  expect_loads_match_chunks(**reopened);
  ASSERT_TRUE((*reopened)->load_coarse({0, 0, 0}).ok());
  EXPECT_TRUE((*reopened)->coarse_read_behind());
  std::uint64_t behind = 0;
  ASSERT_TRUE((*reopened)->for_each_coarse([&](Vec3i, const std::vector<CoarseEntry>& entries) {
                 for (const CoarseEntry& e : entries)
                   if (e.chunk_pos == Vec3i{3, 0, 0} && e.revision < 7) ++behind;
               }).ok());
  EXPECT_EQ(behind, 1u);
  // A server's writer asked to repair region 0 (its loads found it behind)
  // rewrites it from its rows with nothing of its own to add...
  auto writer2 = (*reopened)->reopen();
  ASSERT_TRUE(writer2.ok());
  (*writer2)->set_coarse_behind(true);
  (*writer2)->repair_coarse({0, 0, 0});
  EXPECT_EQ((*writer2)->coarse_pending(), 1u);
  left = (*writer2)->catch_up_coarse(8, std::chrono::seconds(0));
  ASSERT_TRUE(left.ok());
  EXPECT_EQ(*left, 0u);
  ASSERT_TRUE((*reopened)->load_coarse({0, 0, 0}).ok());
  EXPECT_FALSE((*reopened)->coarse_read_behind());
  ASSERT_TRUE((*reopened)->load_coarse({1, 0, 0}).ok());
  EXPECT_TRUE((*reopened)->coarse_read_behind());
  // ...and a tool's write into region 1 catches the rest of region 1 up.
  ASSERT_TRUE((*reopened)->save_chunks(std::vector<ChunkWrite>{{{10, 0, 0}, 1, encode_chunk_blob(sample_chunk(14))}}).ok());
  expect_coarse_matches_chunks(**reopened);
}

TEST_F(SqliteStoreTest, ClosingTheStoreClosesItsConnectionAfterEveryOwnerUsedIt) {
  {
    auto store = SqliteStore::create(dir_, default_world_meta());
    ASSERT_TRUE(store.ok());
    SqliteStore& s = **store;
    // Every owner prepares its statements: chunks, edit log, coarse images,
    // quarantine, access.
    const std::vector<ChunkWrite> writes = {{{0, 0, 0}, 1, encode_chunk_blob(sample_chunk(1))},
                                            {{1, 0, 0}, 1, {1, 1, 0xff}}};
    const std::vector<EditLogEntry> log = {EditLogEntry{0, 1, 1000, "ann", {{0, 0, 0}, {1, 1, 1}}, {1}, {2}}};
    ASSERT_TRUE(s.save_chunks(writes, true, log).ok());
    ASSERT_TRUE(s.load_coarse({0, 0, 0}).ok());
    ASSERT_TRUE(s.quarantine_chunk({1, 0, 0}, "bad").ok());
    ASSERT_TRUE(s.quarantined_revision({1, 0, 0}).ok());
    ASSERT_TRUE(s.put_access("ban:bob", "1").ok());
    ASSERT_TRUE(fs::exists(dir_ + "/world.sqlite-wal"));
  }
  // The last connection closed checkpoints and removes the WAL: it would
  // stay if a statement had been left unfinalized (the close refused).
  EXPECT_FALSE(fs::exists(dir_ + "/world.sqlite-wal"));
}

}  // namespace
}  // namespace terrane
