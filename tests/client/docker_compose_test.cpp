// docker/: the compose file and the server image fail closed and keep their
// secrets in files. `docker-compose config` parses, validates and
// interpolates the compose file without a Docker engine (the tests skip
// when Debian's docker-compose is not installed; scripts/install-deps.sh
// installs it). The images themselves are built and run by
// scripts/docker-check.sh (CTest DockerCheck, labels docker and heavy).
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "client/bots/report.h"
#include "tests/support/run_command.h"

namespace terrane {
namespace {

namespace fs = std::filesystem;
constexpr auto run = &testing_support::run_command;

fs::path docker_dir() { return fs::path(TERRANE_TEST_DATA_DIR) / ".." / ".." / "docker"; }

std::string read(const fs::path& p) {
  std::ifstream f(p);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

class DockerCompose : public ::testing::Test {
 protected:
  void SetUp() override {
    std::string which;
    if (run("command -v docker-compose", &which) != 0) GTEST_SKIP() << "docker-compose not installed";
    tokens_ = fs::path(::testing::TempDir()) / ("terrane-compose-tokens-" + std::to_string(::getpid()));
    std::ofstream(tokens_) << "ops some-admin-token admin\n";
  }
  void TearDown() override { fs::remove(tokens_); }
  // `docker-compose config` of FILE with ENV before it; the exit status.
  static int config(const std::string& env, const fs::path& file, std::string* out) {
    return run(env + " docker-compose -f '" + file.string() + "' config", out);
  }
  // The interpolated compose file, flattened ("services.server.restart").
  std::map<std::string, std::string> parsed(const fs::path& file) const {
    std::string json;
    EXPECT_EQ(run("TERRANE_TOKENS_FILE='" + tokens_.string() + "' docker-compose -f '" + file.string() +
                      "' config | python3 -c 'import sys, yaml, json; print(json.dumps(yaml.safe_load(sys.stdin)))'",
                  &json),
              0)
        << json;
    std::map<std::string, std::string> out;
    EXPECT_EQ(bots::flatten_json(json, &out), "") << json;
    return out;
  }
  static std::vector<std::string> list(const std::map<std::string, std::string>& j, const std::string& key) {
    std::vector<std::string> out;
    for (int i = 0; j.count(key + "." + std::to_string(i)) > 0; ++i) out.push_back(j.at(key + "." + std::to_string(i)));
    return out;
  }
  fs::path tokens_;
};

// Without a tokens file compose refuses (config and up interpolate alike;
// scripts/docker-check.sh runs the real `up`), naming what to set.
TEST_F(DockerCompose, RefusesToStartWithoutATokensFile) {
  std::string out;
  EXPECT_NE(config("env -u TERRANE_TOKENS_FILE", docker_dir() / "docker-compose.yml", &out), 0) << out;
  EXPECT_NE(out.find("set TERRANE_TOKENS_FILE"), std::string::npos) << out;
  out.clear();
  EXPECT_EQ(config("TERRANE_TOKENS_FILE='" + tokens_.string() + "'", docker_dir() / "docker-compose.yml", &out), 0)
      << out;
}

// No token or password is written in the file, none travels in an
// environment or on the server's command line: the tokens come from a
// secret (a read-only file under /run/secrets).
TEST_F(DockerCompose, KeepsSecretsInFilesOnly) {
  const auto c = parsed(docker_dir() / "docker-compose.yml");
  ASSERT_FALSE(c.empty());
  EXPECT_EQ(c.at("secrets.terrane_tokens.file"), tokens_.string());
  EXPECT_EQ(c.at("services.server.secrets.0.source"), "terrane_tokens");
  for (const auto& [key, value] : c) {
    EXPECT_EQ(key.find(".environment"), std::string::npos) << key << " = " << value;
    EXPECT_EQ(value.find("terrane-local"), std::string::npos) << key << " = " << value;
    EXPECT_NE(value, "some-admin-token") << key;
  }
  for (const auto& arg : list(c, "services.server.command"))
    EXPECT_EQ(arg.find("token"), std::string::npos) << "a token flag on the server's command line: " << arg;
  // The bots read theirs from a secret too, as a file (--token-file): no
  // entry point puts it on their command line.
  EXPECT_EQ(c.at("services.bots.secrets.0.source"), "terrane_bots_token");
  EXPECT_EQ(c.count("services.bots.entrypoint.0"), 0u) << c.at("services.bots.entrypoint.0");
  const auto bots = list(c, "services.bots.command");
  const auto token_file = std::find(bots.begin(), bots.end(), "--token-file");
  ASSERT_NE(token_file, bots.end());
  ASSERT_NE(token_file + 1, bots.end());
  EXPECT_EQ(*(token_file + 1), "/run/secrets/terrane_bots_token");
  EXPECT_EQ(std::find(bots.begin(), bots.end(), "--token"), bots.end());
  const std::string text = read(docker_dir() / "docker-compose.yml");
  EXPECT_EQ(text.find("POSTGRES_PASSWORD:"), std::string::npos);
  EXPECT_EQ(text.find("TERRANE_TOKEN:"), std::string::npos);
}

// What an operator's deployment needs: a restart policy that restarts
// after `shutdown --restart` (exit 75) and not after a plain shutdown (0),
// rotated logs, limits, the world and backups in volumes, and the bots
// starting once the server's healthcheck passes.
TEST_F(DockerCompose, ServerRestartsOnFailureWithRotatedLogsLimitsAndVolumes) {
  const auto c = parsed(docker_dir() / "docker-compose.yml");
  ASSERT_FALSE(c.empty());
  EXPECT_EQ(c.at("services.server.restart").rfind("on-failure", 0), 0u) << c.at("services.server.restart");
  EXPECT_EQ(c.at("services.server.logging.driver"), "json-file");
  EXPECT_EQ(c.at("services.server.logging.options.max-size"), "10m");
  EXPECT_EQ(c.at("services.server.logging.options.max-file"), "3");
  EXPECT_EQ(c.count("services.server.mem_limit"), 1u);
  EXPECT_EQ(c.count("services.server.cpus"), 1u);
  EXPECT_EQ(c.count("services.server.pids_limit"), 1u);
  const auto volumes = list(c, "services.server.volumes");
  EXPECT_NE(std::find(volumes.begin(), volumes.end(), "world:/data:rw"), volumes.end());
  EXPECT_NE(std::find(volumes.begin(), volumes.end(), "backups:/backups:rw"), volumes.end());
  // Metrics and /health only on the host's loopback.
  EXPECT_EQ(c.at("services.server.ports.1"), "127.0.0.1:9464:9464/tcp");
  EXPECT_EQ(c.at("services.bots.depends_on.server.condition"), "service_healthy");
  const auto bots = list(c, "services.bots.command");
  EXPECT_NE(std::find(bots.begin(), bots.end(), "server:7777"), bots.end());
  for (const auto& service : {"bots", "prometheus", "grafana"})
    EXPECT_EQ(c.at(std::string("services.") + service + ".logging.options.max-size"), "10m") << service;
}

// The cluster file (two servers on PostgreSQL): the database password is a
// file too, and compose refuses without it.
TEST_F(DockerCompose, ClusterRefusesWithoutADatabasePasswordFile) {
  const fs::path main = docker_dir() / "docker-compose.yml";
  const fs::path cluster = docker_dir() / "docker-compose.cluster.yml";
  std::string out;
  EXPECT_NE(run("TERRANE_TOKENS_FILE='" + tokens_.string() + "' env -u TERRANE_DB_PASSWORD_FILE docker-compose -f '" +
                    main.string() + "' -f '" + cluster.string() + "' config",
                &out),
            0)
      << out;
  EXPECT_NE(out.find("set TERRANE_DB_PASSWORD_FILE"), std::string::npos) << out;
  out.clear();
  EXPECT_EQ(run("TERRANE_TOKENS_FILE='" + tokens_.string() + "' TERRANE_DB_PASSWORD_FILE='" + tokens_.string() +
                    "' docker-compose -f '" + main.string() + "' -f '" + cluster.string() + "' config",
                &out),
            0)
      << out;
  EXPECT_EQ(out.find("password@"), std::string::npos) << out;
  EXPECT_EQ(out.find("POSTGRES_PASSWORD:"), std::string::npos) << out;
}

TEST_F(DockerCompose, ConfigRejectsABrokenFile) {
  const fs::path file = fs::path(::testing::TempDir()) / "broken-compose.yml";
  std::ofstream(file) << "services:\n  server:\n    depends_on: 7\n";
  std::string out;
  EXPECT_NE(config("", file, &out), 0) << out;
  fs::remove(file);
}

// The server image: its own healthcheck, a fixed uid for bind mounts, the
// tokens only from /run/secrets/terrane_tokens (server.conf), no token in
// the image's environment or entry point.
TEST(DockerImage, ServerStageChecksItsHealthAndReadsTokensFromTheSecret) {
  std::ifstream df(docker_dir() / "Dockerfile");
  ASSERT_TRUE(df.good());
  std::string line, stage, healthcheck, user, entrypoint, cmd;
  std::vector<std::string> env;
  while (std::getline(df, line)) {
    if (line.rfind("FROM ", 0) == 0) stage = line.substr(line.rfind(' ') + 1);
    if (line.rfind("USER ", 0) == 0 && stage == "runtime") user = line.substr(5);
    if (line.rfind("ENV ", 0) == 0) env.push_back(stage + ": " + line);
    if (stage != "server") continue;
    if (line.rfind("HEALTHCHECK ", 0) == 0) healthcheck = line;
    if (line.rfind("ENTRYPOINT ", 0) == 0) entrypoint = line.substr(11);
    if (line.rfind("CMD ", 0) == 0) cmd = line.substr(4);
  }
  EXPECT_NE(healthcheck, "") << "no HEALTHCHECK in the server stage";
  EXPECT_EQ(user, "999:999");
  EXPECT_EQ(entrypoint, "[\"terrane-server\"]");
  EXPECT_EQ(cmd, "[\"--config\", \"/etc/terrane/server.conf\", \"--world\", \"/data/world\"]");
  for (const auto& e : env) EXPECT_EQ(e.find("TOKEN"), std::string::npos) << e;
  const std::string conf = read(docker_dir() / "server.conf");
  EXPECT_NE(conf.find("\ntokens-file = /run/secrets/terrane_tokens\n"), std::string::npos) << conf;
  EXPECT_NE(conf.find("\nmetrics = 0.0.0.0:9464\n"), std::string::npos) << "the healthcheck asks /health there\n"
                                                                       << conf;
  EXPECT_EQ(conf.find("token ="), std::string::npos) << conf;
}

}  // namespace
}  // namespace terrane
