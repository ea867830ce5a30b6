// Connection against a fake server on 127.0.0.1: a test thread that accepts,
// reads and writes frames with blocking asio calls.
#include "client/connection.h"

#include <gtest/gtest.h>

#include <condition_variable>
#include <mutex>

namespace terrane {
namespace {

using namespace std::chrono_literals;

// Records what the Connection tells it; the test waits on it.
class RecordingHandler : public ConnectionHandler {
 public:
  std::vector<Outbound> session_frames(SessionStart start) override {
    std::lock_guard lock(m_);
    sessions_.push_back(start);
    std::vector<Outbound> out;
    out.push_back({build_client_state(ClientStateMsg{{1, 2, 3}, 64, 32}), wire::Body::ClientState});
    cv_.notify_all();
    return out;
  }
  void on_bytes_read(std::size_t n) override { add([&] { bytes_read_ += n; }); }
  void on_frame(std::span<const std::uint8_t> body) override {
    auto m = verify_message(body);
    add([&] { frames_.push_back(m ? (*m)->body_type() : wire::Body::NONE); });
  }
  void on_framing_error() override { add([&] { ++framing_errors_; }); }
  void on_written(const Outbound& sent) override { add([&] { written_.push_back(sent.type); }); }
  bool awaiting_answers() override { return false; }
  void on_reconnecting(const std::string& reason) override { add([&] { lost_.push_back(reason); }); }
  void on_redirected(const RedirectMsg&, std::uint32_t) override {}
  void on_closed(const std::string& reason) override { add([&] { closed_ = reason; }); }

  // Waits (up to 10 s) until pred() holds under the lock.
  template <class P>
  bool wait(P pred) {
    std::unique_lock lock(m_);
    return cv_.wait_for(lock, 10s, pred);
  }

  std::mutex m_;
  std::condition_variable cv_;
  std::vector<SessionStart> sessions_;
  std::size_t bytes_read_ = 0;
  std::vector<wire::Body> frames_;
  int framing_errors_ = 0;
  std::vector<wire::Body> written_;
  std::vector<std::string> lost_;
  std::optional<std::string> closed_;

 private:
  template <class F>
  void add(F f) {
    std::lock_guard lock(m_);
    f();
    cv_.notify_all();
  }
};

// A server that speaks frames with blocking calls on the test's thread.
class FakeServer {
 public:
  FakeServer() : acceptor_(io_, asio::ip::tcp::endpoint(asio::ip::make_address("127.0.0.1"), 0)) {}
  std::uint16_t port() const { return acceptor_.local_endpoint().port(); }
  void accept() {
    socket_ = asio::ip::tcp::socket(io_);
    acceptor_.accept(socket_);
    reader_ = FrameReader();
    pending_.clear();
  }
  // The next frame's type (NONE when the connection ended first).
  wire::Body read_frame() {
    while (pending_.empty()) {
      std::uint8_t buf[4096];
      asio::error_code ec;
      const std::size_t n = socket_.read_some(asio::buffer(buf), ec);
      if (ec) return wire::Body::NONE;
      const auto st = reader_.feed(std::span<const std::uint8_t>(buf, n), [&](std::span<const std::uint8_t> body) {
        auto m = verify_message(body);
        pending_.push_back(m ? (*m)->body_type() : wire::Body::NONE);
      });
      if (!st) return wire::Body::NONE;
    }
    const wire::Body t = pending_.front();
    pending_.erase(pending_.begin());
    return t;
  }
  void write(std::span<const std::uint8_t> bytes) { asio::write(socket_, asio::buffer(bytes.data(), bytes.size())); }
  void close() {
    asio::error_code ec;
    socket_.shutdown(asio::ip::tcp::socket::shutdown_both, ec);
    socket_.close(ec);
  }

 private:
  asio::io_context io_;
  asio::ip::tcp::acceptor acceptor_;
  asio::ip::tcp::socket socket_{io_};
  FrameReader reader_;
  std::vector<wire::Body> pending_;
};

ClientOptions options_for(const FakeServer& s) {
  ClientOptions o;
  o.port = s.port();
  o.name = "connection-test";
  o.keepalive = 60s;
  o.silence_timeout = 0ms;
  return o;
}

TEST(ConnectionTest, OpensWithHelloAndTheSessionFramesAndDeliversWholeFrames) {
  FakeServer server;
  RecordingHandler h;
  Connection c(options_for(server), h);
  std::string error;
  ASSERT_TRUE(c.connect(&error)) << error;
  server.accept();
  EXPECT_EQ(server.read_frame(), wire::Body::Hello);
  EXPECT_EQ(server.read_frame(), wire::Body::ClientState);
  ASSERT_TRUE(c.send(build_ping(7), wire::Body::Ping));
  EXPECT_EQ(server.read_frame(), wire::Body::Ping);
  ASSERT_TRUE(h.wait([&] { return h.written_.size() == 3; }));
  EXPECT_EQ(h.written_, (std::vector<wire::Body>{wire::Body::Hello, wire::Body::ClientState, wire::Body::Ping}));
  EXPECT_EQ(h.sessions_, std::vector<SessionStart>{SessionStart::kFirst});
  // A frame split across two writes arrives once, whole.
  const Frame pong = build_pong(9);
  server.write(std::span<const std::uint8_t>(pong).first(3));
  server.write(std::span<const std::uint8_t>(pong).subspan(3));
  ASSERT_TRUE(h.wait([&] { return !h.frames_.empty(); }));
  EXPECT_EQ(h.frames_, std::vector<wire::Body>{wire::Body::Pong});
  ASSERT_TRUE(h.wait([&] { return h.bytes_read_ == pong.size(); }));
  c.disconnect();
  EXPECT_EQ(server.read_frame(), wire::Body::Disconnect);
  ASSERT_TRUE(h.closed_.has_value());
  EXPECT_EQ(*h.closed_, "disconnected by client");
  EXPECT_FALSE(c.send(build_ping(1), wire::Body::Ping)) << "closed";
}

TEST(ConnectionTest, ReconnectsAfterADropAndOpensAResumedSession) {
  FakeServer server;
  RecordingHandler h;
  ClientOptions o = options_for(server);
  o.reconnect = true;
  o.reconnect_min = 10ms;
  Connection c(o, h);
  std::string error;
  ASSERT_TRUE(c.connect(&error)) << error;
  server.accept();
  EXPECT_EQ(server.read_frame(), wire::Body::Hello);
  EXPECT_EQ(server.read_frame(), wire::Body::ClientState);
  server.close();
  server.accept();
  EXPECT_EQ(server.read_frame(), wire::Body::Hello);
  EXPECT_EQ(server.read_frame(), wire::Body::ClientState);
  ASSERT_TRUE(h.wait([&] { return h.sessions_.size() == 2; }));
  EXPECT_EQ(h.sessions_, (std::vector<SessionStart>{SessionStart::kFirst, SessionStart::kReconnect}));
  EXPECT_EQ(h.lost_.size(), 1u);
  EXPECT_FALSE(h.closed_.has_value());
  c.disconnect();
}

TEST(ConnectionTest, ASilentServerIsNoticedWithoutReconnect) {
  FakeServer server;
  RecordingHandler h;
  ClientOptions o = options_for(server);
  o.keepalive = 20ms;
  o.silence_timeout = 100ms;
  Connection c(o, h);
  std::string error;
  ASSERT_TRUE(c.connect(&error)) << error;
  server.accept();
  ASSERT_TRUE(h.wait([&] { return h.closed_.has_value(); }));
  EXPECT_NE(h.closed_->find("no answer from the server"), std::string::npos) << *h.closed_;
  EXPECT_TRUE(c.closed());
}

TEST(ConnectionTest, BytesThatBreakTheFramingCloseTheConnection) {
  FakeServer server;
  RecordingHandler h;
  Connection c(options_for(server), h);
  std::string error;
  ASSERT_TRUE(c.connect(&error)) << error;
  server.accept();
  server.write(build_pong(1));  // a server that has spoken frames
  const std::uint8_t too_long[4] = {0xff, 0xff, 0xff, 0x7f};  // a length over any limit
  server.write(too_long);
  ASSERT_TRUE(h.wait([&] { return h.closed_.has_value(); }));
  EXPECT_EQ(h.framing_errors_, 1);
  EXPECT_EQ(h.closed_->rfind("protocol error", 0), 0u) << *h.closed_;
}

TEST(ConnectionTest, APeerWhoseFirstBytesAreNoFrameIsNotATerraneServer) {
  // An HTTP server answering the Hello: its status line is no frame length.
  FakeServer server;
  RecordingHandler h;
  Connection c(options_for(server), h);
  std::string error;
  ASSERT_TRUE(c.connect(&error)) << error;
  server.accept();
  const std::string http = "HTTP/1.1 400 Bad Request\r\nContent-Length: 0\r\n\r\n";
  server.write(std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(http.data()), http.size()));
  ASSERT_TRUE(h.wait([&] { return h.closed_.has_value(); }));
  EXPECT_EQ(*h.closed_, "not a terrane-server (it sent 'HTTP/1.1 400 Bad Request', which is no frame)");
}

TEST(ConnectionTest, AServerThatAcceptsAReconnectButNeverAnswersClosesForGood) {
  // A stopped server's socket still accepts (the kernel's backlog): with
  // reconnect on, the silence after the reconnect ends it, not a retry.
  FakeServer server;
  RecordingHandler h;
  ClientOptions o = options_for(server);
  o.reconnect = true;
  o.reconnect_min = 10ms;
  o.silence_timeout = 200ms;
  Connection c(o, h);
  std::string error;
  ASSERT_TRUE(c.connect(&error)) << error;
  server.accept();
  server.write(build_pong(1));
  ASSERT_TRUE(h.wait([&] { return h.lost_.size() == 1; }));  // silent: a drop, reconnecting
  EXPECT_NE(h.lost_[0].find("no answer from the server"), std::string::npos) << h.lost_[0];
  server.accept();
  ASSERT_TRUE(h.wait([&] { return h.closed_.has_value(); }));
  EXPECT_NE(h.closed_->find("since reconnecting: it accepts connections but does not answer"), std::string::npos)
      << *h.closed_;
  EXPECT_EQ(h.lost_.size(), 1u);
  EXPECT_TRUE(c.closed());
}

TEST(ConnectionTest, AnUnreachableServerIsReported) {
  std::uint16_t port = 0;
  {
    FakeServer gone;
    port = gone.port();
  }
  RecordingHandler h;
  ClientOptions o;
  o.port = port;
  o.connect_timeout = 2s;
  Connection c(o, h);
  std::string error;
  EXPECT_FALSE(c.connect(&error));
  EXPECT_NE(error.find("cannot connect"), std::string::npos) << error;
}

}  // namespace
}  // namespace terrane
