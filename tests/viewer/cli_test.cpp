// terrane-view's command line: --help, bad usage naming the flag (exit 2),
// a clear error when there is no server (exit 1).
#include <gtest/gtest.h>

#include <array>
#include <cstdio>
#include <string>
#include <sys/wait.h>

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
  for (const char* flag : {"--connect", "--screenshot", "--camera", "--wait-full-res", "--size", "--mips-only", "--enhance"})
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

}  // namespace
