#include "client/replica.h"

#include <gtest/gtest.h>

#include <algorithm>

#include "common/codec/update_batch.h"

namespace terrane {
namespace {

// A record without voxels (Empty, Released) of chunk cp.
StreamRecord bare(StreamRecordKind kind, Vec3i cp, std::uint64_t revision) {
  return StreamRecord{kind, cp, revision, 0, nullptr, nullptr, {}};
}
// A Full record of a chunk filled with one voxel value (box kept alive by
// the caller).
StreamRecord full_record(Vec3i cp, std::uint64_t revision, Box& box, Voxel fill) {
  box.resize({kChunkSize, kChunkSize, kChunkSize});
  box.fill(fill);
  return StreamRecord{StreamRecordKind::kFull, cp, revision, 0, &box, nullptr, {}};
}
// A Mip record of a chunk at level (1..3) filled with one value.
StreamRecord mip_record(Vec3i cp, std::uint64_t revision, int level, Box& box, Voxel fill) {
  const int n = kChunkSize >> level;
  box.resize({n, n, n});
  box.fill(fill);
  return StreamRecord{record_kind_of(mip_form(level)), cp, revision, level, &box, nullptr, {}};
}

TEST(Replica, UnknownIsNotAir) {
  Replica r;
  EXPECT_EQ(r.resolution_at({5, 5, 5}), kNoResolution);
  EXPECT_EQ(r.holding({0, 0, 0}), nullptr);
  EXPECT_FALSE(r.hash({0, 0, 0}).has_value());
  r.apply_stream_record(bare(StreamRecordKind::kEmpty, {0, 0, 0}, 3));
  EXPECT_EQ(*r.holding({0, 0, 0}), (Holding{HoldingForm::kEmpty, 3}));
  EXPECT_EQ(r.resolution_at({5, 5, 5}), 0);
  EXPECT_EQ(r.hash({0, 0, 0}), chunk_hash(nullptr, 3));
}

TEST(Replica, MipThenFullThenReleased) {
  Replica r;
  const Vec3i cp{1, 0, -1};
  Box mip, whole;
  r.apply_stream_record(mip_record(cp, 2, 3, mip, solid(materials::kRock)));
  const Vec3i inside = chunk_origin(cp) + Vec3i{9, 9, 9};
  EXPECT_EQ(r.resolution_at(inside), 3);
  EXPECT_EQ(*r.holding(cp), (Holding{HoldingForm::kMip3, 2}));
  EXPECT_EQ(r.get(inside), solid(materials::kRock));
  EXPECT_FALSE(r.hash(cp).has_value());  // a mip cannot be verified

  r.apply_stream_record(full_record(cp, 2, whole, solid(materials::kSand)));
  EXPECT_EQ(r.resolution_at(inside), 0);
  EXPECT_EQ(*r.holding(cp), (Holding{HoldingForm::kFull, 2}));
  EXPECT_EQ(r.get(inside), solid(materials::kSand));
  Chunk expect(materials::kSand);
  EXPECT_EQ(r.hash(cp), chunk_hash(&expect, 2));

  r.apply_stream_record(bare(StreamRecordKind::kReleased, cp, 2));
  EXPECT_EQ(r.resolution_at(inside), kNoResolution);
  EXPECT_EQ(r.holding(cp), nullptr);
  EXPECT_EQ(r.grid().chunk_count(), 0u);
}

TEST(Replica, AHorizonImageCoversOnlyChunksWithNothingAndGivesWayToTheirOwnRecords) {
  Replica r;
  // Region (0, 0, 0) at level 4: 2^3 voxels per chunk; the image's column x
  // is material 1 + x (chunk i has columns 2i and 2i + 1).
  Box image({16, 16, 16});
  for (int y = 0; y < 16; ++y)
    for (int z = 0; z < 16; ++z)
      for (int x = 0; x < 16; ++x) image.set(x, y, z, solid(static_cast<Material>(1 + x)));
  const Vec3i held{1, 0, 0};
  Box mip3;
  r.apply_stream_record(mip_record(held, 7, 3, mip3, solid(materials::kSand)));
  HorizonMask mask{};
  mask[0] = 0b111;  // chunks x = 0, 1, 2 of y = z = 0
  std::vector<Vec3i> covered;
  r.apply_horizon(StreamRecord{StreamRecordKind::kHorizon, {0, 0, 0}, 0, kHorizonNearLevel, &image, &mask, {}}, covered);
  EXPECT_EQ(covered, (std::vector<Vec3i>{{0, 0, 0}, {2, 0, 0}})) << "the chunk held already is not covered";
  EXPECT_EQ(r.holding(held)->form, HoldingForm::kMip3);
  ASSERT_NE(r.holding({2, 0, 0}), nullptr);
  EXPECT_EQ(*r.holding({2, 0, 0}), (Holding{HoldingForm::kHorizon4, 0}));
  EXPECT_EQ(r.holding({2, 0, 0})->level(), kHorizonNearLevel);
  EXPECT_EQ(r.holding({3, 0, 0}), nullptr) << "outside the mask";
  EXPECT_EQ(r.get({70, 5, 5}), solid(5)) << "chunk 2's voxels are the image's columns 4 and 5";
  EXPECT_EQ(r.resolution_at({70, 5, 5}), kHorizonNearLevel);
  EXPECT_FALSE(r.hash({2, 0, 0}).has_value());
  Box mip;
  ASSERT_TRUE(r.read_mip({2, 0, 0}, mip));
  EXPECT_EQ(mip.size(), (Vec3i{2, 2, 2}));
  EXPECT_EQ(mip.get(1, 1, 1), solid(6));
  EXPECT_EQ(r.chunk_count(), 3u);
  EXPECT_EQ(r.chunk_count(HoldingForm::kHorizon4), 2u);
  EXPECT_EQ(r.chunk_count(HoldingForm::kMip3), 1u);
  std::size_t seen = 0;
  r.for_each_holding([&](Vec3i, const Holding&) { ++seen; });
  EXPECT_EQ(seen, 3u);
  // A chunk's own record replaces the image; a release forgets it.
  r.apply_stream_record(bare(StreamRecordKind::kEmpty, {0, 0, 0}, 4));
  EXPECT_EQ(r.holding({0, 0, 0})->form, HoldingForm::kEmpty);
  EXPECT_EQ(r.get({5, 5, 5}), Voxel{});
  r.apply_stream_record(bare(StreamRecordKind::kReleased, {2, 0, 0}, 0));
  EXPECT_EQ(r.holding({2, 0, 0}), nullptr);
  EXPECT_EQ(r.chunk_count(), 2u);
  // A second image covers again only what has nothing.
  covered.clear();
  r.apply_horizon(StreamRecord{StreamRecordKind::kHorizon, {0, 0, 0}, 0, kHorizonNearLevel, &image, &mask, {}}, covered);
  EXPECT_EQ(covered, (std::vector<Vec3i>{{2, 0, 0}}));
}

TEST(Replica, ALevel6ImageGivesEachChunkItsBlocksVoxelAsHorizon5) {
  Replica r;
  // Region (-1, 0, 0) at level 6: one voxel per 2^3 chunks; voxel (x, y, z)
  // is material 1 + x + 4 * (y * 4 + z).
  Box image({4, 4, 4});
  for (int y = 0; y < 4; ++y)
    for (int z = 0; z < 4; ++z)
      for (int x = 0; x < 4; ++x) image.set(x, y, z, solid(static_cast<Material>(1 + x + 4 * (y * 4 + z))));
  HorizonMask mask;
  mask.fill(0xFF);
  std::vector<Vec3i> covered;
  r.apply_horizon(StreamRecord{StreamRecordKind::kHorizon, {-8, 0, 0}, 0, kHorizonOuterLevel, &image, &mask, {}},
                  covered);
  EXPECT_EQ(covered.size(), static_cast<std::size_t>(kHorizonRegionSlots));
  EXPECT_EQ(r.chunk_count(HoldingForm::kHorizon5), static_cast<std::size_t>(kHorizonRegionSlots));
  for (const Vec3i cp : {Vec3i{-8, 0, 0}, Vec3i{-7, 1, 1}, Vec3i{-3, 5, 2}, Vec3i{-1, 7, 7}}) {
    ASSERT_NE(r.holding(cp), nullptr);
    EXPECT_EQ(*r.holding(cp), (Holding{HoldingForm::kHorizon5, 0}));
    const Vec3i block = floor_div(floor_mod(cp, kHorizonRegionChunks), 2);
    const Voxel want = image.get(block.x, block.y, block.z);
    Box mip;
    ASSERT_TRUE(r.read_mip(cp, mip));
    EXPECT_EQ(mip.size(), (Vec3i{1, 1, 1}));
    EXPECT_EQ(mip.get(0, 0, 0), want) << cp.x << "," << cp.y << "," << cp.z;
    EXPECT_EQ(r.get(cp * kChunkSize + Vec3i{3, 30, 17}), want);
    EXPECT_EQ(r.resolution_at(cp * kChunkSize), kHorizonFarLevel);
  }
}

TEST(Replica, UpdatesApplyToFullResolutionChunksOnly) {
  Replica r;
  const Vec3i full{0, 0, 0}, mip{1, 0, 0};
  r.apply_stream_record(bare(StreamRecordKind::kEmpty, full, 1));
  Box mip_box;
  r.apply_stream_record(mip_record(mip, 1, 3, mip_box, Voxel{}));
  std::vector<UnitUpdate> ups(2);
  ups[0].chunk_pos = full;
  ups[0].unit_index = 9;  // ux 1, uz 1, uy 0
  ups[0].voxels.fill(solid(materials::kGrass));
  ups[1].chunk_pos = mip;
  ups[1].unit_index = 0;
  ups[1].voxels.fill(solid(materials::kGrass));
  std::vector<std::uint8_t> data;
  net_codec_encode_update_batch(ups, data);
  const ChunkRevisionMsg revs[2] = {{full, 2}, {mip, 2}};
  auto n = r.apply_update_batch(UpdateBatchMsg{5, data, {revs[0], revs[1]}});
  ASSERT_TRUE(n.ok());
  EXPECT_EQ(*n, 1u);
  EXPECT_EQ(r.get({4, 0, 4}), solid(materials::kGrass));
  EXPECT_EQ(r.get({3, 0, 4}), Voxel{});
  EXPECT_EQ(*r.holding(full), (Holding{HoldingForm::kFull, 2}));
  EXPECT_EQ(*r.holding(mip), (Holding{HoldingForm::kMip3, 1}));  // the mip holder waits for a refreshed mip

  // A unit of a chunk the batch gives no revision for is invalid.
  auto bad = r.apply_update_batch(UpdateBatchMsg{6, data, {revs[0]}});
  EXPECT_FALSE(bad.ok());
}

// Recording an update's voxels: each voxel whose value changed, as held
// before and after, none that a unit rewrote with its own value; at most
// max of them, the rest applied all the same.
TEST(Replica, UpdatesRecordEachChangedVoxelBeforeAndAfter) {
  const Vec3i cp{1, 0, -1};
  std::vector<UnitUpdate> ups(1);
  ups[0].chunk_pos = cp;
  ups[0].unit_index = 0;
  ups[0].voxels.fill(solid(materials::kGrass));
  ups[0].voxels[0] = solid(materials::kRock);  // as held already: not a change
  std::vector<std::uint8_t> data;
  net_codec_encode_update_batch(ups, data);
  const Vec3i origin = chunk_origin(cp);
  for (const std::size_t max : {std::size_t{1000}, std::size_t{10}}) {
    Replica r;
    Box rock;
    r.apply_stream_record(full_record(cp, 1, rock, solid(materials::kRock)));
    VoxelChanges changes{max, {}, false};
    ASSERT_TRUE(r.apply_update_batch(UpdateBatchMsg{3, data, {ChunkRevisionMsg{cp, 2}}}, nullptr, &changes).ok());
    const std::size_t changed = ups[0].voxels.size() - 1;
    EXPECT_EQ(changes.changes.size(), std::min(max, changed));
    EXPECT_EQ(changes.truncated, max < changed);
    std::vector<Vec3i> seen;
    for (const VoxelChange& c : changes.changes) {
      EXPECT_EQ(c.before, solid(materials::kRock));
      EXPECT_EQ(c.after, solid(materials::kGrass));
      EXPECT_EQ(r.get(c.voxel_pos), solid(materials::kGrass));
      const Vec3i local = c.voxel_pos - origin;
      EXPECT_TRUE(local.x >= 0 && local.x < 4 && local.y >= 0 && local.y < 4 && local.z >= 0 && local.z < 4);
      EXPECT_EQ(std::count(seen.begin(), seen.end(), c.voxel_pos), 0);
      seen.push_back(c.voxel_pos);
    }
    // The whole unit is applied however many were recorded: one voxel stays Rock.
    int rock_left = 0;
    for (int y = 0; y < 4; ++y)
      for (int z = 0; z < 4; ++z)
        for (int x = 0; x < 4; ++x) rock_left += r.get(origin + Vec3i{x, y, z}) == solid(materials::kRock);
    EXPECT_EQ(rock_left, 1);
  }
}

TEST(Replica, SurfaceHeightReadsTheBestResolutionHeld) {
  Replica r;
  r.apply_stream_record(bare(StreamRecordKind::kEmpty, {0, 1, 0}, 0));
  Box rock;
  r.apply_stream_record(full_record({0, 0, 0}, 0, rock, solid(materials::kRock)));
  EXPECT_EQ(r.surface_height(3, 3, -64, 64), 32);
  EXPECT_EQ(r.surface_height(40, 3, -64, 64), std::nullopt);  // chunk column unknown
  const auto hit = r.raycast({3.5f, 60.0f, 3.5f}, {0, -1, 0}, 100);
  ASSERT_TRUE(hit.has_value());
  EXPECT_EQ(hit->voxel, (Vec3i{3, 31, 3}));
}

// The replica keeps each chunk's hash until the chunk changes: whatever
// changes it (an update, a whole chunk again, another form), the
// hash asked next is the hash of the voxels held then, at the same revision
// too.
TEST(Replica, HashFollowsEveryChangeOfTheVoxels) {
  Replica r;
  const Vec3i cp{2, -1, 3};
  auto fresh = [&] { return chunk_hash(r.grid().find_chunk(cp), r.holding(cp)->revision); };
  r.apply_stream_record(bare(StreamRecordKind::kEmpty, cp, 4));
  EXPECT_EQ(r.hash(cp), chunk_hash(nullptr, 4));

  // An update at the same revision.
  std::vector<UnitUpdate> ups(1);
  ups[0].chunk_pos = cp;
  ups[0].unit_index = 17;
  ups[0].voxels.fill(solid(materials::kGrass));
  std::vector<std::uint8_t> data;
  net_codec_encode_update_batch(ups, data);
  ASSERT_TRUE(r.apply_update_batch(UpdateBatchMsg{1, data, {ChunkRevisionMsg{cp, 4}}}).ok());
  const auto after_update = r.hash(cp);
  EXPECT_NE(after_update, chunk_hash(nullptr, 4));
  EXPECT_EQ(after_update, fresh());

  // The whole chunk again, same revision, other voxels.
  Box whole({kChunkSize, kChunkSize, kChunkSize});
  whole.fill(solid(materials::kMud));
  const auto before_full = r.hash(cp);
  r.apply_stream_record(StreamRecord{StreamRecordKind::kFull, cp, 4, 0, &whole, nullptr, {}});
  Chunk mud(materials::kMud);
  EXPECT_NE(r.hash(cp), before_full);
  EXPECT_EQ(r.hash(cp), chunk_hash(&mud, 4));

  // A new revision alone changes the hash; a mip has none; Empty again.
  ups[0].voxels.fill(solid(materials::kMud));
  data.clear();
  net_codec_encode_update_batch(ups, data);
  ASSERT_TRUE(r.apply_update_batch(UpdateBatchMsg{2, data, {ChunkRevisionMsg{cp, 5}}}).ok());
  EXPECT_EQ(r.hash(cp), chunk_hash(&mud, 5));
  Box rock_mip;
  r.apply_stream_record(mip_record(cp, 6, 3, rock_mip, solid(materials::kRock)));
  EXPECT_FALSE(r.hash(cp).has_value());
  r.apply_stream_record(bare(StreamRecordKind::kEmpty, cp, 6));
  EXPECT_EQ(r.hash(cp), chunk_hash(nullptr, 6));
  r.apply_stream_record(bare(StreamRecordKind::kReleased, cp, 6));
  EXPECT_FALSE(r.hash(cp).has_value());
}

// surface_height reads a chunk at a time; it must agree with reading the
// column voxel by voxel through get(), over full, mip, Empty and unknown
// chunks and bounds that cut chunks.
TEST(Replica, FullChunksWithDerivedMipsHoldNoneAndReadHashAndUpdateAlike) {
  Replica kept, derived;
  derived.set_full_chunk_mips(Chunk::Mips::kDerived);
  Box slope({kChunkSize, kChunkSize, kChunkSize});
  for (int y = 0; y < kChunkSize; ++y)
    for (int z = 0; z < kChunkSize; ++z)
      for (int x = 0; x < kChunkSize; ++x)
        slope.set(x, y, z, y < (x + z) / 2 ? solid(materials::kRock) : Voxel{});
  const Vec3i cp{2, 0, -3};
  for (Replica* r : {&kept, &derived})
    r->apply_stream_record(StreamRecord{StreamRecordKind::kFull, cp, 1, 0, &slope, nullptr, {}});
  ASSERT_NE(derived.grid().find_chunk(cp), nullptr);
  EXPECT_EQ(derived.grid().find_chunk(cp)->mips(), Chunk::Mips::kDerived);
  EXPECT_EQ(kept.grid().find_chunk(cp)->mips(), Chunk::Mips::kKept);
  EXPECT_EQ(derived.memory().full.mip_bytes, 0u);
  EXPECT_GT(kept.memory().full.mip_bytes, 0u);
  EXPECT_EQ(derived.hash(cp), kept.hash(cp));
  // An update of a unit: the same voxels and hash after it, mips read alike.
  std::vector<UnitUpdate> ups(1);
  ups[0].chunk_pos = cp;
  ups[0].unit_index = 21;
  ups[0].voxels.fill(make_voxel(materials::kSand, 90));
  std::vector<std::uint8_t> data;
  net_codec_encode_update_batch(ups, data);
  const ChunkRevisionMsg rev{cp, 2};
  for (Replica* r : {&kept, &derived}) ASSERT_TRUE(r->apply_update_batch(UpdateBatchMsg{1, data, {rev}}).ok());
  EXPECT_EQ(derived.hash(cp), kept.hash(cp));
  for (int level = 1; level < kMipLevels; ++level) {
    Box a, b;
    kept.grid().find_chunk(cp)->read_level(level, a);
    derived.grid().find_chunk(cp)->read_level(level, b);
    EXPECT_TRUE(a == b) << "level " << level;
  }
  for (std::int32_t z = 0; z < kChunkSize; z += 5)
    for (std::int32_t x = 0; x < kChunkSize; x += 5) {
      const Vec3i v = chunk_origin(cp) + Vec3i{x, 0, z};
      EXPECT_EQ(derived.surface_height(v.x, v.z, -64, 64), kept.surface_height(v.x, v.z, -64, 64));
    }
}

TEST(Replica, SurfaceHeightAgreesWithTheVoxelsOfTheColumn) {
  Replica r;
  // Column chunks y = -1..3: full with a slope, a mip, Empty, unknown, full.
  Box slope({kChunkSize, kChunkSize, kChunkSize});
  for (int y = 0; y < kChunkSize; ++y)
    for (int z = 0; z < kChunkSize; ++z)
      for (int x = 0; x < kChunkSize; ++x)
        slope.set(x, y, z, y < (x + z) / 2 ? solid(materials::kRock) : Voxel{});
  r.apply_stream_record(StreamRecord{StreamRecordKind::kFull, {0, -1, 0}, 1, 0, &slope, nullptr, {}});
  Box mip({8, 8, 8});
  for (int y = 0; y < 8; ++y)
    for (int z = 0; z < 8; ++z)
      for (int x = 0; x < 8; ++x) mip.set(x, y, z, y < x ? solid(materials::kSand) : Voxel{});
  r.apply_stream_record(StreamRecord{StreamRecordKind::kMip2, {0, 0, 0}, 1, 2, &mip, nullptr, {}});
  r.apply_stream_record(bare(StreamRecordKind::kEmpty, {0, 1, 0}, 1));
  r.apply_stream_record(StreamRecord{StreamRecordKind::kFull, {0, 3, 0}, 1, 0, &slope, nullptr, {}});
  auto by_voxel = [&](std::int32_t x, std::int32_t z, std::int32_t lo, std::int32_t hi) -> std::optional<std::int32_t> {
    for (std::int32_t y = hi - 1; y >= lo; --y)
      if (r.resolution_at({x, y, z}) != kNoResolution && r.get({x, y, z}).material != kAir) return y + 1;
    return std::nullopt;
  };
  int found = 0;
  for (const auto& [lo, hi] : {std::pair{-32, 128}, std::pair{-20, 50}, std::pair{-40, 20}, std::pair{5, 7}, std::pair{100, 110}})
    for (std::int32_t z = 0; z < kChunkSize; z += 3)
      for (std::int32_t x = 0; x < kChunkSize; x += 3) {
        const auto h = r.surface_height(x, z, lo, hi);
        ASSERT_EQ(h, by_voxel(x, z, lo, hi)) << x << "," << z << " in [" << lo << "," << hi << ")";
        found += h.has_value();
      }
  EXPECT_GT(found, 100);
}

// A replica holds thousands of chunks, most of them mips and Empty chunks:
// each costs its holding and its mip handle in the table of chunks (no
// cached hash: only Full chunks keep one, apart), so a block's values stay
// within 32 bytes a chunk and a quarter of spare capacity.
TEST(Replica, AChunkHeldCostsItsEntryAloneAndOnlyFullChunksKeepAHash) {
  Replica r;
  Box mip;
  int held = 0;
  for (int x = 0; x < 16; ++x)
    for (int z = 0; z < 16; ++z)
      for (int y = 0; y < 4; ++y, ++held) {
        const Vec3i cp{x, y, z};
        if (y < 2) r.apply_stream_record(mip_record(cp, 1, 3, mip, solid(materials::kRock)));
        else r.apply_stream_record(bare(StreamRecordKind::kEmpty, cp, 1));
      }
  const ReplicaMemory empty_and_mips = r.memory();
  EXPECT_LE(empty_and_mips.entry_table_bytes, static_cast<std::size_t>(held) * 32 * 5 / 4 + 64 * 64)
      << "per chunk: " << empty_and_mips.entry_table_bytes / held << " bytes";
  // Hashes asked of Empty chunks are not kept; a Full chunk's is, until it changes.
  for (int x = 0; x < 16; ++x) EXPECT_EQ(r.hash({x, 3, 0}), chunk_hash(nullptr, 1));
  EXPECT_EQ(r.memory().entry_table_bytes, empty_and_mips.entry_table_bytes);
  Box whole;
  r.apply_stream_record(full_record({0, 0, 0}, 2, whole, solid(materials::kSand)));
  Chunk sand(materials::kSand);
  EXPECT_EQ(r.hash({0, 0, 0}), chunk_hash(&sand, 2));
  EXPECT_GT(r.memory().entry_table_bytes, empty_and_mips.entry_table_bytes);
  EXPECT_EQ(r.hash({0, 0, 0}), chunk_hash(&sand, 2));
  r.apply_stream_record(full_record({0, 0, 0}, 3, whole, solid(materials::kMud)));
  Chunk mud(materials::kMud);
  EXPECT_EQ(r.hash({0, 0, 0}), chunk_hash(&mud, 3));
}

}  // namespace
}  // namespace terrane
