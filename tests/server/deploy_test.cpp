// The deployment examples (deploy/): the systemd unit passes
// `systemd-analyze verify` (where installed) and says what the server's
// exit statuses and SIGHUP mean; the example config and tokens file start a
// server (the command line overriding only the addresses and paths of this
// machine) whose /health answers; the Kubernetes manifest (parsed with
// python3-yaml where installed, else by its text) has its probes on the
// server's /health port, its paths where the config and the image's flags
// put them, and a Secret that fails closed.
#include <gtest/gtest.h>
#include <httplib.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "tests/support/eventually.h"
#include "tests/support/json_doc.h"
#include "tests/support/run_command.h"
#include "tests/support/scratch_dir.h"
#include "tests/support/server_process.h"

namespace terrane {
namespace {

namespace fs = std::filesystem;
using testing_support::JsonDoc;

fs::path deploy_dir() { return fs::path(TERRANE_SOURCE_DIR) / "deploy"; }

std::string read(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

// 'name = value' lines of a config file (comments and blank lines skipped).
std::map<std::string, std::string> config_values(const std::string& text) {
  std::map<std::string, std::string> values;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) {
    line = line.substr(0, line.find('#'));
    const auto eq = line.find('=');
    if (eq == std::string::npos) continue;
    auto trim = [](std::string s) {
      s.erase(0, s.find_first_not_of(" \t"));
      s.erase(s.find_last_not_of(" \t") + 1);
      return s;
    };
    values[trim(line.substr(0, eq))] = trim(line.substr(eq + 1));
  }
  return values;
}

class DeployTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = testing_support::scratch_dir("terrane-deploy");
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  // Starts a server with config, the command line giving this machine's
  // world, addresses and backups; checks /health answers 200 "ready".
  void serve(const fs::path& config, const fs::path& tokens) {
    testing_support::ServerProcess s((dir_ / "world").string(),
                                     {"--config", config.string(), "--bind", "127.0.0.1", "--metrics", "127.0.0.1:0",
                                      "--tokens-file", tokens.string(), "--backup-dir", (dir_ / "backups").string()});
    ASSERT_NE(s.port(), 0) << s.output();
    const std::uint16_t metrics = s.metrics_port();
    ASSERT_NE(metrics, 0) << s.output();
    httplib::Client http("127.0.0.1", metrics);
    std::string body;
    ASSERT_TRUE(testing_support::eventually([&] {
      auto r = http.Get("/health");
      if (r) body = r->body;
      return r && r->status == 200;
    })) << body;
    EXPECT_EQ(body, "ready\n");
    EXPECT_EQ(s.stop(), 0) << s.output();
  }
  fs::path dir_;
};

TEST_F(DeployTest, TheSystemdUnitVerifiesAndRestartsOnFailureAsTheExitStatusesSay) {
  const std::string unit = read(deploy_dir() / "terrane-server.service");
  ASSERT_FALSE(unit.empty());
  const auto has_line = [&](const std::string& line) { return unit.find("\n" + line + "\n") != std::string::npos; };
  EXPECT_TRUE(has_line("Restart=on-failure"));  // 1 and 75 restart, 0 does not
  EXPECT_TRUE(has_line("RestartPreventExitStatus=2"));  // bad usage fails the same way again
  EXPECT_TRUE(has_line("ExecReload=/bin/kill -HUP $MAINPID"));
  EXPECT_TRUE(has_line("ExecStart=/usr/local/bin/terrane-server --config /etc/terrane/server.conf"));
  EXPECT_TRUE(has_line("User=terrane"));
  for (const char* hardening : {"NoNewPrivileges=yes", "ProtectSystem=strict", "ProtectHome=yes", "PrivateTmp=yes",
                                "CapabilityBoundingSet=", "StateDirectory=terrane"})
    EXPECT_TRUE(has_line(hardening)) << hardening;
  // The example config's world and backups are in the state directory, the
  // only place ProtectSystem=strict leaves writable.
  const auto conf = config_values(read(deploy_dir() / "server.conf.example"));
  EXPECT_EQ(conf.at("world").rfind("/var/lib/terrane/", 0), 0u) << conf.at("world");
  EXPECT_EQ(conf.at("backup-dir").rfind("/var/lib/terrane/", 0), 0u) << conf.at("backup-dir");
  std::string out;
  if (testing_support::run_command("command -v systemd-analyze", &out) != 0)
    GTEST_SKIP() << "systemd-analyze not installed: the unit's text alone was checked";
  // The unit as installed, its ExecStart the binary built here (verify
  // checks that it exists).
  std::string local = unit;
  const std::string exec = "/usr/local/bin/terrane-server";
  local.replace(local.find(exec), exec.size(), std::string(TERRANE_BIN_DIR) + "/terrane-server");
  const fs::path copy = dir_ / "terrane-server.service";
  std::ofstream(copy) << local;
  EXPECT_EQ(testing_support::run_command("cd '" + dir_.string() + "' && systemd-analyze verify '" + copy.string() + "'",
                                         &out),
            0)
      << out;
  // Warnings (an unknown key, a key in the wrong section) name the file.
  EXPECT_EQ(out.find("terrane-server.service"), std::string::npos) << out;
}

TEST_F(DeployTest, TheExampleConfigAndTokensFileStartAServer) {
  serve(deploy_dir() / "server.conf.example", deploy_dir() / "tokens.example");
}

// The manifest as JSON: python3-yaml's reading of it, or nullopt without it.
std::optional<JsonDoc> manifest_json(const fs::path& manifest) {
  std::string out;
  if (testing_support::run_command("python3 -c 'import yaml' 2>/dev/null", &out) != 0) return std::nullopt;
  const int rc = testing_support::run_command(
      "python3 -c 'import json, sys, yaml; print(json.dumps(list(yaml.safe_load_all(open(sys.argv[1])))))' '" +
          manifest.string() + "'",
      &out);
  EXPECT_EQ(rc, 0) << out;
  std::string why;
  auto doc = testing_support::parse_json(out, &why);
  EXPECT_TRUE(doc.has_value()) << why << ": " << out;
  return doc;
}

TEST_F(DeployTest, TheKubernetesManifestsProbesAndPathsAgreeWithTheServersFlags) {
  const fs::path manifest = deploy_dir() / "kubernetes" / "terrane.yaml";
  const std::string text = read(manifest);
  ASSERT_FALSE(text.empty());
  const auto docs = manifest_json(manifest);
  if (!docs) {
    // No python3-yaml: the text's structure alone.
    for (const char* want : {"kind: StatefulSet", "kind: Secret", "kind: Service", "replicas: 1",
                             "volumeClaimTemplates:", "mountPath: /data", "mountPath: /run/secrets",
                             "httpGet: {path: /health, port: metrics}", "containerPort: 9464",
                             "metrics = 0.0.0.0:9464", "tokens-file = /run/secrets/terrane_tokens"})
      EXPECT_NE(text.find(want), std::string::npos) << want;
    GTEST_SKIP() << "python3-yaml not installed: the manifest's text alone was checked";
  }
  std::map<std::string, const JsonDoc*> by_kind;
  for (const JsonDoc& d : docs->array) by_kind[d["kind"].string] = &d;
  ASSERT_EQ(by_kind.count("StatefulSet"), 1u);
  ASSERT_EQ(by_kind.count("Secret"), 1u);
  ASSERT_EQ(by_kind.count("ConfigMap"), 1u);
  ASSERT_EQ(by_kind.count("Service"), 1u);
  const JsonDoc& set = *by_kind["StatefulSet"];
  EXPECT_EQ(set["spec"]["replicas"].number, 1);  // one writer per world
  const JsonDoc& pod = set["spec"]["template"]["spec"];
  ASSERT_EQ(pod["containers"].array.size(), 1u);
  const JsonDoc& c = pod["containers"].array[0];
  EXPECT_EQ(pod["securityContext"]["runAsUser"].number, 999);  // the image's uid
  EXPECT_EQ(pod["securityContext"]["fsGroup"].number, 999);

  // The flags: --config FILE --world DIR.
  std::map<std::string, std::string> args;
  for (std::size_t i = 0; i + 1 < c["args"].array.size(); i += 2)
    args[c["args"].array[i].string] = c["args"].array[i + 1].string;
  ASSERT_EQ(args.count("--config"), 1u);
  ASSERT_EQ(args.count("--world"), 1u);
  std::map<std::string, std::string> mounts;  // volume name -> mount path
  for (const JsonDoc& m : c["volumeMounts"].array) mounts[m["name"].string] = m["mountPath"].string;
  // The world on the claimed volume.
  ASSERT_EQ(set["spec"]["volumeClaimTemplates"].array.size(), 1u);
  const std::string data = set["spec"]["volumeClaimTemplates"].array[0]["metadata"]["name"].string;
  ASSERT_EQ(mounts.count(data), 1u);
  EXPECT_EQ(args["--world"].rfind(mounts[data] + "/", 0), 0u) << args["--world"];
  // The config from the ConfigMap, at --config.
  EXPECT_EQ(mounts["config"], args["--config"]);
  const std::string conf_text = (*by_kind["ConfigMap"])["data"]["server.conf"].string;
  const auto conf = config_values(conf_text);
  EXPECT_EQ(conf.at("backup-dir").rfind(mounts[data] + "/", 0), 0u) << conf.at("backup-dir");
  // The tokens file: the Secret's item under its mount.
  std::string tokens_path;
  for (const JsonDoc& v : pod["volumes"].array) {
    if (v["name"].string != "tokens") continue;
    EXPECT_EQ(v["secret"]["secretName"].string, (*by_kind["Secret"])["metadata"]["name"].string);
    ASSERT_EQ(v["secret"]["items"].array.size(), 1u);
    tokens_path = mounts["tokens"] + "/" + v["secret"]["items"].array[0]["path"].string;
    EXPECT_TRUE((*by_kind["Secret"])["stringData"].has(v["secret"]["items"].array[0]["key"].string));
  }
  EXPECT_EQ(conf.at("tokens-file"), tokens_path);

  // Every probe asks /health on the port named for --metrics.
  std::map<std::string, double> ports;
  for (const JsonDoc& p : c["ports"].array) ports[p["name"].string] = p["containerPort"].number;
  EXPECT_EQ(ports["game"], std::stoi(conf.at("port")));
  const std::string metrics = conf.at("metrics");
  EXPECT_EQ(ports["metrics"], std::stoi(metrics.substr(metrics.rfind(':') + 1)));
  for (const char* probe : {"startupProbe", "readinessProbe", "livenessProbe"}) {
    ASSERT_TRUE(c.has(probe)) << probe;
    EXPECT_EQ(c[probe]["httpGet"]["path"].string, "/health") << probe;
    EXPECT_EQ(c[probe]["httpGet"]["port"].string, "metrics") << probe;
  }
  // The Services reach the named ports.
  for (const JsonDoc& d : docs->array) {
    if (d["kind"].string != "Service") continue;
    for (const JsonDoc& p : d["spec"]["ports"].array) {
      EXPECT_EQ(ports.count(p["targetPort"].string), 1u) << p["targetPort"].string;
    }
  }

  // The ConfigMap's config starts a server here (this machine's addresses
  // and paths on the command line), and the placeholder Secret fails
  // closed: it lists no player.
  const fs::path config = dir_ / "server.conf", secret = dir_ / "terrane_tokens";
  std::ofstream(config) << conf_text;
  std::ofstream(secret) << (*by_kind["Secret"])["stringData"]["terrane_tokens"].string;
  serve(config, deploy_dir() / "tokens.example");
  std::string out;
  EXPECT_EQ(testing_support::run_command(std::string(TERRANE_BIN_DIR) + "/terrane-server --config " + config.string() +
                                             " --world " + (dir_ / "w2").string() + " --bind 127.0.0.1 --tokens-file " +
                                             secret.string() + " --backup-dir " + (dir_ / "b2").string(),
                                         &out),
            2)
      << out;
  EXPECT_NE(out.find("lists no players"), std::string::npos) << out;
}

}  // namespace
}  // namespace terrane
