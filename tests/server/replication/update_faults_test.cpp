// BudgetedUpdateFaults: the test seam of UpdateBatches drops its budget of
// batches, then corrupts its budget (exactly one voxel of the first unit of
// the first chunk, the rest of the batch untouched), counting each, then
// lets every batch through unchanged.
#include "server/replication/update_faults.h"

#include <gtest/gtest.h>

namespace terrane {
namespace {

UnitUpdate unit(Vec3i chunk_pos, std::uint16_t index, Material m) {
  UnitUpdate u;
  u.chunk_pos = chunk_pos;
  u.unit_index = index;
  for (std::size_t i = 0; i < u.voxels.size(); ++i) u.voxels[i] = i % 3 == 0 ? solid(m) : Voxel{};
  return u;
}

// Two chunks' pieces, in chunk order.
struct Pieces {
  UpdatePiece a = net_codec_encode_update_piece(std::vector<UnitUpdate>{unit({0, 0, 0}, 5, 2), unit({0, 0, 0}, 9, 3)});
  UpdatePiece b = net_codec_encode_update_piece(std::vector<UnitUpdate>{unit({1, 0, 0}, 0, 4)});
  std::vector<const UpdatePiece*> list() const { return {&a, &b}; }
};

std::vector<UnitUpdate> joined(const std::vector<const UpdatePiece*>& pieces) {
  std::vector<std::uint8_t> bytes;
  net_codec_join_update_pieces(pieces, bytes);
  std::vector<UnitUpdate> out(8);
  auto n = net_codec_decode_update_batch(bytes, out);
  EXPECT_TRUE(n.ok());
  out.resize(n.ok() ? *n : 0);
  return out;
}

TEST(BudgetedUpdateFaults, DropsItsBudgetThenCorruptsItsBudgetThenPassesEveryBatch) {
  ServerCounters counters;
  BudgetedUpdateFaults faults(2, 1, counters);
  const Pieces p;
  const std::vector<UnitUpdate> original = joined(p.list());
  ASSERT_EQ(original.size(), 3u);

  for (int i = 0; i < 2; ++i) {
    auto pieces = p.list();
    UpdatePiece scratch;
    EXPECT_FALSE(faults.tamper(pieces, scratch)) << "batch " << i;
  }
  EXPECT_EQ(counters.updates_dropped_by_fault.load(), 2u);

  auto pieces = p.list();
  UpdatePiece scratch;
  ASSERT_TRUE(faults.tamper(pieces, scratch));
  EXPECT_EQ(counters.updates_corrupted_by_fault.load(), 1u);
  const std::vector<UnitUpdate> bad = joined(pieces);
  ASSERT_EQ(bad.size(), original.size());
  // Voxel 0 of the first unit was solid(2), so it became Air;
  // everything else as sent.
  EXPECT_EQ(bad[0].voxels[0], Voxel{});
  EXPECT_NE(original[0].voxels[0], Voxel{});
  for (std::size_t u = 0; u < bad.size(); ++u)
    for (std::size_t i = 0; i < bad[u].voxels.size(); ++i)
      if (u != 0 || i != 0) {
        EXPECT_EQ(bad[u].voxels[i], original[u].voxels[i]) << u << " " << i;
      }
  EXPECT_EQ(bad[1], original[1]);
  EXPECT_EQ(bad[2], original[2]);

  for (int i = 0; i < 3; ++i) {
    auto again = p.list();
    UpdatePiece unused;
    ASSERT_TRUE(faults.tamper(again, unused));
    EXPECT_EQ(joined(again), original);
  }
  EXPECT_EQ(counters.updates_dropped_by_fault.load(), 2u);
  EXPECT_EQ(counters.updates_corrupted_by_fault.load(), 1u);
}

TEST(BudgetedUpdateFaults, AnAirVoxelIsMadeRock) {
  ServerCounters counters;
  BudgetedUpdateFaults faults(0, 1, counters);
  UnitUpdate air;
  air.chunk_pos = {2, -1, 3};
  air.unit_index = 7;
  const UpdatePiece piece = net_codec_encode_update_piece(std::vector<UnitUpdate>{air});
  std::vector<const UpdatePiece*> pieces{&piece};
  UpdatePiece scratch;
  ASSERT_TRUE(faults.tamper(pieces, scratch));
  const std::vector<UnitUpdate> bad = joined(pieces);
  ASSERT_EQ(bad.size(), 1u);
  EXPECT_EQ(bad[0].voxels[0], solid(materials::kRock));
  EXPECT_EQ(bad[0].chunk_pos, air.chunk_pos);
  EXPECT_EQ(bad[0].unit_index, air.unit_index);
}

}  // namespace
}  // namespace terrane
