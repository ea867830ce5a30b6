// ViewTable: the precomputed plan and the shells a one-chunk move changes,
// checked against the view rule applied from scratch.
#include "server/replication/view_table.h"

#include <gtest/gtest.h>

#include <set>
#include <tuple>

#include "common/world/view.h"

namespace terrane {
namespace {

using Set = std::set<std::tuple<int, int, int>>;
Set as_set(const std::vector<Vec3i>& v, Vec3i base = {0, 0, 0}) {
  Set s;
  for (const Vec3i o : v) s.insert({o.x + base.x, o.y + base.y, o.z + base.z});
  return s;
}

TEST(ViewTable, OffsetsAreTheViewRule) {
  const ViewTable t(200, 64);
  EXPECT_EQ(t.offsets(), view_offsets(200));
  for (const Vec3i o : t.offsets()) {
    EXPECT_TRUE(t.contains(o));
    EXPECT_EQ(t.level(o), offset_level(o, 64));
  }
  EXPECT_FALSE(t.contains({100, 0, 0}));
  EXPECT_EQ(t.level({100, 0, 0}), -1);
}

TEST(ViewTable, ShellsOfEveryOneChunkMoveMatchTheRuleFromScratch) {
  const ViewTable t(160, 48);
  const Vec3i old_c{3, -1, 7};
  for (int dy = -1; dy <= 1; ++dy)
    for (int dz = -1; dz <= 1; ++dz)
      for (int dx = -1; dx <= 1; ++dx) {
        const Vec3i d{dx, dy, dz};
        if (d == Vec3i{0, 0, 0}) continue;
        const Vec3i new_c = old_c + d;
        const Set before = as_set(t.offsets(), old_c), after = as_set(t.offsets(), new_c);
        Set entering, leaving;
        for (const auto& c : after)
          if (before.count(c) == 0) entering.insert(c);
        for (const auto& c : before)
          if (after.count(c) == 0) leaving.insert(c);
        EXPECT_EQ(as_set(t.entering(d), new_c), entering);
        EXPECT_EQ(as_set(t.leaving(d), old_c), leaving);
        // Finer: every chunk in view whose level went down (or that entered
        // with a level below 3), and no other.
        Set finer;
        for (const Vec3i o : t.offsets()) {
          const Vec3i cp = new_c + o;
          const int now = t.level(o), then = t.level(cp - old_c);
          if (now < 3 && (then < 0 || now < then)) finer.insert({cp.x, cp.y, cp.z});
        }
        EXPECT_EQ(as_set(t.finer(d), new_c), finer);
        EXPECT_LT(t.entering(d).size(), t.offsets().size() / 3) << "a thin shell";
      }
}

TEST(ViewTable, TablesAreSharedPerRadii) {
  EXPECT_EQ(ViewTable::get(256, 64).get(), ViewTable::get(256, 64).get());
  EXPECT_NE(ViewTable::get(256, 64).get(), ViewTable::get(256, 32).get());
}

TEST(ViewTable, RadiiClientsChooseCannotGrowTheSharedTablesWithoutBound) {
  const auto kept = ViewTable::get(96, 32);  // in use by "a replicator"
  for (std::int32_t r = 1; r <= 300; ++r) (void)ViewTable::get(64, r);
  EXPECT_LE(ViewTable::shared_count(), ViewTable::kMaxShared);
  EXPECT_EQ(ViewTable::get(96, 32).get(), kept.get()) << "a table in use stays shared";
}

}  // namespace
}  // namespace terrane
