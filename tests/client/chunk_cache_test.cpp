#include "client/chunk_cache.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include "client/replica.h"
#include "client/view_coverage.h"
#include "common/world/coarse_image.h"
#include "common/world/world_bounds.h"

namespace terrane {
namespace {

namespace fs = std::filesystem;

constexpr std::uint64_t kWorld = 0x1234abcd5678ef00ull;

class ChunkCacheTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("terrane-chunk-cache-" + std::to_string(::getpid()) + "-" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::shared_ptr<ChunkCache> open(std::uint64_t max_bytes = 1u << 30) {
    auto c = ChunkCache::open(dir_.string(), max_bytes);
    EXPECT_TRUE(c.ok());
    return c.ok() ? *c : nullptr;
  }
  fs::path dir_;
};

// A replica holding chunks of every exact form (and an estimate, which is
// never kept), in two regions.
Replica some_replica() {
  Replica r;
  Box box;
  auto full = [&](Vec3i cp, std::uint64_t rev, int seed) {
    box.resize({kChunkSize, kChunkSize, kChunkSize});
    for (int y = 0; y < kChunkSize; ++y)
      for (int z = 0; z < kChunkSize; ++z)
        for (int x = 0; x < kChunkSize; ++x)
          box.set(x, y, z, y + seed < 20 ? Voxel{static_cast<Material>(1 + (x + z + seed) % 5), static_cast<std::uint8_t>(255 - (x * 7 + y) % 40)} : Voxel{});
    r.apply_stream_record(StreamRecord{StreamRecordKind::kFull, cp, rev, 0, &box, nullptr, {}});
  };
  auto mip = [&](Vec3i cp, std::uint64_t rev, int level, int seed) {
    const int n = kChunkSize >> level;
    box.resize({n, n, n});
    for (int i = 0; i < n * n * n; ++i)
      box.voxels()[static_cast<std::size_t>(i)] = (i + seed) % 3 == 0 ? Voxel{} : Voxel{static_cast<Material>(1 + seed % 7), static_cast<std::uint8_t>(128 + i % 100)};
    r.apply_stream_record(StreamRecord{record_kind_of(mip_form(level)), cp, rev, level, &box, nullptr, {}});
  };
  full({0, 0, 0}, 3, 0);
  full({1, 0, 0}, 1, 5);
  mip({2, 0, 1}, 7, 1, 1);
  mip({3, 1, 1}, 2, 2, 2);
  mip({8, 0, 0}, 9, 3, 3);  // the next region along x
  mip({-1, -1, -1}, 4, 3, 4);
  r.apply_stream_record(StreamRecord{StreamRecordKind::kEmpty, {0, 1, 0}, 0, 0, nullptr, nullptr, {}});
  box.resize({4, 4, 4});
  box.fill(Voxel{1, 255});
  r.apply_stream_record(StreamRecord{StreamRecordKind::kEstimate, {9, 0, 0}, 0, 3, &box, nullptr, {}});
  return r;
}

const StreamedView kView{{16, 16, 16}, 512, 64};

void expect_same_exact_chunks(const Replica& a, const Replica& b) {
  std::size_t n = 0;
  a.for_each_holding([&](Vec3i cp, const Holding& h) {
    if (!claimable(h.form)) {
      EXPECT_EQ(b.holding(cp), nullptr) << "an estimate is never kept";
      return;
    }
    ++n;
    const Holding* got = b.holding(cp);
    ASSERT_NE(got, nullptr) << cp.x << "," << cp.y << "," << cp.z;
    EXPECT_EQ(*got, h);
    if (h.full_resolution()) {
      EXPECT_EQ(a.hash(cp), b.hash(cp));
    } else {
      Box x, y;
      ASSERT_TRUE(a.read_mip(cp, x));
      ASSERT_TRUE(b.read_mip(cp, y));
      EXPECT_TRUE(x == y);
    }
  });
  EXPECT_EQ(n, 7u);
}

TEST_F(ChunkCacheTest, AReplicaSavedLoadsBackChunkForChunk) {
  auto cache = open();
  const Replica a = some_replica();
  const auto saved = save_replica(*cache, kWorld, a);
  ASSERT_TRUE(saved.has_value());
  EXPECT_EQ(*saved, 7u);
  EXPECT_EQ(cache->counters().regions_saved, 3u);
  Replica b;
  EXPECT_EQ(load_view(*cache, kWorld, kView, WorldBounds{}, b), 7u);
  expect_same_exact_chunks(a, b);
  // Another world's id finds nothing.
  Replica c;
  EXPECT_EQ(load_view(*cache, kWorld + 1, kView, WorldBounds{}, c), 0u);
  EXPECT_EQ(c.chunk_count(), 0u);
  // Reopened, the cache knows its files and their size.
  auto again = open();
  EXPECT_EQ(again->counters().bytes, cache->counters().bytes);
  Replica d;
  EXPECT_EQ(load_view(*again, kWorld, kView, WorldBounds{}, d), 7u);
}

TEST_F(ChunkCacheTest, ChunksOutOfTheViewAreNotLoaded) {
  auto cache = open();
  ASSERT_TRUE(save_replica(*cache, kWorld, some_replica()).has_value());
  Replica b;
  // A view of 32 voxels around chunk (0, 0, 0): its neighbours only.
  EXPECT_EQ(load_view(*cache, kWorld, StreamedView{{16, 16, 16}, 32, 32}, WorldBounds{}, b), 4u);
  EXPECT_NE(b.holding({1, 0, 0}), nullptr);
  EXPECT_EQ(b.holding({8, 0, 0}), nullptr);
}

// Every truncation and every flipped byte of a file is a miss: it reads
// back whole or not at all.
TEST_F(ChunkCacheTest, EveryTruncationAndFlippedByteIsAMiss) {
  auto cache = open();
  const Replica a = some_replica();
  ASSERT_TRUE(save_replica(*cache, kWorld, a).has_value());
  const std::string path = cache->path_of(kWorld, {0, 0, 0});
  std::ifstream in(path, std::ios::binary);
  const std::vector<std::uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  ASSERT_GT(bytes.size(), ChunkCache::kHeaderBytes);
  std::size_t records = 0;
  ASSERT_TRUE(ChunkCache::check_file(bytes, kWorld, {0, 0, 0}, [&](const StreamRecord&) { ++records; }).ok());
  EXPECT_EQ(records, 5u);
  for (std::size_t n = 0; n < bytes.size(); ++n)
    ASSERT_FALSE(ChunkCache::check_file(std::span(bytes).first(n), kWorld, {0, 0, 0}, nullptr).ok()) << n;
  for (std::size_t i = 0; i < bytes.size(); i += 1 + i / 64) {
    auto bad = bytes;
    bad[i] ^= 0x20;
    std::size_t delivered = 0;
    EXPECT_FALSE(ChunkCache::check_file(bad, kWorld, {0, 0, 0}, [&](const StreamRecord&) { ++delivered; }).ok()) << i;
    // The header and the checksum are checked before any record is decoded.
    EXPECT_EQ(delivered, 0u) << i;
  }
  EXPECT_FALSE(ChunkCache::check_file(bytes, kWorld + 1, {0, 0, 0}, nullptr).ok());
  EXPECT_FALSE(ChunkCache::check_file(bytes, kWorld, {1, 0, 0}, nullptr).ok());

  // A damaged file in the cache: removed, counted, its chunks streamed
  // again (none held from it); the other regions still load.
  auto bad = bytes;
  bad[ChunkCache::kHeaderBytes + 3] ^= 0xFF;
  { std::ofstream(path, std::ios::binary | std::ios::trunc).write(reinterpret_cast<const char*>(bad.data()), static_cast<std::streamsize>(bad.size())); }
  Replica b;
  EXPECT_EQ(load_view(*cache, kWorld, kView, WorldBounds{}, b), 2u);
  EXPECT_EQ(b.holding({0, 0, 0}), nullptr);
  EXPECT_EQ(cache->counters().regions_damaged, 1u);
  EXPECT_FALSE(fs::exists(path));
}

// A file whose checksum is right but whose records are not all of a kept
// kind: the records delivered before the bad one are dropped again.
TEST_F(ChunkCacheTest, AFileThatFailsPartWayGivesNoChunk) {
  auto cache = open();
  std::vector<std::uint8_t> records;
  Vec3i prev{0, 0, 0};
  put_stream_record_head(StreamRecordKind::kEmpty, {1, 1, 1}, 5, prev, records);
  put_stream_record_head(StreamRecordKind::kReleased, {2, 1, 1}, 5, prev, records);
  const auto file = ChunkCache::file_bytes(kWorld, {0, 0, 0}, records, 2);
  fs::create_directories(fs::path(cache->path_of(kWorld, {0, 0, 0})).parent_path());
  { std::ofstream(cache->path_of(kWorld, {0, 0, 0}), std::ios::binary).write(reinterpret_cast<const char*>(file.data()), static_cast<std::streamsize>(file.size())); }
  auto reopened = open();
  Replica b;
  EXPECT_EQ(load_view(*reopened, kWorld, kView, WorldBounds{}, b), 0u);
  EXPECT_EQ(b.holding({1, 1, 1}), nullptr);
  EXPECT_EQ(reopened->counters().regions_damaged, 1u);
}

// Beyond its size the cache drops the files least recently used.
TEST_F(ChunkCacheTest, AFullCacheDropsTheLeastRecentlyUsedRegions) {
  std::vector<std::uint8_t> records;
  Vec3i prev{0, 0, 0};
  put_stream_record_head(StreamRecordKind::kEmpty, {0, 0, 0}, 1, prev, records);
  const std::size_t file_size = ChunkCache::kHeaderBytes + records.size();
  auto cache = open(3 * file_size);
  auto save = [&](int i) {
    std::vector<std::uint8_t> rec;
    Vec3i p{0, 0, 0};
    put_stream_record_head(StreamRecordKind::kEmpty, Vec3i{8 * i, 0, 0}, 1, p, rec);
    ASSERT_EQ(rec.size(), records.size());
    ASSERT_TRUE(cache->save(kWorld, {i, 0, 0}, rec, 1));
  };
  auto held = [&](int i) { return fs::exists(cache->path_of(kWorld, {i, 0, 0})); };
  save(0);
  save(1);
  save(2);
  EXPECT_TRUE(held(0) && held(1) && held(2));
  save(3);
  EXPECT_FALSE(held(0));
  EXPECT_TRUE(held(1) && held(2) && held(3));
  // Region 1 read again: region 2 is now the least recently used.
  ASSERT_EQ(cache->load(kWorld, {1, 0, 0}, [](const StreamRecord&) {}), 1u);
  save(4);
  EXPECT_TRUE(held(1) && held(3) && held(4));
  EXPECT_FALSE(held(2));
  EXPECT_EQ(cache->counters().regions_evicted, 2u);
  EXPECT_LE(cache->counters().bytes, 3 * file_size);
}

// Spelled with a trailing slash or not, a directory is one cache: what one
// process saved, the next finds (and counts once).
TEST_F(ChunkCacheTest, ADirectoryIsOneCacheHoweverItIsSpelled) {
  auto slash = ChunkCache::open(dir_.string() + "/", 1u << 30);
  ASSERT_TRUE(slash.ok());
  ASSERT_TRUE(save_replica(**slash, kWorld, some_replica()).has_value());
  const auto bytes = (*slash)->counters().bytes;
  auto plain = open();
  EXPECT_EQ(plain->counters().bytes, bytes);
  Replica b;
  EXPECT_EQ(load_view(*plain, kWorld, kView, WorldBounds{}, b), 7u);
  auto again = ChunkCache::open(dir_.string() + "/./", 1u << 30);
  ASSERT_TRUE(again.ok());
  EXPECT_EQ((*again)->path_of(kWorld, {0, 0, 0}), plain->path_of(kWorld, {0, 0, 0}));
}

// Files the cache did not name are never counted or removed.
TEST_F(ChunkCacheTest, OtherFilesInTheDirectoryAreLeftAlone) {
  fs::create_directories(dir_ / "notes");
  fs::create_directories(dir_ / "0123456789abcdef");
  { std::ofstream(dir_ / "notes" / "1_2_3.region") << std::string(5000, 'x'); }
  { std::ofstream(dir_ / "0123456789abcdef" / "mine.region") << std::string(5000, 'x'); }
  { std::ofstream(dir_ / "0123456789abcdef" / "1_2_3.region.99-0.tmp") << std::string(5000, 'x'); }
  auto cache = open(1);  // a size nothing fits: every file it counts goes
  EXPECT_EQ(cache->counters().bytes, 0u);
  ASSERT_TRUE(save_replica(*cache, kWorld, some_replica()).has_value());
  EXPECT_TRUE(fs::exists(dir_ / "notes" / "1_2_3.region"));
  EXPECT_TRUE(fs::exists(dir_ / "0123456789abcdef" / "mine.region"));
  EXPECT_TRUE(fs::exists(dir_ / "0123456789abcdef" / "1_2_3.region.99-0.tmp"));
  EXPECT_EQ(cache->counters().bytes, 0u);  // its own files went, over the size
}

// A chunk the caller names (a hash that did not match) is not kept.
TEST_F(ChunkCacheTest, ChunksNamedBySkipAreNotSaved) {
  auto cache = open();
  const Replica a = some_replica();
  const auto saved = save_replica(*cache, kWorld, a, [](Vec3i cp) { return cp == Vec3i{1, 0, 0}; });
  ASSERT_TRUE(saved.has_value());
  EXPECT_EQ(*saved, 6u);
  Replica b;
  EXPECT_EQ(load_view(*cache, kWorld, kView, WorldBounds{}, b), 6u);
  EXPECT_EQ(b.holding({1, 0, 0}), nullptr);
  EXPECT_NE(b.holding({0, 0, 0}), nullptr);
}

TEST_F(ChunkCacheTest, ADirectoryThatCannotBeMadeIsAnErrorNamingIt) {
  const fs::path file = dir_.string() + ".file";
  { std::ofstream(file) << "x"; }
  auto c = ChunkCache::open((file / "cache").string(), 1 << 20);
  ASSERT_FALSE(c.ok());
  EXPECT_NE(c.error().message.find(file.string()), std::string::npos) << c.error().message;
  fs::remove(file);
}

}  // namespace
}  // namespace terrane
