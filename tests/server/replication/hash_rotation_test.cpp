// HashRotation: a push is due every period from the join (never with
// period 0); the chunks held Full come in turn, and one no longer held Full
// is forgotten when its turn comes.
#include "server/replication/hash_rotation.h"

#include <gtest/gtest.h>

#include <map>
#include <tuple>

namespace terrane {
namespace {

using namespace std::chrono_literals;
using Clock = HashRotation::Clock;

TEST(HashRotation, APushIsDueEveryPeriodFromTheJoinAndNeverWithPeriodZero) {
  const auto t = Clock::now();
  HashRotation off(0ms);
  off.start(t);
  EXPECT_EQ(off.next_push(), Clock::time_point::max());
  EXPECT_FALSE(off.due(t + 1h));

  HashRotation r(1000ms);
  r.start(t);
  EXPECT_EQ(r.next_push(), t + 1s);
  EXPECT_FALSE(r.due(t + 999ms));
  EXPECT_TRUE(r.due(t + 1s));
  EXPECT_EQ(r.next_push(), t + 2s);
  EXPECT_FALSE(r.due(t + 1500ms));
  EXPECT_TRUE(r.due(t + 2500ms));  // late: the next is a period after this one
  EXPECT_EQ(r.next_push(), t + 3500ms);
}

TEST(HashRotation, ChunksHeldFullComeInTurnAndOneNoLongerHeldIsForgotten) {
  HashRotation r(1000ms);
  const Vec3i a{0, 0, 0}, b{1, 0, 0}, c{2, 0, 0};
  auto version = [](Vec3i cp) { return std::make_shared<ChunkVersion>(cp, 3, nullptr); };
  struct Less {
    bool operator()(Vec3i p, Vec3i q) const { return std::tie(p.x, p.y, p.z) < std::tie(q.x, q.y, q.z); }
  };
  std::map<Vec3i, VersionPtr, Less> full{{a, version(a)}, {b, version(b)}, {c, version(c)}};
  const auto lookup = [&](Vec3i cp) {
    auto it = full.find(cp);
    return it == full.end() ? nullptr : it->second;
  };
  EXPECT_EQ(r.next(lookup), std::nullopt);  // nothing held yet
  r.add(a);
  r.add(b);
  r.add(c);
  std::vector<Vec3i> turns;
  for (int i = 0; i < 4; ++i) {
    auto n = r.next(lookup);
    ASSERT_TRUE(n);
    EXPECT_EQ(n->second, full.at(n->first));
    turns.push_back(n->first);
  }
  EXPECT_EQ(turns, (std::vector<Vec3i>{a, b, c, a}));
  full.erase(b);  // b no longer held Full
  turns.clear();
  for (int i = 0; i < 4; ++i) turns.push_back(r.next(lookup)->first);
  EXPECT_EQ(turns, (std::vector<Vec3i>{c, a, c, a}));
  full.clear();
  EXPECT_EQ(r.next(lookup), std::nullopt);
  full[b] = version(b);
  EXPECT_EQ(r.next(lookup), std::nullopt);  // forgotten: only add() brings it back
  r.add(b);
  EXPECT_EQ(r.next(lookup)->first, b);
}

}  // namespace
}  // namespace terrane
