// Session over a real socket on 127.0.0.1: frames made of many segments
// (owned bytes and spans shared with their owners, more than one system
// call's worth of buffers) arrive intact and in order, beside frames of one
// owned or one shared segment; the queue's bytes and the counters by
// message type count each frame's whole size; what a frame shares is
// released once it is written.
#include "server/net/session.h"

#include <gtest/gtest.h>

#include <memory>
#include <random>
#include <thread>

#include "protocol/stream_batch.h"
#include "tests/support/eventually.h"
#include "tests/support/server_fixture.h"

namespace terrane {
namespace {

using testing_support::eventually;
using testing_support::RawPeer;

class SessionTest : public ::testing::Test {
 protected:
  SessionTest() {
    acceptor_.open(asio::ip::tcp::v4());
    acceptor_.bind({asio::ip::make_address("127.0.0.1"), 0});
    acceptor_.listen();
    limits_.counters = &counters_;
  }
  ~SessionTest() override {
    if (session_) session_->close(CloseReason::kShutdown, "test over");
    EXPECT_TRUE(eventually([&] { return closed_.load(); }));
    session_.reset();
    work_.reset();
    if (thread_.joinable()) thread_.join();
  }
  // A started session on a new connection from the returned peer.
  std::unique_ptr<RawPeer> connect() {
    auto peer = std::make_unique<RawPeer>(acceptor_.local_endpoint().port());
    EXPECT_TRUE(peer->connected());
    asio::ip::tcp::socket socket(asio::make_strand(io_));
    acceptor_.accept(socket);
    session_ = std::make_shared<Session>(
        std::move(socket), 1, limits_, [](std::uint64_t, InboundMessage) {},
        [this](std::uint64_t, const std::string&) { closed_ = true; });
    session_->start();
    thread_ = std::thread([this] { io_.run(); });
    return peer;
  }

  asio::io_context io_;
  asio::executor_work_guard<asio::io_context::executor_type> work_ = asio::make_work_guard(io_);
  asio::ip::tcp::acceptor acceptor_{io_};
  std::thread thread_;
  ServerCounters counters_;
  SessionLimits limits_;
  std::shared_ptr<Session> session_;
  std::atomic<bool> closed_{false};
};

TEST_F(SessionTest, AGatheredFrameArrivesIntact) {
  auto peer = connect();
  // 150 records, each a shared payload of its own between owned record
  // headers and short copied payloads: some 300 segments, several writes'
  // worth (asio hands at most 64 buffers to one system call).
  std::mt19937 rng(3);
  std::vector<std::shared_ptr<const std::vector<std::uint8_t>>> payloads;
  StreamBatchWriter w;
  for (int i = 0; i < 150; ++i) {
    auto p = std::make_shared<std::vector<std::uint8_t>>(OutFrame::kMinSharedBytes + rng() % 1000);
    for (auto& b : *p) b = static_cast<std::uint8_t>(rng());
    w.add(StreamRecordKind::kFull, {i, 0, -i}, static_cast<std::uint64_t>(i), *p, p);
    const std::vector<std::uint8_t> small(rng() % 40, static_cast<std::uint8_t>(i));
    w.add(StreamRecordKind::kMip3, {i, 1, -i}, 1, small);
    payloads.push_back(std::move(p));
  }
  const std::weak_ptr<const std::vector<std::uint8_t>> watch = payloads.front();
  OutFrame gathered = w.finish();
  ASSERT_GT(gathered.segment_count(), 256u);
  const Frame gathered_bytes = gathered.flatten();
  const std::size_t gathered_size = gathered.size();
  payloads.clear();  // the frame holds them now

  const auto shared = std::make_shared<const Frame>(build_ping(5));
  const Frame pong = build_pong(6);
  session_->send(std::move(gathered));
  session_->send(shared);
  session_->send(OutFrame(pong));

  const auto body = [](const Frame& f) { return Frame(f.begin() + kFrameHeaderBytes, f.end()); };
  const auto first = peer->next();
  ASSERT_TRUE(first);
  EXPECT_EQ(*first, body(gathered_bytes));
  const auto second = peer->next();
  ASSERT_TRUE(second);
  EXPECT_EQ(*second, body(*shared));
  const auto third = peer->next();
  ASSERT_TRUE(third);
  EXPECT_EQ(*third, body(pong));

  const std::size_t total = gathered_size + shared->size() + pong.size();
  EXPECT_TRUE(eventually([&] { return session_->bytes_sent() == total && session_->queued_bytes() == 0; }))
      << session_->bytes_sent() << " of " << total << " sent, " << session_->queued_bytes() << " queued";
  EXPECT_EQ(counters_.net.queued_bytes.load(), 0);
  const auto type = [](wire::Body b) { return static_cast<std::size_t>(b); };
  EXPECT_EQ(counters_.net.sent_bytes[type(wire::Body::StreamBatch)].load(), gathered_size);
  EXPECT_EQ(counters_.net.sent_frames[type(wire::Body::StreamBatch)].load(), 1u);
  EXPECT_EQ(counters_.net.sent_bytes[type(wire::Body::Ping)].load(), shared->size());
  EXPECT_EQ(counters_.net.sent_frames[type(wire::Body::Pong)].load(), 1u);
  // Written: the session let go of what the frame shared.
  EXPECT_TRUE(eventually([&] { return watch.expired(); }));
}

}  // namespace
}  // namespace terrane
