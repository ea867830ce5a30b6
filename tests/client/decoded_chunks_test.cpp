#include "client/decoded_chunks.h"

#include <gtest/gtest.h>

#include "client/replica.h"
#include "common/codec/net_codec.h"
#include "protocol/stream_batch.h"
#include "tests/support/replica_records.h"
#include "tests/support/stream_records.h"

namespace terrane {
namespace {

// A chunk with some structure: a sloped surface of two materials.
Box slope(int seed) {
  Box b({kChunkSize, kChunkSize, kChunkSize});
  for (int y = 0; y < kChunkSize; ++y)
    for (int z = 0; z < kChunkSize; ++z)
      for (int x = 0; x < kChunkSize; ++x)
        if (y < 8 + (x + seed) / 3 + z / 5)
          b.set(x, y, z, make_voxel(y % 7 == seed % 7 ? materials::kSand : materials::kRock, 200));
  return b;
}

using testing_support::full_payload;
using testing_support::take_full;

// The replica takes a Full record of these bytes, as the client does.

void expect_holds(const Replica& r, Vec3i cp, const Box& voxels) {
  Box got({kChunkSize, kChunkSize, kChunkSize});
  r.read_box(chunk_origin(cp), got);
  EXPECT_TRUE(got == voxels);
}

TEST(DecodedChunks, ASecondReplicaTakesTheChunkTheFirstPackedAndHoldsTheSameVoxels) {
  auto shared = std::make_shared<DecodedChunks>();
  Replica a, b;
  a.share_decoded(shared);
  b.share_decoded(shared);
  const Box voxels = slope(1);
  const auto payload = full_payload(voxels);
  take_full(a, {2, 0, 3}, 5, payload);
  EXPECT_EQ(shared->stats().misses, 1u);
  EXPECT_EQ(shared->stats().hits, 0u);
  take_full(b, {2, 0, 3}, 5, payload);
  EXPECT_EQ(shared->stats().hits, 1u);
  expect_holds(a, {2, 0, 3}, voxels);
  expect_holds(b, {2, 0, 3}, voxels);
  EXPECT_EQ(a.hash({2, 0, 3}), b.hash({2, 0, 3}));
  EXPECT_EQ(b.hash({2, 0, 3}), chunk_hash(b.grid().find_chunk({2, 0, 3}), 5));
  EXPECT_EQ(shared->stats().hashes_made, 1u) << "the shared chunk's hash is made once for both";
  EXPECT_EQ(shared->stats().hashes_shared, 1u);
  // Each holds its own copy: an edit of one is not seen by the other.
  StreamRecord empty;
  empty.kind = StreamRecordKind::kEmpty;
  empty.chunk_pos = {2, 0, 3};
  empty.revision = 6;
  b.apply_stream_record(empty);
  expect_holds(a, {2, 0, 3}, voxels);
}

// A batch of these records decoded as a client of the process decodes it:
// bytes the process's replicas decoded before are not decoded again.
void take_batch(Replica& r, const std::shared_ptr<DecodedChunks>& shared, StreamBatchWriter& w, int* skipped) {
  testing_support::take_records(
      r, w, [&](StreamRecordKind kind, std::span<const std::uint8_t> rest) { return shared->known(kind, rest); },
      skipped);
}

TEST(DecodedChunks, BytesDecodedOnceAreNotDecodedAgainAndGiveTheSameVoxels) {
  auto shared = std::make_shared<DecodedChunks>();
  Replica a, b;
  a.share_decoded(shared);
  b.share_decoded(shared);
  const Box chunk = slope(2);
  Box mip({16, 16, 16});
  for (int y = 0; y < 6; ++y)
    for (int z = 0; z < 16; ++z)
      for (int x = 0; x < 16; ++x) mip.set(x, y, z, make_voxel(static_cast<Material>(1 + (x * z + y) % 5), 255));
  std::vector<std::uint8_t> mip_bytes;
  net_codec_encode(16, mip.voxels(), mip_bytes);
  ASSERT_GE(mip_bytes.size(), DecodedChunks::kPrefixBytes);
  // The same chunk's payload a second time, and a mip whose bytes differ
  // from a known one only near their end (another mip, with the same key).
  Box other = mip;
  other.set(15, 5, 15, make_voxel(static_cast<Material>(1 + (15 * 15 + 4) % 5), 255));
  std::vector<std::uint8_t> other_bytes;
  net_codec_encode(16, other.voxels(), other_bytes);
  ASSERT_NE(other_bytes, mip_bytes);
  ASSERT_TRUE(std::equal(mip_bytes.begin(), mip_bytes.begin() + DecodedMips::kKeyBytes, other_bytes.begin()))
      << "the test's mips must begin alike";
  auto write = [&](StreamBatchWriter& w, bool with_other) {
    w.add(StreamRecordKind::kFull, {1, 0, 0}, 3, full_payload(chunk));
    w.add(StreamRecordKind::kMip1, {4, 0, 0}, 2, mip_bytes);
    if (with_other) w.add(StreamRecordKind::kMip1, {5, 0, 0}, 2, other_bytes);
    w.add(StreamRecordKind::kEmpty, {6, 0, 0}, 1, {});
  };
  int skipped = 0;
  StreamBatchWriter first;
  write(first, false);
  take_batch(a, shared, first, &skipped);
  EXPECT_EQ(skipped, 0);
  StreamBatchWriter second;
  write(second, true);
  take_batch(b, shared, second, &skipped);
  EXPECT_EQ(skipped, 2) << "the chunk and the first mip; the other mip's bytes begin alike but differ";
  EXPECT_EQ(shared->stats().known_chunks, 1u);
  EXPECT_EQ(shared->mips().stats().known_units, 1u);
  for (const Replica* r : {&a, &b}) {
    expect_holds(*r, {1, 0, 0}, chunk);
    Box got;
    ASSERT_TRUE(r->read_mip({4, 0, 0}, got));
    EXPECT_TRUE(got == mip);
    EXPECT_EQ(r->holding({6, 0, 0})->form, HoldingForm::kEmpty) << "the records after a skipped one are read in place";
  }
  Box got;
  ASSERT_TRUE(b.read_mip({5, 0, 0}, got));
  EXPECT_TRUE(got == other);
  // A payload cut short is never taken for the one it begins like, nor
  // the bytes of another kind.
  const auto full = full_payload(chunk);
  EXPECT_EQ(shared->known(StreamRecordKind::kFull, std::span(full).first(full.size() - 1)).bytes, 0u);
  EXPECT_EQ(shared->known(StreamRecordKind::kMip1, full).bytes, 0u);
  EXPECT_EQ(shared->known(StreamRecordKind::kFull, full).bytes, full.size());
  // Nor a mip's bytes cut short, or at another level (other voxels).
  EXPECT_EQ(shared->known(StreamRecordKind::kMip1, std::span(mip_bytes).first(mip_bytes.size() - 1)).bytes, 0u);
  EXPECT_EQ(shared->known(StreamRecordKind::kMip2, mip_bytes).bytes, 0u);
  EXPECT_EQ(shared->known(StreamRecordKind::kMip1, mip_bytes).bytes, mip_bytes.size());
  // A mip no replica holds any more is not known.
  a.apply_stream_record(StreamRecord{StreamRecordKind::kReleased, {4, 0, 0}, 2, 0, nullptr, nullptr, {}});
  b.apply_stream_record(StreamRecord{StreamRecordKind::kReleased, {4, 0, 0}, 2, 0, nullptr, nullptr, {}});
  EXPECT_EQ(shared->known(StreamRecordKind::kMip1, mip_bytes).bytes, 0u);
}

TEST(DecodedChunks, OnlyEqualBytesAreShared) {
  // The same chunk and revision with other bytes (a server's fault, or a
  // hostile one): the second replica holds what its own bytes say.
  auto shared = std::make_shared<DecodedChunks>();
  Replica a, b;
  a.share_decoded(shared);
  b.share_decoded(shared);
  const Box first = slope(1), second = slope(4);
  take_full(a, {0, 0, 0}, 2, full_payload(first));
  take_full(b, {0, 0, 0}, 2, full_payload(second));
  EXPECT_EQ(shared->stats().hits, 0u);
  EXPECT_EQ(shared->stats().misses, 2u);
  expect_holds(a, {0, 0, 0}, first);
  expect_holds(b, {0, 0, 0}, second);
}

TEST(DecodedChunks, KeepsAtMostItsCapacityDroppingTheLeastRecentlyUsed) {
  DecodedChunks cache(2);
  std::vector<std::vector<std::uint8_t>> payloads;
  for (int i = 0; i < 3; ++i) payloads.push_back(full_payload(slope(i)));
  cache.add(payloads[0], std::make_shared<const Chunk>(Chunk::from_box(slope(0))));
  cache.add(payloads[1], std::make_shared<const Chunk>(Chunk::from_box(slope(1))));
  ASSERT_NE(cache.find(payloads[0]), nullptr);  // 0 is now the most recent
  cache.add(payloads[2], std::make_shared<const Chunk>(Chunk::from_box(slope(2))));
  EXPECT_EQ(cache.stats().entries, 2u);
  EXPECT_NE(cache.find(payloads[0]), nullptr);
  EXPECT_EQ(cache.find(payloads[1]), nullptr);
  const auto two = cache.find(payloads[2]);
  ASSERT_NE(two, nullptr);
  Box got({kChunkSize, kChunkSize, kChunkSize});
  two->read_box({0, 0, 0}, got, {0, 0, 0}, {kChunkSize, kChunkSize, kChunkSize});
  EXPECT_TRUE(got == slope(2));
}

TEST(DecodedChunks, WithoutACacheEachReplicaPacksItsOwn) {
  Replica r;
  const Box voxels = slope(3);
  take_full(r, {1, 1, 1}, 1, full_payload(voxels));
  expect_holds(r, {1, 1, 1}, voxels);
}

}  // namespace
}  // namespace terrane
