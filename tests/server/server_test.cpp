// The server in-process, spoken to over real sockets on 127.0.0.1 with a
// minimal blocking peer built on protocol/messages.h; and edit application.
#include "server/server.h"

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <numbers>
#include <optional>

#include "server/edits.h"

namespace terrane {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

constexpr int kTimeoutMs = 60000;

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
  bool send(std::span<const std::uint8_t> bytes) {
    while (!bytes.empty()) {
      const ssize_t n = ::send(fd_, bytes.data(), bytes.size(), MSG_NOSIGNAL);
      if (n <= 0) return false;
      bytes = bytes.subspan(static_cast<std::size_t>(n));
    }
    return true;
  }
  // The next message's body bytes, or nullopt on EOF / error / deadline.
  std::optional<Frame> next() {
    while (pending_.empty()) {
      pollfd p{fd_, POLLIN, 0};
      if (::poll(&p, 1, kTimeoutMs) <= 0) return std::nullopt;
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

const wire::Message& msg(const Frame& f) { return *verify_message(f).value(); }

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
    o.port = 0;
    auto s = Server::create(o);
    ASSERT_TRUE(s.ok()) << s.error().message;
    server_ = std::move(*s);
    server_->start();
  }
  std::unique_ptr<RawPeer> join(const std::string& name) {
    auto p = std::make_unique<RawPeer>(server_->port());
    EXPECT_TRUE(p->connected());
    EXPECT_TRUE(p->send(build_hello(HelloMsg{kProtocolVersion, name, ""})));
    auto w = p->next_of(wire::Body::Welcome);
    EXPECT_TRUE(w.has_value());
    return p;
  }

  fs::path dir_;
  std::unique_ptr<Server> server_;
};

TEST_F(ServerTest, WelcomeDescribesTheWorld) {
  start();
  RawPeer p(server_->port());
  ASSERT_TRUE(p.connected());
  ASSERT_TRUE(p.send(build_hello(HelloMsg{kProtocolVersion, "t", ""})));
  auto f = p.next_of(wire::Body::Welcome);
  ASSERT_TRUE(f.has_value());
  auto w = parse_welcome(*msg(*f).body_as_Welcome());
  ASSERT_TRUE(w.ok()) << w.error().describe();
  EXPECT_EQ(w->protocol_version, kProtocolVersion);
  EXPECT_EQ(w->tick_hz, 20u);
  EXPECT_EQ(w->materials.size(), default_material_names().size());
  EXPECT_GE(w->server_epoch, 2u);  // bumped by the start
}

TEST_F(ServerTest, VersionMismatchIsToldWhy) {
  start();
  RawPeer p(server_->port());
  ASSERT_TRUE(p.send(build_hello(HelloMsg{kProtocolVersion + 5, "t", ""})));
  auto f = p.next_of(wire::Body::Disconnect);
  ASSERT_TRUE(f.has_value());
  EXPECT_NE(parse_disconnect(*msg(*f).body_as_Disconnect())->find("protocol version mismatch"), std::string::npos);
  EXPECT_TRUE(p.closed_by_server());
}

TEST_F(ServerTest, WrongAuthTokenIsRejected) {
  ServerOptions o;
  o.auth_token = "open sesame";
  start(o);
  RawPeer p(server_->port());
  ASSERT_TRUE(p.send(build_hello(HelloMsg{kProtocolVersion, "t", "guess"})));
  auto f = p.next_of(wire::Body::Disconnect);
  ASSERT_TRUE(f.has_value());
  EXPECT_EQ(*parse_disconnect(*msg(*f).body_as_Disconnect()), "authentication failed");
}

TEST_F(ServerTest, MessageBeforeHelloIsAProtocolError) {
  start();
  RawPeer p(server_->port());
  ASSERT_TRUE(p.send(build_ping(1)));
  auto f = p.next_of(wire::Body::Disconnect);
  ASSERT_TRUE(f.has_value());
  EXPECT_NE(parse_disconnect(*msg(*f).body_as_Disconnect())->find("expected Hello"), std::string::npos);
}

TEST_F(ServerTest, SilentPeerIsDroppedAtTheHandshakeDeadline) {
  ServerOptions o;
  o.session.handshake_timeout = 200ms;
  start(o);
  RawPeer p(server_->port());
  auto f = p.next_of(wire::Body::Disconnect);
  ASSERT_TRUE(f.has_value());
  EXPECT_EQ(*parse_disconnect(*msg(*f).body_as_Disconnect()), "handshake timeout");
}

TEST_F(ServerTest, TruncatedAndOversizedFramesAffectOnlyTheirSender) {
  start();
  auto good = join("good");
  {
    RawPeer truncated(server_->port());
    const Frame hello = build_hello(HelloMsg{kProtocolVersion, "cut", ""});
    ASSERT_TRUE(truncated.send(std::span<const std::uint8_t>(hello).first(hello.size() / 2)));
    truncated.close();  // the server sees EOF mid-frame
  }
  auto big = join("big");
  const std::uint8_t header[4] = {0x01, 0x00, 0x20, 0x00};  // 2 MiB
  ASSERT_TRUE(big->send(header));
  EXPECT_TRUE(big->closed_by_server());
  ASSERT_TRUE(good->send(build_ping(42)));
  auto pong = good->next_of(wire::Body::Pong);
  ASSERT_TRUE(pong.has_value());
  EXPECT_EQ(msg(*pong).body_as_Pong()->nonce(), 42u);
}

TEST_F(ServerTest, InvalidEditIsRejectedNotFatal) {
  start();
  auto p = join("editor");
  EditRequestMsg e;
  e.edit_id = 5;
  e.kind = EditKind::kFillBox;
  e.box = {{0, 0, 0}, {100, 100, 100}};  // over the volume limit
  e.material = materials::kRock;
  ASSERT_TRUE(p->send(build_edit_request(e)));
  auto r = p->next_of(wire::Body::EditReject);
  ASSERT_TRUE(r.has_value());
  EXPECT_EQ(msg(*r).body_as_EditReject()->edit_id(), 5u);
  ASSERT_TRUE(p->send(build_ping(1)));
  EXPECT_TRUE(p->next_of(wire::Body::Pong).has_value());
}

TEST_F(ServerTest, EditIsAppliedPersistedAndAcknowledged) {
  start();
  auto p = join("editor");
  EditRequestMsg e;
  e.edit_id = 77;
  e.kind = EditKind::kFillBox;
  e.box = {{1000, 10, 1000}, {1004, 14, 1004}};
  e.material = materials::kBrick;
  e.occupancy = 128;
  ASSERT_TRUE(p->send(build_edit_request(e)));
  auto ack = p->next_of(wire::Body::EditAck);
  ASSERT_TRUE(ack.has_value());
  EXPECT_EQ(msg(*ack).body_as_EditAck()->edit_id(), 77u);
  const Vec3i cp = chunk_of(e.box.min);
  std::uint64_t rev = 0;
  Voxel v{};
  server_->inspect([&](const ChunkCache& c) {
    rev = c.revision(cp);
    v = c.grid().get(e.box.min + Vec3i{1, 1, 1});
  });
  EXPECT_EQ(rev, 1u);
  EXPECT_EQ(v, make_voxel(materials::kBrick, 128));
  p.reset();
  server_->stop();
  auto world = World::open(dir_.string());
  ASSERT_TRUE(world.ok());
  auto stored = (*world)->load_chunk(cp);
  ASSERT_TRUE(stored.ok());
  EXPECT_EQ(stored->revision, 1u);
  EXPECT_EQ(stored->chunk.get(local_of(e.box.min)), make_voxel(materials::kBrick, 128));
}

// --- edit application ----------------------------------------------------------

TEST(ApplyEdit, SphereOccupancyMatchesItsVolume) {
  for (const float r : {3.0f, 5.5f, 10.0f}) {
    Grid g;
    ChangedUnits changed;
    EditRequestMsg e;
    e.kind = EditKind::kFillSphere;
    e.center = {0.3f, 40.7f, -5.2f};
    e.radius = r;
    e.material = materials::kSand;
    const Region all{{-64, -64, -64}, {64, 128, 64}};
    apply_edit(g, e, all, changed);
    const double volume = 4.0 / 3.0 * std::numbers::pi * r * r * r;
    EXPECT_NEAR(total_occupancy(g, e.bounds()), volume, volume * 0.03) << "radius " << r;
    EXPECT_FALSE(changed.empty());
  }
}

TEST(ApplyEdit, DiggingASphereOutOfAFilledSphereLeavesNothing) {
  Grid g;
  ChangedUnits changed;
  EditRequestMsg fill;
  fill.kind = EditKind::kFillSphere;
  fill.center = {8, 8, 8};
  fill.radius = 6;
  fill.material = materials::kRock;
  const Region all{{-32, -32, -32}, {64, 64, 64}};
  apply_edit(g, fill, all, changed);
  EditRequestMsg dig = fill;
  dig.material = kAir;
  dig.radius = 8;
  apply_edit(g, dig, all, changed);
  EXPECT_EQ(total_occupancy(g, all), 0.0);
  EXPECT_EQ(g.chunk_count(), 0u);
}

TEST(ApplyEdit, BoxMarksExactlyTheUnitsItChanges) {
  Grid g;
  ChangedUnits changed;
  EditRequestMsg e;
  e.kind = EditKind::kFillBox;
  e.box = {{2, 0, 0}, {6, 1, 1}};  // spans units x 0 and 1 of chunk (0,0,0)
  e.material = materials::kRock;
  e.occupancy = 255;
  EXPECT_EQ(apply_edit(g, e, Region{{-100, -100, -100}, {100, 100, 100}}, changed), 4u);
  ASSERT_EQ(changed.size(), 1u);
  EXPECT_EQ(changed.begin()->second.count(), 2u);
  EXPECT_TRUE(changed.begin()->second.test(0));
  EXPECT_TRUE(changed.begin()->second.test(1));
  // Writing the same again changes nothing.
  changed.clear();
  EXPECT_EQ(apply_edit(g, e, Region{{-100, -100, -100}, {100, 100, 100}}, changed), 0u);
  EXPECT_TRUE(changed.empty());
  // Clipping applies.
  EXPECT_EQ(apply_edit(g, EditRequestMsg{1, EditKind::kFillBox, {{0, 0, 0}, {8, 1, 1}}, {}, 0, kAir, 0},
                       Region{{0, 0, 0}, {3, 1, 1}}, changed),
            1u);
}

}  // namespace
}  // namespace terrane
