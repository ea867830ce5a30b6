// Listener: binds 127.0.0.1 on a free port, hands each accepted connection
// to its accept function until that declines or
// the listener closes; a bad address or a port in use is refused with a
// message naming it.
#include "server/net/listener.h"

#include <gtest/gtest.h>

#include <atomic>
#include <future>
#include <mutex>
#include <thread>
#include <vector>

#include "tests/support/eventually.h"
#include "tests/support/server_fixture.h"

namespace terrane {
namespace {

using testing_support::eventually;
using testing_support::RawPeer;

class ListenerTest : public ::testing::Test {
 protected:
  ~ListenerTest() override {
    work_.reset();
    if (thread_.joinable()) thread_.join();
  }
  void run_io() {
    thread_ = std::thread([this] { io_.run(); });
  }
  std::size_t accepted() {
    std::lock_guard lock(m_);
    return sockets_.size();
  }

  asio::io_context io_;
  asio::executor_work_guard<asio::io_context::executor_type> work_ = asio::make_work_guard(io_);
  std::thread thread_;
  std::mutex m_;
  std::vector<asio::ip::tcp::socket> sockets_;
};

TEST_F(ListenerTest, HandsEachConnectionOnUntilItCloses) {
  Listener listener(io_);
  EXPECT_EQ(listener.port(), 0);
  ASSERT_TRUE(listener.bind("127.0.0.1", 0).ok());
  ASSERT_NE(listener.port(), 0);
  listener.start([this](asio::ip::tcp::socket s) {
    std::lock_guard lock(m_);
    sockets_.push_back(std::move(s));
    return true;
  });
  run_io();
  RawPeer a(listener.port()), b(listener.port());
  ASSERT_TRUE(a.connected() && b.connected());
  ASSERT_TRUE(eventually([&] { return accepted() == 2; }));
  {
    std::lock_guard lock(m_);
    EXPECT_EQ(sockets_[0].remote_endpoint().address().to_string(), "127.0.0.1");
  }
  std::promise<void> closed;
  asio::post(io_, [&] {
    listener.close();
    closed.set_value();
  });
  closed.get_future().wait();
  // Once closed, a connection is refused (nothing listens on the port).
  EXPECT_FALSE(RawPeer(listener.port()).connected());
  EXPECT_EQ(accepted(), 2u);
}

TEST_F(ListenerTest, AcceptsNoMoreOnceItsFunctionDeclines) {
  Listener listener(io_);
  ASSERT_TRUE(listener.bind("127.0.0.1", 0).ok());
  std::atomic<int> offered{0};
  listener.start([&](asio::ip::tcp::socket) {
    ++offered;
    return false;  // as a server that is stopping: the socket is dropped
  });
  run_io();
  RawPeer a(listener.port());
  ASSERT_TRUE(a.connected());
  ASSERT_TRUE(a.closed_by_server()) << "the declined connection is closed";
  EXPECT_EQ(offered.load(), 1);
  // A second connection is never offered: the first one's refusal was the
  // last accept.
  RawPeer b(listener.port());
  ASSERT_TRUE(b.connected());
  std::promise<void> closed;
  asio::post(io_, [&] {
    listener.close();
    closed.set_value();
  });
  closed.get_future().wait();
  EXPECT_TRUE(b.closed_by_server());
  EXPECT_EQ(offered.load(), 1);
}

TEST_F(ListenerTest, RefusesABadAddressAndAPortInUse) {
  Listener first(io_);
  ASSERT_TRUE(first.bind("127.0.0.1", 0).ok());
  Listener bad(io_);
  auto st = bad.bind("not an address", 0);
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.error().message.find("bad bind address not an address"), std::string::npos) << st.error().message;
  Listener taken(io_);
  st = taken.bind("127.0.0.1", first.port());
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.error().message.find("cannot listen on 127.0.0.1:" + std::to_string(first.port())), std::string::npos)
      << st.error().message;
  EXPECT_EQ(taken.port(), 0);
}

}  // namespace
}  // namespace terrane
