#include "client/io_side.h"

#include <gtest/gtest.h>

#include <atomic>
#include <vector>

namespace terrane {
namespace {

TEST(IoSide, OwnedModeRunsHandlersOnItsOwnThreadUntilTheWorkRunsOut) {
  IoSide io(nullptr);
  ASSERT_TRUE(io.owned());
  std::thread::id ran_on;
  int runs = 0;
  // Work queued before the thread starts runs on it.
  asio::post(io.strand(), [&, g = io.guard()] {
    ran_on = std::this_thread::get_id();
    ++runs;
    asio::post(io.strand(), [&, g2 = io.guard()] { ++runs; });
  });
  io.start_thread();
  io.finish();  // returns once nothing is left
  EXPECT_EQ(runs, 2);
  EXPECT_NE(ran_on, std::this_thread::get_id());
}

TEST(IoSide, SharedModeRunsOneHandlerAtATimeAndFinishWaitsForThePendingOnes) {
  asio::io_context shared;
  auto work = asio::make_work_guard(shared);
  std::vector<std::thread> pool;
  for (int i = 0; i < 4; ++i) pool.emplace_back([&] { shared.run(); });
  std::atomic<int> in_handler{0};
  bool overlapped = false;
  int count = 0;  // not atomic: the strand is the only lock
  {
    IoSide io(&shared);
    ASSERT_FALSE(io.owned());
    for (int i = 0; i < 2000; ++i)
      asio::post(io.strand(), [&, g = io.guard()] {
        if (in_handler.fetch_add(1) != 0) overlapped = true;
        ++count;
        in_handler.fetch_sub(1);
      });
    io.finish();
    EXPECT_EQ(count, 2000);
  }
  EXPECT_FALSE(overlapped);
  work.reset();
  for (auto& t : pool) t.join();
}

}  // namespace
}  // namespace terrane
