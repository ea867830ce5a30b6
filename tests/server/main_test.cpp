// terrane-server's command line (server/main.cpp), run as a process: exit
// statuses as its --help and docs/running-a-server.md say (2 on bad usage,
// 1 when the world cannot be opened), the tokens flags, and what it says
// about a world it creates.
#include <gtest/gtest.h>
#include <httplib.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <string>

#include <fstream>
#include <sstream>
#include <vector>

#include "tests/support/child_process.h"
#include "tests/support/eventually.h"
#include "tests/support/json_doc.h"
#include "tests/support/run_command.h"
#include "tests/support/server_process.h"

namespace terrane {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

class ServerMainTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("terrane-main-" + std::to_string(::getpid()) + "-" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  // terrane-server ARGS run to its end (a usage or start error): its exit
  // status; its output in *out.
  int server(const std::string& args, std::string* out) {
    return testing_support::run_command("timeout 60 " + std::string(TERRANE_BIN_DIR) + "/terrane-server " + args, out);
  }
  std::string file(const std::string& name, const std::string& text) {
    const fs::path p = dir_ / name;
    std::FILE* f = std::fopen(p.c_str(), "w");
    EXPECT_NE(f, nullptr);
    if (f) {
      std::fputs(text.c_str(), f);
      std::fclose(f);
    }
    return p.string();
  }

  fs::path dir_;
};

TEST_F(ServerMainTest, AuthTokenWithATokensFileIsAUsageError) {
  const std::string tokens = file("tokens", "alice alice-token-1\n");
  std::string out;
  EXPECT_EQ(server("--world " + (dir_ / "w").string() + " --auth-token shared-1 --tokens-file " + tokens, &out), 2)
      << out;
  EXPECT_NE(out.find("give --auth-token or --tokens-file, not both"), std::string::npos) << out;
}

TEST_F(ServerMainTest, UsageErrorsExitTwo) {
  std::string out;
  // A malformed tokens file is bad usage, like a malformed --config file.
  const std::string bad = file("bad-tokens", "alice alice-token-1 superuser\n");
  EXPECT_EQ(server("--world " + (dir_ / "w").string() + " --tokens-file " + bad, &out), 2) << out;
  EXPECT_NE(out.find(bad + ":1: role 'superuser' is neither player nor admin"), std::string::npos) << out;
  out.clear();
  EXPECT_EQ(server("--world " + (dir_ / "w").string() + " --tokens-file " + (dir_ / "missing").string(), &out), 2)
      << out;
  out.clear();
  EXPECT_EQ(server("--world " + (dir_ / "w").string() + " --bind 0.0.0.0", &out), 2) << out;
  EXPECT_NE(out.find("without authentication"), std::string::npos) << out;
  out.clear();
  EXPECT_EQ(server("--world " + (dir_ / "w").string() + " --no-such-flag", &out), 2) << out;
  out.clear();
  // A view's table grows with its cube: 4,096 is the widest a server serves.
  EXPECT_EQ(server("--world " + (dir_ / "w").string() + " --max-view-distance 8192", &out), 2) << out;
  EXPECT_NE(out.find("max-view-distance"), std::string::npos) << out;
  EXPECT_FALSE(fs::exists(dir_ / "w")) << "no world is made on bad usage";
}

TEST_F(ServerMainTest, NoCreateRefusesAMissingWorldAndOtherwiseTheLogSaysItCreatesOne) {
  std::string out;
  const fs::path world = dir_ / "restored";
  EXPECT_EQ(server("--world " + world.string() + " --no-create", &out), 1) << out;
  EXPECT_NE(out.find("no world at " + world.string() + " (--no-create"), std::string::npos) << out;
  EXPECT_FALSE(fs::exists(world)) << "--no-create made the directory";

  {
    testing_support::ServerProcess s(world.string(), {});
    ASSERT_NE(s.port(), 0) << s.output();
    EXPECT_NE(s.output().find("creating a new world at " + world.string()), std::string::npos) << s.output();
    EXPECT_EQ(s.stop(), 0) << s.output();
  }
  // Now there is one: --no-create opens it, and says nothing of creating.
  testing_support::ServerProcess s(world.string(), {"--no-create"});
  ASSERT_NE(s.port(), 0) << s.output();
  EXPECT_EQ(s.output().find("creating a new world"), std::string::npos) << s.output();
  EXPECT_EQ(s.stop(), 0) << s.output();
}

std::string read_text(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

// --log-format json --log-file PATH: every line of the file is one JSON
// object (time with its offset, level, logger, message), nothing goes to
// stdout, and SIGHUP reopens PATH after the file was moved away (as
// logrotate does), the old file keeping what was written before.
TEST_F(ServerMainTest, AJsonLogFileHasOneObjectALineAndIsReopenedOnSighup) {
  const fs::path log = dir_ / "server.log", rotated = dir_ / "server.log.1";
  testing_support::ChildProcess s({std::string(TERRANE_BIN_DIR) + "/terrane-server", "--world",
                                   (dir_ / "world").string(), "--port", "0", "--worker-threads", "2", "--log-format",
                                   "json", "--log-file", log.string()});
  ASSERT_TRUE(testing_support::eventually([&] { return read_text(log).find("listening on") != std::string::npos; }))
      << read_text(log) << s.output();
  const auto lines = [](const std::string& text) {
    std::vector<testing_support::JsonDoc> docs;
    std::istringstream in(text);
    for (std::string line; std::getline(in, line);) {
      std::string why;
      auto doc = testing_support::parse_json(line, &why);
      EXPECT_TRUE(doc.has_value()) << why << ": " << line;
      if (doc) docs.push_back(*doc);
    }
    return docs;
  };
  const auto first = lines(read_text(log));
  ASSERT_FALSE(first.empty());
  bool listening = false;
  for (const auto& d : first) {
    EXPECT_EQ(d["logger"].string, "server");
    EXPECT_FALSE(d["level"].string.empty());
    // 2026-11-29T09:50:18.123+00:00
    EXPECT_EQ(d["time"].string.size(), 29u) << d["time"].string;
    EXPECT_EQ(d["time"].string[10], 'T') << d["time"].string;
    EXPECT_EQ(d["time"].string[26], ':') << d["time"].string;
    if (d["message"].string.rfind("listening on 127.0.0.1:", 0) == 0) {
      listening = true;
      EXPECT_EQ(d["level"].string, "info");
    }
  }
  EXPECT_TRUE(listening) << read_text(log);
  EXPECT_EQ(s.output().find("listening on"), std::string::npos) << "the log went to stdout too: " << s.output();

  fs::rename(log, rotated);
  ASSERT_TRUE(s.signal(SIGHUP));
  ASSERT_TRUE(testing_support::eventually([&] { return read_text(log).find("SIGHUP") != std::string::npos; }))
      << read_text(rotated) << s.output();
  EXPECT_EQ(read_text(rotated).find("SIGHUP"), std::string::npos);
  EXPECT_EQ(s.stop(), 0) << s.output();
  const auto after = lines(read_text(log));
  ASSERT_FALSE(after.empty());
  bool stopped = false;
  for (const auto& d : after) stopped = stopped || d["message"].string.rfind("stopped after", 0) == 0;
  EXPECT_TRUE(stopped) << read_text(log);
}

// --backup-every with a short period: the server makes N + 1 backups (as
// /metrics counts them, with the last success's time) and keeps the newest
// N in --backup-dir, each a world a server opens.
TEST_F(ServerMainTest, ScheduledBackupsKeepTheNewestAndShowInTheMetrics) {
  const fs::path backups = dir_ / "backups";
  testing_support::ServerProcess s((dir_ / "world").string(), {"--metrics", "127.0.0.1:0", "--backup-every", "200ms",
                                                              "--backup-keep", "2", "--backup-dir", backups.string()});
  ASSERT_NE(s.port(), 0) << s.output();
  const std::uint16_t metrics_port = s.metrics_port();
  ASSERT_NE(metrics_port, 0) << s.output();
  httplib::Client http("127.0.0.1", metrics_port);
  std::string text;
  const auto value = [&](const std::string& name) {
    const auto at = text.find("\n" + name + " ");
    return at == std::string::npos ? -1.0 : std::stod(text.substr(at + name.size() + 2));
  };
  ASSERT_TRUE(testing_support::eventually([&] {
    auto r = http.Get("/metrics");
    if (r && r->status == 200) text = r->body;
    return value("terrane_backups_total") >= 3;
  })) << text << s.output();
  EXPECT_EQ(value("terrane_backup_failures_total"), 0) << text;
  const double now_s = std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
  EXPECT_GT(value("terrane_backup_last_success_timestamp_seconds"), now_s - 120) << text;
  EXPECT_NE(text.find("# TYPE terrane_backup_last_success_timestamp_seconds gauge"), std::string::npos) << text;
  EXPECT_EQ(s.stop(), 0) << s.output();
  EXPECT_NE(s.output().find("scheduled backup: the world copied to " + backups.string()), std::string::npos)
      << s.output();
  std::vector<fs::path> kept;
  for (const auto& e : fs::directory_iterator(backups)) kept.push_back(e.path());
  ASSERT_EQ(kept.size(), 2u) << s.output();
  for (const auto& k : kept) {
    EXPECT_EQ(k.filename().string().rfind("world-", 0), 0u) << k;
    testing_support::ServerProcess restored(k.string(), {"--no-create"});
    EXPECT_NE(restored.port(), 0) << restored.output();
    EXPECT_EQ(restored.stop(), 0) << restored.output();
  }
  std::string out;
  EXPECT_EQ(server("--world " + (dir_ / "w").string() + " --backup-every 6h", &out), 2) << out;
  EXPECT_NE(out.find("--backup-every: give --backup-dir DIR"), std::string::npos) << out;
  EXPECT_EQ(server("--world " + (dir_ / "w").string() + " --backup-every soon --backup-dir x", &out), 2) << out;
  EXPECT_NE(out.find("--backup-every: 'soon' is not a duration"), std::string::npos) << out;
  EXPECT_EQ(server("--world " + (dir_ / "w").string() + " --backup-keep 3", &out), 2) << out;
  EXPECT_NE(out.find("--backup-keep: scheduled backups need --backup-every"), std::string::npos) << out;
}

TEST_F(ServerMainTest, ABadLogFormatOrAnUnwritableLogFileIsAUsageError) {
  std::string out;
  EXPECT_EQ(server("--world " + (dir_ / "w").string() + " --log-format xml", &out), 2) << out;
  EXPECT_NE(out.find("--log-format: 'xml' is neither text nor json"), std::string::npos) << out;
  EXPECT_EQ(server("--world " + (dir_ / "w").string() + " --log-file " + (dir_ / "no/such/dir/log").string(), &out),
            2)
      << out;
  EXPECT_NE(out.find("--log-file: cannot open log file"), std::string::npos) << out;
}

// --log-level warn: the info lines (among them "listening on") are
// dropped, the warnings kept (a new world's "creating a new world", an
// open server's "authentication: none").
TEST_F(ServerMainTest, LogLevelWarnDropsInfoLinesAndKeepsWarnings) {
  testing_support::ChildProcess s({std::string(TERRANE_BIN_DIR) + "/terrane-server", "--world",
                                   (dir_ / "world").string(), "--port", "0", "--log-level", "warn"});
  ASSERT_TRUE(s.started());
  // Logged by start() once the signals are caught, just before "listening on".
  ASSERT_TRUE(s.wait_for_output("authentication: none", 60s)) << s.output();
  EXPECT_EQ(s.stop(), 0) << s.output();
  const std::string out = s.output();
  EXPECT_NE(out.find("creating a new world at " + (dir_ / "world").string()), std::string::npos) << out;
  EXPECT_EQ(out.find("listening on"), std::string::npos) << out;
  EXPECT_EQ(out.find("stopped after"), std::string::npos) << out;
  EXPECT_EQ(out.find("[info]"), std::string::npos) << out;
}

TEST_F(ServerMainTest, ABadLogLevelIsAUsageErrorOnTheCommandLineOrInAConfigFile) {
  std::string out;
  EXPECT_EQ(server("--world " + (dir_ / "w").string() + " --log-level loud", &out), 2) << out;
  EXPECT_NE(out.find("--log-level: 'loud' is none of trace, debug, info, warn, error, off"), std::string::npos)
      << out;
  out.clear();
  const std::string config = file("server.conf", "log-level = verbose\n");
  EXPECT_EQ(server("--world " + (dir_ / "w").string() + " --config " + config, &out), 2) << out;
  EXPECT_NE(out.find("--log-level: 'verbose'"), std::string::npos) << out;
  EXPECT_FALSE(fs::exists(dir_ / "w")) << "no world is made on bad usage";
}

}  // namespace
}  // namespace terrane
