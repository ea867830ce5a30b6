// The lease regions' geometry (server/storage/cluster_link.h): which region
// a chunk is leased with, and whether two boxes touch a region in common.
#include "server/storage/cluster_link.h"

#include <gtest/gtest.h>

namespace terrane {
namespace {

constexpr int kRegionSide = kCoarseRegionChunks * kChunkSize;  // voxels

TEST(ClusterLinkTest, TwoBoxesMeetInALeaseRegionWhereTheyHaveChunksInOne) {
  // Both in region (0,0,0), in different chunks of it.
  const Region first{{0, 0, 0}, {2, 2, 2}};
  const Region far_corner{{kRegionSide - 2, kRegionSide - 2, kRegionSide - 2}, {kRegionSide, kRegionSide, kRegionSide}};
  ASSERT_FALSE(chunks_meet(first, far_corner));
  EXPECT_TRUE(lease_regions_meet(first, far_corner));
  EXPECT_TRUE(lease_regions_meet(far_corner, first));
  // Side by side across a region border: no region in common, until one
  // reaches over it.
  const Region east{{kRegionSide, 0, 0}, {kRegionSide + 2, 2, 2}};
  EXPECT_FALSE(lease_regions_meet(far_corner, east));
  EXPECT_FALSE(lease_regions_meet(first, east));
  const Region across{{kRegionSide - 1, 0, 0}, {kRegionSide + 1, 2, 2}};
  EXPECT_TRUE(lease_regions_meet(across, first));
  EXPECT_TRUE(lease_regions_meet(across, east));
  // Below zero the regions count down (floor division): -1 is region -1.
  const Region west{{-2, 0, 0}, {0, 2, 2}};
  EXPECT_FALSE(lease_regions_meet(west, first));
  EXPECT_TRUE(lease_regions_meet(west, Region{{-kRegionSide, 0, 0}, {-kRegionSide + 1, 1, 1}}));
  // An empty box meets nothing, even inside another.
  EXPECT_FALSE(lease_regions_meet(Region{{1, 1, 1}, {1, 2, 2}}, first));
  EXPECT_FALSE(lease_regions_meet(first, Region{}));
}

TEST(ClusterLinkTest, LeaseRegionsMeetAsTheirChunksRegionsDo) {
  // The same answer as listing every chunk's region, over boxes around a
  // region corner.
  const auto by_chunks = [](const Region& a, const Region& b) {
    bool any = false;
    for_each_chunk_in(a, [&](Vec3i ca) {
      for_each_chunk_in(b, [&](Vec3i cb) { any = any || lease_region_of(ca) == lease_region_of(cb); });
    });
    return any;
  };
  const int s = kRegionSide;
  for (const int ax : {-s - 3, -5, 0, s - 20, s - 1})
    for (const int bx : {-s, -1, 3, s - 2, s})
      for (const int aw : {1, 17, s})
        for (const int bw : {1, 40}) {
          const Region a{{ax, -s + 4, 0}, {ax + aw, 2, 3}}, b{{bx, 0, -3}, {bx + bw, s + 1, 1}};
          EXPECT_EQ(lease_regions_meet(a, b), by_chunks(a, b)) << ax << " " << bx << " " << aw << " " << bw;
        }
}

}  // namespace
}  // namespace terrane
