// terrane-bots: N headless bots against a terrane-server, a replication
// load test with a report (client/bots/options.cpp has the usage text).
#include <unistd.h>

#include <cstdio>
#include <fstream>
#include <sstream>
#include <vector>

#include "client/bots/merge.h"
#include "client/bots/options.h"
#include "client/bots/presets.h"
#include "client/bots/report.h"
#include "client/bots/runner.h"

namespace terrane::bots {
namespace {

int usage_error(const std::string& message) {
  std::fprintf(stderr, "terrane-bots: %s\n(terrane-bots --help lists the options)\n", message.c_str());
  return kExitUsage;
}

bool read_file(const std::string& path, std::string* out) {
  std::ifstream f(path, std::ios::binary);
  if (!f) return false;
  std::stringstream s;
  s << f.rdbuf();
  *out = s.str();
  return true;
}

bool write_file(const std::string& path, const std::string& text) {
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  f << text;
  return static_cast<bool>(f.flush());
}

// terrane-bots compare A.json B.json [--html A_VS_B.html]
int compare(int argc, char** argv) {
  std::vector<std::string> paths;
  std::string html_path;
  for (int a = 2; a < argc; ++a) {
    const std::string arg = argv[a];
    if (arg == "--html") {
      if (a + 1 >= argc) return usage_error("compare --html: missing value");
      html_path = argv[++a];
    } else if (arg.rfind("--", 0) == 0) {
      return usage_error("compare: unknown option " + arg + " (compare takes --html)");
    } else {
      paths.push_back(arg);
    }
  }
  if (paths.size() != 2)
    return usage_error("compare takes two JSON reports: terrane-bots compare A.json B.json [--html A_VS_B.html]");
  std::string a, b, err;
  if (!read_file(paths[0], &a)) return std::fprintf(stderr, "terrane-bots: cannot read %s\n", paths[0].c_str()), 1;
  if (!read_file(paths[1], &b)) return std::fprintf(stderr, "terrane-bots: cannot read %s\n", paths[1].c_str()), 1;
  const std::string table = compare_reports(paths[0], a, paths[1], b, &err);
  if (!err.empty()) return std::fprintf(stderr, "terrane-bots: %s\n", err.c_str()), 1;
  std::fputs(table.c_str(), stdout);
  if (html_path.empty()) return 0;
  // The page reads both reports whole (as merge does): one written before
  // histograms cannot be charted.
  BotsReport ra, rb;
  if (auto e = report_from_json(a, &ra); !e.empty())
    return std::fprintf(stderr, "terrane-bots: %s: %s\n", paths[0].c_str(), e.c_str()), 1;
  if (auto e = report_from_json(b, &rb); !e.empty())
    return std::fprintf(stderr, "terrane-bots: %s: %s\n", paths[1].c_str(), e.c_str()), 1;
  if (!write_file(html_path, compare_html(paths[0], ra, paths[1], rb)))
    return std::fprintf(stderr, "terrane-bots: cannot write %s\n", html_path.c_str()), 1;
  return 0;
}

// terrane-bots merge PART.json... --report ALL.json [--html ALL.html]
int merge(int argc, char** argv) {
  std::vector<std::string> paths;
  std::string report_path, html_path;
  for (int a = 2; a < argc; ++a) {
    const std::string arg = argv[a];
    if (arg == "--report" || arg == "--html") {
      if (a + 1 >= argc) return usage_error("merge " + arg + ": missing value");
      (arg == "--report" ? report_path : html_path) = argv[++a];
    } else if (arg.rfind("--", 0) == 0) {
      return usage_error("merge: unknown option " + arg + " (merge takes --report and --html)");
    } else {
      paths.push_back(arg);
    }
  }
  if (paths.empty() || report_path.empty())
    return usage_error("merge takes the parts' JSON reports and --report: terrane-bots merge PART.json... --report "
                       "ALL.json [--html ALL.html]");
  std::vector<BotsReport> parts(paths.size());
  for (std::size_t i = 0; i < paths.size(); ++i) {
    std::string text;
    if (!read_file(paths[i], &text)) return std::fprintf(stderr, "terrane-bots: cannot read %s\n", paths[i].c_str()), 1;
    if (auto err = report_from_json(text, &parts[i]); !err.empty())
      return std::fprintf(stderr, "terrane-bots: %s: %s\n", paths[i].c_str(), err.c_str()), 1;
  }
  BotsReport merged;
  if (auto err = merge_reports(parts, &merged); !err.empty())
    return std::fprintf(stderr, "terrane-bots: merge: %s\n", err.c_str()), 1;
  std::fputs(report_table(merged).c_str(), stdout);
  if (!write_file(report_path, report_json(merged)))
    return std::fprintf(stderr, "terrane-bots: cannot write %s\n", report_path.c_str()), 1;
  if (!html_path.empty() && !write_file(html_path, report_html(merged)))
    return std::fprintf(stderr, "terrane-bots: cannot write %s\n", html_path.c_str()), 1;
  return merged.exit_status();
}

int run(int argc, char** argv) {
  if (argc >= 2 && std::string(argv[1]) == "compare") return compare(argc, argv);
  if (argc >= 2 && std::string(argv[1]) == "merge") return merge(argc, argv);
  BotsOptions o;
  bool help = false, list_presets = false;
  if (auto err = parse_bots_options(argc, argv, 1, &o, &help, &list_presets); !err.empty()) return usage_error(err);
  if (help) return std::printf("%s\n%s", kBotsHelp, presets_text().c_str()), 0;
  if (list_presets) return std::fputs(presets_text().c_str(), stdout), 0;
  if (!o.save_scenario_path.empty() && !write_file(o.save_scenario_path, scenario_text(o)))
    return std::fprintf(stderr, "terrane-bots: cannot write %s\n", o.save_scenario_path.c_str()), 1;

  const bool live = o.progress == "on" || (o.progress == "auto" && isatty(STDERR_FILENO) != 0);
  std::function<void(const Progress&)> progress;
  if (live)
    progress = [](const Progress& p) {
      std::fprintf(stderr,
                   "\r[%5.0f s] bots %d/%d  in %.2f MB/s  out %.3f MB/s  edits %.0f/s  fan-out p99 %.0f ms  "
                   "mismatches %zu   ",
                   p.t_s, p.bots_connected, p.bots_total, p.mb_per_s_in, p.mb_per_s_out, p.edits_per_s,
                   p.fanout_p99_ms, p.mismatches);
      std::fflush(stderr);
    };
  BotsReport report;
  std::string err;
  if (!run_bots(o, progress, &report, &err)) {
    if (live) std::fputc('\n', stderr);
    std::fprintf(stderr, "terrane-bots: %s\n", err.c_str());
    return 1;
  }
  if (live) std::fputc('\n', stderr);
  std::fputs(report_table(report).c_str(), stdout);
  if (!o.report_path.empty() && !write_file(o.report_path, report_json(report)))
    return std::fprintf(stderr, "terrane-bots: cannot write %s\n", o.report_path.c_str()), 1;
  if (!o.html_path.empty() && !write_file(o.html_path, report_html(report)))
    return std::fprintf(stderr, "terrane-bots: cannot write %s\n", o.html_path.c_str()), 1;
  return report.exit_status();
}

}  // namespace
}  // namespace terrane::bots

int main(int argc, char** argv) { return terrane::bots::run(argc, argv); }
