// ViewPlan: the coarse pass walks the whole view nearest first from the
// centre it began at, then the chunks a move brought into view; in_view and
// desired follow the table around the centre and the world's bounds; the
// refine queue gives the nearest chunk first, and after a move recomputes
// its keys for the new centre and drops what needs no refining.
#include "server/replication/view_plan.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <set>
#include <tuple>

#include "common/world/coarse_image.h"
#include "common/world/view.h"
#include "protocol/messages.h"

namespace terrane {
namespace {

constexpr std::int32_t kView = 96, kFull = 32, kMargin = 32;

struct Less {
  bool operator()(Vec3i a, Vec3i b) const { return std::tie(a.x, a.y, a.z) < std::tie(b.x, b.y, b.z); }
};

TEST(ViewPlan, TheCoarsePassWalksTheViewNearestFirstThenTheChunksAMoveBroughtIntoView) {
  const WorldBounds bounds;
  ViewPlan plan(bounds);
  EXPECT_FALSE(plan.valid());
  plan.reset(kView, kFull, kMargin, {0, 1, 0});
  ASSERT_TRUE(plan.valid());
  std::vector<Vec3i> walked;
  while (auto cp = plan.next_coarse()) walked.push_back(*cp);
  ASSERT_EQ(walked.size(), plan.table().offsets().size());
  EXPECT_EQ(walked.front(), (Vec3i{0, 1, 0}));
  for (std::size_t i = 1; i < walked.size(); ++i)
    EXPECT_LE(offset_center_dist2(walked[i - 1] - Vec3i{0, 1, 0}), offset_center_dist2(walked[i] - Vec3i{0, 1, 0}));
  EXPECT_TRUE(plan.coarse_walked());

  plan.shift({1, 0, 0});
  EXPECT_EQ(plan.center(), (Vec3i{1, 1, 0}));
  EXPECT_FALSE(plan.coarse_walked());
  std::set<Vec3i, Less> entered;
  while (auto cp = plan.next_coarse()) entered.insert(*cp);
  std::set<Vec3i, Less> expected;
  for (const Vec3i o : plan.table().entering({1, 0, 0})) expected.insert(Vec3i{1, 1, 0} + o);
  EXPECT_EQ(entered, expected);
  EXPECT_FALSE(entered.empty());
  for (const Vec3i cp : entered) EXPECT_FALSE(plan.table().contains(cp - Vec3i{0, 1, 0}));

  plan.enter_again({2, 1, 0});
  EXPECT_EQ(plan.next_coarse(), (Vec3i{2, 1, 0}));
  EXPECT_EQ(plan.next_coarse(), std::nullopt);

  // A new plan starts the walk over.
  plan.reset(kView, kFull, kMargin, {5, 1, 5});
  EXPECT_EQ(plan.next_coarse(), (Vec3i{5, 1, 5}));
}

TEST(ViewPlan, InViewAndTheLevelWantedFollowTheTableAroundTheCentreWithinTheWorld) {
  WorldBounds bounds;
  bounds.min_y = 0;
  bounds.max_y = 64;  // chunks y = 0 and 1
  ViewPlan plan(bounds);
  plan.reset(kView, kFull, kMargin, {10, 0, 0});
  EXPECT_TRUE(plan.in_view({10, 0, 0}));
  EXPECT_EQ(plan.desired({10, 0, 0}), 0);
  EXPECT_FALSE(plan.in_view({10, 2, 0}));   // above the world
  EXPECT_FALSE(plan.in_view({10, -1, 0}));  // below it
  EXPECT_FALSE(plan.in_view({20, 0, 0}));   // beyond the view
  EXPECT_EQ(plan.desired({20, 0, 0}), kMipLevels);
  EXPECT_GT(plan.desired({12, 0, 0}), 0);  // 2 chunks = 64 voxels: beyond full resolution
  EXPECT_EQ(plan.keep_table().view_distance(), kView + kMargin);
}

// unknown_regions and in_view_mask against walking the view's offsets
// chunk by chunk (what the horizon's plan did before them): the same
// regions in the same order with the same first chunks, and the same
// chunks in view, with and without known chunks, a border and the wire's
// edge.
TEST(ViewPlan, UnknownRegionsAndTheirMasksAreWhatWalkingTheViewFinds) {
  struct Case {
    std::int32_t view;
    Vec3i center;
    bool border;
    int known_every;  // every n-th chunk of the view known (0: none)
  };
  const std::int32_t lim = kMaxWireCoordinate / kChunkSize;
  for (const Case& c : {Case{320, {3, 1, -5}, false, 0}, Case{320, {3, 1, -5}, false, 7}, Case{480, {-20, 3, 9}, true, 0},
                        Case{480, {-20, 3, 9}, true, 3}, Case{256, {lim - 2, 0, 0}, false, 0},
                        Case{200, {0, 0, -lim + 1}, false, 5}}) {
    WorldBounds bounds;  // y -128..256
    if (c.border) {
      bounds.bounded_xz = true;
      bounds.min_x = -900;
      bounds.max_x = -300;
      bounds.min_z = 100;
      bounds.max_z = 700;
    }
    ViewPlan plan(bounds);
    plan.reset(c.view, kFull, kMargin, c.center);
    std::set<Vec3i, Less> known;
    std::size_t k = 0;
    for (const Vec3i o : plan.table().offsets())
      if (c.known_every != 0 && ++k % static_cast<std::size_t>(c.known_every) == 0) known.insert(c.center + o);
    const auto is_known = [&](Vec3i cp) { return known.count(cp) != 0; };
    // The walk: each region at its first unknown chunk in view, in order.
    std::vector<std::pair<Vec3i, Vec3i>> want;
    std::set<Vec3i, Less> seen;
    std::map<Vec3i, HorizonMask, Less> masks;
    for (const Vec3i o : plan.table().offsets()) {
      const Vec3i cp = c.center + o;
      if (!plan.in_view(cp)) continue;
      const Vec3i region = coarse_region_of(cp);
      horizon_mask_set(masks[region], coarse_index(cp));
      if (is_known(cp) || !wire_chunk_ok(region * 8) || !wire_chunk_ok(region * 8 + Vec3i{7, 7, 7})) continue;
      if (seen.insert(region).second) want.emplace_back(region, cp);
    }
    ASSERT_GT(want.size(), 3u);
    // may_know: true only for regions with a known chunk (false elsewhere,
    // so both paths are taken), then true everywhere.
    for (const bool always : {false, true}) {
      const auto may_know = [&](Vec3i region) {
        return always || std::any_of(known.begin(), known.end(), [&](Vec3i cp) { return coarse_region_of(cp) == region; });
      };
      const auto got = plan.unknown_regions(may_know, is_known);
      ASSERT_EQ(got.size(), want.size()) << "view " << c.view << (always ? ", always walked" : "");
      for (std::size_t i = 0; i < got.size(); ++i) {
        EXPECT_EQ(got[i].region, want[i].first) << "view " << c.view << ", region " << i;
        EXPECT_EQ(got[i].first, want[i].second) << "view " << c.view << ", region " << i;
      }
    }
    for (const auto& [region, mask] : masks) EXPECT_EQ(plan.in_view_mask(region), mask) << "view " << c.view;
    EXPECT_EQ(plan.in_view_mask(coarse_region_of(c.center + Vec3i{0, 40, 0})), HorizonMask{}) << "above the world";
  }
}

TEST(ViewPlan, TheRefineQueueGivesTheNearestFirstAndAfterAMoveRecomputesItsKeysAndDropsWhatNeedsNone) {
  const WorldBounds bounds;
  ViewPlan plan(bounds);
  plan.reset(kView, kFull, kMargin, {0, 0, 0});
  const auto all = [](Vec3i) { return true; };
  plan.refill_refine({{3, 0, 0}, {1, 0, 0}, {-2, 0, 0}});
  plan.push_refine({0, 0, 2});
  EXPECT_EQ(plan.pop_refine(all), (Vec3i{1, 0, 0}));
  // Moved two chunks towards +x: (3,0,0) is now the nearest; (0,0,2) needs
  // no refining any more.
  plan.shift({1, 0, 0});
  plan.shift({1, 0, 0});
  plan.push_refine({3, 0, 0});  // pushed again by the move: once
  const auto needs = [](Vec3i cp) { return cp != Vec3i{0, 0, 2}; };
  EXPECT_EQ(plan.pop_refine(needs), (Vec3i{3, 0, 0}));
  EXPECT_EQ(plan.pop_refine(needs), (Vec3i{-2, 0, 0}));
  EXPECT_EQ(plan.pop_refine(needs), std::nullopt);
}

}  // namespace
}  // namespace terrane
