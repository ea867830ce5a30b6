// docker/: the compose file must stay valid. `docker-compose config` parses
// and validates it without a Docker engine; the test skips when Debian's
// docker-compose is not installed (scripts/install-deps.sh installs it).
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "tests/support/run_command.h"
#include "client/bots/report.h"
#include "tests/support/child_process.h"
#include "tests/support/eventually.h"

namespace terrane {
namespace {

constexpr auto run = &testing_support::run_command;

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

// The compose file's and the Dockerfile's command lines, run as written on
// this machine without Docker: only what cannot be the same outside a
// container is replaced (the world's path, the reports' paths, the
// addresses: loopback and free ports for 0.0.0.0, 7777 and 9464, the
// service name "server"). Then the server's healthcheck must pass and the
// bots' run, exactly as configured, must succeed.
class DockerComposeHeavy : public ::testing::Test {
 protected:
  static std::vector<std::string> list(const std::map<std::string, std::string>& j, const std::string& key) {
    std::vector<std::string> out;
    for (int i = 0; j.count(key + "." + std::to_string(i)) > 0; ++i) out.push_back(j.at(key + "." + std::to_string(i)));
    return out;
  }
  static std::string replace_all(std::string s, const std::string& from, const std::string& to) {
    for (std::size_t at = 0; (at = s.find(from, at)) != std::string::npos; at += to.size()) s.replace(at, from.size(), to);
    return s;
  }
};

TEST_F(DockerComposeHeavy, TheServerAndBotsCommandLinesRunAsWritten) {
  std::string which;
  ASSERT_EQ(run("command -v docker-compose", &which), 0) << "docker-compose is not installed: run scripts/install-deps.sh";
  const std::filesystem::path docker = std::filesystem::path(TERRANE_TEST_DATA_DIR) / ".." / ".." / "docker";
  std::string json;
  ASSERT_EQ(run("docker-compose -f '" + (docker / "docker-compose.yml").string() +
                    "' config | python3 -c 'import sys, yaml, json; print(json.dumps(yaml.safe_load(sys.stdin)))'",
                &json),
            0)
      << json;
  std::map<std::string, std::string> compose;
  ASSERT_EQ(terrane::bots::flatten_json(json, &compose), "") << json;
  // The Dockerfile's server ENTRYPOINT (a JSON array on one line).
  std::ifstream df(docker / "Dockerfile");
  std::string line, entry;
  bool in_server = false;
  while (std::getline(df, line)) {
    if (line.rfind("FROM ", 0) == 0) in_server = line.find(" AS server") != std::string::npos;
    if (in_server && line.rfind("ENTRYPOINT ", 0) == 0) entry = line.substr(11);
  }
  ASSERT_FALSE(entry.empty()) << "no ENTRYPOINT in the Dockerfile's server stage";
  std::map<std::string, std::string> ep;
  ASSERT_EQ(terrane::bots::flatten_json("{\"e\": " + entry + "}", &ep), "") << entry;
  const auto dir = std::filesystem::temp_directory_path() / ("terrane-docker-" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir / "reports");
  const std::string path = std::string(TERRANE_BIN_DIR) + ":" + std::getenv("PATH");

  auto server_argv = [&] {
    std::vector<std::string> argv = list(ep, "e");
    for (std::string a : list(compose, "services.server.command")) {
      a = replace_all(a, "/data/world", (dir / "world").string());
      a = a == "7777" ? "0" : replace_all(a, "0.0.0.0:9464", "127.0.0.1:0");
      argv.push_back(replace_all(a, "0.0.0.0", "127.0.0.1"));
    }
    return argv;
  };
  const std::string token = compose.at("services.server.environment.TERRANE_TOKEN");
  // Without a token the image refuses to start, saying why.
  {
    testing_support::ChildProcess bare(server_argv(), {{"PATH", path}, {"TERRANE_TOKEN", ""}});
    EXPECT_NE(bare.wait(std::chrono::seconds(60)), 0);
    EXPECT_NE(bare.output().find("set TERRANE_TOKEN"), std::string::npos) << bare.output();
  }
  testing_support::ChildProcess server(server_argv(), {{"PATH", path}, {"TERRANE_TOKEN", token}});
  ASSERT_TRUE(server.wait_for_output("/metrics", std::chrono::seconds(120))) << server.output();
  const std::string out = server.output();
  // (No std::regex: GCC 12 warns inside it under the sanitizer build.)
  auto number_after = [&](const std::string& text) {
    const auto at = out.find(text);
    return at == std::string::npos ? std::string() : std::to_string(std::stoi(out.substr(at + text.size())));
  };
  const std::string port = number_after("listening on 127.0.0.1:");
  const std::string metrics_port = number_after("metrics on http://127.0.0.1:");
  ASSERT_FALSE(port.empty() || metrics_port.empty()) << out;

  // The healthcheck, as written (its port is the metrics port).
  const auto health = list(compose, "services.server.healthcheck.test");
  ASSERT_EQ(health.size(), 4u);
  ASSERT_EQ(health[0], "CMD");
  std::string check;
  for (std::size_t i = 1; i < health.size(); ++i) {
    if (i > 1) check.push_back(' ');
    check.push_back('\'');
    check.append(replace_all(replace_all(health[i], "9464", metrics_port), "'", "'\\''"));
    check.push_back('\'');
  }
  const bool healthy = testing_support::eventually(
      [&] {
        std::string ignored;
        return run(check, &ignored) == 0;
      },
      std::chrono::seconds(120));
  EXPECT_TRUE(healthy) << check;

  // The bots' command, as written.
  std::vector<std::string> bots = {"terrane-bots"};
  for (std::string a : list(compose, "services.bots.command")) {
    a = replace_all(a, "server:7777", "127.0.0.1:" + port);
    a = replace_all(a, "server:9464", "127.0.0.1:" + metrics_port);
    bots.push_back(replace_all(a, "/reports/", (dir / "reports").string() + "/"));
  }
  testing_support::ChildProcess run_bots(bots, {{"PATH", path}});
  const int status = run_bots.wait(std::chrono::seconds(900));
  EXPECT_EQ(status, 0) << run_bots.output();
  EXPECT_NE(run_bots.output().find("PASSED"), std::string::npos) << run_bots.output();
  EXPECT_NE(run_bots.output().find("the server over the run"), std::string::npos) << run_bots.output();
  EXPECT_TRUE(std::filesystem::exists(dir / "reports" / "bots.json"));
  EXPECT_EQ(server.stop(), 0) << server.output();
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace terrane
