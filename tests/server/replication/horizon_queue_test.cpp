// HorizonQueue: images are sent in the order the plan asked for them
// whatever order they come in; one asked for by an earlier plan (a region
// not asked for now, or another level) is dropped; a region is asked for
// once per plan, and a new plan forgets the last one's.
#include "server/replication/horizon_queue.h"

#include <gtest/gtest.h>

#include <memory>

namespace terrane {
namespace {

HorizonPtr image(Vec3i region, int level) {
  auto i = std::make_shared<HorizonImage>();
  i->region = region;
  i->level = level;
  i->unit = {1, 2, 3};
  return i;
}

struct Sent {
  std::vector<Vec3i> regions;
  std::function<void(const HorizonPtr&)> fn() {
    return [this](const HorizonPtr& i) { regions.push_back(i->region); };
  }
};

TEST(HorizonQueue, ImagesAreSentInThePlansOrderWhateverOrderTheyComeIn) {
  HorizonQueue q;
  const Vec3i a{0, 0, 0}, b{1, 0, 0}, c{0, 0, -1};
  EXPECT_FALSE(q.waiting());
  EXPECT_TRUE(q.want(a, kHorizonNearLevel));
  EXPECT_TRUE(q.want(b, kHorizonFarLevel));
  EXPECT_TRUE(q.want(c, kHorizonFarLevel));
  EXPECT_FALSE(q.want(b, kHorizonNearLevel));  // once per plan
  EXPECT_TRUE(q.waiting());

  Sent sent;
  q.arrive({image(c, kHorizonFarLevel), image(b, kHorizonFarLevel)}, sent.fn());
  EXPECT_TRUE(sent.regions.empty());  // a's turn first
  q.arrive({image(a, kHorizonNearLevel)}, sent.fn());
  EXPECT_EQ(sent.regions, (std::vector<Vec3i>{a, b, c}));
  EXPECT_FALSE(q.waiting());
}

TEST(HorizonQueue, AnImageAnEarlierPlanAskedForIsDropped) {
  HorizonQueue q;
  const Vec3i a{0, 0, 0}, b{5, 0, 0};
  ASSERT_TRUE(q.want(a, kHorizonFarLevel));
  q.clear();  // a new plan
  EXPECT_FALSE(q.waiting());
  ASSERT_TRUE(q.want(b, kHorizonFarLevel));
  ASSERT_TRUE(q.want(a, kHorizonNearLevel));
  Sent sent;
  // a at the old level, and a region not asked for: dropped.
  q.arrive({image(a, kHorizonFarLevel), image({9, 9, 9}, kHorizonFarLevel), image(b, kHorizonFarLevel)}, sent.fn());
  EXPECT_EQ(sent.regions, std::vector<Vec3i>{b});
  EXPECT_TRUE(q.waiting());
  q.arrive({image(a, kHorizonNearLevel)}, sent.fn());
  EXPECT_EQ(sent.regions, (std::vector<Vec3i>{b, a}));
  EXPECT_FALSE(q.waiting());
  // After its turn, an image again is not asked for any more.
  q.arrive({image(a, kHorizonNearLevel)}, sent.fn());
  EXPECT_EQ(sent.regions.size(), 2u);
}

}  // namespace
}  // namespace terrane
