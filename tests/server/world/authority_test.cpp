// LocalAuthority, a world this server alone writes: every box is writable
// now, whatever the rule, nothing is claimed, forwarded or stale. (The
// shared world's authority is tested in shared_authority_test.cpp, and
// with several servers in tests/client/cluster_test.cpp.)
#include "server/world/authority.h"

#include <gtest/gtest.h>

namespace terrane {
namespace {

TEST(LocalAuthority, EveryBoxIsWritableNowAndNothingIsClaimedForwardedOrStale) {
  LocalAuthority a;
  a.start();
  const Region boxes[] = {Region{{0, 0, 0}, {1, 1, 1}}, Region{{-100000, -64, 5}, {100000, 200, 9}}, Region{}};
  for (const Region& r : boxes)
    for (const ClaimRule rule : {ClaimRule::kAny, ClaimRule::kPreferNeighbours}) {
      std::string why = "unchanged";
      std::optional<std::uint32_t> holder;
      EXPECT_EQ(a.writable(r, &why, &holder, rule), Authority::Writable::kYes);
      EXPECT_EQ(why, "unchanged");
      EXPECT_FALSE(holder.has_value());
      EXPECT_FALSE(a.claiming(r));
      EXPECT_FALSE(a.forward_pending(1, r));
    }
  EXPECT_FALSE(a.stale(Vec3i{1, 2, 3}));
  a.landed(Vec3i{1, 2, 3});
  a.settle();
  EXPECT_FALSE(a.stale(Vec3i{1, 2, 3}));
}

}  // namespace
}  // namespace terrane
