// Operators' commands against the real server over 127.0.0.1: only admins
// may run them; kick ends only that session; a ban and the whitelist
// refuse with a clear reason and survive a restart; say reaches every
// client; save and backup keep what was acknowledged; shutdown warns, then
// stops.
#include "server/ops/admin.h"

#include <gtest/gtest.h>
#include <sys/resource.h>

#include <filesystem>
#include <future>
#include <mutex>
#include <thread>

#include "common/world/world.h"
#include "tests/support/eventually.h"
#include "tests/support/server_fixture.h"

namespace terrane {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using testing_support::msg;
using testing_support::RawPeer;
using testing_support::ServerTest;

constexpr const char* kAdminToken = "admin-secret-1";

class AdminTest : public ServerTest {
 protected:
  void start_admin(ServerOptions o = {}) {
    o.ops.admin_token = kAdminToken;
    start(o);
  }
  // A session that sent Hello: its Welcome, or the Disconnect reason.
  struct Joined {
    std::unique_ptr<RawPeer> peer;
    bool welcomed = false;
    std::string refused;
  };
  Joined connect(const std::string& name, const std::string& token = "") {
    Joined j;
    j.peer = std::make_unique<RawPeer>(server_->port());
    EXPECT_TRUE(j.peer->send(build_hello(HelloMsg{kProtocolVersion, name, token, {}})));
    while (auto f = j.peer->next()) {
      const wire::Message& m = msg(*f);
      if (m.body_type() == wire::Body::Welcome) {
        j.welcomed = true;
        break;
      }
      if (m.body_type() == wire::Body::Disconnect) {
        j.refused = *parse_disconnect(*m.body_as_Disconnect());
        break;
      }
    }
    return j;
  }
  AdminResultMsg command(RawPeer& admin, const std::string& cmd, std::vector<std::string> args = {}) {
    const std::uint32_t id = ++next_id_;
    EXPECT_TRUE(admin.send(build_admin_request(AdminRequestMsg{id, cmd, std::move(args)})));
    auto f = admin.next_of(wire::Body::AdminResult);
    EXPECT_TRUE(f.has_value()) << cmd;
    if (!f) return {};
    auto r = parse_admin_result(*msg(*f).body_as_AdminResult());
    EXPECT_TRUE(r.ok());
    EXPECT_EQ(r->request_id, id);
    return *r;
  }
  // Reads until the Disconnect: its reason ("" if the stream ended without one).
  static std::string disconnect_reason(RawPeer& p) {
    while (auto f = p.next()) {
      const wire::Message& m = msg(*f);
      if (m.body_type() == wire::Body::Disconnect) return *parse_disconnect(*m.body_as_Disconnect());
    }
    return "";
  }
  std::uint32_t next_id_ = 0;
};

TEST_F(AdminTest, OnlyAdminsMayRunCommands) {
  start_admin();
  auto player = connect("player");
  ASSERT_TRUE(player.welcomed);
  const AdminResultMsg r = command(*player.peer, "status");
  EXPECT_FALSE(r.ok);
  EXPECT_NE(r.text.find("not an admin"), std::string::npos) << r.text;
  // Scripts read the same refusal from json, as every ok: false (PROTOCOL.md).
  EXPECT_EQ(r.json, "{\"error\": \"not an admin: this session's token does not have the admin role\"}");
  // A wrong admin token is refused outright, not let in as a player.
  auto wrong = connect("admin", "not-the-token");
  EXPECT_FALSE(wrong.welcomed);
  EXPECT_EQ(wrong.refused, "authentication failed");
  auto admin = connect("admin", kAdminToken);
  ASSERT_TRUE(admin.welcomed);
  const AdminResultMsg s = command(*admin.peer, "status");
  EXPECT_TRUE(s.ok) << s.text;
  // The player and this admin: operators' sessions are not players.
  EXPECT_NE(s.json.find("\"clients\": 1, \"admin_sessions\": 1"), std::string::npos) << s.json;
  EXPECT_NE(s.text.find("1 players, 1 admin sessions"), std::string::npos) << s.text;
  const AdminResultMsg u = command(*admin.peer, "frobnicate");
  EXPECT_FALSE(u.ok);
  EXPECT_NE(u.text.find("unknown command 'frobnicate'"), std::string::npos) << u.text;
}

// A session that never sends ClientState (terrane-admin) has no plan and no
// hashes to push: its replicator must not wake for them (it once spun an io
// thread flat out one second after the Welcome).
TEST_F(AdminTest, ASessionWithoutAViewCostsNoCpu) {
  start_admin();
  auto admin = connect("admin", kAdminToken);
  ASSERT_TRUE(admin.welcomed);
  const ServerCounters& c = server_->counters();
  auto wait_ticks = [&](std::uint64_t n) {
    const std::uint64_t target = c.ticks.load() + n;
    ASSERT_TRUE(testing_support::eventually([&] { return c.ticks.load() >= target; }));
  };
  auto cpu_s = [] {
    rusage u{};
    getrusage(RUSAGE_SELF, &u);
    return static_cast<double>(u.ru_utime.tv_sec + u.ru_stime.tv_sec) +
           static_cast<double>(u.ru_utime.tv_usec + u.ru_stime.tv_usec) * 1e-6;
  };
  wait_ticks(30);  // past the first hash-push deadline (1 s)
  const double cpu0 = cpu_s();
  const auto t0 = std::chrono::steady_clock::now();
  wait_ticks(40);  // two seconds of the server's own clock
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  // An idle server with one session uses a few percent of a core; a spinning
  // thread uses most of one.
  EXPECT_LT(cpu_s() - cpu0, 0.5 * wall) << "CPU " << cpu_s() - cpu0 << " s over " << wall << " s";
  EXPECT_TRUE(command(*admin.peer, "status").ok);
}

TEST_F(AdminTest, TokensFileRolesMakeAdmins) {
  ServerOptions o;
  o.ops.player_tokens = {{"op", {"op-token", true}}, {"pat", {"pat-token", false}}};
  start(o);
  auto op = connect("op", "op-token");
  auto pat = connect("pat", "pat-token");
  ASSERT_TRUE(op.welcomed && pat.welcomed);
  EXPECT_TRUE(command(*op.peer, "status").ok);
  EXPECT_FALSE(command(*pat.peer, "status").ok);
}

TEST_F(AdminTest, PlayersListsWhoIsConnectedAndKickEndsOnlyThatSession) {
  start_admin();
  auto admin = connect("admin", kAdminToken);
  auto griefer = connect("griefer");
  auto builder = connect("builder");
  ASSERT_TRUE(admin.welcomed && griefer.welcomed && builder.welcomed);
  ASSERT_TRUE(builder.peer->send(build_client_state(ClientStateMsg{{40.5f, 30.0f, -12.5f}, 32, 16})));
  // The position shows once the server has read it.
  AdminResultMsg players;
  testing_support::eventually([&] {
    players = command(*admin.peer, "players");
    return players.json.find("[40.5, 30, -12.5]") != std::string::npos;
  });
  EXPECT_TRUE(players.ok);
  EXPECT_NE(players.json.find("\"name\": \"builder\""), std::string::npos) << players.json;
  EXPECT_NE(players.json.find("[40.5, 30, -12.5]"), std::string::npos) << players.json;
  EXPECT_NE(players.json.find("\"address\": \"127.0.0.1\""), std::string::npos) << players.json;
  EXPECT_NE(players.text.find("3 connected"), std::string::npos) << players.text;
  // The server pings every client; once the builder answers, its round trip shows.
  EXPECT_NE(players.json.find("\"ping_ms\": null"), std::string::npos) << players.json;
  auto ping = builder.peer->next_of(wire::Body::Ping);
  ASSERT_TRUE(ping.has_value());
  ASSERT_TRUE(builder.peer->send(build_pong(msg(*ping).body_as_Ping()->nonce())));
  testing_support::eventually([&] {
    players = command(*admin.peer, "players");
    return players.text.find("ms ") != std::string::npos;
  });
  EXPECT_NE(players.text.find("ms "), std::string::npos) << players.text;
  EXPECT_NE(players.json.find("\"ping_ms\": null"), std::string::npos) << "the others have not answered: " << players.json;
  // A forged Pong (a nonce from the future) changes nothing.
  ASSERT_TRUE(griefer.peer->send(build_pong(~0ull)));

  const AdminResultMsg k = command(*admin.peer, "kick", {"griefer", "stop", "that"});
  EXPECT_TRUE(k.ok) << k.text;
  EXPECT_EQ(disconnect_reason(*griefer.peer), "kicked by an operator: stop that");
  // The others stay: both still answer.
  EXPECT_TRUE(command(*admin.peer, "status").ok);
  ASSERT_TRUE(builder.peer->send(build_ping(7)));
  EXPECT_TRUE(builder.peer->next_of(wire::Body::Pong).has_value());
  EXPECT_FALSE(command(*admin.peer, "kick", {"nobody"}).ok);
  // A kicked player may come back.
  EXPECT_TRUE(connect("griefer").welcomed);
}

TEST_F(AdminTest, ABanRefusesWithItsReasonSurvivesARestartAndUnbanLiftsIt) {
  start_admin();
  {
    auto admin = connect("admin", kAdminToken);
    auto griefer = connect("griefer");
    ASSERT_TRUE(admin.welcomed && griefer.welcomed);
    const AdminResultMsg b = command(*admin.peer, "ban", {"griefer", "tunnelling", "under", "spawn"});
    EXPECT_TRUE(b.ok) << b.text;
    EXPECT_NE(b.text.find("1 session ended"), std::string::npos) << b.text;
    EXPECT_EQ(disconnect_reason(*griefer.peer), "banned: tunnelling under spawn");
    const AdminResultMsg timed = command(*admin.peer, "ban", {"visitor", "--for", "2h"});
    EXPECT_TRUE(timed.ok) << timed.text;
    EXPECT_FALSE(command(*admin.peer, "ban", {"x", "--for", "soon"}).ok);
  }
  server_->stop();
  server_.reset();
  start_admin();
  auto again = connect("griefer");
  EXPECT_FALSE(again.welcomed);
  EXPECT_EQ(again.refused, "banned: tunnelling under spawn");
  auto visitor = connect("visitor");
  EXPECT_FALSE(visitor.welcomed);
  EXPECT_NE(visitor.refused.find("banned for "), std::string::npos) << visitor.refused;
  auto admin = connect("admin", kAdminToken);
  ASSERT_TRUE(admin.welcomed);
  const AdminResultMsg bans = command(*admin.peer, "bans");
  EXPECT_NE(bans.text.find("2 bans"), std::string::npos) << bans.text;
  EXPECT_TRUE(command(*admin.peer, "unban", {"griefer"}).ok);
  EXPECT_FALSE(command(*admin.peer, "unban", {"griefer"}).ok);  // not banned any more
  EXPECT_TRUE(connect("griefer").welcomed);
  // An address ban refuses every name from it (admins still come in).
  EXPECT_TRUE(command(*admin.peer, "ban", {"127.0.0.1"}).ok);
  EXPECT_EQ(connect("anyone").refused, "banned");
  EXPECT_TRUE(connect("admin2", kAdminToken).welcomed);
}

TEST_F(AdminTest, ANetworkBanRefusesEveryAddressInItAndEndsTheirSessions) {
  start_admin();
  auto admin = connect("admin", kAdminToken);
  auto player = connect("player");
  ASSERT_TRUE(admin.welcomed && player.welcomed);
  // A network outside ours bans nobody here; it is an address ban, not a name.
  const AdminResultMsg far = command(*admin.peer, "ban", {"10.0.0.0/8"});
  ASSERT_TRUE(far.ok) << far.text;
  EXPECT_NE(far.text.find("banned network 10.0.0.0/8"), std::string::npos) << far.text;
  EXPECT_NE(far.text.find("0 sessions ended"), std::string::npos) << far.text;
  auto named = connect("10.0.0.0/8");  // kept open: the next ban ends it too
  EXPECT_TRUE(named.welcomed) << "the network is not a player's name";
  // Host bits are cleared: 127.1.2.3/8 is 127.0.0.0/8, which holds us.
  const AdminResultMsg ours = command(*admin.peer, "ban", {"127.1.2.3/8", "whole", "subnet"});
  ASSERT_TRUE(ours.ok) << ours.text;
  EXPECT_NE(ours.text.find("banned network 127.0.0.0/8"), std::string::npos) << ours.text;
  EXPECT_NE(ours.text.find("2 sessions ended"), std::string::npos) << ours.text;
  EXPECT_EQ(disconnect_reason(*player.peer), "banned: whole subnet");
  EXPECT_EQ(disconnect_reason(*named.peer), "banned: whole subnet");
  EXPECT_EQ(connect("anyone").refused, "banned: whole subnet");
  EXPECT_TRUE(connect("admin2", kAdminToken).welcomed) << "admins still come in";
  EXPECT_FALSE(command(*admin.peer, "ban", {"127.0.0.0/33"}).ok) << "a prefix longer than the address";
  EXPECT_TRUE(command(*admin.peer, "unban", {"127.9.9.9/8"}).ok) << "unban names the network the same way";
  EXPECT_TRUE(connect("anyone").welcomed);
}

TEST_F(AdminTest, TheWhitelistRefusesWhoIsNotListedAndIsKeptAcrossRestarts) {
  start_admin();
  {
    auto admin = connect("admin", kAdminToken);
    ASSERT_TRUE(admin.welcomed);
    EXPECT_TRUE(command(*admin.peer, "whitelist", {"add", "alice"}).ok);
    EXPECT_TRUE(command(*admin.peer, "whitelist", {"on"}).ok);
    const AdminResultMsg list = command(*admin.peer, "whitelist", {"list"});
    EXPECT_NE(list.json.find("\"names\": [\"alice\"]"), std::string::npos) << list.json;
  }
  server_->stop();
  server_.reset();
  start_admin();
  auto bob = connect("bob");
  EXPECT_FALSE(bob.welcomed);
  EXPECT_NE(bob.refused.find("not on the whitelist"), std::string::npos) << bob.refused;
  EXPECT_TRUE(connect("alice").welcomed);
  auto admin = connect("admin", kAdminToken);
  ASSERT_TRUE(admin.welcomed);
  EXPECT_TRUE(command(*admin.peer, "whitelist", {"off"}).ok);
  EXPECT_TRUE(connect("bob").welcomed);
}

// status tells the edit log's size as the storage writer keeps it (the
// admin thread never touches the store for it): it grows with each edit
// stored, and a restart counts it again from the world.
TEST_F(AdminTest, StatusShowsTheEditLogGrowingWithEdits) {
  start_admin();
  auto admin = connect("admin", kAdminToken);
  ASSERT_TRUE(admin.welcomed);
  AdminResultMsg s;
  const auto status_until = [&](const std::string& json_part) {
    return testing_support::eventually([&] {
      s = command(*admin.peer, "status");
      return s.json.find(json_part) != std::string::npos;
    });
  };
  ASSERT_TRUE(status_until("\"edit_log_entries\": 0, \"edit_log_bytes\": 0")) << s.json;
  EXPECT_NE(s.text.find("edit log 0 entries, 0.00 MiB"), std::string::npos) << s.text;

  auto p = join("editor");
  const Vec3i cp = chunk_of(Vec3i{1002, 12, 1002});
  ASSERT_TRUE(hold_full(*p, {1002.0f, 12.0f, 1002.0f}, cp));
  for (std::uint32_t id = 1; id <= 3; ++id) {
    const EditRequestMsg e = testing_support::fill_box_edit(id, Region{{1001, 11, 1001}, {1003, 13, 1003}},
                                                            materials::kBrick, static_cast<std::uint8_t>(100 + id));
    ASSERT_TRUE(p->send(build_edit_request(e)));
    ASSERT_TRUE(p->next_of(wire::Body::EditAck));
    ASSERT_TRUE(status_until("\"edit_log_entries\": " + std::to_string(id) + ",")) << s.json;
    EXPECT_NE(s.text.find("edit log " + std::to_string(id) + " entries, "), std::string::npos) << s.text;
  }
  // Each entry holds the box's voxels before and after.
  const auto bytes_at = s.json.find("\"edit_log_bytes\": ");
  ASSERT_NE(bytes_at, std::string::npos) << s.json;
  const std::uint64_t bytes = std::stoull(s.json.substr(bytes_at + 18));
  EXPECT_GT(bytes, 0u) << s.json;
  p->close();
  admin.peer->close();

  server_->stop();
  server_.reset();
  start_admin();
  auto again = connect("admin", kAdminToken);
  ASSERT_TRUE(again.welcomed);
  admin.peer = std::move(again.peer);
  ASSERT_TRUE(status_until("\"edit_log_entries\": 3, \"edit_log_bytes\": " + std::to_string(bytes) + ","))
      << s.json;
}

TEST_F(AdminTest, SayReachesEveryClient) {
  start_admin();
  auto admin = connect("admin", kAdminToken);
  auto a = connect("a");
  auto b = connect("b");
  ASSERT_TRUE(admin.welcomed && a.welcomed && b.welcomed);
  EXPECT_TRUE(command(*admin.peer, "say", {"restart", "at", "noon"}).ok);
  for (RawPeer* p : {a.peer.get(), b.peer.get()}) {
    auto f = p->next_of(wire::Body::ServerNotice);
    ASSERT_TRUE(f.has_value());
    auto n = parse_server_notice(*msg(*f).body_as_ServerNotice());
    ASSERT_TRUE(n.ok());
    EXPECT_EQ(n->kind, wire::NoticeKind::Say);
    EXPECT_EQ(n->text, "restart at noon");
  }
}

TEST_F(AdminTest, SaveAndBackupKeepWhatWasAcknowledged) {
  start_admin();
  auto admin = connect("admin", kAdminToken);
  auto p = join("editor");
  const Vec3i cp = chunk_of(Vec3i{1002, 12, 1002});
  ASSERT_TRUE(hold_full(*p, {1002.0f, 12.0f, 1002.0f}, cp));
  const EditRequestMsg e = testing_support::fill_box_edit(1, Region{{1001, 11, 1001}, {1003, 13, 1003}}, materials::kBrick, 201);
  ASSERT_TRUE(p->send(build_edit_request(e)));
  ASSERT_TRUE(p->next_of(wire::Body::EditAck));
  const AdminResultMsg save = command(*admin.peer, "save");
  EXPECT_TRUE(save.ok) << save.text;
  EXPECT_NE(save.json.find("saved_through_tick"), std::string::npos) << save.json;
  const fs::path copy = dir_ / "backup";
  const AdminResultMsg backup = command(*admin.peer, "backup", {copy.string()});
  ASSERT_TRUE(backup.ok) << backup.text;
  auto world = World::open(copy.string());
  ASSERT_TRUE(world.ok()) << world.error().message;
  auto stored = (*world)->load_chunk(cp);
  ASSERT_TRUE(stored.ok());
  EXPECT_EQ(stored->chunk.get(local_of(Vec3i{1002, 12, 1002})), make_voxel(materials::kBrick, 201));
  // A second backup into the same place is refused, naming it.
  const AdminResultMsg twice = command(*admin.peer, "backup", {copy.string()});
  EXPECT_FALSE(twice.ok);
  EXPECT_NE(twice.text.find(copy.string()), std::string::npos) << twice.text;
}

TEST_F(AdminTest, ShutdownWarnsEveryClientThenAsksTheOwnerToStop) {
  std::promise<void> asked;
  std::once_flag once;
  ServerOptions o;
  o.ops.on_shutdown = [&](bool) { std::call_once(once, [&] { asked.set_value(); }); };
  start_admin(o);
  auto admin = connect("admin", kAdminToken);
  auto player = connect("player");
  ASSERT_TRUE(admin.welcomed && player.welcomed);
  const AdminResultMsg r = command(*admin.peer, "shutdown", {"--in", "1", "--restart", "--reason", "upgrade"});
  EXPECT_TRUE(r.ok) << r.text;
  auto f = player.peer->next_of(wire::Body::ServerNotice);
  ASSERT_TRUE(f.has_value());
  auto n = parse_server_notice(*msg(*f).body_as_ServerNotice());
  ASSERT_TRUE(n.ok());
  EXPECT_EQ(n->kind, wire::NoticeKind::Shutdown);
  EXPECT_EQ(n->seconds_left, 1u);
  EXPECT_TRUE(n->reconnect);
  EXPECT_NE(n->text.find("upgrade"), std::string::npos) << n->text;
  EXPECT_EQ(asked.get_future().wait_for(60s), std::future_status::ready);
  // The owner stops it: the last notice says it restarts, then the Disconnect.
  server_->stop();
  auto last = player.peer->next_of(wire::Body::ServerNotice);
  ASSERT_TRUE(last.has_value());
  EXPECT_TRUE(parse_server_notice(*msg(*last).body_as_ServerNotice())->reconnect);
  EXPECT_EQ(disconnect_reason(*player.peer), "server shutting down");
}

TEST(AdminDuration, TakesSecondsMinutesHoursAndDays) {
  EXPECT_EQ(parse_duration_s("90"), 90);
  EXPECT_EQ(parse_duration_s("90s"), 90);
  EXPECT_EQ(parse_duration_s("15m"), 900);
  EXPECT_EQ(parse_duration_s("2h"), 7200);
  EXPECT_EQ(parse_duration_s("7d"), 604800);
  EXPECT_EQ(parse_duration_s(""), std::nullopt);
  EXPECT_EQ(parse_duration_s("0"), std::nullopt);
  EXPECT_EQ(parse_duration_s("-5m"), std::nullopt);
  EXPECT_EQ(parse_duration_s("5w"), std::nullopt);
  EXPECT_EQ(parse_duration_s("9999999999d"), std::nullopt);
}

}  // namespace
}  // namespace terrane
