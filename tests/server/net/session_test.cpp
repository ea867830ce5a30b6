// Session over a real socket on 127.0.0.1: frames made of many segments
// (owned bytes and spans shared with their owners, more than one system
// call's worth of buffers) arrive intact and in order, beside frames of one
// owned or one shared segment; the queue's bytes and the counters by
// message type count each frame's whole size; what a frame shares is
// released once it is written. Frames queued by one handler go out in one
// write; control frames wait for the first data frame (the Welcome).
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

TEST_F(SessionTest, WritesLargerThanTheSocketTakesArriveIntact) {
  auto peer = connect();
  // 8 frames of about 800 kB, each 100 shared segments and their record
  // heads: more than a socket's buffers take at once and more than one
  // system call's buffers, so each write goes on from inside a segment.
  std::mt19937 rng(7);
  std::vector<Frame> sent;
  std::size_t total = 0;
  for (int f = 0; f < 8; ++f) {
    StreamBatchWriter w;
    for (int i = 0; i < 100; ++i) {
      auto p = std::make_shared<std::vector<std::uint8_t>>(7000 + rng() % 2000);
      for (auto& b : *p) b = static_cast<std::uint8_t>(rng());
      w.add(StreamRecordKind::kFull, {i, f, 0}, static_cast<std::uint64_t>(i), *p, p);
    }
    OutFrame frame = w.finish();
    ASSERT_GT(frame.segment_count(), 150u);
    sent.push_back(frame.flatten());
    total += frame.size();
    session_->send(std::move(frame));
  }
  ASSERT_GT(total, 6'000'000u);
  for (const Frame& bytes : sent) {
    const auto got = peer->next();
    ASSERT_TRUE(got);
    EXPECT_EQ(*got, Frame(bytes.begin() + kFrameHeaderBytes, bytes.end()));
  }
  EXPECT_TRUE(eventually([&] { return session_->bytes_sent() == total && session_->queued_bytes() == 0; }));
}

TEST_F(SessionTest, FramesQueuedByOneHandlerShareOneWrite) {
  auto peer = connect();
  constexpr int kFrames = 12;
  // A fan-out's update, a stream batch, a pong: queued on the session's
  // strand one after another, as the replicator and the world queue them.
  asio::post(session_->executor(), [this] {
    for (int i = 0; i < kFrames; ++i) session_->send(OutFrame(build_ping(static_cast<std::uint64_t>(i))));
  });
  for (int i = 0; i < kFrames; ++i) {
    const auto f = peer->next();
    ASSERT_TRUE(f) << "frame " << i;
    const Frame ping = build_ping(static_cast<std::uint64_t>(i));
    EXPECT_EQ(*f, Frame(ping.begin() + kFrameHeaderBytes, ping.end()));
  }
  EXPECT_EQ(counters_.net.writes.load(), 1u);
  EXPECT_EQ(counters_.net.sent_frames[static_cast<std::size_t>(wire::Body::Ping)].load(),
            static_cast<std::uint64_t>(kFrames));
}

TEST_F(SessionTest, ControlFramesWaitForTheFirstDataFrame) {
  auto peer = connect();
  // A client may send a Ping before its Welcome; the Pong must not
  // overtake the Welcome (here a data frame standing for it).
  session_->send(OutFrame(build_pong(1)), SendClass::kControl);
  EXPECT_TRUE(eventually([&] {
    return counters_.net.sent_frames[static_cast<std::size_t>(wire::Body::Pong)].load() == 1;
  }));
  // The write it scheduled has had its turn on the strand: nothing went.
  std::atomic<bool> passed{false};
  asio::post(session_->executor(), [&] { passed = true; });
  EXPECT_TRUE(eventually([&] { return passed.load(); }));
  EXPECT_EQ(counters_.net.writes.load(), 0u);
  session_->send(OutFrame(build_ping(2)));
  const auto body = [](const Frame& f) { return Frame(f.begin() + kFrameHeaderBytes, f.end()); };
  const auto first = peer->next();
  ASSERT_TRUE(first);
  EXPECT_EQ(*first, body(build_ping(2)));
  const auto second = peer->next();
  ASSERT_TRUE(second);
  EXPECT_EQ(*second, body(build_pong(1)));
  // After it, control frames go first again: a pong queued with data
  // frames by one handler leads them.
  const std::uint64_t writes = counters_.net.writes.load();
  asio::post(session_->executor(), [this] {
    session_->send(OutFrame(build_ping(3)));
    session_->send(OutFrame(build_pong(4)), SendClass::kControl);
  });
  const auto third = peer->next();
  ASSERT_TRUE(third);
  EXPECT_EQ(*third, body(build_pong(4)));
  const auto fourth = peer->next();
  ASSERT_TRUE(fourth);
  EXPECT_EQ(*fourth, body(build_ping(3)));
  EXPECT_EQ(counters_.net.writes.load(), writes + 1);
}

TEST_F(SessionTest, ASessionClosedBeforeItsFirstDataFrameSendsTheDisconnectAlone) {
  auto peer = connect();
  // A Pong queued for a client never welcomed, then the session closed (a
  // bad frame in the same read): nothing but the Disconnect may go.
  asio::post(session_->executor(), [this] {
    session_->send(OutFrame(build_pong(1)), SendClass::kControl);
    session_->close(CloseReason::kProtocolError, "protocol error: test");
  });
  const auto first = peer->next();
  ASSERT_TRUE(first);
  const auto m = verify_message(*first);
  ASSERT_TRUE(m);
  EXPECT_EQ((*m)->body_type(), wire::Body::Disconnect);
  EXPECT_FALSE(peer->next());  // nothing after it: the stream ends
  EXPECT_TRUE(eventually([&] { return session_->queued_bytes() == 0 && counters_.net.queued_bytes.load() == 0; }));
}

}  // namespace
}  // namespace terrane
