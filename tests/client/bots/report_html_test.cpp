// terrane-bots' HTML report (client/bots/report_html.cpp) in a real browser:
// Debian's chromium, headless, loads the page from a file with its network
// features off, and the page's own script (report_assets/report.js) says in
// <pre id="report-status"> whether every chart drew ("ok charts=N"), which
// were left empty, or which script errors it caught. The pages come from a
// real short run against a real server (the run, `merge` of its report
// and `compare` of two reports) and from a report whose strings are hostile.
// Chromium is required: scripts/install-deps.sh installs it, and a machine
// without it fails here rather than skipping.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "client/bots/report.h"
#include "tests/support/run_command.h"
#include "tests/support/scratch_dir.h"
#include "tests/support/server_process.h"

namespace terrane::bots {
namespace {

namespace fs = std::filesystem;
using testing_support::run_command;
using testing_support::ServerProcess;

std::string read_text(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

// Shell-quoted (single quotes): the paths are ours, but a temp dir may hold
// anything.
std::string quoted(const std::string& s) {
  std::string o = "'";
  for (const char c : s) o += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return o + "'";
}

// The DOM of page after its scripts ran, from headless chromium with a
// fresh profile and nothing that reaches the network on its own; "" and a
// test failure when chromium is missing or fails. The virtual time budget
// lets the page's load event and script finish before the DOM is taken
// (virtual time: no wall-clock wait).
std::string browser_dom(const fs::path& page, const fs::path& scratch) {
  std::string out;
  if (run_command("command -v chromium", &out) != 0) {
    ADD_FAILURE() << "chromium is not installed: the HTML report's test needs it "
                     "(scripts/install-deps.sh installs it; apt-get install chromium)";
    return "";
  }
  const fs::path profile = scratch / "chromium-profile";
  fs::remove_all(profile);
  const fs::path dom = scratch / (page.stem().string() + ".dom.html");
  const std::string cmd = "timeout 120 chromium --headless --no-sandbox --disable-gpu --disable-quic --no-first-run"
                          " --disable-background-networking --disable-component-update --disable-sync"
                          " --disable-extensions --user-data-dir=" +
                          quoted(profile.string()) + " --virtual-time-budget=10000 --dump-dom " +
                          quoted("file://" + fs::absolute(page).string()) + " > " + quoted(dom.string());
  out.clear();
  const int status = run_command(cmd, &out);
  EXPECT_EQ(status, 0) << cmd << "\n" << out;
  return read_text(dom);
}

// The text of <pre id="report-status">, or "(no status element)".
std::string report_status(const std::string& dom) {
  const std::string open = "id=\"report-status\"";
  const auto at = dom.find(open);
  if (at == std::string::npos) return "(no status element)";
  const auto from = dom.find('>', at) + 1, to = dom.find("</pre>", from);
  return dom.substr(from, to - from);
}

std::size_t occurrences(const std::string& text, const std::string& what) {
  std::size_t n = 0;
  for (auto at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
  return n;
}

class ReportPageTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = testing_support::scratch_dir("terrane-report-page");
    fs::create_directories(dir_);
  }
  void TearDown() override {
    if (server_) {
      EXPECT_EQ(server_->stop(), 0);
      if (HasFailure()) std::fprintf(stderr, "--- server output ---\n%s", server_->output().c_str());
    }
    if (!HasFailure()) fs::remove_all(dir_);
  }
  std::string path(const char* name) const { return (dir_ / name).string(); }
  int bots(const std::string& args, std::string* out) {
    out->clear();
    return run_command(std::string(TERRANE_BIN_DIR) + "/terrane-bots " + args, out);
  }

  fs::path dir_;
  std::unique_ptr<ServerProcess> server_;
};

// Every chart a real editing run with the server's metrics has (ack and
// fan-out per second, the latency histogram and CDF, bots and joins, join
// times, bytes by message type, the server's CPU, memory, tick and send
// queues) drew points, with no script error; so do merge's page of the
// same report and compare's page of it against the merged one.
TEST_F(ReportPageTest, ARealRunsPagesDrawEveryChartWithoutScriptErrors) {
  server_ = std::make_unique<ServerProcess>((dir_ / "world").string(),
                                            std::vector<std::string>{"--metrics", "127.0.0.1:0"});
  ASSERT_NE(server_->port(), 0) << server_->output();
  const std::uint16_t metrics = server_->metrics_port();
  ASSERT_NE(metrics, 0) << server_->output();
  const std::string run = "--connect 127.0.0.1:" + std::to_string(server_->port()) +
                          " --server-metrics 127.0.0.1:" + std::to_string(metrics) +
                          " --bots 8 --behavior mixed --duration 4 --ramp-up 1 --spread 96 --view-distance 96"
                          " --full-res-radius 32 --edit-interval 0.5 --hash-checks 2 --quiet 0.5 --wait-joined 240"
                          " --threads 2 --progress off --threshold 'fanout_p99<100000'"
                          " --threshold 'join_full_p99<1000000'";
  std::string out;
  ASSERT_EQ(bots(run + " --report " + path("run.json") + " --html " + path("run.html"), &out), 0) << out;
  ASSERT_EQ(bots("merge " + path("run.json") + " --report " + path("merged.json") + " --html " + path("merged.html"),
                 &out),
            0)
      << out;
  ASSERT_EQ(bots("compare " + path("run.json") + " " + path("merged.json") + " --html " + path("compare.html"), &out),
            0)
      << out;

  // 11 charts: ack, fan-out, histogram, CDF, bots, joins, bytes by type,
  // server CPU, RSS, tick, send queues.
  for (const char* page : {"run.html", "merged.html", "compare.html"}) {
    const std::string html = read_text(path(page));
    // Self-contained: nothing is fetched.
    EXPECT_EQ(html.find("src=\"http"), std::string::npos) << page;
    EXPECT_EQ(html.find("href=\"http"), std::string::npos) << page;
    EXPECT_NE(html.find("<table class=\"latency\">"), std::string::npos) << page;
    const std::string dom = browser_dom(path(page), dir_);
    EXPECT_EQ(report_status(dom), "ok charts=11") << page;
    // uPlot drew each into a canvas of its own.
    EXPECT_EQ(occurrences(dom, "<canvas"), 11u) << page;
  }
  // The thresholds are lines on their charts: their labels are in the legends.
  const std::string dom = browser_dom(path("run.html"), dir_);
  EXPECT_NE(dom.find("threshold fanout_p99&lt;100000"), std::string::npos);
  EXPECT_NE(dom.find("threshold join_full_p99&lt;1000000"), std::string::npos);
}

// A string a server or a file put in the report (here a run's name, a
// disconnect reason and a mismatch's reason) cannot end the page's JSON
// block and run as script, and a chart with no point is named as empty.
TEST_F(ReportPageTest, AHostileStringCannotEndTheDataBlockAndEmptyChartsAreNamed) {
  const std::string hostile = "</script><script>document.body.setAttribute('data-pwned', '1')</script><!--";
  BotsReport r;
  r.bots = 2;
  r.options.bots = 2;
  r.disconnects.emplace_back(1, hostile);
  r.unexpected_disconnects = 1;
  r.mismatches.push_back(Mismatch{0, {1, 2, 3}, 4, 5, hostile, true});
  r.timeline.resize(3);  // three seconds, no bot connected, nothing joined
  for (std::size_t s = 0; s < r.timeline.size(); ++s) r.timeline[s].t_s = static_cast<double>(s + 1);
  {
    std::ofstream f(path("hostile.html"));
    f << compare_html(hostile, r, "b", r);
  }
  const std::string html = read_text(path("hostile.html"));
  EXPECT_EQ(html.find(hostile), std::string::npos) << "written as it came";
  const std::string dom = browser_dom(path("hostile.html"), dir_);
  EXPECT_EQ(dom.find("data-pwned=\"1\""), std::string::npos) << "the injected script ran";
  // The script ran to its end with no error: the join chart has no sample
  // (no bot joined) and says so.
  EXPECT_EQ(report_status(dom), "empty: joins");
}

}  // namespace
}  // namespace terrane::bots
