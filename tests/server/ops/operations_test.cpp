// Operations, on a real SQLite world and real sessions on 127.0.0.1: the
// admin commands answer with the world's part (given) and the sessions'
// own (players); once the admin room is closed, commands are refused; a
// scheduled shutdown tells the welcomed clients, stops the server on a
// thread of its own, and the last notice says whether to reconnect; a
// shutdown whose timer is stopped never stops the server; /metrics and
// /health serve what the server gives.
#include "server/ops/operations.h"

#include <gtest/gtest.h>
#include <httplib.h>

#include <atomic>
#include <future>
#include <thread>

#include "common/world/world.h"
#include "tests/support/eventually.h"
#include "tests/support/null_replica.h"
#include "tests/support/scratch_dir.h"
#include "tests/support/server_fixture.h"

namespace terrane {
namespace {

using testing_support::eventually;
using testing_support::NullReplica;
using testing_support::msg;
using testing_support::RawPeer;

class OperationsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    auto world = World::create((dir_ / "world").string(), default_world_meta());
    ASSERT_TRUE(world.ok()) << world.error().message;
    world_ = std::move(*world);
    acceptor_.open(asio::ip::tcp::v4());
    acceptor_.bind({asio::ip::make_address("127.0.0.1"), 0});
    acceptor_.listen();
  }
  void TearDown() override {
    if (ops_) {
      ops_->stop_timers();
      ops_->close_admin();
      ops_->stop_metrics();
    }
    work_.reset();
    if (thread_.joinable()) thread_.join();
    ops_.reset();
    world_.reset();
    std::filesystem::remove_all(dir_);
  }
  // The operations on options, their world's status as given, flush and
  // rollback unused; stopping counts the server's stops.
  void open(const OpsOptions& options = {}) {
    Operations::Wiring w;
    w.world.status = [] {
      ServerStatus s;
      s.world_dir = "the-world";
      s.epoch = 7;
      s.ticks = 42;
      s.tick_hz = 20;
      return s;
    };
    w.metrics = [] { return std::string("terrane_test_metric 1\n"); };
    w.health = [this] { return healthy_ ? Health{HealthState::kReady, "ok"} : Health{HealthState::kFailing, "storage failed"}; };
    w.stop = [this] { ++stops_; };
    auto ops = Operations::open(options, world_->store(), (dir_ / "world").string(), io_, sessions_, counters_,
                                std::move(w));
    ASSERT_TRUE(ops.ok()) << ops.error().message;
    ops_ = std::move(*ops);
    context_.emplace(ClientSession::Context{welcome_, ops_->admitter(), ops_->admin(), counters_,
                                            [this](std::uint64_t id) { sessions_.remove(id); }});
    thread_ = std::thread([this] { io_.run(); });
  }
  // A client welcomed as name, in the table.
  std::unique_ptr<RawPeer> join(const std::string& name) {
    auto peer = std::make_unique<RawPeer>(acceptor_.local_endpoint().port());
    asio::ip::tcp::socket socket(asio::make_strand(io_));
    acceptor_.accept(socket);
    const std::uint64_t id = sessions_.next_id();
    auto client = ClientSession::open(std::move(socket), id, limits_, *context_, std::make_shared<NullReplica>());
    EXPECT_TRUE(sessions_.add(id, client));
    client->session()->start();
    EXPECT_TRUE(peer->send(build_hello(HelloMsg{kProtocolVersion, name, "", {}})));
    EXPECT_TRUE(peer->next_of(wire::Body::Welcome).has_value());
    return peer;
  }
  AdminResultMsg command(const std::string& cmd) {
    std::promise<AdminResultMsg> result;
    ops_->admin()("op", AdminRequestMsg{1, cmd, {}}, [&](AdminResultMsg r) { result.set_value(std::move(r)); });
    return result.get_future().get();
  }
  static ServerNoticeMsg notice(RawPeer& p) {
    auto f = p.next_of(wire::Body::ServerNotice);
    EXPECT_TRUE(f.has_value());
    if (!f) return {};
    return *parse_server_notice(*msg(*f).body_as_ServerNotice());
  }

  const std::filesystem::path dir_ = testing_support::scratch_dir("terrane-ops");
  std::unique_ptr<World> world_;
  asio::io_context io_;
  asio::executor_work_guard<asio::io_context::executor_type> work_ = asio::make_work_guard(io_);
  asio::ip::tcp::acceptor acceptor_{io_};
  std::thread thread_;
  ServerCounters counters_;
  SessionTable sessions_{100};
  SessionLimits limits_;
  WelcomeMsg welcome_;
  std::unique_ptr<Operations> ops_;
  std::optional<ClientSession::Context> context_;
  std::atomic<int> stops_{0};
  std::atomic<bool> healthy_{true};
};

TEST_F(OperationsTest, CommandsAnswerWithTheWorldsPartAndTheSessionsOwn) {
  open();
  auto alice = join("alice");
  auto bob = join("bob");
  const AdminResultMsg status = command("status");
  ASSERT_TRUE(status.ok) << status.text;
  EXPECT_NE(status.text.find("world the-world (epoch 7), up "), std::string::npos) << status.text;
  EXPECT_NE(status.text.find("42 ticks at 20 Hz"), std::string::npos) << status.text;
  const AdminResultMsg players = command("players");
  ASSERT_TRUE(players.ok) << players.text;
  EXPECT_NE(players.text.find("alice"), std::string::npos) << players.text;
  EXPECT_NE(players.text.find("bob"), std::string::npos) << players.text;
  EXPECT_LT(players.text.find("alice"), players.text.find("bob")) << "by name";

  ops_->close_admin();
  const AdminResultMsg refused = command("status");
  EXPECT_FALSE(refused.ok);
  EXPECT_EQ(refused.text, "the server is stopping");
}

TEST_F(OperationsTest, AScheduledShutdownWarnsTheClientsThenStopsTheServer) {
  open();
  auto alice = join("alice");
  ops_->schedule_shutdown(1, false, "maintenance");
  const ServerNoticeMsg warned = notice(*alice);
  EXPECT_EQ(warned.kind, wire::NoticeKind::Shutdown);
  EXPECT_EQ(warned.seconds_left, 1u);
  EXPECT_FALSE(warned.reconnect);
  EXPECT_EQ(warned.text, "server stopping in 1 s: maintenance");
  ASSERT_TRUE(eventually([&] { return stops_.load() == 1; }));
  // The server's stop tells the clients, as the operator said: no restart.
  ops_->notify_stopping();
  const ServerNoticeMsg bye = notice(*alice);
  EXPECT_FALSE(bye.reconnect);
  EXPECT_EQ(bye.text, "server stopping now");
}

TEST_F(OperationsTest, ClientsAreToldToReconnectUnlessAnOperatorSaidOtherwise) {
  open();
  auto alice = join("alice");
  ops_->notify_stopping();
  const ServerNoticeMsg bye = notice(*alice);
  EXPECT_TRUE(bye.reconnect);
  EXPECT_EQ(bye.text, "server stopping now; it restarts: reconnect");
}

TEST_F(OperationsTest, AShutdownWhoseTimerStoppedNeverStopsTheServer) {
  open();
  ops_->schedule_shutdown(1, true, "");
  ops_->stop_timers();
  // The io thread ends only once the timer no longer waits; it never fired.
  work_.reset();
  thread_.join();
  EXPECT_EQ(stops_.load(), 0);
}

TEST_F(OperationsTest, ServesMetricsAndHealthAsTheServerGivesThem) {
  OpsOptions o;
  o.metrics_address = "127.0.0.1:0";
  open(o);
  ASSERT_NE(ops_->metrics_port(), 0);
  ops_->start();
  httplib::Client http("127.0.0.1", ops_->metrics_port());
  auto metrics = http.Get("/metrics");
  ASSERT_TRUE(metrics) << httplib::to_string(metrics.error());
  EXPECT_EQ(metrics->body.rfind("terrane_test_metric 1\n", 0), 0u) << metrics->body;
  auto health = http.Get("/health");
  ASSERT_TRUE(health);
  EXPECT_EQ(health->status, 200);
  healthy_ = false;
  health = http.Get("/health");
  ASSERT_TRUE(health);
  EXPECT_EQ(health->status, 503);
  EXPECT_NE(health->body.find("storage failed"), std::string::npos);
}

// /health names its state: ready (200), draining while a shutdown is
// pending (503), ready again once it is cancelled, failing (503) whatever
// is pending; as text, as JSON, and as the terrane_health_state gauge.
TEST_F(OperationsTest, HealthSaysReadyDrainingOrFailingAndTheGaugeAgrees) {
  OpsOptions o;
  o.metrics_address = "127.0.0.1:0";
  open(o);
  ops_->start();
  auto alice = join("alice");
  httplib::Client http("127.0.0.1", ops_->metrics_port());
  auto get = [&](const std::string& path, int* status) {
    auto r = http.Get(path);
    EXPECT_TRUE(r) << httplib::to_string(r.error());
    if (!r) return std::string();
    *status = r->status;
    return r->body;
  };
  int status = 0;
  EXPECT_EQ(get("/health", &status), "ready\n");
  EXPECT_EQ(status, 200);
  EXPECT_EQ(get("/health?format=json", &status), "{\"state\": \"ready\", \"reason\": \"ok\"}\n");
  EXPECT_NE(get("/metrics", &status).find("terrane_health_state{state=\"ready\"} 1\n"), std::string::npos);

  ops_->schedule_shutdown(3600, false, "maintenance");
  EXPECT_EQ(notice(*alice).seconds_left, 3600u);
  std::string body = get("/health", &status);
  EXPECT_EQ(status, 503);
  EXPECT_EQ(body.rfind("draining: shutdown pending: stopping in 36", 0), 0u) << body;
  EXPECT_EQ(get("/health?format=json", &status).rfind("{\"state\": \"draining\", \"reason\": \"shutdown pending", 0), 0u);
  body = get("/metrics", &status);
  EXPECT_NE(body.find("terrane_health_state{state=\"draining\"} 1\n"), std::string::npos) << body;
  EXPECT_NE(body.find("terrane_health_state{state=\"ready\"} 0\n"), std::string::npos) << body;
  healthy_ = false;  // failing beats draining
  EXPECT_EQ(get("/health", &status), "failing: storage failed\n");
  EXPECT_EQ(status, 503);
  healthy_ = true;

  const AdminResultMsg cancelled = command("cancel-shutdown");
  EXPECT_TRUE(cancelled.ok) << cancelled.text;
  const ServerNoticeMsg told = notice(*alice);
  EXPECT_EQ(told.kind, wire::NoticeKind::Say);
  EXPECT_EQ(told.text, "the scheduled shutdown is cancelled");
  EXPECT_EQ(get("/health", &status), "ready\n");
  EXPECT_EQ(status, 200);
  const AdminResultMsg none = command("cancel-shutdown");
  EXPECT_FALSE(none.ok);
  EXPECT_EQ(none.text, "no shutdown is pending");
}

// A cancelled shutdown never stops the server: the io thread ends once no
// timer waits, and none fired.
TEST_F(OperationsTest, ACancelledShutdownNeverStopsTheServer) {
  open();
  ops_->schedule_shutdown(1, false, "");
  EXPECT_TRUE(ops_->shutdown_in().has_value());
  ASSERT_TRUE(ops_->cancel_shutdown());
  EXPECT_FALSE(ops_->shutdown_in().has_value());
  EXPECT_FALSE(ops_->cancel_shutdown());
  work_.reset();
  thread_.join();
  EXPECT_EQ(stops_.load(), 0);
}

// A scheduled shutdown warns again at the marks before it is due (here 5 s
// before: scheduled in 6 s), then stops the server.
TEST_F(OperationsTest, AShutdownWarnsAgainAtIntervals) {
  open();
  auto alice = join("alice");
  ops_->schedule_shutdown(6, true, "upgrade");
  EXPECT_EQ(notice(*alice).seconds_left, 6u);
  const ServerNoticeMsg again = notice(*alice);  // 5 s before
  EXPECT_EQ(again.kind, wire::NoticeKind::Shutdown);
  EXPECT_EQ(again.seconds_left, 5u);
  EXPECT_TRUE(again.reconnect);
  EXPECT_EQ(again.text, "server stopping in 5 s and restarting: upgrade");
  ASSERT_TRUE(eventually([&] { return stops_.load() == 1; }));
}

TEST_F(OperationsTest, ABadMetricsAddressIsRefused) {
  OpsOptions o;
  o.metrics_address = "nowhere";
  auto ops = Operations::open(o, world_->store(), (dir_ / "world").string(), io_, sessions_, counters_,
                              Operations::Wiring{});
  ASSERT_FALSE(ops.ok());
  EXPECT_EQ(ops.error().message.rfind("--metrics: ", 0), 0u) << ops.error().message;
}

}  // namespace
}  // namespace terrane
