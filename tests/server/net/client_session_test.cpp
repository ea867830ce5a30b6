// ClientSession: the handshake, admission, pings and operators' commands
// over a real socket on 127.0.0.1, with a fake Admitter and a fake
// replica that records what the session hands on. A version-1 Hello is told
// both versions and never reaches the replica; an admitted client's replica
// joins before the Welcome goes out, a Ping follows, and the Pong measures
// the round trip; world messages go to the replica, admin commands only to
// the AdminFn and only from admins.
#include "server/net/client_session.h"

#include <gtest/gtest.h>

#include <thread>

#include "tests/support/eventually.h"
#include "tests/support/server_fixture.h"

namespace terrane {
namespace {

using testing_support::eventually;
using testing_support::msg;
using testing_support::RawPeer;

// Admits every name but "mallory" (authentication fails) and "banned"
// (refused with a reason); "root" is an admin.
class FakeAdmitter final : public Admitter {
 public:
  Admission admit(const std::string& name, const std::string&, const std::string&, std::int64_t) const override {
    if (name == "mallory") return Admission{false, false, CloseReason::kAuthFailed, "authentication failed"};
    if (name == "banned") return Admission{false, false, CloseReason::kBanned, "banned: griefing"};
    return Admission{true, name == "root", CloseReason::kAuthFailed, ""};
  }
};

// Records the calls (session strand), read by the test thread under m.
class FakeReplica final : public ClientReplica {
 public:
  void join(const std::string& name, bool, std::uint32_t) override { note("join " + name); }
  bool move(const ClientStateMsg& state) override {
    note("move " + std::to_string(static_cast<int>(state.position.x)));
    return state.position.x < 1000;  // farther: refused, as too fast
  }
  void edit(EditRequestMsg e) override { note("edit " + std::to_string(e.edit_id)); }
  void read_box(const ReadBoxMsg& r) override { note("read " + std::to_string(r.request_id)); }
  void holdings(const HoldingsMsg& h) override { note("holdings " + std::to_string(h.chunks.size())); }
  void hash_request(Vec3i cp) override { note("hash " + std::to_string(cp.x)); }
  void drained() override {}
  void closed() override { note("closed"); }

  std::vector<std::string> calls() const {
    std::lock_guard lock(m_);
    return calls_;
  }
  bool called(const std::string& call) const {
    const auto c = calls();
    return std::find(c.begin(), c.end(), call) != c.end();
  }

 private:
  void note(std::string call) {
    std::lock_guard lock(m_);
    calls_.push_back(std::move(call));
  }
  mutable std::mutex m_;
  std::vector<std::string> calls_;
};

class ClientSessionTest : public ::testing::Test {
 protected:
  void SetUp() override {
    welcome_.server_epoch = 7;
    welcome_.spawn = {1, 2, 3};
    acceptor_.open(asio::ip::tcp::v4());
    acceptor_.bind({asio::ip::make_address("127.0.0.1"), 0});
    acceptor_.listen();
    admin_ = [this](const std::string& who, AdminRequestMsg req, std::function<void(AdminResultMsg)> reply) {
      {
        std::lock_guard lock(admin_m_);
        admin_calls_.push_back(who + " " + req.command);
      }
      reply(AdminResultMsg{req.request_id, true, "done\n", "{}"});
    };
    accept();
    thread_ = std::thread([this] { io_.run(); });
  }
  void TearDown() override {
    asio::post(io_, [this] { acceptor_.close(); });
    work_.reset();
    thread_.join();
  }
  // Accepts connections until the acceptor closes (io thread).
  void accept() {
    acceptor_.async_accept(asio::make_strand(io_), [this](const asio::error_code& ec, asio::ip::tcp::socket s) {
      if (ec) return;
      auto client = ClientSession::open(std::move(s), 1, limits_, context_, replica_);
      {
        std::lock_guard lock(clients_m_);
        clients_.push_back(client);
      }
      client->session()->start();
      accept();
    });
  }
  std::shared_ptr<ClientSession> client() {
    std::lock_guard lock(clients_m_);
    return clients_.empty() ? nullptr : clients_.back();
  }
  std::uint16_t port() const { return acceptor_.local_endpoint().port(); }
  // Sends a Hello as name; the first message back.
  std::optional<Frame> hello(RawPeer& p, const std::string& name, std::uint16_t version = kProtocolVersion) {
    EXPECT_TRUE(p.send(build_hello(HelloMsg{version, name, "token", {}})));
    return p.next();
  }
  static std::string disconnect_text(const Frame& f) {
    const wire::Message& m = msg(f);
    if (m.body_type() != wire::Body::Disconnect) return "(not a Disconnect)";
    return *parse_disconnect(*m.body_as_Disconnect());
  }

  asio::io_context io_;
  asio::executor_work_guard<asio::io_context::executor_type> work_ = asio::make_work_guard(io_);
  asio::ip::tcp::acceptor acceptor_{io_};
  std::thread thread_;
  SessionLimits limits_;
  WelcomeMsg welcome_;
  FakeAdmitter admitter_;
  ClientSession::AdminFn admin_;
  ServerCounters counters_;
  std::atomic<int> forgotten_{0};
  ClientSession::Context context_{welcome_, admitter_, admin_, counters_, [this](std::uint64_t) { ++forgotten_; }};
  std::shared_ptr<FakeReplica> replica_ = std::make_shared<FakeReplica>();
  std::mutex clients_m_;
  std::vector<std::shared_ptr<ClientSession>> clients_;
  std::mutex admin_m_;
  std::vector<std::string> admin_calls_;
};

TEST_F(ClientSessionTest, AVersionOneHelloIsToldBothVersionsAndNeverReachesTheReplica) {
  RawPeer p(port());
  auto f = hello(p, "old", 1);
  ASSERT_TRUE(f);
  const std::string text = disconnect_text(*f);
  EXPECT_NE(text.find("protocol version 1 is not supported"), std::string::npos) << text;
  EXPECT_NE(text.find("speaks version " + std::to_string(kProtocolVersion)), std::string::npos) << text;
  EXPECT_TRUE(p.closed_by_server());
  ASSERT_TRUE(eventually([&] { return replica_->called("closed"); }));
  EXPECT_EQ(replica_->calls(), std::vector<std::string>{"closed"});  // no join
  EXPECT_EQ(forgotten_.load(), 1);
  EXPECT_EQ(counters_.clients.load(), 0);
}

TEST_F(ClientSessionTest, ARefusedClientGetsTheAdmittersReasonAndAFailedTokenIsCounted) {
  {
    RawPeer p(port());
    auto f = hello(p, "banned");
    ASSERT_TRUE(f);
    EXPECT_EQ(disconnect_text(*f), "banned: griefing");
    EXPECT_TRUE(p.closed_by_server());
  }
  RawPeer p(port());
  auto f = hello(p, "mallory");
  ASSERT_TRUE(f);
  EXPECT_EQ(disconnect_text(*f), "authentication failed");
  EXPECT_TRUE(p.closed_by_server());
  EXPECT_EQ(counters_.auth_failures.load(), 1u);
  ASSERT_TRUE(eventually([&] { return replica_->calls().size() == 2; }));
  EXPECT_EQ(replica_->calls(), (std::vector<std::string>{"closed", "closed"}));
}

TEST_F(ClientSessionTest, AnAdmittedClientsReplicaJoinsThenTheWelcomeAndAPingGoOutAndThePongIsMeasured) {
  RawPeer p(port());
  auto f = hello(p, "ann");
  ASSERT_TRUE(f);
  ASSERT_EQ(msg(*f).body_type(), wire::Body::Welcome);
  EXPECT_EQ(msg(*f).body_as_Welcome()->server_epoch(), 7u);
  EXPECT_EQ(replica_->calls(), std::vector<std::string>{"join ann"});  // before the Welcome was sent
  EXPECT_EQ(counters_.clients.load(), 1);
  EXPECT_EQ(counters_.joins.load(), 1u);
  auto ping = p.next_of(wire::Body::Ping);
  ASSERT_TRUE(ping);
  const std::uint64_t nonce = msg(*ping).body_as_Ping()->nonce();
  EXPECT_NE(nonce, 0u);
  const auto c = client();
  ASSERT_TRUE(c);
  ClientSession::Info info = c->info();
  EXPECT_EQ(info.name, "ann");
  EXPECT_TRUE(info.welcomed);
  EXPECT_FALSE(info.admin);
  EXPECT_EQ(info.position.y, 2.0f);  // the spawn, until it moves
  EXPECT_LT(info.ping_ms, 0);
  ASSERT_TRUE(p.send(build_pong(nonce + 1)));  // not the Ping's: ignored
  ASSERT_TRUE(p.send(build_pong(nonce)));
  ASSERT_TRUE(eventually([&] { return c->info().ping_ms >= 0; }));
  EXPECT_LT(c->info().ping_ms, 60000);
  p.close();
  ASSERT_TRUE(eventually([&] { return replica_->called("closed"); }));
  EXPECT_EQ(counters_.clients.load(), 0);
}

TEST_F(ClientSessionTest, WorldMessagesGoToTheReplicaAndAnAcceptedMoveToTheOperatorsView) {
  RawPeer p(port());
  auto f = hello(p, "ann");
  ASSERT_TRUE(f);
  ASSERT_TRUE(p.send(build_client_state(ClientStateMsg{{40, 5, 6}, 96, 24})));
  EditRequestMsg e = testing_support::fill_box_edit(9, Region{{0, 0, 0}, {1, 1, 1}}, 1);
  ASSERT_TRUE(p.send(build_edit_request(e)));
  ASSERT_TRUE(p.send(build_chunk_hash_request(Vec3i{3, 0, 0})));
  ASSERT_TRUE(eventually([&] { return replica_->called("hash 3"); }));
  EXPECT_EQ(replica_->calls(), (std::vector<std::string>{"join ann", "move 40", "edit 9", "hash 3"}));
  EXPECT_EQ(client()->info().position.x, 40.0f);
  // A move the replica refuses is not shown to operators.
  ASSERT_TRUE(p.send(build_client_state(ClientStateMsg{{5000, 5, 6}, 96, 24})));
  ASSERT_TRUE(eventually([&] { return replica_->called("move 5000"); }));
  EXPECT_EQ(client()->info().position.x, 40.0f);
}

TEST_F(ClientSessionTest, AdminCommandsReachTheAdminFnOnlyFromAdmins) {
  RawPeer player(port());
  ASSERT_TRUE(hello(player, "ann"));
  ASSERT_TRUE(player.send(build_admin_request(AdminRequestMsg{4, "status", {}})));
  auto r = player.next_of(wire::Body::AdminResult);
  ASSERT_TRUE(r);
  auto refused = parse_admin_result(*msg(*r).body_as_AdminResult());
  ASSERT_TRUE(refused.ok());
  EXPECT_EQ(refused->request_id, 4u);
  EXPECT_FALSE(refused->ok);
  EXPECT_NE(refused->text.find("not an admin"), std::string::npos) << refused->text;

  RawPeer root(port());
  ASSERT_TRUE(hello(root, "root"));
  ASSERT_TRUE(root.send(build_admin_request(AdminRequestMsg{5, "status", {}})));
  r = root.next_of(wire::Body::AdminResult);
  ASSERT_TRUE(r);
  auto answered = parse_admin_result(*msg(*r).body_as_AdminResult());
  ASSERT_TRUE(answered.ok());
  EXPECT_EQ(answered->request_id, 5u);
  EXPECT_TRUE(answered->ok);
  std::lock_guard lock(admin_m_);
  EXPECT_EQ(admin_calls_, std::vector<std::string>{"root status"});
}

}  // namespace
}  // namespace terrane
