// HorizonCache on the world strand against a real SQLite Storage: an image
// is made once and then served from the cache at once, to every client
// that asks; a change in its region keeps it served until kRefresh has
// passed; a client that left is not handed the image made for it.
#include "server/world/horizon_cache.h"

#include <gtest/gtest.h>

#include <memory>

#include "tests/support/world_strand.h"

namespace terrane {
namespace {

using testing_support::RecordingClient;
using testing_support::WorldStrand;

class HorizonCacheTest : public ::testing::Test {
 protected:
  ~HorizonCacheTest() override { w_.quiesce(); }
  std::shared_ptr<RecordingClient> join(ClientId id) {
    auto c = std::make_shared<RecordingClient>();
    w_.on_strand([&] { fan_out_.join(id, c); });
    return c;
  }

  WorldStrand w_;
  WorldOptions options_;
  ServerCounters counters_;
  FanOut fan_out_{options_, counters_};
  HorizonCache cache_{w_.strand, *w_.storage, fan_out_};
};

TEST_F(HorizonCacheTest, AnImageIsMadeOnceAndThenServedAtOnceToEveryClient) {
  const Vec3i region{0, 0, 0};
  auto first = join(1);
  w_.on_strand([&] { cache_.want(1, {HorizonWant{region, kHorizonFarLevel}}); });
  ASSERT_TRUE(first->wait([](RecordingClient& c) { return c.images_.size() == 1; }));
  const HorizonPtr image = first->images_[0];
  ASSERT_NE(image, nullptr);
  EXPECT_EQ(image->region, region);
  const std::uint64_t made = w_.storage->counters().horizons_made.load();
  auto second = join(2);
  w_.on_strand([&] {
    // A chunk of the region changed just now: still served (kRefresh).
    cache_.changed(Vec3i{1, 0, 1});
    cache_.want(2, {HorizonWant{region, kHorizonFarLevel}});
    std::lock_guard lock(second->m);
    ASSERT_EQ(second->images_.size(), 1u);  // within the call
    EXPECT_EQ(second->images_[0], image);
  });
  EXPECT_EQ(w_.storage->counters().horizons_made.load(), made);
  // The other level is an image of its own.
  w_.on_strand([&] { cache_.want(2, {HorizonWant{region, kHorizonNearLevel}}); });
  ASSERT_TRUE(second->wait([](RecordingClient& c) { return c.images_.size() == 2; }));
  EXPECT_NE(second->images_[1], image);
  EXPECT_EQ(second->images_[1]->level, kHorizonNearLevel);
}

TEST_F(HorizonCacheTest, AClientThatLeftIsNotHandedItsImage) {
  auto c = join(1);
  w_.on_strand([&] {
    cache_.want(1, {HorizonWant{Vec3i{1, 0, 0}, kHorizonFarLevel}});
    fan_out_.leave(1);
  });
  auto other = join(2);
  w_.on_strand([&] { cache_.want(2, {HorizonWant{Vec3i{1, 0, 0}, kHorizonFarLevel}}); });
  ASSERT_TRUE(other->wait([](RecordingClient& r) { return r.images_.size() == 1; }));
  std::lock_guard lock(c->m);
  EXPECT_TRUE(c->images_.empty());
}

}  // namespace
}  // namespace terrane
