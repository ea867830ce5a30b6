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

#include "client/client.h"
#include "tests/support/server_process.h"

namespace terrane {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using testing_support::ServerProcess;

constexpr auto kDeadline = 120s;
constexpr const char* kToken = "operator-token-1";

int run(const std::string& cmd, std::string* out) {
  FILE* p = popen((cmd + " 2>&1").c_str(), "r");
  if (p == nullptr) return -1;
  char buf[4096];
  std::size_t n;
  while ((n = fread(buf, 1, sizeof buf, p)) > 0) out->append(buf, n);
  const int status = pclose(p);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

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
  void start_server(std::uint16_t port = 0) {
    server_ = std::make_unique<ServerProcess>(
        dir_.string(), std::vector<std::string>{"--admin-token", kToken, "--port", std::to_string(port)});
    ASSERT_NE(server_->port(), 0) << server_->output();
  }
  int admin(const std::string& args, std::string* out, const std::string& token = kToken) {
    return run(std::string(TERRANE_BIN_DIR) + "/terrane-admin --connect 127.0.0.1:" + std::to_string(server_->port()) +
                   " --token '" + token + "' " + args,
               out);
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

TEST_F(AdminToolTest, CommandsAnswerInTextOrJsonAndSayReachesTheLibrary) {
  start_server();
  Client listener(player("listener"));
  std::string err;
  ASSERT_TRUE(listener.connect(&err)) << err;
  ASSERT_TRUE(listener.wait_until([](const ClientView& v) { return v.welcomed || v.closed; }, kDeadline));

  std::string out;
  ASSERT_EQ(admin("--json status", &out), 0) << out;
  EXPECT_EQ(out.front(), '{') << out;
  EXPECT_NE(out.find("\"clients\": 2"), std::string::npos) << out;  // the listener and the tool
  out.clear();
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
  EXPECT_EQ(run(std::string(TERRANE_BIN_DIR) + "/terrane-admin --token x status", &out), 2) << out;
  EXPECT_NE(out.find("--connect HOST:PORT is required"), std::string::npos) << out;
  listener.disconnect();
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
  // The server stops by itself (terrane-admin asked; nothing signalled it).
  ASSERT_EQ(server_->wait_exit(kDeadline), 0) << server_->output();
  EXPECT_NE(server_->output().find("world saved"), std::string::npos) << server_->output();
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

}  // namespace
}  // namespace terrane
