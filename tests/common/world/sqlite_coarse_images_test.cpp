#include "common/world/sqlite_coarse_images.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <memory>
#include <string>
#include <vector>

#include <sqlite3.h>

#include "tests/support/scratch_world.h"

namespace terrane {
namespace {

// The coarse images over the scratch world's connection, reading the
// chunk rows through it.
class SqliteCoarseImagesTest : public testing_support::ScratchWorldTest {
 protected:
  SqliteCoarseImagesTest() : ScratchWorldTest("terrane-coarse") {}
  void SetUp() override {
    ASSERT_NO_FATAL_FAILURE(ScratchWorldTest::SetUp());
    images_ = std::make_unique<SqliteCoarseImages>(db_, dir_, [this](Vec3i p) { return load_row(p); });
  }
  void TearDown() override {
    images_.reset();
    ScratchWorldTest::TearDown();
  }
  FileResult<std::optional<StoredChunk>> load_row(Vec3i pos) {
    sqlite3_stmt* st = nullptr;
    sqlite3_prepare_v2(db_, "SELECT revision, data FROM chunks WHERE cx = ? AND cy = ? AND cz = ?", -1, &st, nullptr);
    sqlite3_bind_int(st, 1, pos.x);
    sqlite3_bind_int(st, 2, pos.y);
    sqlite3_bind_int(st, 3, pos.z);
    FileResult<std::optional<StoredChunk>> out = std::optional<StoredChunk>{};
    if (sqlite3_step(st) == SQLITE_ROW) {
      const auto* data = static_cast<const std::uint8_t*>(sqlite3_column_blob(st, 1));
      auto chunk = decode_chunk_blob({data, static_cast<std::size_t>(sqlite3_column_bytes(st, 1))});
      if (chunk)
        out = std::optional<StoredChunk>{
            StoredChunk{static_cast<std::uint64_t>(sqlite3_column_int64(st, 0)), std::move(*chunk)}};
      else
        out = FileError{"damaged", chunk.error()};
    }
    sqlite3_finalize(st);
    return out;
  }
  // Rows written with their entries, in one transaction, as
  // SqliteStore::save_chunks does.
  void write(const std::vector<CoarseEntry>& entries) {
    exec("BEGIN IMMEDIATE");
    for (const CoarseEntry& e : entries) put_row(e.chunk_pos, e.revision, blob_of(e.chunk_pos, e.revision));
    ASSERT_TRUE(images_->written(entries, {}).ok());
    exec("COMMIT");
    images_->committed(entries);
  }
  // A chunk's voxels, different for each position and revision.
  static Box box_of(Vec3i pos, std::uint64_t revision) {
    Box box({32, 32, 32});
    const int top = static_cast<int>((pos.x * 7 + pos.y * 3 + pos.z * 5 + static_cast<int>(revision)) & 31);
    for (int y = 0; y <= top; ++y)
      for (int z = 0; z < 32; ++z)
        for (int x = 0; x < 32; ++x) box.set(x, y, z, solid(static_cast<Material>(1 + (top + x / 8) % 20)));
    return box;
  }
  static std::vector<std::uint8_t> blob_of(Vec3i pos, std::uint64_t revision) {
    return encode_chunk_blob(box_of(pos, revision));
  }
  static CoarseEntry entry(Vec3i pos, std::uint64_t revision) {
    return CoarseEntry{pos, revision, coarse_voxels(box_of(pos, revision))};
  }
  static std::vector<CoarseEntry> in_index_order(std::vector<CoarseEntry> v) {
    std::sort(v.begin(), v.end(),
              [](const CoarseEntry& a, const CoarseEntry& b) { return coarse_index(a.chunk_pos) < coarse_index(b.chunk_pos); });
    return v;
  }
  std::unique_ptr<SqliteCoarseImages> images_;
};

constexpr std::chrono::steady_clock::duration kNow{0};

TEST_F(SqliteCoarseImagesTest, ImagesWrittenWithTheChunksReadBackAsStored) {
  const std::vector<CoarseEntry> first = {entry({3, 0, 1}, 2), entry({0, 0, 0}, 5), entry({7, 7, 7}, 1)};
  const std::vector<CoarseEntry> second = {entry({8, 0, 0}, 4)};
  write(first);
  write(second);
  EXPECT_EQ(images_->pending(), 0u);
  EXPECT_EQ(*images_->load_as_kept({0, 0, 0}), in_index_order(first));
  EXPECT_EQ(*images_->load({0, 0, 0}), in_index_order(first));
  EXPECT_FALSE(images_->read_behind());
  EXPECT_EQ(*images_->load({1, 0, 0}), second);
  EXPECT_TRUE(images_->load({5, 5, 5})->empty());
  std::vector<Vec3i> regions;
  ASSERT_TRUE(images_->for_each([&](Vec3i r, const std::vector<CoarseEntry>& e) {
                       regions.push_back(r);
                       EXPECT_FALSE(e.empty());
                     }).ok());
  EXPECT_EQ(regions, (std::vector<Vec3i>{{0, 0, 0}, {1, 0, 0}}));
  // A newer revision of one chunk replaces its entry only.
  write({entry({3, 0, 1}, 3)});
  EXPECT_EQ(*images_->load_as_kept({0, 0, 0}), in_index_order({entry({3, 0, 1}, 3), first[1], first[2]}));
}

TEST_F(SqliteCoarseImagesTest, BehindTheChunksChangesWaitAreReadPastThenCaughtUp) {
  write({entry({1, 1, 1}, 1)});
  images_->set_behind(true);
  const std::vector<CoarseEntry> later = {entry({1, 1, 1}, 2), entry({2, 1, 1}, 1)};
  write(later);
  write({entry({-1, 0, 0}, 6)});  // another region
  EXPECT_EQ(images_->pending(), 2u);
  EXPECT_EQ(*images_->load_as_kept({0, 0, 0}), std::vector<CoarseEntry>{entry({1, 1, 1}, 1)});
  EXPECT_EQ(*images_->load({0, 0, 0}), in_index_order(later));  // read past the image
  EXPECT_TRUE(images_->read_behind());
  // Not due yet: nothing written.
  EXPECT_EQ(*images_->catch_up(10, std::chrono::hours(1)), 2u);
  EXPECT_EQ(*images_->load_as_kept({0, 0, 0}), std::vector<CoarseEntry>{entry({1, 1, 1}, 1)});
  // One region at a time.
  EXPECT_EQ(*images_->catch_up(1, kNow), 1u);
  EXPECT_EQ(*images_->catch_up(1, kNow), 0u);
  EXPECT_EQ(*images_->load_as_kept({0, 0, 0}), in_index_order(later));
  EXPECT_EQ(*images_->load_as_kept({-1, 0, 0}), std::vector<CoarseEntry>{entry({-1, 0, 0}, 6)});
  EXPECT_EQ(*images_->load({0, 0, 0}), in_index_order(later));
  EXPECT_FALSE(images_->read_behind());
}

TEST_F(SqliteCoarseImagesTest, ErasedAndUndecodableRowsLoseTheirEntries) {
  write({entry({0, 0, 0}, 1), entry({1, 0, 0}, 1), entry({2, 0, 0}, 1)});
  exec("BEGIN IMMEDIATE");
  exec("DELETE FROM chunks WHERE cx = 1 AND cy = 0 AND cz = 0");
  ASSERT_TRUE(images_->erased({1, 0, 0}).ok());
  exec("COMMIT");
  EXPECT_EQ(*images_->load_as_kept({0, 0, 0}), (std::vector<CoarseEntry>{entry({0, 0, 0}, 1), entry({2, 0, 0}, 1)}));
  exec("BEGIN IMMEDIATE");
  put_row({2, 0, 0}, 2, {1, 1, 0xff});
  ASSERT_TRUE(images_->written({}, {{2, 0, 0}}).ok());
  exec("COMMIT");
  EXPECT_EQ(*images_->load_as_kept({0, 0, 0}), std::vector<CoarseEntry>{entry({0, 0, 0}, 1)});
  EXPECT_EQ(*images_->load({0, 0, 0}), std::vector<CoarseEntry>{entry({0, 0, 0}, 1)});
}

TEST_F(SqliteCoarseImagesTest, RebuildMakesEveryImageFromTheRows) {
  put_row({0, 0, 0}, 3, blob_of({0, 0, 0}, 3));
  put_row({9, 0, 0}, 1, blob_of({9, 0, 0}, 1));
  put_row({9, 0, 1}, 1, {1, 1, 0xff});  // damaged: no entry
  put_row({-8, 2, 0}, 7, blob_of({-8, 2, 0}, 7));
  exec("DROP TABLE coarse");
  const auto rows = [&](const SqliteCoarseImages::ChunkRowFn& fn) -> FileStatus {
    sqlite3_stmt* st = nullptr;
    sqlite3_prepare_v2(db_, "SELECT cx, cy, cz, revision, data FROM chunks ORDER BY cx, cy, cz", -1, &st, nullptr);
    while (sqlite3_step(st) == SQLITE_ROW) {
      const auto* data = static_cast<const std::uint8_t*>(sqlite3_column_blob(st, 4));
      fn(Vec3i{sqlite3_column_int(st, 0), sqlite3_column_int(st, 1), sqlite3_column_int(st, 2)},
         static_cast<std::uint64_t>(sqlite3_column_int64(st, 3)),
         {data, static_cast<std::size_t>(sqlite3_column_bytes(st, 4))});
    }
    sqlite3_finalize(st);
    return Ok{};
  };
  int seen = 0;
  exec("BEGIN IMMEDIATE");
  ASSERT_TRUE(images_->rebuild(rows, [&] { ++seen; }).ok());
  exec("COMMIT");
  EXPECT_EQ(seen, 4);
  EXPECT_EQ(*images_->load_as_kept({0, 0, 0}), std::vector<CoarseEntry>{entry({0, 0, 0}, 3)});
  EXPECT_EQ(*images_->load_as_kept({1, 0, 0}), std::vector<CoarseEntry>{entry({9, 0, 0}, 1)});
  EXPECT_EQ(*images_->load_as_kept({-1, 0, 0}), std::vector<CoarseEntry>{entry({-8, 2, 0}, 7)});
  std::vector<Vec3i> regions;
  ASSERT_TRUE(images_->for_each([&](Vec3i r, const std::vector<CoarseEntry>&) { regions.push_back(r); }).ok());
  EXPECT_EQ(regions.size(), 3u);
}

TEST_F(SqliteCoarseImagesTest, ADamagedImageIsRepairedFromItsRows) {
  write({entry({0, 0, 0}, 1), entry({4, 4, 4}, 2)});
  exec("UPDATE coarse SET image = x'0102ff' WHERE rx = 0 AND ry = 0 AND rz = 0");
  auto kept = images_->load_as_kept({0, 0, 0});
  ASSERT_FALSE(kept.ok());
  EXPECT_TRUE(kept.error().decode.has_value());
  EXPECT_NE(kept.error().message.find("region (0, 0, 0)"), std::string::npos) << kept.error().message;
  images_->set_behind(true);
  images_->repair({0, 0, 0});
  EXPECT_EQ(images_->pending(), 1u);
  EXPECT_EQ(*images_->catch_up(1, kNow), 0u);
  EXPECT_EQ(*images_->load_as_kept({0, 0, 0}), (std::vector<CoarseEntry>{entry({0, 0, 0}, 1), entry({4, 4, 4}, 2)}));
}

}  // namespace
}  // namespace terrane
