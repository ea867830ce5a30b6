// ContextThreads: the context runs on as many threads of its role as asked
// (they run handlers at once: each of three waits for the other two), at
// least one; join() runs what is queued, including what that queues, then
// returns with the threads ended.
#include "server/base/context_threads.h"

#include <gtest/gtest.h>
#include <pthread.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <mutex>
#include <set>
#include <string>

namespace terrane {
namespace {

using namespace std::chrono_literals;

std::string thread_name() {
  char name[16] = {};
  pthread_getname_np(pthread_self(), name, sizeof name);
  return name;
}

TEST(ContextThreads, RunsHandlersOnAsManyThreadsOfItsRoleAtOnce) {
  ContextThreads threads;
  threads.run(3, ThreadRole::kIo, false);
  std::mutex m;
  std::condition_variable cv;
  int arrived = 0;
  bool all_met = true;
  std::set<std::string> names;
  std::set<std::thread::id> ids;
  for (int i = 0; i < 3; ++i)
    asio::post(threads.context(), [&] {
      std::unique_lock lock(m);
      ++arrived;
      names.insert(thread_name());
      ids.insert(std::this_thread::get_id());
      cv.notify_all();
      // Only three threads at once get all three here (bounded: a failure
      // does not hang the suite).
      if (!cv.wait_for(lock, 60s, [&] { return arrived == 3; })) all_met = false;
    });
  threads.join();
  EXPECT_TRUE(all_met);
  EXPECT_EQ(arrived, 3);
  EXPECT_EQ(ids.size(), 3u);
  EXPECT_EQ(names, std::set<std::string>{"terrane-io"});
}

TEST(ContextThreads, RunsOnOneThreadWhenAskedForNone) {
  ContextThreads threads;
  threads.run(0, ThreadRole::kWorld, false);
  std::atomic<bool> ran{false};
  std::string name;
  asio::post(threads.context(), [&] {
    name = thread_name();
    ran = true;
  });
  threads.join();
  EXPECT_TRUE(ran);
  EXPECT_EQ(name, "terrane-world");
}

TEST(ContextThreads, JoinRunsWhatIsQueuedAndWhatThatQueuesThenEnds) {
  ContextThreads threads;
  std::atomic<int> ran{0};
  asio::steady_timer timer(threads.context());
  asio::post(threads.context(), [&] {
    ++ran;
    asio::post(threads.context(), [&] { ++ran; });
    // Pending work: join() waits for the timer too.
    timer.expires_after(10ms);
    timer.async_wait([&](const asio::error_code& ec) {
      if (!ec) ++ran;
    });
  });
  threads.run(2, ThreadRole::kIo, false);
  threads.join();
  EXPECT_EQ(ran.load(), 3);
  threads.join();  // idempotent
  EXPECT_EQ(ran.load(), 3);
}

}  // namespace
}  // namespace terrane
