#include "client/decoded_mips.h"

#include <gtest/gtest.h>

#include <memory>
#include <vector>

#include "client/decoded_chunks.h"
#include "client/replica.h"
#include "common/codec/net_codec.h"
#include "common/world/horizon.h"
#include "protocol/stream_batch.h"

namespace terrane {
namespace {

// A box of side n with some structure (seed varies it): a slope of two
// materials with partial occupancy at its surface.
Box terrain(int n, int seed) {
  Box b({n, n, n});
  for (int y = 0; y < n; ++y)
    for (int z = 0; z < n; ++z)
      for (int x = 0; x < n; ++x) {
        const int h = n / 4 + (x + seed) % n / 3 + z / 5;
        if (y < h) b.set(x, y, z, make_voxel((y + seed) % 3 == 0 ? materials::kSand : materials::kRock, 255));
        else if (y == h) b.set(x, y, z, make_voxel(materials::kGrass, static_cast<std::uint8_t>(40 + 7 * seed)));
      }
  return b;
}

// The record's encoded bytes, as a server sends them.
std::vector<std::uint8_t> encoded(const Box& voxels) {
  std::vector<std::uint8_t> out;
  net_codec_encode(voxels.size().x, voxels.voxels(), out);
  return out;
}

// A Mip or Estimate record (kind) of chunk cp with these voxels and bytes.
StreamRecord mip_record(StreamRecordKind kind, Vec3i cp, std::uint64_t revision, const Box& voxels,
                        const std::vector<std::uint8_t>& bytes) {
  return StreamRecord{kind, cp, revision, payload_level(kind), &voxels, nullptr, bytes};
}

TEST(DecodedMips, EqualVoxelsUnderOneKeyAreOneBox) {
  DecodedMips mips;
  const Box voxels = terrain(16, 1);
  const auto key = DecodedMips::key_of(encoded(voxels), 1);
  const auto a = mips.intern(key, voxels);
  const auto b = mips.intern(key, terrain(16, 1));
  EXPECT_EQ(a.get(), b.get());
  EXPECT_EQ(*a, voxels);
  EXPECT_EQ(mips.stats().hits, 1u);
  EXPECT_EQ(mips.stats().misses, 1u);
  EXPECT_EQ(mips.stats().entries, 1u);
}

TEST(DecodedMips, AKeyWithOtherVoxelsGivesABoxOfThoseVoxels) {
  // Keys alike, voxels not (a hash collision, or a hostile server's bytes):
  // each caller gets exactly its own voxels.
  DecodedMips mips;
  const Box first = terrain(8, 1), second = terrain(8, 2);
  ASSERT_NE(first, second);
  const auto a = mips.intern(7, first);
  const auto b = mips.intern(7, second);
  EXPECT_NE(a.get(), b.get());
  EXPECT_EQ(*a, first);
  EXPECT_EQ(*b, second);
  EXPECT_EQ(mips.stats().hits, 0u);
}

TEST(DecodedMips, KeysTellLevelsAndSidesApart) {
  const std::vector<std::uint8_t> bytes = encoded(terrain(8, 3));
  EXPECT_NE(DecodedMips::key_of(bytes, 2), DecodedMips::key_of(bytes, 3));
  // Equal bytes: a 4^3 box of one value and a 2^3 box of it.
  EXPECT_NE(DecodedMips::key_of(Box({4, 4, 4}, solid(materials::kRock))),
            DecodedMips::key_of(Box({2, 2, 2}, solid(materials::kRock))));
}

TEST(DecodedMips, BoxesNoReplicaHoldsAreForgotten) {
  DecodedMips mips;
  {
    std::vector<std::shared_ptr<const Box>> held;
    for (int i = 0; i < 3000; ++i) held.push_back(mips.intern(static_cast<std::size_t>(i), terrain(4, i)));
    EXPECT_EQ(mips.stats().entries, 3000u);
  }
  EXPECT_EQ(mips.stats().entries, 0u);
  const std::size_t bytes_dead = mips.stats().bytes;
  // The table is swept as it grows: 3,000 more boxes, each dropped at once,
  // leave it no larger than the first 3,000 held did.
  for (int i = 0; i < 3000; ++i) mips.intern(static_cast<std::size_t>(10000 + i), terrain(4, i));
  EXPECT_EQ(mips.stats().entries, 0u);
  EXPECT_LE(mips.stats().bytes, bytes_dead * 2);
}

// Units that begin alike: a 16^3 mip and copies of it with one voxel near
// its end changed, each of other bytes but the same first kKeyBytes (so
// the same key).
std::vector<std::vector<std::uint8_t>> units_beginning_alike(std::size_t count) {
  const Box base = terrain(16, 1);
  const auto base_bytes = encoded(base);
  std::vector<std::vector<std::uint8_t>> out{base_bytes};
  const Material materials[] = {materials::kSand, materials::kRock, materials::kGrass, kAir};
  for (int i = 0; i < 4 * 256 && out.size() < count; ++i) {
    Box b = base;
    b.set(15 - i / 4 % 16, 15, 15 - i / 64, make_voxel(materials[i % 4], 255));
    auto bytes = encoded(b);
    const bool alike = bytes.size() >= DecodedMips::kKeyBytes &&
                       std::equal(bytes.begin(), bytes.begin() + DecodedMips::kKeyBytes, base_bytes.begin());
    if (alike && std::find(out.begin(), out.end(), bytes) == out.end()) out.push_back(std::move(bytes));
  }
  return out;
}

// A unit is found before decoding by its first bytes, compared whole: each
// of several units beginning alike is found as itself, while held, and
// never one for another; at most kMaxPerKey of them are kept findable.
TEST(DecodedMips, UnitsThatBeginAlikeAreEachFoundAsThemselves) {
  const auto units = units_beginning_alike(DecodedMips::kMaxPerKey + 2);
  ASSERT_EQ(units.size(), DecodedMips::kMaxPerKey + 2) << "the test's units must begin alike";
  DecodedMips mips;
  std::vector<std::shared_ptr<const MipVoxels>> held;
  for (const auto& u : units) held.push_back(mips.intern_unit(DecodedMips::key_of(u, 1), 16, u));
  std::size_t found = 0;
  for (std::size_t i = 0; i < units.size(); ++i) {
    std::vector<std::uint8_t> rest = units[i];
    rest.insert(rest.end(), {0xAB, 0xCD, 0xEF});  // the next record's bytes
    const KnownPayload k = mips.known_unit(1, rest);
    if (k.made == nullptr) continue;
    ++found;
    EXPECT_EQ(k.made.get(), held[i].get()) << i;
    EXPECT_EQ(k.bytes, units[i].size()) << i;
  }
  EXPECT_EQ(found, DecodedMips::kMaxPerKey) << "the newest kMaxPerKey of one key";
  // A unit cut short, or followed by other bytes in place of its end, is
  // not taken for one it begins like.
  for (const auto& u : units) {
    EXPECT_EQ(mips.known_unit(1, std::span(u).first(u.size() - 1)).made, nullptr);
    EXPECT_EQ(mips.known_unit(2, u).made, nullptr) << "another level";
  }
}

// An item no replica holds any more leaves its slot to a new one, but a
// live equal item further along is still found (no copy made).
TEST(DecodedMips, AnEqualUnitBehindADeadOneIsShared) {
  const auto units = units_beginning_alike(2);
  ASSERT_EQ(units.size(), 2u);
  DecodedMips mips;
  const auto key = DecodedMips::key_of(units[0], 1);
  ASSERT_EQ(key, DecodedMips::key_of(units[1], 1));
  auto first = mips.intern_unit(key, 16, units[0]);
  const auto second = mips.intern_unit(key, 16, units[1]);
  first.reset();  // dead now, ahead of the second in the table
  const auto again = mips.intern_unit(key, 16, units[1]);
  EXPECT_EQ(again.get(), second.get());
  EXPECT_EQ(mips.stats().entries, 1u);
  // The dead one's slot takes the next new one.
  const auto back = mips.intern_unit(key, 16, units[0]);
  EXPECT_EQ(mips.stats().entries, 2u);
  EXPECT_TRUE(std::ranges::equal(back->unit(), units[0]));
}

// Every form a chunk's voxels take short of full resolution reads back as
// what its record said, with and without a shared cache.
TEST(ReplicaMips, EveryCoarseFormReadsBackAsApplied) {
  for (const bool shared : {false, true}) {
    Replica r;
    if (shared) r.share_decoded(std::make_shared<DecodedChunks>());
    int seed = 0;
    for (const StreamRecordKind kind :
         {StreamRecordKind::kMip1, StreamRecordKind::kMip2, StreamRecordKind::kMip3, StreamRecordKind::kEstimate}) {
      const int level = kind == StreamRecordKind::kEstimate ? 3 : static_cast<int>(kind);
      const Vec3i cp{seed, 0, 0};
      const Box voxels = terrain(kChunkSize >> level, ++seed);
      r.apply_stream_record(mip_record(kind, cp, 3, voxels, encoded(voxels)));
      Box back;
      ASSERT_TRUE(r.read_mip(cp, back));
      EXPECT_EQ(back, voxels) << "level " << level << (shared ? " shared" : "");
      const Vec3i p{5, 17, 30};
      EXPECT_EQ(r.get(chunk_origin(cp) + p), voxels.get(p.x >> level, p.y >> level, p.z >> level));
    }
    for (const int level : {kHorizonNearLevel, kHorizonFarLevel}) {
      const Vec3i region{0, 2 * level, 0};
      const Box image = terrain(kHorizonRegionChunks * (kChunkSize >> level), level);
      std::vector<Vec3i> covered;
      const HorizonMask all = [] {
        HorizonMask m;
        m.fill(0xFF);
        return m;
      }();
      r.apply_horizon(StreamRecord{StreamRecordKind::kHorizon, region * kHorizonRegionChunks, 0, level, &image, &all, {}},
                      covered);
      ASSERT_EQ(covered.size(), static_cast<std::size_t>(kHorizonRegionSlots));
      const int n = kChunkSize >> level;
      for (const Vec3i cp : covered) {
        Box back;
        ASSERT_TRUE(r.read_mip(cp, back));
        const Vec3i at = floor_mod(cp, kHorizonRegionChunks) * n;
        for (int y = 0; y < n; ++y)
          for (int z = 0; z < n; ++z)
            for (int x = 0; x < n; ++x) ASSERT_EQ(back.get(x, y, z), image.get(at + Vec3i{x, y, z}));
      }
    }
  }
}

TEST(ReplicaMips, ReplicasThatAppliedEqualRecordsShareOneCopy) {
  auto shared = std::make_shared<DecodedChunks>();
  Replica a, b, alone;
  a.share_decoded(shared);
  b.share_decoded(shared);
  const Vec3i cp{4, 1, -2};
  const Box voxels = terrain(16, 5);
  const auto bytes = encoded(voxels);
  a.apply_stream_record(mip_record(StreamRecordKind::kMip1, cp, 9, voxels, bytes));
  b.apply_stream_record(mip_record(StreamRecordKind::kMip1, cp, 9, voxels, bytes));
  alone.apply_stream_record(mip_record(StreamRecordKind::kMip1, cp, 9, voxels, bytes));
  EXPECT_EQ(shared->mips().stats().entries, 1u);
  EXPECT_EQ(shared->mips().stats().hits, 1u);
  // Each of the two counts half the box; the replica on its own, all of it.
  EXPECT_EQ(a.memory().mip_bytes, b.memory().mip_bytes);
  EXPECT_LT(2 * a.memory().mip_bytes, alone.memory().mip_bytes + 2);
  EXPECT_GE(2 * a.memory().mip_bytes + 2, alone.memory().mip_bytes);

  // A new record for the chunk in one replica never shows in the other.
  const Box newer = terrain(16, 6);
  b.apply_stream_record(mip_record(StreamRecordKind::kMip1, cp, 10, newer, encoded(newer)));
  Box back;
  ASSERT_TRUE(a.read_mip(cp, back));
  EXPECT_EQ(back, voxels);
  EXPECT_EQ(a.revision(cp), 9u);
  ASSERT_TRUE(b.read_mip(cp, back));
  EXPECT_EQ(back, newer);
  // Neither does one replica's release, nor its chunk's Full record.
  Box whole({kChunkSize, kChunkSize, kChunkSize}, solid(materials::kRock));
  b.apply_stream_record(StreamRecord{StreamRecordKind::kFull, cp, 11, 0, &whole, nullptr, {}});
  b.apply_stream_record(StreamRecord{StreamRecordKind::kReleased, cp, 11, 0, nullptr, nullptr, {}});
  ASSERT_TRUE(a.read_mip(cp, back));
  EXPECT_EQ(back, voxels);
  // The box lives while a holds it, and not after.
  EXPECT_EQ(shared->mips().stats().entries, 1u);
  a.apply_stream_record(StreamRecord{StreamRecordKind::kReleased, cp, 9, 0, nullptr, nullptr, {}});
  EXPECT_EQ(shared->mips().stats().entries, 0u);
}

// A mip is kept as its record's bytes, not its voxels: eight replicas
// holding one 16^3 mip hold one unit between them, smaller than the 8 KiB
// of its voxels, and every read decodes the voxels the record had.
TEST(ReplicaMips, AMipIsKeptOnceAsItsRecordsBytesNotItsVoxels) {
  auto shared = std::make_shared<DecodedChunks>();
  std::vector<Replica> replicas(8);
  const Vec3i cp{-3, 2, 5};
  const Box voxels = terrain(16, 3);
  const auto bytes = encoded(voxels);
  ASSERT_LT(bytes.size(), voxels.voxel_count() * sizeof(Voxel) / 4) << "the test's terrain must encode small";
  for (Replica& r : replicas) {
    r.share_decoded(shared);
    r.apply_stream_record(mip_record(StreamRecordKind::kMip1, cp, 4, voxels, bytes));
  }
  const DecodedMips::Stats s = shared->mips().stats();
  EXPECT_EQ(s.entries, 1u);
  EXPECT_EQ(s.hits, replicas.size() - 1);
  std::size_t held = 0;
  for (const Replica& r : replicas) held += r.memory().mip_bytes;
  EXPECT_LE(held, bytes.size() + 128) << "all replicas together hold one unit";
  for (const Replica& r : replicas) {
    Box back;
    ASSERT_TRUE(r.read_mip(cp, back));
    EXPECT_EQ(back, voxels);
    const Vec3i at = chunk_origin(cp) + Vec3i{7, 9, 30};
    EXPECT_EQ(r.get(at), voxels.get(7 / 2, 9 / 2, 30 / 2));
  }
  // A replica on its own keeps the bytes too.
  Replica alone;
  alone.apply_stream_record(mip_record(StreamRecordKind::kMip1, cp, 4, voxels, bytes));
  EXPECT_LE(alone.memory().mip_bytes, bytes.size() + 128);
  // The same bytes again tell nothing new; other bytes of the same voxels
  // neither (a record without its bytes is encoded by the replica).
  alone.apply_stream_record(mip_record(StreamRecordKind::kMip1, cp, 4, voxels, bytes));
  alone.apply_stream_record(StreamRecord{StreamRecordKind::kMip1, cp, 4, 1, &voxels, nullptr, {}});
  EXPECT_EQ(alone.redundant_mips(), 2u);
  // Reads of two mips in turn each give their own voxels (one mip decoded
  // per thread at a time).
  const Vec3i other{9, 9, 9};
  const Box voxels2 = terrain(16, 4);
  alone.apply_stream_record(mip_record(StreamRecordKind::kMip1, other, 4, voxels2, encoded(voxels2)));
  for (int round = 0; round < 2; ++round) {
    EXPECT_EQ(alone.get(chunk_origin(cp) + Vec3i{2, 20, 6}), voxels.get(1, 10, 3));
    EXPECT_EQ(alone.get(chunk_origin(other) + Vec3i{2, 20, 6}), voxels2.get(1, 10, 3));
  }
}

// A patch changes the mip held as a unit into voxels of its own (the
// patched sub-units from the record, the rest as held); replicas patched
// alike share that box, and one not patched keeps the unit.
TEST(ReplicaMips, APatchedMipIsHeldAsItsVoxelsAndSharedByReplicasPatchedAlike) {
  auto shared = std::make_shared<DecodedChunks>();
  Replica a, b, c;
  const Vec3i cp{1, 0, 1};
  const Box voxels = terrain(16, 2);
  const auto bytes = encoded(voxels);
  for (Replica* r : {&a, &b, &c}) {
    r->share_decoded(shared);
    r->apply_stream_record(mip_record(StreamRecordKind::kMip1, cp, 4, voxels, bytes));
  }
  // Sub-units 0 and 5 become Air.
  const std::uint64_t mask = (std::uint64_t{1} << 0) | (std::uint64_t{1} << 5);
  Box patch_voxels({16, 16, 16});
  Box expected = voxels;
  for (const int i : {0, 5}) {
    const Vec3i o = patch_subunit_origin(1, i);
    for (int y = o.y; y < o.y + 4; ++y)
      for (int z = o.z; z < o.z + 4; ++z)
        for (int x = o.x; x < o.x + 4; ++x) expected.set(x, y, z, Voxel{});
  }
  StreamRecord patch{StreamRecordKind::kMipPatch, cp, 5, 1, &patch_voxels, nullptr, {}};
  patch.patch_mask = mask;
  a.apply_stream_record(patch);
  b.apply_stream_record(patch);
  for (Replica* r : {&a, &b}) {
    Box back;
    ASSERT_TRUE(r->read_mip(cp, back));
    EXPECT_EQ(back, expected);
    EXPECT_EQ(r->revision(cp), 5u);
  }
  Box back;
  ASSERT_TRUE(c.read_mip(cp, back));
  EXPECT_EQ(back, voxels) << "c was not patched";
  EXPECT_EQ(shared->mips().stats().entries, 2u) << "the unit (c) and one patched box (a and b)";
  EXPECT_GT(a.memory().mip_bytes, c.memory().mip_bytes) << "a box of voxels against a share of the unit";
}

TEST(ReplicaMips, EqualHorizonImagesAreSharedAndAChunksOwnRecordReplacesItsPartInOneReplicaOnly) {
  auto shared = std::make_shared<DecodedChunks>();
  Replica a, b;
  a.share_decoded(shared);
  b.share_decoded(shared);
  const Box image = terrain(kHorizonRegionChunks * (kChunkSize >> kHorizonNearLevel), 2);
  HorizonMask all;
  all.fill(0xFF);
  std::vector<Vec3i> covered;
  const StreamRecord h{StreamRecordKind::kHorizon, {0, 0, 0}, 0, kHorizonNearLevel, &image, &all, {}};
  a.apply_horizon(h, covered);
  b.apply_horizon(h, covered);
  EXPECT_EQ(shared->mips().stats().entries, 1u);
  const Box own = terrain(4, 9);
  b.apply_stream_record(mip_record(StreamRecordKind::kMip3, {1, 1, 1}, 4, own, encoded(own)));
  Box back;
  ASSERT_TRUE(b.read_mip({1, 1, 1}, back));
  EXPECT_EQ(back, own);
  ASSERT_TRUE(a.read_mip({1, 1, 1}, back));
  EXPECT_EQ(back.size(), (Vec3i{2, 2, 2}));
  EXPECT_EQ(back.get(0, 0, 0), image.get(2, 2, 2));
  EXPECT_EQ(a.holding({1, 1, 1})->form, HoldingForm::kHorizon4);
}

}  // namespace
}  // namespace terrane
