#include "protocol/stream_batch.h"

#include <gtest/gtest.h>

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
  const Frame f = w.finish();
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

TEST(StreamBatch, RecordsCostAFewBytesBeyondTheCodec) {
  const Box chunk = terrain(32, 7);
  const auto payload = full_payload(chunk);
  StreamBatchWriter w;
  for (int i = 0; i < 10; ++i) w.add(StreamRecordKind::kFull, {i, 0, 0}, 1, payload);
  const Frame f = w.finish();
  // Ten chunks, one frame: the overhead over the codec is tiny.
  EXPECT_LT(f.size(), 10 * payload.size() + 10 * 6 + 64);
}

TEST(StreamBatch, EveryTruncationAndBadByteIsAnErrorNotACrash) {
  const Box chunk = terrain(32, 2);
  StreamBatchWriter w;
  w.add(StreamRecordKind::kFull, {1, 2, 3}, 4, full_payload(chunk));
  w.add(StreamRecordKind::kEmpty, {1, 3, 3}, 0, {});
  const Frame f = w.finish();
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
  for (const int kind : {6, 7, 10, 255}) {
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
  const Frame f = w.finish();
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
  ASSERT_EQ(got.size(), 3u);
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
  // A horizon record costs the codec's bytes, its mask if any and a few
  // bytes (kind, position, revision, level, flag: 8 here at most).
  EXPECT_LE(records_of(f).size(), near_bytes.size() + far_bytes.size() + 64 + 8 + 8 + 5);
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
