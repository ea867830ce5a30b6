// SessionTable: the live sessions over real sockets on 127.0.0.1. A session
// past the cap is refused (and counted until removed); ids are unique
// across threads, and removals from several threads all count; the walk
// sees welcomed clients only; close_all closes every live session with its
// reason, and each leaves the table as its socket closes.
#include "server/net/session_table.h"

#include <gtest/gtest.h>

#include <atomic>
#include <set>
#include <thread>

#include "tests/support/eventually.h"
#include "tests/support/null_replica.h"
#include "tests/support/server_fixture.h"

namespace terrane {
namespace {

using testing_support::eventually;
using testing_support::NullReplica;
using testing_support::msg;
using testing_support::RawPeer;

class AdmitAll final : public Admitter {
 public:
  Admission admit(const std::string&, const std::string&, const std::string&, std::int64_t) const override {
    return Admission{true, false, CloseReason::kAuthFailed, ""};
  }
};

class SessionTableTest : public ::testing::Test {
 protected:
  SessionTableTest() {
    acceptor_.open(asio::ip::tcp::v4());
    acceptor_.bind({asio::ip::make_address("127.0.0.1"), 0});
    acceptor_.listen();
  }
  // Every session opened here ends closed: a session and its client
  // session hold each other until the session closes (the cycle the
  // server breaks in ClientSession::on_closed), so one left open leaks.
  void TearDown() override {
    if (!thread_.joinable()) run_io();
    for (const auto& weak : opened_)
      if (auto s = weak.lock()) s->close(CloseReason::kShutdown, "test over");
    EXPECT_TRUE(eventually([&] { return forgotten_.load() == opened_.size(); }))
        << forgotten_.load() << " of " << opened_.size() << " sessions closed";
  }
  ~SessionTableTest() override {
    work_.reset();
    if (thread_.joinable()) thread_.join();
  }
  void run_io() {
    thread_ = std::thread([this] { io_.run(); });
  }
  // A client session on a new connection from peer, with the table's next
  // id, started as the server starts one (it reads once the io thread
  // runs).
  std::shared_ptr<ClientSession> connect(std::unique_ptr<RawPeer>& peer, std::uint64_t& id) {
    peer = std::make_unique<RawPeer>(acceptor_.local_endpoint().port());
    EXPECT_TRUE(peer->connected());
    asio::ip::tcp::socket socket(asio::make_strand(io_));
    acceptor_.accept(socket);
    id = table_.next_id();
    auto client = ClientSession::open(std::move(socket), id, limits_, context_, replica_);
    opened_.push_back(client->session());
    client->session()->start();
    return client;
  }
  static std::string disconnect_text(RawPeer& p) {
    const auto f = p.next_of(wire::Body::Disconnect);
    if (!f) return "(no Disconnect)";
    return *parse_disconnect(*msg(*f).body_as_Disconnect());
  }

  asio::io_context io_;
  asio::executor_work_guard<asio::io_context::executor_type> work_ = asio::make_work_guard(io_);
  asio::ip::tcp::acceptor acceptor_{io_};
  std::thread thread_;
  SessionTable table_{3};
  SessionLimits limits_;
  WelcomeMsg welcome_;
  AdmitAll admitter_;
  ClientSession::AdminFn admin_ = [](const std::string&, AdminRequestMsg, std::function<void(AdminResultMsg)>) {};
  ServerCounters counters_;
  ClientSession::Context context_{welcome_, admitter_, admin_, counters_,
                                  [this](std::uint64_t id) {
                                    table_.remove(id);
                                    forgotten_.fetch_add(1);
                                  }};
  std::shared_ptr<NullReplica> replica_ = std::make_shared<NullReplica>();
  std::vector<std::weak_ptr<Session>> opened_;
  std::atomic<std::size_t> forgotten_{0};
};

TEST_F(SessionTableTest, RefusesASessionPastTheCapUntilOneIsRemoved) {
  std::unique_ptr<RawPeer> peers[5];
  std::shared_ptr<ClientSession> clients[5];
  std::uint64_t ids[5] = {};
  for (int i = 0; i < 4; ++i) clients[i] = connect(peers[i], ids[i]);
  EXPECT_EQ(ids[0], 1u);
  EXPECT_EQ(ids[3], 4u);
  EXPECT_TRUE(table_.add(ids[0], clients[0]));
  EXPECT_TRUE(table_.add(ids[1], clients[1]));
  EXPECT_TRUE(table_.add(ids[2], clients[2]));
  EXPECT_FALSE(table_.add(ids[3], clients[3])) << "a fourth past a cap of three";
  EXPECT_EQ(table_.size(), 4u) << "the refused one counts until it is removed";
  table_.remove(ids[3]);
  table_.remove(999);  // not in the table: nothing changes
  EXPECT_EQ(table_.size(), 3u);
  EXPECT_FALSE(table_.add(ids[3], clients[3]));
  table_.remove(ids[3]);
  table_.remove(ids[0]);
  clients[4] = connect(peers[4], ids[4]);
  EXPECT_TRUE(table_.add(ids[4], clients[4])) << "room again once one left";
  EXPECT_EQ(table_.size(), 3u);
  EXPECT_EQ(table_.live().size(), 3u);
}

TEST_F(SessionTableTest, IdsAreUniqueAndRemovalsFromSeveralThreadsAllCount) {
  SessionTable big(1000);
  constexpr int kThreads = 4, kEach = 10;
  std::vector<std::unique_ptr<RawPeer>> peers(kThreads * kEach);
  std::vector<std::uint64_t> ids(peers.size());
  std::vector<std::shared_ptr<ClientSession>> clients;
  for (std::size_t i = 0; i < peers.size(); ++i) {
    clients.push_back(connect(peers[i], ids[i]));
    ASSERT_TRUE(big.add(ids[i], clients.back()));
  }
  ASSERT_EQ(big.size(), peers.size());
  // Ids handed out on several threads at once never repeat.
  std::vector<std::vector<std::uint64_t>> taken(kThreads);
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t)
    threads.emplace_back([&, t] {
      for (int i = 0; i < 1000; ++i) taken[t].push_back(big.next_id());
      // Each thread removes its share, and one id twice (a second removal
      // of the same session changes nothing).
      for (int i = 0; i < kEach; ++i) big.remove(ids[static_cast<std::size_t>(t * kEach + i)]);
      big.remove(ids[static_cast<std::size_t>(t * kEach)]);
      (void)big.size();
    });
  for (auto& th : threads) th.join();
  std::set<std::uint64_t> unique;
  for (const auto& v : taken) unique.insert(v.begin(), v.end());
  EXPECT_EQ(unique.size(), static_cast<std::size_t>(kThreads * 1000));
  EXPECT_EQ(big.size(), 0u);
  EXPECT_TRUE(big.live().empty());
}

TEST_F(SessionTableTest, WalksWelcomedClientsOnlyAndClosesEveryLiveSession) {
  run_io();
  std::unique_ptr<RawPeer> named, silent;
  std::uint64_t named_id = 0, silent_id = 0;
  auto a = connect(named, named_id);
  auto b = connect(silent, silent_id);
  ASSERT_TRUE(table_.add(named_id, a));
  ASSERT_TRUE(table_.add(silent_id, b));
  ASSERT_TRUE(named->send(build_hello(HelloMsg{kProtocolVersion, "alice", "token", {}})));
  ASSERT_TRUE(named->next_of(wire::Body::Welcome).has_value());
  auto walked = [&] {
    std::vector<std::pair<std::uint64_t, std::string>> out;
    table_.for_each_welcomed([&](std::uint64_t id, Session&, const ClientSession::Info& info) {
      out.emplace_back(id, info.name);
    });
    return out;
  };
  ASSERT_TRUE(eventually([&] { return !walked().empty(); }));
  EXPECT_EQ(walked(), (std::vector<std::pair<std::uint64_t, std::string>>{{named_id, "alice"}}))
      << "the client that has not said hello is not walked";
  EXPECT_EQ(table_.live().size(), 2u);

  table_.close_all(CloseReason::kShutdown, "server shutting down");
  EXPECT_EQ(disconnect_text(*named), "server shutting down");
  EXPECT_EQ(disconnect_text(*silent), "server shutting down");
  named->close();
  silent->close();
  // Each leaves the table as its socket closes (the sessions' forget).
  EXPECT_TRUE(eventually([&] { return table_.size() == 0; }));
}

// Two sessions of one player whose joins are handled out of order (the
// earlier join's thread reaches the table last): both calls pick the
// earlier join as the loser, so exactly one session of the name is left.
TEST_F(SessionTableTest, OfTwoJoinsOfOnePlayerTheLaterWinsWhicheverIsHandledFirst) {
  run_io();
  std::unique_ptr<RawPeer> first, second, other;
  std::uint64_t first_id = 0, second_id = 0, other_id = 0;
  auto a = connect(first, first_id);
  auto b = connect(second, second_id);
  auto c = connect(other, other_id);
  ASSERT_TRUE(table_.add(first_id, a));
  ASSERT_TRUE(table_.add(second_id, b));
  ASSERT_TRUE(table_.add(other_id, c));
  for (auto* p : {first.get(), second.get()}) {
    ASSERT_TRUE(p->send(build_hello(HelloMsg{kProtocolVersion, "alice", "token", {}})));
    ASSERT_TRUE(p->next_of(wire::Body::Welcome).has_value());
  }
  ASSERT_TRUE(other->send(build_hello(HelloMsg{kProtocolVersion, "bob", "token", {}})));
  ASSERT_TRUE(other->next_of(wire::Body::Welcome).has_value());
  ASSERT_TRUE(eventually([&] { return b->info().welcomed && c->info().welcomed; }));
  const std::uint64_t first_join = a->info().join_order, second_join = b->info().join_order;
  ASSERT_LT(first_join, second_join) << "join orders follow the Welcomes";

  // The later join is handled first: it ends the earlier session.
  const SessionTable::Replacement later = table_.replace_earlier_joins(second_id, "alice", second_join,
                                                                      CloseReason::kReplaced, "replaced");
  EXPECT_EQ(later.ended, std::vector<std::uint64_t>{first_id});
  EXPECT_FALSE(later.newer.has_value());
  // The earlier join, handled last, ends nobody and is told it lost.
  const SessionTable::Replacement earlier = table_.replace_earlier_joins(first_id, "alice", first_join,
                                                                        CloseReason::kReplaced, "replaced");
  EXPECT_TRUE(earlier.ended.empty());
  ASSERT_TRUE(earlier.newer.has_value());
  EXPECT_EQ(*earlier.newer, second_id);
  EXPECT_EQ(disconnect_text(*first), "replaced");
  // Another player's join ends no session of alice's.
  const SessionTable::Replacement bobs = table_.replace_earlier_joins(other_id, "bob", c->info().join_order,
                                                                     CloseReason::kReplaced, "replaced");
  EXPECT_TRUE(bobs.ended.empty());
  EXPECT_FALSE(bobs.newer.has_value());
}

}  // namespace
}  // namespace terrane
