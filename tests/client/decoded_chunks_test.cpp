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
  // Each holds its own copy: an edit of one is not seen by the other.
  b.apply_stream_record(StreamRecord{StreamRecordKind::kEmpty, {2, 0, 3}, 6, 0, nullptr, nullptr, {}});
  expect_holds(a, {2, 0, 3}, voxels);
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
