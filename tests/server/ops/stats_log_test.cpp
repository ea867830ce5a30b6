// StatsLog: the line from given counters (clients and chunks as they are
// now; edits and bytes per second since the last line, or since it was
// made), and, started on a running context, lines every period until
// stop(), after which its io threads can end.
#include "server/ops/stats_log.h"

#include <gtest/gtest.h>
#include <spdlog/sinks/base_sink.h>

#include <mutex>
#include <string>
#include <thread>

#include "server/base/log.h"
#include "tests/support/eventually.h"

namespace terrane {
namespace {

using namespace std::chrono_literals;
using testing_support::eventually;

TEST(StatsLog, ALineCountsItsRatesFromTheLastLine) {
  asio::io_context io;
  ServerCounters c;
  const auto t0 = StatsLog::Clock::time_point{} + 1000s;
  StatsLog log(io, c, StatsLog::kPeriod, t0);
  c.clients = 3;
  c.chunks_loaded = 700;
  c.edits_applied = 50;
  c.net.sent_bytes[1] = 1'500'000;
  c.net.sent_bytes[7] = 500'000;
  c.net.received_bytes[2] = 10'000;
  EXPECT_EQ(log.next_line(t0 + 10s), "3 clients; 5.0 edits/s; out 0.20 MB/s, in 0.001 MB/s; 700 chunks loaded");
  // Ten seconds later: only what moved since counts.
  c.clients = 1;
  c.edits_applied = 70;
  c.net.sent_bytes[1] = 6'500'000;
  c.net.received_bytes[2] = 30'000;
  EXPECT_EQ(log.next_line(t0 + 20s), "1 clients; 2.0 edits/s; out 0.50 MB/s, in 0.002 MB/s; 700 chunks loaded");
  // Nothing moved, and no time passed (the rates do not divide by zero).
  EXPECT_EQ(log.next_line(t0 + 20s), "1 clients; 0.0 edits/s; out 0.00 MB/s, in 0.000 MB/s; 700 chunks loaded");
}

// Counts the messages that contain a text (base_sink locks around it).
class CountingSink final : public spdlog::sinks::base_sink<std::mutex> {
 public:
  explicit CountingSink(std::string text) : text_(std::move(text)) {}
  std::size_t count() {
    std::lock_guard lock(mutex_);
    return count_;
  }

 protected:
  void sink_it_(const spdlog::details::log_msg& msg) override {
    if (std::string_view(msg.payload.data(), msg.payload.size()).find(text_) != std::string_view::npos) ++count_;
  }
  void flush_() override {}

 private:
  const std::string text_;
  std::size_t count_ = 0;
};

TEST(StatsLog, LogsEveryPeriodUntilStopped) {
  auto sink = std::make_shared<CountingSink>("2 clients;");
  server_log().sinks().push_back(sink);
  asio::io_context io;
  auto work = asio::make_work_guard(io);
  ServerCounters c;
  c.clients = 2;
  StatsLog log(io, c, 5ms);
  std::thread t([&] { io.run(); });
  log.start();
  EXPECT_TRUE(eventually([&] { return sink->count() >= 3; }));
  log.stop();
  // The timer no longer waits: the context ends once nothing else does.
  work.reset();
  t.join();
  std::erase(server_log().sinks(), sink);
}

}  // namespace
}  // namespace terrane
