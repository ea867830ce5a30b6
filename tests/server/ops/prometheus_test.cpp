// A real Prometheus (Debian's prometheus package) scrapes the server's
// /metrics over 127.0.0.1 and answers queries about it; and the docker/
// monitoring files hold together: the scrape config passes promtool, and
// every metric the Grafana dashboard asks for is one the server exports.
#include <gtest/gtest.h>
#include <httplib.h>

#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <thread>

#include "server/ops/metrics.h"
#include "tests/support/child_process.h"
#include "tests/support/eventually.h"
#include "tests/support/run_command.h"
#include "tests/support/scratch_dir.h"
#include "tests/support/server_fixture.h"

namespace terrane {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using testing_support::ChildProcess;
using testing_support::ServerTest;

const fs::path kDocker = fs::path(TERRANE_TEST_DATA_DIR) / ".." / ".." / "docker";

std::string read_file(const fs::path& p) {
  std::ifstream f(p);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

bool have(const char* program) { return std::system((std::string("command -v ") + program + " > /dev/null").c_str()) == 0; }

class PrometheusTest : public ServerTest {};

TEST_F(PrometheusTest, ARealPrometheusScrapesTheServerAndSeesItsEdits) {
  ASSERT_TRUE(have("prometheus")) << "prometheus is not installed: run scripts/install-deps.sh";
  ServerOptions o;
  o.ops.metrics_address = "127.0.0.1:0";
  start(o);
  const fs::path dir = testing_support::scratch_dir("terrane-prometheus");
  fs::create_directories(dir / "data");
  std::ofstream(dir / "prometheus.yml") << "global:\n  scrape_interval: 1s\nscrape_configs:\n  - job_name: terrane\n"
                                        << "    static_configs:\n      - targets: [\"127.0.0.1:"
                                        << server_->metrics_port() << "\"]\n";
  const std::uint16_t web = testing_support::free_loopback_port();
  ChildProcess prom({"prometheus", "--config.file=" + (dir / "prometheus.yml").string(),
                     "--storage.tsdb.path=" + (dir / "data").string(),
                     "--web.listen-address=127.0.0.1:" + std::to_string(web)});
  ASSERT_TRUE(prom.started());

  // Three acknowledged edits.
  auto p = join("editor");
  const Vec3i cp = chunk_of(Vec3i{1002, 12, 1002});
  ASSERT_TRUE(hold_full(*p, {1002.0f, 12.0f, 1002.0f}, cp));
  for (std::uint32_t id = 1; id <= 3; ++id) {
    const EditRequestMsg e = testing_support::fill_box_edit(id, Region{{1001, 11, 1001}, {1003, 13, 1003}}, materials::kBrick, static_cast<std::uint8_t>(100 + id));
    ASSERT_TRUE(p->send(build_edit_request(e)));
    ASSERT_TRUE(p->next_of(wire::Body::EditAck));
  }

  // Prometheus' query API, until it has scraped the edits (or a deadline).
  httplib::Client api("127.0.0.1", web);
  api.set_connection_timeout(2, 0);
  api.set_read_timeout(10, 0);
  auto query = [&](const std::string& q) -> std::string {
    auto res = api.Get("/api/v1/query", httplib::Params{{"query", q}}, httplib::Headers{});
    return res && res->status == 200 ? res->body : std::string();
  };
  std::string answer, up;
  testing_support::eventually(
      [&] {
        answer = query("terrane_edits_applied_total");
        up = query("up{job=\"terrane\"}");
        return answer.find("\"3\"]") != std::string::npos && up.find("\"1\"]") != std::string::npos;
      },
      120s);
  EXPECT_NE(up.find("\"1\"]"), std::string::npos) << "target not up: " << up << "\n" << prom.output();
  EXPECT_NE(answer.find("\"3\"]"), std::string::npos) << answer << "\n" << prom.output();
  // A histogram Prometheus can take a quantile of.
  const std::string p99 = query("histogram_quantile(0.99, terrane_tick_duration_seconds_bucket)");
  EXPECT_NE(p99.find("\"status\":\"success\""), std::string::npos) << p99;
  EXPECT_NE(p99.find("\"result\":[{"), std::string::npos) << p99;
  prom.stop();
  fs::remove_all(dir);
}

TEST(MonitoringFiles, ScrapeConfigPassesPromtool) {
  ASSERT_TRUE(have("promtool")) << "promtool is not installed: run scripts/install-deps.sh";
  std::string out;
  EXPECT_EQ(testing_support::run_command("promtool check config '" + (kDocker / "prometheus.yml").string() + "'", &out), 0)
      << out;
  EXPECT_NE(out.find("SUCCESS"), std::string::npos) << out;
}

TEST(MonitoringFiles, EveryMetricTheDashboardShowsIsExported) {
  const std::string dashboard = read_file(kDocker / "grafana" / "dashboards" / "terrane.json");
  ASSERT_FALSE(dashboard.empty());
  ServerCounters c;
  StorageCounters st;
  EncodeCounters enc;
  const std::string text = render_metrics(MetricsSources{c, st, enc, false, read_process_stats()});
  // (No std::regex: GCC 12 warns inside it under the sanitizer build.)
  std::set<std::string> exported;
  std::istringstream lines(text);
  for (std::string line; std::getline(lines, line);)
    if (!line.empty() && line[0] != '#') exported.insert(line.substr(0, line.find_first_of(" {")));
  auto word = [](char ch) { return (ch >= 'a' && ch <= 'z') || ch == '_' || (ch >= '0' && ch <= '9'); };
  std::set<std::string> asked;
  for (const std::string prefix : {"terrane_", "process_"})
    for (std::size_t at = dashboard.find(prefix); at != std::string::npos; at = dashboard.find(prefix, at + 1)) {
      if (at > 0 && word(dashboard[at - 1])) continue;
      std::size_t end = at;
      while (end < dashboard.size() && word(dashboard[end])) ++end;
      asked.insert(dashboard.substr(at, end - at));
    }
  EXPECT_GE(asked.size(), 10u);
  for (const std::string& m : asked) EXPECT_EQ(exported.count(m), 1u) << "the dashboard asks for " << m;
}

}  // namespace
}  // namespace terrane
