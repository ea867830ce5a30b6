// Test support: the server in-process on 127.0.0.1 (port 0) and a minimal
// blocking peer built on protocol/messages.h that sends raw frames and reads
// verified messages with a deadline. Header-only; server tests only.
#pragma once

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "protocol/messages.h"
#include "protocol/stream_batch.h"
#include "server/server.h"

namespace terrane::testing_support {

namespace fs = std::filesystem;

inline constexpr int kTimeoutMs = 60000;

// A blocking test peer: sends frames, reads verified messages with a deadline.
class RawPeer {
 public:
  explicit RawPeer(std::uint16_t port) {
    fd_ = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in addr{};
    addr.sin_family = AF_INET;
    addr.sin_port = htons(port);
    addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    connected_ = ::connect(fd_, reinterpret_cast<const sockaddr*>(&addr), sizeof addr) == 0;
  }
  ~RawPeer() { close(); }
  bool connected() const { return connected_; }
  void close() {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
  }
  // Closes with a reset (RST) instead of a FIN, as a kernel does for a
  // client that leaves with data unread.
  void reset() {
    if (fd_ < 0) return;
    const linger abort_now{1, 0};
    ::setsockopt(fd_, SOL_SOCKET, SO_LINGER, &abort_now, sizeof abort_now);
    close();
  }
  bool send(std::span<const std::uint8_t> bytes) {
    while (!bytes.empty()) {
      const ssize_t n = ::send(fd_, bytes.data(), bytes.size(), MSG_NOSIGNAL);
      if (n <= 0) return false;
      bytes = bytes.subspan(static_cast<std::size_t>(n));
    }
    return true;
  }
  // The next message's body bytes, or nullopt on EOF / error / deadline.
  // timeout_ms: how long to wait for more bytes.
  std::optional<Frame> next(int timeout_ms = kTimeoutMs) {
    while (pending_.empty()) {
      pollfd p{fd_, POLLIN, 0};
      if (::poll(&p, 1, timeout_ms) <= 0) return std::nullopt;
      std::uint8_t buf[16384];
      const ssize_t n = ::recv(fd_, buf, sizeof buf, 0);
      if (n <= 0) return std::nullopt;
      const auto st = reader_.feed(std::span<const std::uint8_t>(buf, static_cast<std::size_t>(n)),
                                   [&](std::span<const std::uint8_t> body) { pending_.emplace_back(body.begin(), body.end()); });
      if (!st) return std::nullopt;
    }
    Frame f = std::move(pending_.front());
    pending_.erase(pending_.begin());
    return f;
  }
  // Skips messages until one of the given type; nullopt if the stream ends.
  std::optional<Frame> next_of(wire::Body type) {
    while (auto f = next()) {
      auto m = verify_message(*f);
      if (!m) return std::nullopt;
      if ((*m)->body_type() == type) return f;
    }
    return std::nullopt;
  }
  // True if the server closes the connection (EOF or reset) before the deadline.
  // Reads until a frame of each type has arrived, in either order (an
  // EditAck and the UpdateBatch of its tick travel in different priority
  // classes); the first of each, or nullopt if the stream ends first.
  std::optional<std::pair<Frame, Frame>> next_of_both(wire::Body a, wire::Body b) {
    std::optional<Frame> fa, fb;
    while (!fa || !fb) {
      auto f = next();
      if (!f) return std::nullopt;
      auto m = verify_message(*f);
      if (!m) return std::nullopt;
      if ((*m)->body_type() == a && !fa) fa = std::move(*f);
      else if ((*m)->body_type() == b && !fb) fb = std::move(*f);
    }
    return std::make_pair(std::move(*fa), std::move(*fb));
  }
  bool closed_by_server() {
    while (next()) {
    }
    pollfd p{fd_, POLLIN, 0};
    if (::poll(&p, 1, 0) < 0) return false;
    std::uint8_t b;
    return ::recv(fd_, &b, 1, MSG_DONTWAIT) <= 0;
  }

 private:
  int fd_ = -1;
  bool connected_ = false;
  FrameReader reader_;
  std::vector<Frame> pending_;
};

inline const wire::Message& msg(const Frame& f) { return *verify_message(f).value(); }

// A FillBox edit request.
inline EditRequestMsg fill_box_edit(std::uint32_t id, Region box, Material material, std::uint8_t occupancy = 255) {
  EditRequestMsg e;
  e.edit_id = id;
  e.kind = EditKind::kFillBox;
  e.box = box;
  e.material = material;
  e.occupancy = occupancy;
  return e;
}

class ServerTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("terrane-server-" + std::to_string(::getpid()) + "-" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
  }
  void TearDown() override {
    if (server_) server_->stop();
    server_.reset();
    fs::remove_all(dir_);
  }
  void start(ServerOptions o = {}) {
    o.world_dir = dir_.string();
    o.net.port = 0;
    auto s = Server::create(o);
    ASSERT_TRUE(s.ok()) << s.error().message;
    server_ = std::move(*s);
    server_->start();
  }
  // Says Hello (with features) on p and returns the Welcome (a failed
  // expectation and an empty message if none comes).
  static WelcomeMsg welcome_of(RawPeer& p, const std::string& name, std::uint32_t features = 0) {
    EXPECT_TRUE(p.send(build_hello(HelloMsg{kProtocolVersion, name, "", {}, features})));
    auto f = p.next_of(wire::Body::Welcome);
    EXPECT_TRUE(f.has_value());
    if (!f) return {};
    auto w = parse_welcome(*msg(*f).body_as_Welcome());
    EXPECT_TRUE(w.ok());
    return w.ok() ? *w : WelcomeMsg{};
  }
  std::unique_ptr<RawPeer> join(const std::string& name, std::uint32_t features = 0) {
    auto p = std::make_unique<RawPeer>(server_->port());
    EXPECT_TRUE(p->connected());
    EXPECT_TRUE(p->send(build_hello(HelloMsg{kProtocolVersion, name, "", {}, features})));
    auto w = p->next_of(wire::Body::Welcome);
    EXPECT_TRUE(w.has_value());
    return p;
  }
  // Moves the peer to pos (small view) and reads until chunk cp is held at
  // full resolution (Coverage Full or Empty); false if the stream ends.
  static bool hold_full(RawPeer& p, Vec3f pos, Vec3i cp) { return hold_at(p, pos, {{cp, 0}}); }
  // Moves p to pos (view 96, full resolution 24) and reads the stream until
  // each chunk is held at its level or finer (0 full resolution or Empty,
  // 1..3 a mip; an Estimate record is coarser than every level).
  static bool hold_at(RawPeer& p, Vec3f pos, std::vector<std::pair<Vec3i, int>> wanted) {
    if (!p.send(build_client_state(ClientStateMsg{pos, 96, 24}))) return false;
    while (auto f = p.next_of(wire::Body::StreamBatch)) {
      const bool ok = for_each_record(msg(*f), [&](const StreamRecord& r) {
        const int level = r.kind == StreamRecordKind::kFull || r.kind == StreamRecordKind::kEmpty ? 0
                          : r.kind == StreamRecordKind::kEstimate || r.kind == StreamRecordKind::kReleased
                              ? kMipLevels
                              : r.level;
        std::erase_if(wanted, [&](const auto& w) { return w.first == r.chunk_pos && level <= w.second; });
      });
      if (!ok) return false;
      if (wanted.empty()) return true;
    }
    return false;
  }
  // Calls fn for each record of a StreamBatch message; false if the batch
  // does not decode.
  static bool for_each_record(const wire::Message& m, const std::function<void(const StreamRecord&)>& fn) {
    auto records = parse_stream_batch(*m.body_as_StreamBatch());
    if (!records) return false;
    StreamDecodeScratch scratch;
    return decode_stream_batch(*records, scratch, [&](const StreamRecord& r) -> Status {
             fn(r);
             return Ok{};
           })
        .ok();
  }
  // Sends a Ping and reads p's frames up to its Pong, which the server sends
  // after everything it had queued for p before (one strand, in order),
  // calling fn for each stream record on the way. False if the stream ends
  // or a batch does not decode.
  static bool records_until_pong(RawPeer& p, std::uint64_t nonce, const std::function<void(const StreamRecord&)>& fn) {
    if (!p.send(build_ping(nonce))) return false;
    while (auto f = p.next()) {
      const wire::Message& m = msg(*f);
      if (m.body_type() == wire::Body::Pong) return true;
      if (m.body_type() == wire::Body::StreamBatch && !for_each_record(m, fn)) return false;
    }
    return false;
  }

  fs::path dir_;
  std::unique_ptr<Server> server_;
};

}  // namespace terrane::testing_support
