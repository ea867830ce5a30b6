// terrane-server's command line (server/main.cpp), run as a process: exit
// statuses as its --help and docs/running-a-server.md say (2 on bad usage,
// 1 when the world cannot be opened), the tokens flags, and what it says
// about a world it creates.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <string>

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

}  // namespace
}  // namespace terrane
