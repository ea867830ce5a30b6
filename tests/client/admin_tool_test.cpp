// terrane-admin against a real terrane-server process: commands, their exit
// statuses and JSON; notices reach the client library; a shutdown with
// --restart brings the library back by itself once the server is back, and
// one without it does not.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <string>

#include <map>
#include <random>

#include "tests/support/json_doc.h"
#include "tests/support/run_command.h"
#include "client/client.h"
#include "tests/support/view_chunks.h"
#include "tests/support/server_process.h"

namespace terrane {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using testing_support::ServerProcess;

constexpr auto kDeadline = 120s;
constexpr const char* kToken = "operator-token-1";


class AdminToolTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("terrane-admin-" + std::to_string(::getpid()) + "-" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
  }
  void TearDown() override {
    if (server_) {
      EXPECT_EQ(server_->stop(), 0);
      if (HasFailure()) std::fprintf(stderr, "--- server output ---\n%s", server_->output().c_str());
    }
    fs::remove_all(dir_);
  }
  void start_server(std::uint16_t port = 0, std::vector<std::string> extra = {}) {
    std::vector<std::string> args{"--admin-token", kToken, "--port", std::to_string(port)};
    args.insert(args.end(), extra.begin(), extra.end());
    server_ = std::make_unique<ServerProcess>(dir_.string(), args);
    ASSERT_NE(server_->port(), 0) << server_->output();
  }
  int admin(const std::string& args, std::string* out, const std::string& token = kToken) {
    return testing_support::run_command(std::string(TERRANE_BIN_DIR) + "/terrane-admin --connect 127.0.0.1:" + std::to_string(server_->port()) +
                   " --token '" + token + "' " + args,
               out);
  }
  // terrane-admin --json ARGS: its exit status; stdout must be exactly one
  // JSON document (parsed into *doc), whatever the command or its outcome.
  int admin_json(const std::string& args, testing_support::JsonDoc* doc, const std::string& token = kToken) {
    std::string out, err;
    const int status = testing_support::run_command_split(
        std::string(TERRANE_BIN_DIR) + "/terrane-admin --json --connect 127.0.0.1:" +
            std::to_string(server_->port()) + " --token '" + token + "' " + args,
        &out, &err);
    std::string why;
    auto parsed = testing_support::parse_json(out, &why);
    EXPECT_TRUE(parsed.has_value()) << "terrane-admin --json " << args << ": stdout is not one JSON document (" << why
                                    << "):\n" << out << "\nstderr:\n" << err;
    if (status != 0 && parsed) {
      EXPECT_EQ((*parsed)["error"].kind, testing_support::JsonDoc::Kind::kString) << out;
    }
    *doc = parsed ? std::move(*parsed) : testing_support::JsonDoc{};
    return status;
  }
  ClientOptions player(const std::string& name) const {
    ClientOptions o;
    o.port = server_->port();
    o.name = name;
    o.state.view_distance = 32;
    o.state.full_res_radius = 16;
    return o;
  }

  fs::path dir_;
  std::unique_ptr<ServerProcess> server_;
};


// Whether some line starts "[YYYY-MM-DD HH:MM:SS.mmm +HH:MM] [server]": a
// log line with its offset from UTC (the sign may be + or -).
bool has_zoned_server_line(const std::string& out) {
  const std::string shape = "[dddd-dd-dd dd:dd:dd.ddd Sdd:dd] [server]";
  std::size_t at = 0;
  while (at < out.size()) {
    const std::size_t end = std::min(out.find('\n', at), out.size());
    if (end - at >= shape.size()) {
      bool ok = true;
      for (std::size_t i = 0; i < shape.size() && ok; ++i) {
        const char c = out[at + i];
        if (shape[i] == 'd') ok = c >= '0' && c <= '9';
        else if (shape[i] == 'S') ok = c == '+' || c == '-';
        else ok = c == shape[i];
      }
      if (ok) return true;
    }
    at = end + 1;
  }
  return false;
}

TEST_F(AdminToolTest, CommandsAnswerInTextOrJsonAndSayReachesTheLibrary) {
  start_server();
  Client listener(player("listener"));
  std::string err;
  ASSERT_TRUE(listener.connect(&err)) << err;
  ASSERT_TRUE(listener.wait_until([](const ClientView& v) { return v.welcomed || v.closed; }, kDeadline));

  testing_support::JsonDoc status;
  ASSERT_EQ(admin_json("status", &status), 0);
  // The listener is a player; the tool is an admin session, not a player.
  EXPECT_EQ(status["clients"].number, 1);
  EXPECT_EQ(status["admin_sessions"].number, 1);
  std::string out;
  ASSERT_EQ(admin("players", &out), 0) << out;
  EXPECT_NE(out.find("listener"), std::string::npos) << out;
  out.clear();
  ASSERT_EQ(admin("say hello from the operators", &out), 0) << out;
  ASSERT_TRUE(listener.wait_until([](const ClientView& v) { return !v.notices.empty() || v.closed; }, kDeadline));
  const auto notices = listener.notices();
  ASSERT_EQ(notices.size(), 1u);
  EXPECT_EQ(notices[0].kind, wire::NoticeKind::Say);
  EXPECT_EQ(notices[0].text, "hello from the operators");

  out.clear();
  EXPECT_EQ(admin("kick nobody", &out), 1) << out;
  EXPECT_NE(out.find("no player named 'nobody'"), std::string::npos) << out;
  out.clear();
  EXPECT_EQ(admin("status", &out, "wrong-token"), 1) << out;
  EXPECT_NE(out.find("authentication failed"), std::string::npos) << out;
  out.clear();
  EXPECT_EQ(admin("", &out), 2) << out;
  EXPECT_NE(out.find("no command given"), std::string::npos) << out;
  out.clear();
  EXPECT_EQ(testing_support::run_command(std::string(TERRANE_BIN_DIR) + "/terrane-admin --token x status", &out), 2) << out;
  EXPECT_NE(out.find("--connect HOST:PORT is required"), std::string::npos) << out;
  listener.disconnect();
}

// Every command's --json answer, success or refusal, is one JSON document
// on stdout (the client library's log lines go to stderr); a refusal is an
// object with "error" and a non-zero exit status.
TEST_F(AdminToolTest, JsonOutputIsOneDocumentForEveryCommand) {
  using testing_support::JsonDoc;
  fs::create_directories(dir_);
  const fs::path tokens = dir_.parent_path() / (dir_.filename().string() + ".tokens");
  {
    std::FILE* f = std::fopen(tokens.c_str(), "w");
    ASSERT_NE(f, nullptr);
    std::fputs("alice alice-token-1 player\nlistener listener-token-1 player\n", f);
    std::fclose(f);
  }
  start_server(0, {"--tokens-file", tokens.string()});
  ClientOptions lo = player("listener");
  lo.auth_token = "listener-token-1";
  Client listener(lo);
  std::string err;
  ASSERT_TRUE(listener.connect(&err)) << err;
  ASSERT_TRUE(listener.wait_until([](const ClientView& v) { return v.welcomed || v.closed; }, kDeadline));

  JsonDoc d;
  EXPECT_EQ(admin_json("status", &d), 0);
  EXPECT_EQ(d["clients"].number, 1);
  EXPECT_FALSE(d["version"].string.empty());
  EXPECT_EQ(d["address"].string, "127.0.0.1:" + std::to_string(server_->port()));
  EXPECT_EQ(d["border"].string, "no border");
  EXPECT_EQ(d["world"].string, dir_.string());
  EXPECT_EQ(d["shutdown_in_s"].kind, JsonDoc::Kind::kNull);
  EXPECT_EQ(admin_json("shutdown --in 10m", &d), 0);
  EXPECT_EQ(admin_json("status", &d), 0);
  EXPECT_GT(d["shutdown_in_s"].number, 590);
  EXPECT_EQ(admin_json("shutdown --cancel", &d), 0);
  EXPECT_TRUE(d["cancelled"].boolean);
  EXPECT_EQ(admin_json("cancel-shutdown", &d), 1);
  EXPECT_EQ(admin_json("help", &d), 0);
  EXPECT_EQ(d["help"].kind, JsonDoc::Kind::kString);
  EXPECT_EQ(admin_json("players", &d), 0);
  ASSERT_EQ(d["players"].array.size(), 2u);
  EXPECT_EQ(admin_json("say hello", &d), 0);
  EXPECT_EQ(d["said"].string, "hello");
  EXPECT_EQ(admin_json("kick nobody", &d), 1);
  EXPECT_NE(d["error"].string.find("no player named 'nobody'"), std::string::npos);
  EXPECT_EQ(admin_json("ban griefer --for 1h being rude", &d), 0);
  EXPECT_EQ(d["banned"].string, "griefer");
  EXPECT_EQ(admin_json("bans", &d), 0);
  EXPECT_EQ(d["bans"].array.size(), 1u);
  EXPECT_EQ(admin_json("unban griefer", &d), 0);
  EXPECT_EQ(admin_json("unban griefer", &d), 1);
  EXPECT_EQ(admin_json("whitelist add alice", &d), 0);
  EXPECT_EQ(admin_json("whitelist on", &d), 0);
  EXPECT_EQ(admin_json("whitelist list", &d), 0);
  EXPECT_TRUE(d["on"].boolean);
  EXPECT_EQ(admin_json("whitelist remove alice", &d), 0);
  EXPECT_EQ(admin_json("whitelist off", &d), 0);
  EXPECT_EQ(admin_json("whitelist bogus", &d), 1);
  EXPECT_EQ(admin_json("log --limit 5", &d), 0);
  EXPECT_EQ(d["edits"].kind, JsonDoc::Kind::kArray);
  EXPECT_EQ(admin_json("rollback", &d), 1);
  EXPECT_EQ(admin_json("save", &d), 0);
  EXPECT_EQ(d["saved_through_tick"].kind, JsonDoc::Kind::kNumber);
  const fs::path backup = dir_.parent_path() / (dir_.filename().string() + ".backup");
  fs::remove_all(backup);
  EXPECT_EQ(admin_json("backup " + backup.string(), &d), 0);
  EXPECT_EQ(d["backup"].string, backup.string());
  fs::remove_all(backup);
  EXPECT_EQ(admin_json("no-such-command", &d), 1);
  // Refused before any command: a player's token, a wrong token, no server.
  EXPECT_EQ(admin_json("--name alice status", &d, "alice-token-1"), 1);
  EXPECT_NE(d["error"].string.find("not an admin"), std::string::npos) << d["error"].string;
  EXPECT_EQ(admin_json("status", &d, "wrong-token"), 1);
  EXPECT_NE(d["error"].string.find("authentication failed"), std::string::npos) << d["error"].string;
  EXPECT_EQ(admin_json("shutdown --in 0", &d), 0);
  EXPECT_EQ(d["seconds"].number, 0);
  EXPECT_EQ(server_->wait_exit(kDeadline), 0) << server_->output();
  EXPECT_EQ(admin_json("status", &d), 1);
  EXPECT_NE(d["error"].string.find("cannot reach"), std::string::npos) << d["error"].string;
  server_.reset();
  fs::remove(tokens);
  listener.disconnect();
}

// SIGHUP reads the tokens file again and the server goes on: a new player
// may join, a removed one may not; a bad file keeps the previous tokens and
// the log names its file and line.
TEST_F(AdminToolTest, SighupReloadsTheTokensFileAndABadOneKeepsThePrevious) {
  fs::create_directories(dir_);
  const fs::path tokens = dir_.parent_path() / (dir_.filename().string() + ".tokens");
  auto write = [&](const std::string& text) {
    std::FILE* f = std::fopen(tokens.c_str(), "w");
    ASSERT_NE(f, nullptr);
    std::fputs(text.c_str(), f);
    std::fclose(f);
  };
  write("alice alice-token-1\nbob bob-token-1\n");
  start_server(0, {"--tokens-file", tokens.string()});
  auto joins = [&](const std::string& name, const std::string& token) {
    ClientOptions o = player(name);
    o.auth_token = token;
    o.stream = false;
    Client c(o);
    std::string err;
    if (!c.connect(&err)) return false;
    c.wait_until([](const ClientView& v) { return v.welcomed || v.closed; }, kDeadline);
    const bool welcomed = c.welcome().has_value();
    c.disconnect();
    return welcomed;
  };
  EXPECT_TRUE(joins("bob", "bob-token-1"));
  EXPECT_FALSE(joins("carol", "carol-token-1"));

  write("alice alice-token-1\ncarol carol-token-1  # joined in May\n");
  ASSERT_TRUE(server_->hangup());
  ASSERT_TRUE(server_->wait_for_output("reload: tokens: +carol -bob", kDeadline)) << server_->output();
  EXPECT_TRUE(joins("carol", "carol-token-1"));
  EXPECT_FALSE(joins("bob", "bob-token-1"));

  write("alice alice-token-1\ncarol carol-token-1 superuser\n");
  ASSERT_TRUE(server_->hangup());
  ASSERT_TRUE(server_->wait_for_output("reload: keeping the previous tokens: " + tokens.string() + ":2:", kDeadline))
      << server_->output();
  EXPECT_TRUE(joins("carol", "carol-token-1"));
  EXPECT_TRUE(joins("alice", "alice-token-1"));
  EXPECT_EQ(server_->stop(), 0);  // SIGHUP did not stop it; SIGTERM does, cleanly
  server_.reset();
  fs::remove(tokens);
}

TEST_F(AdminToolTest, ShutdownWithRestartBringsTheLibraryBackByItself) {
  start_server();
  const std::uint16_t port = server_->port();
  ClientOptions o = player("stayer");
  o.reconnect = true;
  o.reconnect_min = 50ms;
  Client c(o);
  std::string err;
  ASSERT_TRUE(c.connect(&err)) << err;
  ASSERT_TRUE(c.wait_until([](const ClientView& v) { return v.welcomed || v.closed; }, kDeadline));
  std::string out;
  ASSERT_EQ(admin("shutdown --in 0 --restart --reason upgrade", &out), 0) << out;
  // The server stops by itself (terrane-admin asked; nothing signalled it),
  // with exit status 75 so a supervisor restarting on failure (Docker's
  // restart: on-failure) brings it back; a shutdown without --restart
  // exits 0 (below).
  ASSERT_EQ(server_->wait_exit(kDeadline), 75) << server_->output();
  EXPECT_NE(server_->output().find("world saved"), std::string::npos) << server_->output();
  // Its lines carry the time zone (the offset from UTC).
  EXPECT_TRUE(has_zoned_server_line(server_->output())) << server_->output();
  // It says why it stopped: no signal came.
  EXPECT_NE(server_->output().find("shutting down: an operator's shutdown"), std::string::npos) << server_->output();
  EXPECT_EQ(server_->output().find("signal 15"), std::string::npos) << server_->output();
  ASSERT_TRUE(c.wait_until(
      [](const ClientView& v) {
        return v.closed || (!v.notices.empty() && v.notices.back().kind == wire::NoticeKind::Shutdown);
      },
      kDeadline));
  EXPECT_TRUE(c.notices().back().reconnect);
  // Back on the same port: the library reconnects without being asked.
  server_ = std::make_unique<ServerProcess>(
      dir_.string(), std::vector<std::string>{"--admin-token", kToken, "--port", std::to_string(port)});
  ASSERT_EQ(server_->port(), port) << server_->output();
  ASSERT_TRUE(c.wait_until([](const ClientView& v) { return v.counters.reconnects == 1 || v.closed; }, kDeadline));
  EXPECT_FALSE(c.closed()) << c.disconnect_reason();
  c.disconnect();
}

TEST_F(AdminToolTest, ShutdownWithoutRestartEndsTheLibrarysSession) {
  start_server();
  ClientOptions o = player("leaver");
  o.reconnect = true;
  o.reconnect_min = 50ms;
  Client c(o);
  std::string err;
  ASSERT_TRUE(c.connect(&err)) << err;
  ASSERT_TRUE(c.wait_until([](const ClientView& v) { return v.welcomed || v.closed; }, kDeadline));
  std::string out;
  ASSERT_EQ(admin("shutdown", &out), 0) << out;
  ASSERT_TRUE(c.wait_until([](const ClientView& v) { return v.closed; }, kDeadline));
  EXPECT_EQ(c.disconnect_reason(), "server shutting down");
  EXPECT_FALSE(c.notices().back().reconnect);
  EXPECT_EQ(server_->wait_exit(kDeadline), 0) << server_->output();
}

// A griefer's 200 edits among a builder's, some before and some after his:
// the rollback restores exactly the voxels the griefer changed and nobody
// changed since, and a third client's replica agrees with the server's
// chunk hashes afterwards.
TEST_F(AdminToolTest, RollbackRestoresExactlyTheGriefersVoxels) {
  start_server(0, {"--edits-per-second", "1000"});
  auto join = [&](const std::string& name) {
    ClientOptions o = player(name);
    o.state.view_distance = 96;
    o.state.full_res_radius = 48;
    auto c = std::make_unique<Client>(o);
    std::string err;
    EXPECT_TRUE(c->connect(&err)) << err;
    EXPECT_TRUE(c->wait_until([](const ClientView& v) { return v.welcomed || v.closed; }, kDeadline));
    const auto w = c->welcome();
    const auto near = testing_support::chunks_within(w->spawn, 48, *w);
    EXPECT_TRUE(c->wait_until(
        [&](const ClientView& v) {
          for (const Vec3i cp : near) {
            const Holding* cov = v.replica.holding(cp);
            if (cov == nullptr || !cov->full_resolution()) return v.closed;
          }
          return true;
        },
        kDeadline));
    return c;
  };
  auto builder = join("builder");
  auto griefer = join("griefer");
  auto watcher = join("watcher");
  const WelcomeMsg w = *watcher->welcome();
  const Vec3i s{static_cast<int>(w.spawn.x), static_cast<int>(w.spawn.y), static_cast<int>(w.spawn.z)};
  const Region area{s + Vec3i{-8, -6, -8}, s + Vec3i{8, 2, 8}};  // inside everyone's full-resolution region

  // The model: every voxel's writes in order (the test waits for each ack,
  // so the server applies them in this order).
  std::map<std::tuple<int, int, int>, std::vector<std::pair<bool, Voxel>>> writes;  // (griefer?, value)
  std::map<std::tuple<int, int, int>, Voxel> original;
  for (int y = area.min.y; y < area.max.y; ++y)
    for (int z = area.min.z; z < area.max.z; ++z)
      for (int x = area.min.x; x < area.max.x; ++x) original[{x, y, z}] = watcher->get({x, y, z});
  std::mt19937 rng(7);
  auto edit = [&](Client& c, bool grief, Voxel v, int max_side) {
    std::uniform_int_distribution<int> side(1, max_side);
    const Vec3i size{side(rng), side(rng), side(rng)};
    const Vec3i span = area.size() - size;
    const Vec3i min = area.min + Vec3i{std::uniform_int_distribution<int>(0, span.x)(rng),
                                       std::uniform_int_distribution<int>(0, span.y)(rng),
                                       std::uniform_int_distribution<int>(0, span.z)(rng)};
    const Region box{min, min + size};
    const std::uint32_t id = c.fill_box(box, v);
    ASSERT_NE(id, 0u);
    ASSERT_TRUE(c.wait_until([&](const ClientView& view) { return view.edits.count(id) != 0 || view.closed; },
                             kDeadline));
    std::optional<EditOutcome> o;
    c.wait_until([&](const ClientView& view) {
      o = view.edits.at(id);
      return true;
    }, 0ms);
    ASSERT_TRUE(o && o->accepted) << (o ? o->reason : "no outcome");
    for (int y = box.min.y; y < box.max.y; ++y)
      for (int z = box.min.z; z < box.max.z; ++z)
        for (int x = box.min.x; x < box.max.x; ++x) writes[{x, y, z}].emplace_back(grief, v);
  };
  const Voxel brick = solid(materials::kBrick), rock = solid(materials::kRock);
  for (int i = 0; i < 10; ++i) ASSERT_NO_FATAL_FAILURE(edit(*builder, false, brick, 6));
  for (int i = 0; i < 200; ++i)
    ASSERT_NO_FATAL_FAILURE(edit(*griefer, true, solid(i % 2 ? materials::kSnow : materials::kSand), 3));
  for (int i = 0; i < 20; ++i) ASSERT_NO_FATAL_FAILURE(edit(*builder, false, rock, 4));

  testing_support::JsonDoc log;
  ASSERT_EQ(admin_json("log --player griefer --limit 5", &log), 0);
  ASSERT_EQ(log["edits"].array.size(), 5u);
  for (const auto& e : log["edits"].array) EXPECT_EQ(e["player"].string, "griefer");
  // Edits that changed nothing are not logged: the log holds the rest.
  ASSERT_EQ(admin_json("log --player griefer --limit 1000", &log), 0);
  std::size_t logged = 0;
  for (const auto& e : log["edits"].array) logged += e["player"].string == "griefer" ? 1 : 0;
  EXPECT_EQ(logged, log["edits"].array.size());
  std::string out;
  EXPECT_GT(logged, 150u);
  EXPECT_LE(logged, 200u);
  out.clear();
  ASSERT_EQ(admin("rollback --player griefer", &out), 0) << out;
  EXPECT_NE(out.find("rolled back " + std::to_string(logged) + " edits by griefer"), std::string::npos) << out;

  // Expected: a voxel whose last writes were the griefer's goes back to its
  // value before that run of his writes; every other voxel stays.
  std::map<std::tuple<int, int, int>, Voxel> expected = original;
  int restored = 0;
  for (const auto& [p, list] : writes) {
    std::size_t run = list.size();
    while (run > 0 && list[run - 1].first) --run;
    const Voxel before_run = run == 0 ? original[p] : list[run - 1].second;
    expected[p] = run == list.size() ? list.back().second : before_run;
    if (run != list.size() && before_run != list.back().second) ++restored;
  }
  EXPECT_GT(restored, 50);
  EXPECT_NE(out.find(std::to_string(restored) + " voxels restored"), std::string::npos) << out;
  auto replica_matches = [&](const ClientView& v) {
    for (const auto& [p, want] : expected) {
      const auto [x, y, z] = p;
      if (v.replica.get({x, y, z}) != want) return false;
    }
    return true;
  };
  ASSERT_TRUE(watcher->wait_until([&](const ClientView& v) { return v.closed || replica_matches(v); }, kDeadline));
  // And the server agrees: every chunk of the area, by chunk hash.
  std::vector<Vec3i> chunks;
  for_each_chunk_in(area, [&](Vec3i cp) { chunks.push_back(cp); });
  for (const Vec3i cp : chunks) ASSERT_TRUE(watcher->request_chunk_hash(cp));
  ASSERT_TRUE(watcher->wait_until(
      [&](const ClientView& v) {
        for (const Vec3i cp : chunks)
          if (!v.hash_checks.count(cp) || !v.hash_checks.at(cp)) return v.closed;
        return true;
      },
      kDeadline));
  // The rollback is itself logged, as the admin's edit: rolling it back
  // brings the griefer's voxels back.
  out.clear();
  ASSERT_EQ(admin("rollback --player admin", &out), 0) << out;
  ASSERT_TRUE(watcher->wait_until(
      [&](const ClientView& v) {
        for (const auto& [p, list] : writes) {
          const auto [x, y, z] = p;
          if (v.replica.get({x, y, z}) != list.back().second) return v.closed;
        }
        return true;
      },
      kDeadline));
  out.clear();
  EXPECT_EQ(admin("rollback --player nobody", &out), 1) << out;
  EXPECT_NE(out.find("no edits by 'nobody'"), std::string::npos) << out;
  out.clear();
  EXPECT_EQ(admin("rollback", &out), 1) << out;
  EXPECT_NE(out.find("--player NAME is required"), std::string::npos) << out;
}

}  // namespace
}  // namespace terrane
