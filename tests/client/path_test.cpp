// find_path over a small world: flat ground, steps, drops, walls, holes and
// the edge of what is known at full resolution.
#include "client/path.h"

#include <gtest/gtest.h>

#include <cstdlib>

#include "common/voxel/grid.h"

namespace terrane {
namespace {

// A Grid known at full resolution inside [known.min, known.max).
struct TestWorld {
  Grid grid;
  Region known{{-64, -64, -64}, {64, 64, 64}};
  Voxel get(Vec3i p) const { return grid.get(p); }
  int resolution_at(Vec3i p) const { return known.contains(p) ? 0 : -1; }
  void floor(int y) { grid.fill(Region{{-64, y - 1, -64}, {64, y, 64}}, solid(materials::kGrass)); }
  void wall(Region r) { grid.fill(r, solid(materials::kRock)); }
};

// Every step moves to a neighbouring column, within the climb and drop,
// onto a place to stand.
void expect_walkable(const TestWorld& w, Vec3i start, const PathResult& r, const PathOptions& o = {}) {
  ASSERT_TRUE(r.found) << r.error;
  Vec3i prev = start;
  for (const Vec3i s : r.steps) {
    EXPECT_LE(std::abs(s.x - prev.x), 1);
    EXPECT_LE(std::abs(s.z - prev.z), 1);
    EXPECT_LE(s.y - prev.y, o.max_climb);
    EXPECT_GE(s.y - prev.y, -o.max_drop);
    EXPECT_TRUE(is_place(w, s, o)) << s.x << "," << s.y << "," << s.z;
    prev = s;
  }
}

TEST(Path, StraightAcrossFlatGround) {
  TestWorld w;
  w.floor(0);
  const auto r = find_path(w, {0, 0, 0}, {10, 0, 0});
  expect_walkable(w, {0, 0, 0}, r);
  EXPECT_EQ(r.steps.size(), 10u);
  EXPECT_EQ(r.steps.back(), (Vec3i{10, 0, 0}));
}

TEST(Path, DiagonalIsShorterThanTwoStraightSteps) {
  TestWorld w;
  w.floor(0);
  const auto r = find_path(w, {0, 0, 0}, {5, 0, 5});
  expect_walkable(w, {0, 0, 0}, r);
  EXPECT_EQ(r.steps.size(), 5u);
}

TEST(Path, ClimbsAStairOneStepAtATimeButNotAWall) {
  TestWorld w;
  w.floor(0);
  // A stair up to y = 3 along +x: columns x = 3, 4, 5 rise by one each.
  for (int i = 0; i < 3; ++i) w.wall(Region{{3 + i, 0, -64}, {64, 1 + i, 64}});
  const auto r = find_path(w, {0, 0, 0}, {8, 3, 0});
  expect_walkable(w, {0, 0, 0}, r);
  EXPECT_EQ(r.steps.back(), (Vec3i{8, 3, 0}));

  // A sheer cliff of 3 across the whole known world cannot be climbed.
  TestWorld cliff;
  cliff.floor(0);
  cliff.wall(Region{{3, 0, -64}, {64, 3, 64}});
  const auto up = find_path(cliff, {0, 0, 0}, {8, 3, 0});
  EXPECT_FALSE(up.found);
  EXPECT_NE(up.error.find("cannot be reached"), std::string::npos) << up.error;
  // ... but can be jumped down (a drop of 3).
  const auto down = find_path(cliff, {8, 3, 0}, {0, 0, 0});
  expect_walkable(cliff, {8, 3, 0}, down);
}

TEST(Path, GoesAroundAWallWithAGap) {
  TestWorld w;
  w.floor(0);
  // A wall at x = 5, too high to climb, with a gap at z in [10, 11).
  w.wall(Region{{5, 0, -64}, {6, 4, 10}});
  w.wall(Region{{5, 0, 11}, {6, 4, 64}});
  const auto r = find_path(w, {0, 0, 0}, {10, 0, 0});
  expect_walkable(w, {0, 0, 0}, r);
  bool through_gap = false;
  for (const Vec3i s : r.steps) through_gap |= s.x == 5 && s.z == 10;
  EXPECT_TRUE(through_gap);
  // Never cuts the wall's corner: no diagonal step into or out of the gap.
  Vec3i prev{0, 0, 0};
  for (const Vec3i s : r.steps) {
    if (s.x == 5 || prev.x == 5) {
      EXPECT_TRUE(s.z == prev.z || s.x == prev.x);
    }
    prev = s;
  }
}

TEST(Path, UnreachableGoalsSayWhy) {
  TestWorld w;
  w.floor(0);
  // Walled in: a closed ring of high wall around the goal.
  w.wall(Region{{8, 0, -3}, {13, 5, -2}});
  w.wall(Region{{8, 0, 3}, {13, 5, 4}});
  w.wall(Region{{8, 0, -3}, {9, 5, 4}});
  w.wall(Region{{12, 0, -3}, {13, 5, 4}});
  const auto r = find_path(w, {0, 0, 0}, {10, 0, 0});
  EXPECT_FALSE(r.found);
  EXPECT_TRUE(r.steps.empty());
  EXPECT_GT(r.explored, 100u);

  // In the air, or buried: not a place.
  EXPECT_NE(find_path(w, {0, 0, 0}, {3, 5, 3}).error.find("goal is not a place"), std::string::npos);
  EXPECT_NE(find_path(w, {0, -3, 0}, {3, 0, 3}).error.find("start is not a place"), std::string::npos);

  // A bounded search gives up and says so.
  PathOptions small;
  small.max_nodes = 10;
  const auto far = find_path(w, {0, 0, 0}, {40, 0, 40}, small);
  EXPECT_FALSE(far.found);
  EXPECT_NE(far.error.find("within 10 places"), std::string::npos) << far.error;
}

TEST(Path, StaysInsideWhatIsHeldAtFullResolution) {
  TestWorld w;
  w.floor(0);
  // Known only for x < 20: a goal beyond is not a place, and a path
  // between two known places never leaves the known part.
  w.known = Region{{-64, -64, -64}, {20, 64, 64}};
  EXPECT_FALSE(find_path(w, {0, 0, 0}, {30, 0, 0}).found);
  // A wall across z = 5 that ends at x = 25, where nothing is known: the
  // way around it is there, but only through the unknown.
  w.wall(Region{{-64, 0, 5}, {25, 4, 6}});
  const auto r = find_path(w, {0, 0, 0}, {0, 0, 10});
  EXPECT_FALSE(r.found) << "walked through the unknown";
  w.known = Region{{-64, -64, -64}, {64, 64, 64}};
  expect_walkable(w, {0, 0, 0}, find_path(w, {0, 0, 0}, {0, 0, 10}));
}

TEST(Path, PlaceNearFindsTheNearestStandingHeight) {
  TestWorld w;
  w.floor(0);
  w.wall(Region{{0, 5, 0}, {1, 6, 1}});  // a ledge at y = 6 above the floor
  PathOptions o;
  EXPECT_EQ(place_near(w, 0, 0, 0, 8, o), (Vec3i{0, 0, 0}));
  EXPECT_EQ(place_near(w, 0, 0, 7, 8, o), (Vec3i{0, 6, 0}));
  EXPECT_FALSE(place_near(w, 0, 0, 30, 8, o).has_value());
}

}  // namespace
}  // namespace terrane
