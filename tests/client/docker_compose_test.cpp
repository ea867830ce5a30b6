// docker/: the compose file must stay valid. `docker-compose config` parses
// and validates it without a Docker engine; the test skips when Debian's
// docker-compose is not installed (scripts/install-deps.sh installs it).
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cstdio>
#include <string>

namespace terrane {
namespace {

int run(const std::string& cmd, std::string* out) {
  FILE* p = popen((cmd + " 2>&1").c_str(), "r");
  if (p == nullptr) return -1;
  char buf[4096];
  std::size_t n;
  while ((n = fread(buf, 1, sizeof buf, p)) > 0) out->append(buf, n);
  const int status = pclose(p);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

TEST(DockerCompose, ConfigValidatesAndRunsBotsAgainstTheServer) {
  std::string which;
  if (run("command -v docker-compose", &which) != 0) GTEST_SKIP() << "docker-compose not installed";
  const std::string file = std::string(TERRANE_TEST_DATA_DIR) + "/../../docker/docker-compose.yml";
  std::string out;
  ASSERT_EQ(run("docker-compose -f '" + file + "' config", &out), 0) << out;
  EXPECT_NE(out.find("target: server"), std::string::npos) << out;
  EXPECT_NE(out.find("target: bots"), std::string::npos) << out;
  EXPECT_NE(out.find("server:7777"), std::string::npos) << "the bots connect to the server service\n" << out;
  EXPECT_NE(out.find("condition: service_healthy"), std::string::npos) << out;
}

TEST(DockerCompose, ConfigRejectsABrokenFile) {
  std::string which;
  if (run("command -v docker-compose", &which) != 0) GTEST_SKIP() << "docker-compose not installed";
  const std::string file = ::testing::TempDir() + "/broken-compose.yml";
  {
    FILE* f = std::fopen(file.c_str(), "w");
    ASSERT_NE(f, nullptr);
    std::fputs("services:\n  server:\n    depends_on: 7\n", f);
    std::fclose(f);
  }
  std::string out;
  EXPECT_NE(run("docker-compose -f '" + file + "' config", &out), 0) << out;
  std::remove(file.c_str());
}

}  // namespace
}  // namespace terrane
