// MipSchedule: the first change parked sets when the refreshes are due and
// starts the order again; the world's "due now" brings the flush forward
// (and, with nothing parked before, the due time); a flush takes the order
// (chunks in the order of their first change) and leaves it empty; a
// yield puts the flush off without moving the due time.
#include "server/replication/mip_schedule.h"

#include <gtest/gtest.h>

namespace terrane {
namespace {

using namespace std::chrono_literals;

TEST(MipSchedule, TheFirstChangeSetsTheDueTimeAndAFlushTakesTheOrder) {
  const auto t = MipSchedule::Clock::now();
  MipSchedule m;
  m.first_change(t + 500ms);
  EXPECT_EQ(m.due(), t + 500ms);
  EXPECT_EQ(m.next_flush(), t + 500ms);
  m.add({2, 0, 0});
  m.add({1, 0, 0});
  EXPECT_EQ(m.order(), (std::vector<Vec3i>{{2, 0, 0}, {1, 0, 0}}));
  // A yield puts the flush off; the due time stays (it bounds the wait).
  m.put_off(t + 700ms);
  EXPECT_EQ(m.next_flush(), t + 700ms);
  EXPECT_EQ(m.due(), t + 500ms);
  EXPECT_EQ(m.take(), (std::vector<Vec3i>{{2, 0, 0}, {1, 0, 0}}));
  EXPECT_TRUE(m.order().empty());
  // The next first change starts a new order.
  m.add({7, 0, 0});
  m.first_change(t + 2s);
  EXPECT_TRUE(m.order().empty());
  m.add({3, 0, 0});
  m.forget();
  EXPECT_TRUE(m.order().empty());
}

TEST(MipSchedule, TheWorldsDueNowBringsTheFlushForward) {
  const auto t = MipSchedule::Clock::now();
  MipSchedule m;
  m.first_change(t + 500ms);
  m.due_now(t + 100ms, false);  // parked before: due since the first change
  EXPECT_EQ(m.next_flush(), t + 100ms);
  EXPECT_EQ(m.due(), t + 500ms);
  m.due_now(t + 300ms, false);  // never later
  EXPECT_EQ(m.next_flush(), t + 100ms);
  m.due_now(t + 50ms, true);  // nothing parked before: due since now
  EXPECT_EQ(m.due(), t + 50ms);
  EXPECT_EQ(m.next_flush(), t + 50ms);
}

}  // namespace
}  // namespace terrane
