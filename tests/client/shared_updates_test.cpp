// SharedUpdates through the replicas of one process: replicas holding one
// shared chunk and sent the same units hold one result, made once, with
// the voxels each would have made alone; other units, another base or a
// replica on its own are never given another's result.
#include "client/shared_updates.h"

#include <gtest/gtest.h>

#include <initializer_list>

#include "client/decoded_chunks.h"
#include "client/replica.h"
#include "common/codec/net_codec.h"
#include "protocol/stream_batch.h"
#include "tests/support/replica_records.h"
#include "tests/support/stream_records.h"

namespace terrane {
namespace {

using testing_support::full_payload;
using testing_support::take_full;

Box slope() {
  Box b({kChunkSize, kChunkSize, kChunkSize});
  for (int y = 0; y < kChunkSize; ++y)
    for (int z = 0; z < kChunkSize; ++z)
      for (int x = 0; x < kChunkSize; ++x)
        if (y < 8 + x / 3 + z / 5) b.set(x, y, z, make_voxel(y % 5 == 0 ? materials::kSand : materials::kRock, 200));
  return b;
}


// One unit (index) of chunk cp filled with v, and the batch that carries it.
UpdateBatchMsg one_unit(Vec3i cp, std::uint16_t index, Voxel v, std::uint64_t revision,
                        std::vector<std::uint8_t>& data) {
  std::vector<UnitUpdate> ups(1);
  ups[0].chunk_pos = cp;
  ups[0].unit_index = index;
  ups[0].voxels.fill(v);
  data.clear();
  net_codec_encode_update_batch(ups, data);
  return UpdateBatchMsg{revision, data, {ChunkRevisionMsg{cp, revision}}};
}

Box held(const Replica& r, Vec3i cp) {
  Box got({kChunkSize, kChunkSize, kChunkSize});
  r.read_box(chunk_origin(cp), got);
  return got;
}

constexpr Vec3i kAt{1, 0, 2};

// Each replica of sharing takes shared, each of alone keeps its own; all
// then take the same Full record of the slope at kAt, revision 5.
void hold_slope(const std::shared_ptr<DecodedChunks>& shared, std::initializer_list<Replica*> sharing,
                std::initializer_list<Replica*> alone = {}) {
  const auto payload = full_payload(slope());
  for (Replica* r : sharing) {
    r->share_decoded(shared);
    take_full(*r, kAt, 5, payload);
  }
  for (Replica* r : alone) take_full(*r, kAt, 5, payload);
}

TEST(SharedUpdates, ReplicasHoldingOneChunkSentTheSameUnitsHoldOneResultMadeOnce) {
  auto shared = std::make_shared<DecodedChunks>();
  Replica a, b, alone;
  hold_slope(shared, {&a, &b}, {&alone});
  ASSERT_EQ(a.grid().find_chunk(kAt), b.grid().find_chunk(kAt)) << "the Full record's chunk is shared";

  std::vector<std::uint8_t> data;
  const UpdateBatchMsg dig = one_unit(kAt, 9 + 64 * 2, Voxel{}, 6, data);
  ASSERT_TRUE(a.apply_update_batch(dig).ok());
  EXPECT_EQ(shared->updates().stats().misses, 1u);
  ASSERT_TRUE(b.apply_update_batch(dig).ok());
  ASSERT_TRUE(alone.apply_update_batch(dig).ok());
  EXPECT_EQ(shared->updates().stats().hits, 1u);
  EXPECT_EQ(a.grid().find_chunk(kAt), b.grid().find_chunk(kAt)) << "b took a's result";
  EXPECT_NE(a.grid().find_chunk(kAt), alone.grid().find_chunk(kAt));
  EXPECT_TRUE(held(a, kAt) == held(alone, kAt)) << "the result is what a replica's own apply makes";
  EXPECT_TRUE(held(b, kAt) == held(alone, kAt));
  EXPECT_EQ(b.hash(kAt), alone.hash(kAt));
  EXPECT_EQ(a.get(chunk_origin(kAt) + Vec3i{4, 8, 4}), Voxel{});

  // The next tick's units go on from the shared result, again made once.
  const UpdateBatchMsg fill = one_unit(kAt, 0, make_voxel(materials::kGrass, 255), 7, data);
  for (Replica* r : {&a, &b, &alone}) ASSERT_TRUE(r->apply_update_batch(fill).ok());
  EXPECT_EQ(shared->updates().stats().hits, 2u);
  EXPECT_TRUE(held(a, kAt) == held(alone, kAt));
  EXPECT_TRUE(held(b, kAt) == held(alone, kAt));
  EXPECT_EQ(*b.holding(kAt), (Holding{HoldingForm::kFull, 7}));
}

// Replicas do not apply a tick at once: one that comes late, after the
// first went on to the next tick, still takes both ticks' results.
TEST(SharedUpdates, AReplicaThatComesLateTakesEveryTicksResultMadeBeforeIt) {
  auto shared = std::make_shared<DecodedChunks>();
  Replica first, late, alone;
  hold_slope(shared, {&first, &late}, {&alone});
  std::vector<std::uint8_t> d1, d2;
  const UpdateBatchMsg tick1 = one_unit(kAt, 70, Voxel{}, 6, d1);
  const UpdateBatchMsg tick2 = one_unit(kAt, 71, make_voxel(materials::kSand, 255), 7, d2);
  ASSERT_TRUE(first.apply_update_batch(tick1).ok());
  ASSERT_TRUE(first.apply_update_batch(tick2).ok());  // (first holds tick 1's result no more)
  EXPECT_EQ(shared->updates().stats().misses, 2u);
  ASSERT_TRUE(late.apply_update_batch(tick1).ok());
  ASSERT_TRUE(late.apply_update_batch(tick2).ok());
  EXPECT_EQ(shared->updates().stats().hits, 2u);
  EXPECT_EQ(late.grid().find_chunk(kAt), first.grid().find_chunk(kAt));
  for (const UpdateBatchMsg* m : {&tick1, &tick2}) ASSERT_TRUE(alone.apply_update_batch(*m).ok());
  EXPECT_TRUE(held(late, kAt) == held(alone, kAt));
}

// Two replicas on two threads apply one tick at once: both miss, both make
// the result. The second to offer its own is handed the first's, so the
// two hold one chunk again and their next tick is made once.
TEST(SharedUpdates, TwoResultsOfOneTickMadeAtOnceBecomeOne) {
  SharedUpdates table;
  const auto base = std::make_shared<const Chunk>(Chunk::from_box(slope()));
  std::vector<UnitUpdate> units(1);
  units[0].chunk_pos = kAt;
  units[0].unit_index = 12;
  units[0].voxels.fill(make_voxel(materials::kSand, 255));
  const std::size_t key = SharedUpdates::key_of(base.get(), units);
  auto make = [&] {
    Chunk c = base->clone();
    c.modify(Region{{0, 4, 4}, {4, 8, 8}}, [](Vec3i, Voxel) { return make_voxel(materials::kSand, 255); });
    return std::make_shared<const Chunk>(std::move(c));
  };
  EXPECT_EQ(table.find(key, base, units), nullptr);
  EXPECT_EQ(table.find(key, base, units), nullptr);
  const auto first = make(), second = make();
  EXPECT_EQ(table.add(key, base, units, first), first);
  EXPECT_EQ(table.add(key, base, units, second), first) << "the second holds the first's result";
  EXPECT_EQ(table.stats().adopted, 1u);
  // Other units on the same base are another result: never adopted.
  std::vector<UnitUpdate> other = units;
  other[0].voxels.fill(Voxel{});
  const auto own = make();
  EXPECT_EQ(table.add(SharedUpdates::key_of(base.get(), other), base, other, own), own);
  // Nor a result for another base object with equal voxels.
  const auto twin = std::make_shared<const Chunk>(Chunk::from_box(slope()));
  const auto theirs = make();
  EXPECT_EQ(table.add(SharedUpdates::key_of(twin.get(), units), twin, units, theirs), theirs);
  EXPECT_EQ(table.stats().adopted, 1u);
}

// A replica that took the chunk's Full record at a revision the others made
// by updates holds equal voxels in another object. Its next tick takes the
// others' result (its base equals their twin at that revision), and it
// holds their chunk from then on: one lineage, not one per way in.
TEST(SharedUpdates, AReplicaWhoseChunkEqualsAnotherLineagesJoinsIt) {
  auto shared = std::make_shared<DecodedChunks>();
  Replica first, second, newcomer, alone;
  hold_slope(shared, {&first, &second}, {&alone});
  std::vector<std::uint8_t> d1, d2, d3;
  const UpdateBatchMsg tick1 = one_unit(kAt, 70, Voxel{}, 6, d1);
  const UpdateBatchMsg tick2 = one_unit(kAt, 71, make_voxel(materials::kSand, 255), 7, d2);
  const UpdateBatchMsg tick3 = one_unit(kAt, 72, Voxel{}, 8, d3);
  for (Replica* r : {&first, &second, &alone}) ASSERT_TRUE(r->apply_update_batch(tick1).ok());
  // The newcomer comes into view at revision 6: a Full record of what the
  // updates made.
  newcomer.share_decoded(shared);
  take_full(newcomer, kAt, 6, full_payload(held(alone, kAt)));
  ASSERT_NE(newcomer.grid().find_chunk(kAt), first.grid().find_chunk(kAt)) << "equal voxels, another object";
  ASSERT_TRUE(first.apply_update_batch(tick2).ok());
  const auto before = shared->updates().stats();
  ASSERT_TRUE(newcomer.apply_update_batch(tick2).ok());
  EXPECT_EQ(shared->updates().stats().hits, before.hits + 1) << "taken through the twin, not made";
  EXPECT_EQ(shared->updates().stats().twins, before.twins + 1);
  EXPECT_EQ(newcomer.grid().find_chunk(kAt), first.grid().find_chunk(kAt));
  // From here on, one lineage: the next tick is made once for all.
  ASSERT_TRUE(second.apply_update_batch(tick2).ok());
  for (Replica* r : {&alone}) ASSERT_TRUE(r->apply_update_batch(tick2).ok());
  const auto mid = shared->updates().stats();
  for (Replica* r : {&newcomer, &first, &second, &alone}) ASSERT_TRUE(r->apply_update_batch(tick3).ok());
  EXPECT_EQ(shared->updates().stats().misses, mid.misses + 1);
  EXPECT_EQ(newcomer.grid().find_chunk(kAt), second.grid().find_chunk(kAt));
  EXPECT_TRUE(held(newcomer, kAt) == held(alone, kAt));
  EXPECT_EQ(newcomer.hash(kAt), alone.hash(kAt));
}

// Two lineages that made one tick's result each: the second to offer its
// result holds the first's when their voxels are equal, and keeps its own
// when they are not (a twin is only ever taken for equal voxels).
TEST(SharedUpdates, AResultEqualToItsTwinIsHeldAsTheTwinAndAnotherIsNot) {
  SharedUpdates table;
  const auto base1 = std::make_shared<const Chunk>(Chunk::from_box(slope()));
  const auto base2 = std::make_shared<const Chunk>(Chunk::from_box(slope()));
  std::vector<UnitUpdate> units(1);
  units[0].chunk_pos = kAt;
  units[0].unit_index = 12;
  units[0].voxels.fill(make_voxel(materials::kSand, 255));
  auto make = [&](const Chunk& base, Material m) {
    Chunk c = base.clone();
    c.modify(Region{{0, 4, 4}, {4, 8, 8}}, [m](Vec3i, Voxel) { return make_voxel(m, 255); });
    return std::make_shared<const Chunk>(std::move(c));
  };
  const SharedUpdates::At at{kAt, 6};
  const auto r1 = make(*base1, materials::kSand);
  EXPECT_EQ(table.add(SharedUpdates::key_of(base1.get(), units), base1, units, r1, at), r1);
  const auto r2 = make(*base2, materials::kSand);
  EXPECT_EQ(table.add(SharedUpdates::key_of(base2.get(), units), base2, units, r2, at), r1) << "equal voxels";
  EXPECT_EQ(table.stats().twins, 1u);
  // base2's next find of these units gives the twin (its entry says so).
  EXPECT_EQ(table.find(SharedUpdates::key_of(base2.get(), units), base2, units, SharedUpdates::At{kAt, 5}), r1);
  // Other voxels at the same position and revision: never the twin.
  const auto base3 = std::make_shared<const Chunk>(Chunk::from_box(slope()));
  const auto r3 = make(*base3, materials::kRock);
  EXPECT_EQ(table.add(SharedUpdates::key_of(base3.get(), units), base3, units, r3, at), r3);
  EXPECT_EQ(table.stats().twins, 1u);
  // base1 kept as the twin at revision 5 (as an earlier tick's result): a
  // base of equal voxels is given what these units made of base1, a base
  // of other voxels is not.
  std::vector<UnitUpdate> earlier = units;
  earlier[0].unit_index = 13;
  const auto base0 = std::make_shared<const Chunk>(Chunk::from_box(slope()));
  table.add(SharedUpdates::key_of(base0.get(), earlier), base0, earlier, base1, SharedUpdates::At{kAt, 5});
  const SharedUpdates::At five{kAt, 5};
  const auto equal = std::make_shared<const Chunk>(Chunk::from_box(slope()));
  EXPECT_EQ(table.find(SharedUpdates::key_of(equal.get(), units), equal, units, five), r1);
  EXPECT_EQ(table.stats().twins, 2u);
  Chunk other = base1->clone();
  other.modify(Region{{9, 9, 9}, {10, 10, 10}}, [](Vec3i, Voxel) { return Voxel{}; });
  const auto differs = std::make_shared<const Chunk>(std::move(other));
  EXPECT_EQ(table.find(SharedUpdates::key_of(differs.get(), units), differs, units, five), nullptr);
  EXPECT_EQ(table.stats().twins, 2u);
  // Without a position and revision, no twin is looked for.
  const auto equal_too = std::make_shared<const Chunk>(Chunk::from_box(slope()));
  EXPECT_EQ(table.find(SharedUpdates::key_of(equal_too.get(), units), equal_too, units), nullptr);
}

TEST(SharedUpdates, OtherUnitsOrAnotherBaseAreNeverGivenAnothersResult) {
  auto shared = std::make_shared<DecodedChunks>();
  Replica a, b, c;
  hold_slope(shared, {&a, &b, &c});
  std::vector<std::uint8_t> da, db;
  const UpdateBatchMsg to_sand = one_unit(kAt, 3, make_voxel(materials::kSand, 255), 6, da);
  const UpdateBatchMsg to_air = one_unit(kAt, 3, Voxel{}, 6, db);
  ASSERT_TRUE(a.apply_update_batch(to_sand).ok());
  ASSERT_TRUE(b.apply_update_batch(to_air).ok());
  EXPECT_EQ(shared->updates().stats().hits, 0u) << "other units: made anew";
  EXPECT_EQ(b.get(chunk_origin(kAt) + Vec3i{12, 0, 0}), Voxel{});
  EXPECT_EQ(a.get(chunk_origin(kAt) + Vec3i{12, 0, 0}).material, materials::kSand);
  // c's chunk is the Full record's, not a's result: a's units on another
  // base are applied by c itself.
  ASSERT_TRUE(c.apply_update_batch(to_sand).ok());
  EXPECT_EQ(shared->updates().stats().hits, 1u) << "c holds the same base as a did and is sent a's units";
  EXPECT_TRUE(held(a, kAt) == held(c, kAt));
  // b (holding its own result) sent a's units of the next tick: another base.
  ASSERT_TRUE(b.apply_update_batch(one_unit(kAt, 3, make_voxel(materials::kSand, 255), 7, db)).ok());
  EXPECT_EQ(shared->updates().stats().hits, 1u);
  EXPECT_TRUE(held(b, kAt) == held(a, kAt));
}

TEST(SharedUpdates, AUnitThatEmptiesTheChunkLeavesNothingToShareAndNothingHeld) {
  auto shared = std::make_shared<DecodedChunks>();
  Replica a, b;
  a.share_decoded(shared);
  b.share_decoded(shared);
  // A chunk whose only matter is in unit 0.
  Box one({kChunkSize, kChunkSize, kChunkSize});
  one.set(1, 1, 1, make_voxel(materials::kRock, 255));
  const auto payload = full_payload(one);
  take_full(a, kAt, 5, payload);
  take_full(b, kAt, 5, payload);
  std::vector<std::uint8_t> data;
  const UpdateBatchMsg clear = one_unit(kAt, 0, Voxel{}, 6, data);
  ASSERT_TRUE(a.apply_update_batch(clear).ok());
  ASSERT_TRUE(b.apply_update_batch(clear).ok());
  EXPECT_EQ(a.grid().find_chunk(kAt), nullptr);
  EXPECT_EQ(b.grid().find_chunk(kAt), nullptr);
  EXPECT_EQ(a.get(chunk_origin(kAt) + Vec3i{1, 1, 1}), Voxel{});
  EXPECT_EQ(shared->updates().stats().entries, 0u);
}

// The units a server sends are copied into the table: bounded by their
// count too, however many a batch holds (512 units of a chunk each here).
TEST(SharedUpdates, TheTableHoldsAtMostItsUnitsEvenWhenEveryResultLives) {
  SharedUpdates table;
  std::vector<UnitUpdate> whole(kUpdateUnitsPerChunk);
  for (std::size_t i = 0; i < whole.size(); ++i) whole[i].unit_index = static_cast<std::uint16_t>(i);
  std::vector<std::shared_ptr<const Chunk>> alive;
  const std::size_t adds = 2 * SharedUpdates::kMaxUnits / whole.size();
  for (std::size_t i = 0; i < adds; ++i) {
    auto base = std::make_shared<const Chunk>(), result = std::make_shared<const Chunk>();
    alive.push_back(base);
    alive.push_back(result);
    table.add(SharedUpdates::key_of(base.get(), whole), base, whole, result);
    EXPECT_LE(table.stats().entries * whole.size(), SharedUpdates::kMaxUnits);
  }
  // The newest is still there to be taken.
  const auto& base = alive[alive.size() - 2];
  EXPECT_EQ(table.find(SharedUpdates::key_of(base.get(), whole), base, whole), alive.back());
}

}  // namespace
}  // namespace terrane
