// terrane-view's command line: --help, bad usage naming the flag (exit 2),
// a clear error when there is no server (exit 1).
#include <gtest/gtest.h>

#include <array>
#include <cstdio>
#include <string>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>

#include "tests/support/server_process.h"

namespace {

struct ViewRun {
  int code;
  std::string output;
};

ViewRun run(const std::string& args) {
  const std::string cmd = std::string(TERRANE_BIN_DIR) + "/terrane-view " + args + " 2>&1";
  FILE* p = popen(cmd.c_str(), "r");
  std::string out;
  std::array<char, 512> buf{};
  while (p && std::fgets(buf.data(), buf.size(), p)) out += buf.data();
  const int status = p ? pclose(p) : -1;
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, out};
}

TEST(ViewerCli, HelpListsTheHeadlessOptions) {
  const ViewRun r = run("--help");
  EXPECT_EQ(r.code, 0);
  for (const char* flag :
       {"--connect", "--token", "--screenshot", "--camera", "--wait-full-res", "--size", "--mips-only", "--enhance"})
    EXPECT_NE(r.output.find(flag), std::string::npos) << flag;
}

TEST(ViewerCli, BadUsageNamesTheFlag) {
  const std::pair<const char*, const char*> cases[] = {
      {"", "--connect"},
      {"--connect localhost", "--connect"},
      {"--connect 127.0.0.1:1 --screenshot x.png --camera 1,2,3", "--camera"},
      {"--connect 127.0.0.1:1 --screenshot x.png --size 10x", "--size"},
      {"--connect 127.0.0.1:1 --screenshot x.png --view-distance 0", "view-distance"},
      {"--connect 127.0.0.1:1 --wait-full-res", "--screenshot"},
      {"--connect 127.0.0.1:1 --frobnicate", "frobnicate"},
  };
  for (const auto& [args, flag] : cases) {
    const ViewRun r = run(args);
    EXPECT_EQ(r.code, 2) << args << "\n" << r.output;
    EXPECT_NE(r.output.find(flag), std::string::npos) << args << "\n" << r.output;
  }
}

TEST(ViewerCli, NoServerIsAClearError) {
  // Port 1 on loopback: nothing listens there.
  const ViewRun r = run("--connect 127.0.0.1:1 --screenshot /dev/null --timeout 5");
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("cannot connect to 127.0.0.1:1"), std::string::npos) << r.output;
}

TEST(ViewerCli, TheTokenReachesTheServer) {
  // A server that wants a token: the viewer is refused without it and with
  // a wrong one, and says so (it connects before it loads any GL driver),
  // and joins with the right one.
  const auto dir = std::filesystem::temp_directory_path() / ("terrane-view-token-" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  {
    terrane::testing_support::ServerProcess server(dir.string(), {"--auth-token", "sesame"});
    ASSERT_NE(server.port(), 0) << server.output();
    const std::string connect = "--connect 127.0.0.1:" + std::to_string(server.port()) + " --screenshot /dev/null --timeout 20";
    for (const std::string token : {"", " --token guess"}) {
      const ViewRun r = run(connect + token);
      EXPECT_EQ(r.code, 1) << r.output;
      EXPECT_NE(r.output.find("authentication failed"), std::string::npos) << token << "\n" << r.output;
    }
    EXPECT_TRUE(server.wait_for_output("authentication failed for 'terrane-view'", std::chrono::seconds(20)))
        << server.output();
    // With the token it joins (what it does after that, headless GL with a
    // one-second timeout, does not matter here).
    (void)run("--connect 127.0.0.1:" + std::to_string(server.port()) + " --screenshot /dev/null --timeout 1 --token sesame");
    EXPECT_TRUE(server.wait_for_output("joined as 'terrane-view'", std::chrono::seconds(20))) << server.output();
    EXPECT_EQ(server.stop(), 0);
  }
  std::filesystem::remove_all(dir);
}

}  // namespace
