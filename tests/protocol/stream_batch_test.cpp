#include "protocol/stream_batch.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <memory>
#include <random>

#include "common/codec/net_codec.h"
#include "common/world/horizon.h"
#include "tests/support/stream_records.h"

namespace terrane {
namespace {

std::span<const std::uint8_t> records_of(const Frame& f) {
  auto m = verify_message(std::span<const std::uint8_t>(f).subspan(kFrameHeaderBytes));
  EXPECT_TRUE(m.ok());
  auto r = parse_stream_batch(*(*m)->body_as_StreamBatch());
  EXPECT_TRUE(r.ok());
  return *r;
}

Box terrain(int n, int seed) {
  Box b({n, n, n});
  for (int y = 0; y < n; ++y)
    for (int z = 0; z < n; ++z)
      for (int x = 0; x < n; ++x)
        if (y < n / 2 + (x * seed + z) % 3) b.set(x, y, z, make_voxel(static_cast<Material>(1 + (x + seed) % 4), 200));
  return b;
}

using testing_support::full_payload;

TEST(StreamBatch, EveryRecordKindRoundTrips) {
  const Box chunk = terrain(32, 3);
  const Box mip = terrain(8, 5);
  std::vector<std::uint8_t> mip_bytes;
  net_codec_encode(8, mip.voxels(), mip_bytes);
  StreamBatchWriter w;
  w.add(StreamRecordKind::kEmpty, {5, -2, 7}, 0, {});
  w.add(StreamRecordKind::kMip2, {-300000, 4, 9}, 12, mip_bytes);
  w.add(StreamRecordKind::kFull, {6, -2, 7}, 1ull << 40, full_payload(chunk));
  w.add(StreamRecordKind::kReleased, {6, -1, 7}, 3, {});
  const Box estimate = terrain(4, 7);
  std::vector<std::uint8_t> estimate_bytes;
  net_codec_encode(4, estimate.voxels(), estimate_bytes);
  w.add(StreamRecordKind::kEstimate, {6, -1, 8}, 0, estimate_bytes);
  EXPECT_EQ(w.records(), 5u);
  const Frame f = w.finish().flatten();
  EXPECT_TRUE(w.empty());
  StreamDecodeScratch s;
  std::vector<StreamRecord> got;
  std::vector<Box> boxes;
  ASSERT_TRUE(decode_stream_batch(records_of(f), s, [&](const StreamRecord& r) -> Status {
                got.push_back(r);
                boxes.push_back(r.voxels != nullptr ? *r.voxels : Box());
                return Ok{};
              }).ok());
  ASSERT_EQ(got.size(), 5u);
  EXPECT_EQ(got[0].kind, StreamRecordKind::kEmpty);
  EXPECT_EQ(got[0].chunk_pos, (Vec3i{5, -2, 7}));
  EXPECT_EQ(got[1].kind, StreamRecordKind::kMip2);
  EXPECT_EQ(got[1].level, 2);
  EXPECT_EQ(got[1].chunk_pos, (Vec3i{-300000, 4, 9}));
  EXPECT_EQ(got[1].revision, 12u);
  EXPECT_TRUE(boxes[1] == mip);
  EXPECT_EQ(got[2].kind, StreamRecordKind::kFull);
  EXPECT_EQ(got[2].revision, 1ull << 40);
  EXPECT_TRUE(boxes[2] == chunk);
  EXPECT_EQ(got[3].kind, StreamRecordKind::kReleased);
  EXPECT_EQ(got[3].chunk_pos, (Vec3i{6, -1, 7}));
  EXPECT_EQ(got[4].kind, StreamRecordKind::kEstimate);
  EXPECT_EQ(got[4].level, kMipLevels - 1);  // a 4^3 unit, as Mip 3
  EXPECT_EQ(got[4].chunk_pos, (Vec3i{6, -1, 8}));
  EXPECT_TRUE(boxes[4] == estimate);
  // Each record's payload is its encoded units as written (the frame is
  // still alive); records without voxels have none.
  auto same = [](std::span<const std::uint8_t> a, const std::vector<std::uint8_t>& b) {
    return std::equal(a.begin(), a.end(), b.begin(), b.end());
  };
  EXPECT_TRUE(got[0].payload.empty());
  EXPECT_TRUE(same(got[1].payload, mip_bytes));
  EXPECT_TRUE(same(got[2].payload, full_payload(chunk)));
  EXPECT_TRUE(got[3].payload.empty());
  EXPECT_TRUE(same(got[4].payload, estimate_bytes));
}

// Voxels that encode to many bytes (random materials and occupancies).
Box noise(int n, unsigned seed) {
  Box b({n, n, n});
  std::mt19937 rng(seed);
  for (int y = 0; y < n; ++y)
    for (int z = 0; z < n; ++z)
      for (int x = 0; x < n; ++x)
        b.set(x, y, z, make_voxel(static_cast<Material>(1 + rng() % 8), static_cast<std::uint8_t>(rng())));
  return b;
}

std::shared_ptr<const std::vector<std::uint8_t>> encoded(const Box& b) {
  auto out = std::make_shared<std::vector<std::uint8_t>>();
  if (b.size().x == 32) {
    *out = full_payload(b);
  } else {
    net_codec_encode(b.size().x, b.voxels(), *out);
  }
  return out;
}

TEST(StreamBatch, AGatheredBatchIsTheCopiedBatchByteForByte) {
  // Every record kind, payloads above and below OutFrame::kMinSharedBytes,
  // horizon records with and without a mask; 0..3 Released records more
  // change the padding after the records.
  const auto full = encoded(noise(32, 1)), mip1 = encoded(noise(16, 2)), mip2 = encoded(terrain(8, 3));
  const auto mip3 = encoded(noise(4, 4)), estimate = encoded(terrain(4, 5));
  const auto near = encoded(noise(16, 6)), far = encoded(terrain(8, 7)), far_big = encoded(noise(8, 8));
  ASSERT_GE(full->size(), OutFrame::kMinSharedBytes);
  ASSERT_GE(mip1->size(), OutFrame::kMinSharedBytes);
  ASSERT_GE(near->size(), OutFrame::kMinSharedBytes);
  ASSERT_LT(mip3->size(), OutFrame::kMinSharedBytes);
  HorizonMask mask{};
  mask[3] = 0x81;
  for (int extra = 0; extra < 4; ++extra) {
    auto write = [&](bool share) {
      auto owner = [&](const std::shared_ptr<const std::vector<std::uint8_t>>& p) {
        return share ? std::shared_ptr<const void>(p) : nullptr;
      };
      StreamBatchWriter w;
      w.add_horizon({-1, 0, 2}, kHorizonNearLevel, &mask, *near, owner(near));
      w.add_horizon({3, -1, 0}, kHorizonFarLevel, nullptr, *far, owner(far));
      w.add_horizon({3, 0, 0}, kHorizonFarLevel, &mask, *far_big, owner(far_big));
      w.add(StreamRecordKind::kFull, {1, 2, 3}, 9, *full, owner(full));
      w.add(StreamRecordKind::kMip1, {-5, 2, 3}, 1ull << 40, *mip1, owner(mip1));
      w.add(StreamRecordKind::kMip2, {-5, 3, 3}, 2, *mip2, owner(mip2));
      w.add(StreamRecordKind::kMip3, {-5, 3, 4}, 3, *mip3, owner(mip3));
      w.add(StreamRecordKind::kEstimate, {300000, 3, 4}, 0, *estimate, owner(estimate));
      w.add(StreamRecordKind::kEmpty, {0, 0, 0}, 4, {});
      for (int i = 0; i < extra; ++i) w.add(StreamRecordKind::kReleased, {i, 1, 1}, 5, {});
      return w.finish();
    };
    const OutFrame gathered = write(true), copied = write(false);
    const Frame bytes = gathered.flatten();
    EXPECT_EQ(bytes, copied.flatten()) << extra;
    // The records' vector built whole, as FlatBuffers copies it in.
    EXPECT_EQ(bytes, build_stream_batch(records_of(copied.flatten()))) << extra;
    EXPECT_EQ(gathered.size(), bytes.size());
    EXPECT_EQ(gathered.shared_bytes(), full->size() + mip1->size() + near->size() + far_big->size() +
                                           (mip2->size() >= OutFrame::kMinSharedBytes ? mip2->size() : 0) +
                                           (far->size() >= OutFrame::kMinSharedBytes ? far->size() : 0));
    EXPECT_EQ(copied.shared_bytes(), 0u);
    // The shared payloads are the owners' own bytes, not copies.
    std::vector<const std::uint8_t*> starts;
    gathered.for_each_segment([&](std::span<const std::uint8_t> s) { starts.push_back(s.data()); });
    for (const auto& p : {full, mip1, near, far_big})
      EXPECT_NE(std::find(starts.begin(), starts.end(), p->data()), starts.end());
    // And it decodes as the records written.
    StreamDecodeScratch s;
    std::vector<StreamRecordKind> kinds;
    ASSERT_TRUE(decode_stream_batch(records_of(bytes), s, [&](const StreamRecord& r) -> Status {
                  kinds.push_back(r.kind);
                  return Ok{};
                }).ok());
    EXPECT_EQ(kinds.size(), 9u + static_cast<std::size_t>(extra));
  }
}

TEST(StreamBatch, AGatheredBatchKeepsItsPayloadsOwnersAlive) {
  auto full = encoded(noise(32, 9));
  const std::weak_ptr<const std::vector<std::uint8_t>> watch = full;
  StreamBatchWriter w;
  w.add(StreamRecordKind::kFull, {1, 2, 3}, 9, *full, full);
  const auto expected = *full;
  full.reset();
  EXPECT_FALSE(watch.expired()) << "the writer holds it";
  OutFrame f = w.finish();
  EXPECT_FALSE(watch.expired()) << "the frame holds it";
  StreamDecodeScratch s;
  const Frame bytes = f.flatten();
  ASSERT_TRUE(decode_stream_batch(records_of(bytes), s, [&](const StreamRecord& r) -> Status {
                EXPECT_TRUE(std::equal(r.payload.begin(), r.payload.end(), expected.begin(), expected.end()));
                return Ok{};
              }).ok());
  f = OutFrame{};
  EXPECT_TRUE(watch.expired());
}

TEST(StreamBatch, RecordsCostAFewBytesBeyondTheCodec) {
  const Box chunk = terrain(32, 7);
  const auto payload = full_payload(chunk);
  StreamBatchWriter w;
  for (int i = 0; i < 10; ++i) w.add(StreamRecordKind::kFull, {i, 0, 0}, 1, payload);
  const Frame f = w.finish().flatten();
  // Ten chunks, one frame: the overhead over the codec is tiny.
  EXPECT_LT(f.size(), 10 * payload.size() + 10 * 6 + 64);
}

TEST(StreamBatch, EveryTruncationAndBadByteIsAnErrorNotACrash) {
  const Box chunk = terrain(32, 2);
  StreamBatchWriter w;
  w.add(StreamRecordKind::kFull, {1, 2, 3}, 4, full_payload(chunk));
  w.add(StreamRecordKind::kEmpty, {1, 3, 3}, 0, {});
  const Frame f = w.finish().flatten();
  const auto records = records_of(f);
  const std::vector<std::uint8_t> bytes(records.begin(), records.end());
  StreamDecodeScratch s;
  auto count = [&](std::span<const std::uint8_t> b, int* n) {
    *n = 0;
    return decode_stream_batch(b, s, [&](const StreamRecord&) -> Status {
      ++*n;
      return Ok{};
    });
  };
  int n = 0;
  ASSERT_TRUE(count(bytes, &n).ok());
  EXPECT_EQ(n, 2);
  for (std::size_t cut = 1; cut < bytes.size(); ++cut) {
    // A cut at a record boundary is a valid shorter batch; anywhere else an error.
    const auto st = count(std::span(bytes).first(cut), &n);
    if (st.ok()) {
      EXPECT_EQ(n, 1) << "cut " << cut;
    }
  }
  // Unknown kinds; 6 and 7 are the horizon forms, never a record's kind.
  for (const int kind : {6, 7, 11, 255}) {
    std::vector<std::uint8_t> bad = bytes;
    bad[0] = static_cast<std::uint8_t>(kind);
    EXPECT_EQ(count(bad, &n).error().code, DecodeErrorCode::kInvalidValue) << "kind " << kind;
  }
  // A position beyond the wire range.
  std::vector<std::uint8_t> far = {4, 0xFF, 0xFF, 0xFF, 0x7F, 0, 0, 0};
  EXPECT_EQ(count(far, &n).error().code, DecodeErrorCode::kInvalidValue);
  // A record in range followed by a delta near INT64_MIN: out of range, and
  // no overflow computing it (UBSan runs this).
  std::vector<std::uint8_t> huge = {8, 1, 0, 0, 0};  // a released record at x = -1
  huge.insert(huge.end(), {8, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0x01, 0, 0, 0});
  EXPECT_EQ(count(huge, &n).error().code, DecodeErrorCode::kInvalidValue);
  EXPECT_EQ(n, 1);
  // An endless varint.
  std::vector<std::uint8_t> endless(20, 0xFF);
  endless[0] = 4;
  EXPECT_FALSE(count(endless, &n).ok());
}

TEST(StreamBatch, HorizonRecordsCarryARegionImageAndTheChunksItCovers) {
  const Box near = terrain(16, 4);
  const Box far = terrain(8, 6);
  std::vector<std::uint8_t> near_bytes, far_bytes;
  net_codec_encode(16, near.voxels(), near_bytes);
  net_codec_encode(8, far.voxels(), far_bytes);
  HorizonMask mask{};
  mask[0] = 0b101;  // chunks (0,0,0) and (2,0,0) of the region
  mask[63] = 0x80;  // chunk (7,7,7)
  StreamBatchWriter w;
  w.add_horizon({-3, 0, 2}, kHorizonNearLevel, &mask, near_bytes);
  w.add(StreamRecordKind::kEmpty, {-24, 1, 17}, 2, {});  // relative to the region's first chunk
  w.add_horizon({4, -1, -7}, kHorizonFarLevel, nullptr, far_bytes);
  const Box outer = terrain(4, 8);
  std::vector<std::uint8_t> outer_bytes;
  net_codec_encode(4, outer.voxels(), outer_bytes);
  w.add_horizon({-1, 0, 0}, kHorizonOuterLevel, &mask, outer_bytes);
  const Frame f = w.finish().flatten();
  StreamDecodeScratch s;
  std::vector<StreamRecord> got;
  std::vector<Box> images;
  std::vector<HorizonMask> masks;
  ASSERT_TRUE(decode_stream_batch(records_of(f), s, [&](const StreamRecord& r) -> Status {
                got.push_back(r);
                images.push_back(r.voxels != nullptr ? *r.voxels : Box{});
                masks.push_back(r.mask != nullptr ? *r.mask : HorizonMask{});
                return Ok{};
              }).ok());
  ASSERT_EQ(got.size(), 4u);
  EXPECT_EQ(got[0].kind, StreamRecordKind::kHorizon);
  EXPECT_EQ(got[0].chunk_pos, (Vec3i{-24, 0, 16}));
  EXPECT_EQ(got[0].level, kHorizonNearLevel);
  EXPECT_EQ(images[0], near);
  EXPECT_EQ(masks[0], mask);
  EXPECT_EQ(got[1].chunk_pos, (Vec3i{-24, 1, 17}));
  EXPECT_EQ(got[2].chunk_pos, (Vec3i{32, -8, -56}));
  EXPECT_EQ(got[2].level, kHorizonFarLevel);
  EXPECT_EQ(images[2], far);
  HorizonMask all;
  all.fill(0xFF);
  EXPECT_EQ(masks[2], all) << "no mask: every chunk of the region";
  EXPECT_EQ(got[3].chunk_pos, (Vec3i{-8, 0, 0}));
  EXPECT_EQ(got[3].level, kHorizonOuterLevel);
  EXPECT_EQ(images[3], outer) << "level 6: 4^3 voxels for the region";
  EXPECT_EQ(masks[3], mask);
  // A horizon record costs the codec's bytes, its mask if any and a few
  // bytes (kind, position, revision, level, flag: 8 here at most).
  EXPECT_LE(records_of(f).size(), near_bytes.size() + far_bytes.size() + outer_bytes.size() + 2 * 64 + 3 * 8 + 5);
}

TEST(StreamBatch, BadHorizonRecordsAreErrors) {
  std::vector<std::uint8_t> unit;
  net_codec_encode(8, terrain(8, 2).voxels(), unit);
  StreamDecodeScratch s;
  const auto decode = [&](const std::vector<std::uint8_t>& b) {
    return decode_stream_batch(b, s, [](const StreamRecord&) -> Status { return Ok{}; });
  };
  // kind 9, position (16, 0, 8) as zigzag varints (32, 0, 16), revision 0.
  const std::vector<std::uint8_t> head = {9, 32, 0, 16, 0};
  auto record = [&](std::vector<std::uint8_t> rest) {
    std::vector<std::uint8_t> b = head;
    b.insert(b.end(), rest.begin(), rest.end());
    return b;
  };
  std::vector<std::uint8_t> good = record({5, 0});
  good.insert(good.end(), unit.begin(), unit.end());
  ASSERT_TRUE(decode(good).ok());
  auto bad_level = good;
  bad_level[5] = 3;
  EXPECT_EQ(decode(bad_level).error().code, DecodeErrorCode::kInvalidValue);
  bad_level[5] = 7;
  EXPECT_EQ(decode(bad_level).error().code, DecodeErrorCode::kInvalidValue);
  // Level 6 takes a 4^3 unit.
  std::vector<std::uint8_t> outer_unit;
  net_codec_encode(4, terrain(4, 3).voxels(), outer_unit);
  std::vector<std::uint8_t> outer_good = record({6, 0});
  outer_good.insert(outer_good.end(), outer_unit.begin(), outer_unit.end());
  EXPECT_TRUE(decode(outer_good).ok());
  for (std::size_t cut = 1; cut < outer_good.size(); ++cut)
    EXPECT_FALSE(
        decode(std::vector<std::uint8_t>(outer_good.begin(), outer_good.begin() + static_cast<std::ptrdiff_t>(cut))).ok())
        << "level 6, cut " << cut;
  auto bad_flag = good;
  bad_flag[6] = 2;
  EXPECT_EQ(decode(bad_flag).error().code, DecodeErrorCode::kInvalidValue);
  auto unaligned = good;
  unaligned[1] = 34;  // x = 17
  EXPECT_EQ(decode(unaligned).error().code, DecodeErrorCode::kInvalidValue);
  // A mask promised and cut short.
  EXPECT_EQ(decode(record({5, 1, 0xFF, 0xFF})).error().code, DecodeErrorCode::kTruncated);
  // Every cut inside the record is an error.
  for (std::size_t cut = 1; cut < good.size(); ++cut)
    EXPECT_FALSE(decode(std::vector<std::uint8_t>(good.begin(), good.begin() + static_cast<std::ptrdiff_t>(cut))).ok())
        << "cut " << cut;
}

// The 4^3 units of a mip's sub-units in mask, ascending (what a server
// sends in a Mip patch).
std::vector<std::uint8_t> patch_units(const Box& mip, int level, std::uint64_t mask) {
  std::vector<std::uint8_t> out;
  for (std::uint64_t rest = mask; rest != 0; rest &= rest - 1) {
    const Vec3i o = patch_subunit_origin(level, std::countr_zero(rest));
    Box unit({4, 4, 4});
    for (int y = 0; y < 4; ++y)
      for (int z = 0; z < 4; ++z)
        for (int x = 0; x < 4; ++x) unit.set(x, y, z, mip.get(o.x + x, o.y + y, o.z + z));
    net_codec_encode(4, unit.voxels(), out);
  }
  return out;
}

TEST(StreamBatch, MipPatchesCarryTheirSubUnitsInPlace) {
  const Box mip1 = noise(16, 11), mip2 = terrain(8, 12);
  const std::uint64_t mask1 = (std::uint64_t{1} << 63) | 0x10001, mask2 = 0x81;
  StreamBatchWriter w;
  w.add_mip_patch({3, -1, 2}, 9, 1, mask1, patch_units(mip1, 1, mask1));
  w.add_mip_patch({4, -1, 2}, 1ull << 33, 2, mask2, patch_units(mip2, 2, mask2));
  const Frame f = w.finish().flatten();
  StreamDecodeScratch s;
  std::vector<StreamRecord> got;
  std::vector<Box> boxes;
  ASSERT_TRUE(decode_stream_batch(records_of(f), s, [&](const StreamRecord& r) -> Status {
                got.push_back(r);
                boxes.push_back(*r.voxels);
                return Ok{};
              }).ok());
  ASSERT_EQ(got.size(), 2u);
  const std::uint64_t masks[2] = {mask1, mask2};
  const Box* mips[2] = {&mip1, &mip2};
  for (int k = 0; k < 2; ++k) {
    const int level = k + 1;
    EXPECT_EQ(got[k].kind, StreamRecordKind::kMipPatch);
    EXPECT_EQ(got[k].level, level);
    EXPECT_EQ(got[k].patch_mask, masks[k]);
    ASSERT_EQ(boxes[k].size(), (Vec3i{32 >> level, 32 >> level, 32 >> level}));
    // Every voxel of a patched sub-unit is the mip's, in its place.
    int voxels = 0;
    for (std::uint64_t rest = masks[k]; rest != 0; rest &= rest - 1) {
      const Vec3i o = patch_subunit_origin(level, std::countr_zero(rest));
      for (int y = 0; y < 4; ++y)
        for (int z = 0; z < 4; ++z)
          for (int x = 0; x < 4; ++x, ++voxels)
            ASSERT_EQ(boxes[k].get(o.x + x, o.y + y, o.z + z), mips[k]->get(o.x + x, o.y + y, o.z + z));
    }
    EXPECT_EQ(voxels, 64 * std::popcount(masks[k]));
  }
  EXPECT_EQ(got[1].revision, 1ull << 33);
  // Sub-unit 63 of level 1 is the cube at (12, 12, 12); 7 of level 2 at (4, 4, 4).
  EXPECT_EQ(patch_subunit_origin(1, 63), (Vec3i{12, 12, 12}));
  EXPECT_EQ(patch_subunit_origin(1, 4), (Vec3i{0, 0, 4}));
  EXPECT_EQ(patch_subunit_origin(1, 16), (Vec3i{0, 4, 0}));
  EXPECT_EQ(patch_subunit_origin(2, 7), (Vec3i{4, 4, 4}));
}

TEST(StreamBatch, BadMipPatchesAreErrors) {
  const Box mip = terrain(16, 13);
  StreamBatchWriter w;
  w.add_mip_patch({1, 0, 0}, 5, 1, 0x3, patch_units(mip, 1, 0x3));
  const Frame f = w.finish().flatten();
  const auto records = records_of(f);
  const std::vector<std::uint8_t> good(records.begin(), records.end());
  StreamDecodeScratch s;
  const auto decode = [&](const std::vector<std::uint8_t>& b) {
    return decode_stream_batch(b, s, [](const StreamRecord&) -> Status { return Ok{}; });
  };
  ASSERT_TRUE(decode(good).ok());
  // kind 10, position (1, 0, 0) as (2, 0, 0), revision 5, then the level.
  ASSERT_EQ(good[0], 10);
  ASSERT_EQ(good[5], 1);
  for (const int level : {0, 3, 4, 255}) {
    auto bad = good;
    bad[5] = static_cast<std::uint8_t>(level);
    EXPECT_EQ(decode(bad).error().code, DecodeErrorCode::kInvalidValue) << "level " << level;
  }
  // No sub-unit at all.
  std::vector<std::uint8_t> none = {10, 2, 0, 0, 5, 1, 0, 0, 0, 0, 0, 0, 0, 0};
  EXPECT_EQ(decode(none).error().code, DecodeErrorCode::kInvalidValue);
  // A mask promising more units than follow, and every cut inside the record.
  auto more = good;
  more[6] = 0x7;
  EXPECT_FALSE(decode(more).ok());
  for (std::size_t cut = 1; cut < good.size(); ++cut)
    EXPECT_FALSE(decode(std::vector<std::uint8_t>(good.begin(), good.begin() + static_cast<std::ptrdiff_t>(cut))).ok())
        << "cut " << cut;
}

TEST(StreamBatch, TooManyRecordsAreOverLimit) {
  std::vector<std::uint8_t> bytes;
  for (std::size_t i = 0; i <= kMaxStreamRecords; ++i) bytes.insert(bytes.end(), {4, 0, 0, 0, 0});  // Empty
  StreamDecodeScratch s;
  const auto st = decode_stream_batch(bytes, s, [](const StreamRecord&) -> Status { return Ok{}; });
  ASSERT_FALSE(st.ok());
  EXPECT_EQ(st.error().code, DecodeErrorCode::kOverLimit);
}

}  // namespace
}  // namespace terrane
