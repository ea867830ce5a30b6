// RequestQueue: requests are handled on the strand in the order queued,
// whatever thread queued them; a slice spent lets what was posted to the
// strand meanwhile run before the rest; each wait is reported, and 0 once
// the queue is empty.
#include "server/world/request_queue.h"

#include <gtest/gtest.h>

#include <atomic>
#include <future>
#include <mutex>
#include <thread>
#include <vector>

#include "tests/support/eventually.h"

namespace terrane {
namespace {

class RequestQueueTest : public ::testing::Test {
 protected:
  RequestQueueTest() {
    thread_ = std::thread([this] { io_.run(); });
  }
  ~RequestQueueTest() override {
    work_.reset();
    thread_.join();
  }
  // Holds the strand until the returned promise is set.
  std::promise<void> hold_strand() {
    std::promise<void> release;
    std::promise<void> held;
    asio::post(strand_, [f = release.get_future().share(), &held]() {
      held.set_value();
      f.wait();
    });
    held.get_future().wait();
    return release;
  }
  // Waits for what the strand has queued so far (the queue outlives its drains).
  void sync() {
    std::promise<void> done;
    asio::post(strand_, [&] { done.set_value(); });
    done.get_future().wait();
  }
  static WorldRequest leave(ClientId id) { return WorldRequest{id, {}, LeaveRequest{}}; }

  asio::io_context io_;
  asio::executor_work_guard<asio::io_context::executor_type> work_{asio::make_work_guard(io_)};
  RequestQueue::Strand strand_{asio::make_strand(io_)};
  std::thread thread_;
  std::mutex m_;
  std::vector<ClientId> handled_;  // guarded by m_
};

TEST_F(RequestQueueTest, RequestsAreHandledOnTheStrandInTheOrderQueued) {
  std::atomic<bool> off_strand{false};
  RequestQueue queue(strand_, [&](WorldRequest& r) {
    if (!strand_.running_in_this_thread()) off_strand = true;
    std::lock_guard lock(m_);
    handled_.push_back(r.id);
  });
  std::vector<std::int64_t> waits;
  queue.on_wait([&](std::chrono::nanoseconds w) { waits.push_back(w.count()); });
  auto release = hold_strand();
  for (ClientId id = 1; id <= 100; ++id) queue.push(leave(id));
  release.set_value();
  ASSERT_TRUE(testing_support::eventually([&] {
    std::lock_guard lock(m_);
    return handled_.size() == 100;
  }));
  sync();
  EXPECT_FALSE(off_strand);
  for (ClientId id = 1; id <= 100; ++id) EXPECT_EQ(handled_[id - 1], id);
  // One wait per request, then 0: nothing waits.
  ASSERT_FALSE(waits.empty());
  EXPECT_EQ(waits.back(), 0);
  EXPECT_GE(waits.size(), 101u);
}

TEST_F(RequestQueueTest, ASpentSliceLetsWhatWasPostedMeanwhileRunFirst) {
  bool marker_posted = false;
  RequestQueue queue(strand_, [&](WorldRequest& r) {
    if (r.id == 1) {
      // Posted while the first request is handled, then the slice is spent.
      asio::post(strand_, [this] {
        std::lock_guard lock(m_);
        handled_.push_back(0);
      });
      marker_posted = true;
      const auto until = std::chrono::steady_clock::now() + RequestQueue::kSlice;
      while (std::chrono::steady_clock::now() < until) {
      }
    }
    std::lock_guard lock(m_);
    handled_.push_back(r.id);
  });
  auto release = hold_strand();
  queue.push(leave(1));
  queue.push(leave(2));
  release.set_value();
  ASSERT_TRUE(testing_support::eventually([&] {
    std::lock_guard lock(m_);
    return handled_.size() == 3;
  }));
  sync();
  EXPECT_TRUE(marker_posted);
  EXPECT_EQ(handled_, (std::vector<ClientId>{1, 0, 2}));
}

TEST_F(RequestQueueTest, RequestsQueuedFromManyThreadsKeepEachThreadsOrder) {
  RequestQueue queue(strand_, [&](WorldRequest& r) {
    std::lock_guard lock(m_);
    handled_.push_back(r.id);
  });
  std::vector<std::thread> threads;
  for (ClientId t = 0; t < 4; ++t)
    threads.emplace_back([&queue, t] {
      for (ClientId i = 0; i < 250; ++i) queue.push(leave(t * 1000 + i));
    });
  for (auto& t : threads) t.join();
  ASSERT_TRUE(testing_support::eventually([&] {
    std::lock_guard lock(m_);
    return handled_.size() == 1000;
  }));
  sync();
  std::lock_guard lock(m_);
  std::vector<ClientId> next(4, 0);
  for (const ClientId id : handled_) {
    const ClientId t = id / 1000;
    EXPECT_EQ(id % 1000, next[t]);
    next[t] = id % 1000 + 1;
  }
}

}  // namespace
}  // namespace terrane
