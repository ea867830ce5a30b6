#include "client/pending_ops.h"

#include <gtest/gtest.h>

#include <optional>
#include <thread>

namespace terrane {
namespace {

TEST(PendingOps, CountsGuardsAndMovesDoNotCountTwice) {
  PendingOps ops;
  {
    PendingOps::Guard a = ops.guard();
    EXPECT_EQ(ops.pending(), 1);
    PendingOps::Guard b = std::move(a);
    EXPECT_EQ(ops.pending(), 1);
    PendingOps::Guard c = ops.guard();
    EXPECT_EQ(ops.pending(), 2);
  }
  EXPECT_EQ(ops.pending(), 0);
  ops.wait_idle();  // returns at once
}

TEST(PendingOps, WaitIdleReturnsOnceTheLastGuardOnAnotherThreadIsGone) {
  PendingOps ops;
  std::optional<PendingOps::Guard> held(ops.guard());
  std::mutex m;
  std::condition_variable cv;
  bool release = false;
  std::thread worker([&, g = std::move(*held)]() mutable {
    std::unique_lock lock(m);
    cv.wait(lock, [&] { return release; });
    PendingOps::Guard gone = std::move(g);
  });
  held.reset();
  EXPECT_EQ(ops.pending(), 1);
  {
    std::lock_guard lock(m);
    release = true;
  }
  cv.notify_all();
  ops.wait_idle();
  EXPECT_EQ(ops.pending(), 0);
  worker.join();
}

}  // namespace
}  // namespace terrane
