// The sharded load test as the docs give it to orchestrators: the compose
// file's "shards" profile (docker/docker-compose.yml) and the Kubernetes
// Indexed Job (deploy/kubernetes/bots-shards.yaml, bots-merge.yaml). Each
// part's command line is parsed by terrane-bots' own flag parser: the parts
// are shards 0..N-1 of one scenario, each once, with N the Job's
// completions, and the merge reads exactly their reports. `docker-compose
// config` validates the compose file without a Docker engine; the
// Kubernetes manifests are parsed with python3-yaml (both come with
// scripts/install-deps.sh's docker-compose) and checked field by field (no
// Kubernetes schema validator is packaged in Debian 12).
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "client/bots/options.h"
#include "tests/client/bots/parse_flags.h"
#include "tests/support/json_doc.h"
#include "tests/support/run_command.h"

namespace terrane::bots {
namespace {

namespace fs = std::filesystem;
using testing_support::JsonDoc;

fs::path repo() { return fs::path(TERRANE_SOURCE_DIR); }

// YAML documents as JSON, through python3-yaml.
std::vector<JsonDoc> yaml_docs(const std::string& command) {
  std::string out;
  const int rc = testing_support::run_command(
      command + " | python3 -c 'import json, sys, yaml; print(json.dumps(list(yaml.safe_load_all(sys.stdin))))'", &out);
  EXPECT_EQ(rc, 0) << out;
  std::string why;
  const auto doc = testing_support::parse_json(out, &why);
  EXPECT_TRUE(doc.has_value()) << why << ": " << out;
  return doc ? doc->array : std::vector<JsonDoc>{};
}

std::vector<std::string> strings(const JsonDoc& array) {
  std::vector<std::string> out;
  for (const JsonDoc& a : array.array) out.push_back(a.string);
  return out;
}

// A part's command line as terrane-bots parses it here: the secret's path
// (read when parsed) is a scratch file holding a token, as the mounted
// secret does in the container.
std::string parse_part(std::vector<std::string> args, BotsOptions* o) {
  static const fs::path token = [] {
    const fs::path p = fs::path(::testing::TempDir()) / ("terrane-shard-token-" + std::to_string(::getpid()));
    std::ofstream(p) << "a-bots-token\n";
    return p;
  }();
  for (std::size_t i = 0; i + 1 < args.size(); ++i)
    if (args[i] == "--token-file") {
      EXPECT_EQ(args[i + 1].rfind("/run/secrets/", 0), 0u) << "the token is a secret: " << args[i + 1];
      args[i + 1] = token.string();
    }
  return parse_flags(args, o);
}

// The parts' command lines: shards 0..n-1 of one scenario, each reporting
// to report_of(i); returns the reports in shard order.
std::vector<std::string> expect_shards_of_one_scenario(const std::vector<std::vector<std::string>>& parts) {
  std::vector<std::string> reports(parts.size());
  std::optional<std::string> scenario;
  std::vector<int> seen(parts.size(), 0);
  for (const std::vector<std::string>& args : parts) {
    BotsOptions o;
    EXPECT_EQ(parse_part(args, &o), "");
    EXPECT_EQ(o.shard_count, static_cast<int>(parts.size()));
    if (o.shard_index < 0 || o.shard_index >= static_cast<int>(parts.size())) {
      ADD_FAILURE() << "shard " << o.shard_index;
      continue;
    }
    ++seen[static_cast<std::size_t>(o.shard_index)];
    reports[static_cast<std::size_t>(o.shard_index)] = o.report_path;
    // Everything but the part and its report is one scenario.
    o.shard_index = 0;
    o.report_path.clear();
    const std::string text = scenario_text(o);
    if (scenario) {
      EXPECT_EQ(text, *scenario);
    }
    scenario = text;
  }
  for (std::size_t i = 0; i < seen.size(); ++i) EXPECT_EQ(seen[i], 1) << "shard " << i;
  return reports;
}

// The merge's command line: "merge" with the parts' reports, then its own.
void expect_merge_of(const std::vector<std::string>& args, const std::vector<std::string>& reports) {
  ASSERT_GE(args.size(), reports.size() + 1);
  EXPECT_EQ(args[0], "merge");
  EXPECT_EQ(std::vector<std::string>(args.begin() + 1, args.begin() + 1 + static_cast<long>(reports.size())),
            reports);
  const std::vector<std::string> rest(args.begin() + 1 + static_cast<long>(reports.size()), args.end());
  ASSERT_EQ(rest.size(), 4u);
  EXPECT_EQ(rest[0], "--report");
  EXPECT_EQ(rest[2], "--html");
}

TEST(ShardManifests, TheComposeShardsProfileRunsEachPartOnceAndMergesTheirReports) {
  std::string which;
  ASSERT_EQ(testing_support::run_command("command -v docker-compose", &which), 0)
      << "docker-compose is not installed (scripts/install-deps.sh installs it)";
  const std::vector<JsonDoc> docs =
      yaml_docs("TERRANE_TOKENS_FILE=/dev/null TERRANE_BOTS_TOKEN_FILE=/dev/null docker-compose -f '" +
                (repo() / "docker" / "docker-compose.yml").string() + "' config");
  ASSERT_EQ(docs.size(), 1u);
  const JsonDoc& services = docs[0]["services"];
  std::vector<std::vector<std::string>> parts;
  for (const auto& [name, s] : services.object) {
    if (name.rfind("bots-shard-", 0) != 0) continue;
    EXPECT_EQ(strings(s["profiles"]), std::vector<std::string>{"shards"}) << name;
    EXPECT_EQ(s["depends_on"]["server"]["condition"].string, "service_healthy") << name;
    EXPECT_EQ(s["image"].string, services["bots"]["image"].string) << name;
    parts.push_back(strings(s["command"]));
    // The service's number is its part's.
    BotsOptions o;
    EXPECT_EQ(parse_part(parts.back(), &o), "") << name;
    EXPECT_EQ(name, "bots-shard-" + std::to_string(o.shard_index));
  }
  ASSERT_EQ(parts.size(), 4u);
  const std::vector<std::string> reports = expect_shards_of_one_scenario(parts);
  const JsonDoc& merge = services["bots-merge"];
  EXPECT_EQ(strings(merge["profiles"]), std::vector<std::string>{"shards"});
  expect_merge_of(strings(merge["command"]), reports);
  // Parts and merge share the reports volume at the reports' directory.
  for (const auto& [name, s] : services.object) {
    if (name.rfind("bots-shard-", 0) != 0 && name != "bots-merge") continue;
    bool mounted = false;
    // (docker-compose config writes "reports:/reports:rw", or the long form)
    for (const JsonDoc& v : s["volumes"].array)
      mounted = mounted || v.string.rfind("reports:/reports", 0) == 0 ||
                (v["source"].string == "reports" && v["target"].string == "/reports");
    EXPECT_TRUE(mounted) << name;
  }
  for (const std::string& r : reports) EXPECT_EQ(r.rfind("/reports/", 0), 0u) << r;
}

TEST(ShardManifests, TheKubernetesIndexedJobRunsPartIOfCompletionsAndTheMergeJobReadsThemAll) {
  std::string out;
  ASSERT_EQ(testing_support::run_command("python3 -c 'import yaml'", &out), 0)
      << "python3-yaml is not installed (scripts/install-deps.sh's docker-compose brings it)";
  const fs::path dir = repo() / "deploy" / "kubernetes";
  const std::vector<JsonDoc> shards = yaml_docs("cat '" + (dir / "bots-shards.yaml").string() + "'");
  const std::vector<JsonDoc> merges = yaml_docs("cat '" + (dir / "bots-merge.yaml").string() + "'");
  std::map<std::string, const JsonDoc*> by_kind;
  for (const JsonDoc& d : shards) by_kind[d["kind"].string] = &d;
  ASSERT_EQ(by_kind.count("Job"), 1u);
  ASSERT_EQ(by_kind.count("PersistentVolumeClaim"), 1u);
  const JsonDoc& job = *by_kind["Job"];
  EXPECT_EQ(job["apiVersion"].string, "batch/v1");
  EXPECT_EQ(job["spec"]["completionMode"].string, "Indexed");
  const int n = static_cast<int>(job["spec"]["completions"].number);
  ASSERT_GE(n, 2);
  EXPECT_EQ(job["spec"]["parallelism"].number, n);  // the parts run together
  const JsonDoc& pod = job["spec"]["template"]["spec"];
  EXPECT_EQ(pod["restartPolicy"].string, "Never");
  ASSERT_EQ(pod["containers"].array.size(), 1u);
  const JsonDoc& c = pod["containers"].array[0];
  // $(SHARD) is the pod's completion index.
  std::string var;
  for (const JsonDoc& e : c["env"].array)
    if (e["valueFrom"]["fieldRef"]["fieldPath"].string == "metadata.annotations['batch.kubernetes.io/job-completion-index']")
      var = e["name"].string;
  ASSERT_FALSE(var.empty()) << "no variable holds the completion index";
  // Kubernetes expands $(VAR) in args; each index's command line parses.
  std::vector<std::vector<std::string>> parts;
  for (int i = 0; i < n; ++i) {
    std::vector<std::string> args = strings(c["args"]);
    for (std::string& a : args)
      for (std::size_t at; (at = a.find("$(" + var + ")")) != std::string::npos;)
        a.replace(at, var.size() + 3, std::to_string(i));
    parts.push_back(args);
  }
  const std::vector<std::string> reports = expect_shards_of_one_scenario(parts);
  // The reports on the claimed volume, which the merge Job mounts too.
  const std::string claim = (*by_kind["PersistentVolumeClaim"])["metadata"]["name"].string;
  const auto mount_of_claim = [&](const JsonDoc& spec, const JsonDoc& container) {
    std::string volume, path;
    for (const JsonDoc& v : spec["volumes"].array)
      if (v["persistentVolumeClaim"]["claimName"].string == claim) volume = v["name"].string;
    for (const JsonDoc& m : container["volumeMounts"].array)
      if (m["name"].string == volume) path = m["mountPath"].string;
    return path;
  };
  const std::string reports_dir = mount_of_claim(pod, c);
  ASSERT_FALSE(reports_dir.empty());
  for (const std::string& r : reports) EXPECT_EQ(r.rfind(reports_dir + "/", 0), 0u) << r;
  EXPECT_EQ(strings((*by_kind["PersistentVolumeClaim"])["spec"]["accessModes"]),
            std::vector<std::string>{"ReadWriteMany"});  // parts on several nodes

  ASSERT_EQ(merges.size(), 1u);
  const JsonDoc& merge = merges[0];
  EXPECT_EQ(merge["kind"].string, "Job");
  const JsonDoc& merge_pod = merge["spec"]["template"]["spec"];
  ASSERT_EQ(merge_pod["containers"].array.size(), 1u);
  const JsonDoc& mc = merge_pod["containers"].array[0];
  EXPECT_EQ(mc["image"].string, c["image"].string);
  EXPECT_EQ(mount_of_claim(merge_pod, mc), reports_dir);
  expect_merge_of(strings(mc["args"]), reports);
}

}  // namespace
}  // namespace terrane::bots
