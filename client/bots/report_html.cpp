// The HTML report: one self-contained page (report.h). The figures are
// HTML tables written here; the charts are drawn in the browser by
// report_assets/report.js with uPlot (report_assets/README.md), both
// embedded in the page, from the runs' JSON reports in one JSON block.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <optional>
#include <sstream>
#include <string>
#include <string_view>
#include <vector>

#include "client/bots/report.h"
#include "client/bots/report_assets.h"
#include "common/cli/json.h"

namespace terrane::bots {

namespace {

std::string html_esc(std::string_view s) {
  std::string o;
  o.reserve(s.size());
  for (const char c : s) {
    if (c == '<') o += "&lt;";
    else if (c == '>') o += "&gt;";
    else if (c == '&') o += "&amp;";
    else if (c == '"') o += "&quot;";
    else if (c == '\'') o += "&#39;";
    else o += c;
  }
  return o;
}

// Text inside a <script> element ends at the first "</script" (and "<!--"
// changes how the parser looks for that end), whatever the JSON inside
// says. In JSON a '<' can only stand inside a string, where "\u003c" means
// the same: so no '<' is written at all, and a hostile string (a server's
// disconnect reason, a file name) cannot end the element. json_escape
// already writes the report's strings so; this is the second guard.
std::string script_safe_json(std::string_view json) {
  std::string o;
  o.reserve(json.size());
  for (const char c : json) {
    if (c == '<') o += "\\u003c";
    else o += c;
  }
  return o;
}

std::string count(std::uint64_t n) {
  std::string digits = std::to_string(n), o;
  for (std::size_t i = 0; i < digits.size(); ++i) {
    if (i > 0 && (digits.size() - i) % 3 == 0) o += ',';
    o += digits[i];
  }
  return o;
}


std::string bound_ms(const std::optional<double>& ms) {
  if (!ms) return "-";
  if (!std::isfinite(*ms)) return "&gt; 1000 ms";
  return "&le; " + fixed(*ms, 1) + " ms";
}

// The runs' letters in a comparison: A, B.
std::string tag(std::size_t i) { return std::string(1, static_cast<char>('A' + i)); }

// A table of label rows, one value column per run (and B/A for two runs
// when both values are numbers). Values are HTML already.
class FigureTable {
 public:
  explicit FigureTable(std::size_t runs) : runs_(runs) {}
  void section(const std::string& title) { rows_.push_back({title, {}, {}, true}); }
  // values[i]: run i's value (HTML), numbers[i]: the same as a number for
  // the ratio (NaN when it is none).
  void row(const std::string& label, std::vector<std::string> values, std::vector<double> numbers = {}) {
    rows_.push_back({label, std::move(values), std::move(numbers), false});
  }
  std::string html(const std::vector<std::string>& run_names) const {
    std::ostringstream h;
    h << "<table class=\"figures\"><tr><th></th>";
    for (std::size_t i = 0; i < runs_; ++i) h << "<th>" << (runs_ > 1 ? tag(i) + ": " : "") << html_esc(run_names[i]) << "</th>";
    if (runs_ == 2) h << "<th>B/A</th>";
    h << "</tr>\n";
    for (const Row& r : rows_) {
      if (r.section) {
        h << "<tr><td class=\"section\" colspan=\"" << runs_ + (runs_ == 2 ? 2 : 1) << "\">" << html_esc(r.label)
          << "</td></tr>\n";
        continue;
      }
      h << "<tr><td>" << html_esc(r.label) << "</td>";
      for (std::size_t i = 0; i < runs_; ++i) h << "<td>" << (i < r.values.size() ? r.values[i] : "-") << "</td>";
      if (runs_ == 2) {
        std::string ratio;
        if (r.numbers.size() == 2 && std::isfinite(r.numbers[0]) && std::isfinite(r.numbers[1]) && r.numbers[0] != 0)
          ratio = fixed(r.numbers[1] / r.numbers[0], 2) + "&times;";
        h << "<td>" << ratio << "</td>";
      }
      h << "</tr>\n";
    }
    h << "</table>\n";
    return h.str();
  }

 private:
  struct Row {
    std::string label;
    std::vector<std::string> values;
    std::vector<double> numbers;
    bool section;
  };
  std::size_t runs_;
  std::vector<Row> rows_;
};

struct Run {
  std::string name;
  const BotsReport* r;
};

// One row whose value per run is f(report) as a number shown with d
// decimals (and a unit).
template <typename F>
void number_row(FigureTable& t, const std::vector<Run>& runs, const std::string& label, int d, const std::string& unit,
                F f) {
  std::vector<std::string> values;
  std::vector<double> numbers;
  for (const Run& run : runs) {
    const double v = f(*run.r);
    numbers.push_back(v);
    values.push_back((d < 0 ? count(static_cast<std::uint64_t>(std::max(0.0, v))) : fixed(v, d)) + unit);
  }
  t.row(label, std::move(values), std::move(numbers));
}

std::string latency_table(const std::vector<Run>& runs) {
  struct Dist {
    const char* name;
    const LatencySummary BotsReport::*field;
  };
  static const Dist kDists[] = {
      {"edit fan-out", &BotsReport::edit_fanout_ms},
      {"edit fan-out, other server", &BotsReport::edit_fanout_other_server_ms},
      {"edit ack", &BotsReport::edit_ack_ms},
      {"join until the coarse view", &BotsReport::join_coarse_ms},
      {"join until full resolution", &BotsReport::join_full_ms},
      {"keepalive round trip", &BotsReport::round_trip_ms},
      {"the bots' own io lag (10 ms probe)", &BotsReport::bots_io_lag_ms},
  };
  std::ostringstream h;
  h << "<table class=\"latency\"><tr><th>distribution (ms)</th>" << (runs.size() > 1 ? "<th>run</th>" : "")
    << "<th>p50</th><th>p95</th><th>p99</th><th>max</th><th>samples</th></tr>\n";
  for (const Dist& d : kDists) {
    bool any = false;
    for (const Run& run : runs) any = any || (run.r->*d.field).count > 0;
    if (!any && d.field == &BotsReport::edit_fanout_other_server_ms) continue;
    for (std::size_t i = 0; i < runs.size(); ++i) {
      const LatencySummary& l = runs[i].r->*d.field;
      h << "<tr><td>" << (i == 0 ? d.name : "") << "</td>" << (runs.size() > 1 ? "<td>" + tag(i) + "</td>" : "");
      if (l.count == 0) {
        h << "<td colspan=\"4\">no samples</td><td>0</td></tr>\n";
        continue;
      }
      h << "<td>" << fixed(l.p50, 1) << "</td><td>" << fixed(l.p95, 1) << "</td><td>" << fixed(l.p99, 1) << "</td><td>"
        << fixed(l.max, 1) << "</td><td>" << count(l.count) << "</td></tr>\n";
    }
  }
  h << "</table>\n";
  return h.str();
}

std::string figures_table(const std::vector<Run>& runs, const std::vector<std::string>& names) {
  FigureTable t(runs.size());
  using R = const BotsReport&;
  auto d = [](std::uint64_t v) { return static_cast<double>(v); };
  t.section("Run");
  number_row(t, runs, "bots", -1, "", [](R r) { return r.bots; });
  number_row(t, runs, "duration", 1, " s", [](R r) { return r.duration_s; });
  number_row(t, runs, "all bots joined after", 1, " s", [](R r) { return r.joined_s; });
  number_row(t, runs, "joins incomplete", -1, "", [](R r) { return r.joins_incomplete; });
  t.section("Bytes");
  number_row(t, runs, "received, all (MB)", 2, "", [&](R r) { return d(r.bytes_received) / 1e6; });
  number_row(t, runs, "received while joining (MB)", 2, "", [&](R r) { return d(r.join_bytes_received) / 1e6; });
  number_row(t, runs, "received steady (MB)", 2, "", [&](R r) { return d(r.steady_bytes_received) / 1e6; });
  number_row(t, runs, "sent (MB)", 2, "", [&](R r) { return d(r.bytes_sent) / 1e6; });
  number_row(t, runs, "join coarse view, all bots (MB)", 2, "", [&](R r) { return d(r.join_coarse_bytes) / 1e6; });
  number_row(t, runs, "bytes per non-empty voxel (join, mean)", 3, "", [](R r) { return r.bytes_per_non_empty_voxel; });
  t.section("Edits");
  number_row(t, runs, "sent", -1, "", [&](R r) { return d(r.edits_sent); });
  number_row(t, runs, "acknowledged", -1, "", [&](R r) { return d(r.edits_acked); });
  number_row(t, runs, "rejected", -1, "", [&](R r) { return d(r.edits_rejected); });
  number_row(t, runs, "measured (fan-out)", -1, "", [&](R r) { return d(r.edits_measured); });
  number_row(t, runs, "receivers per edit", 2, "", [](R r) { return r.receivers_per_edit; });
  number_row(t, runs, "update bytes per edited voxel per receiver", 3, "",
             [](R r) { return r.update_bytes_per_edited_voxel_per_receiver; });
  t.section("Replicas and connections");
  number_row(t, runs, "regions checked", -1, "", [&](R r) { return d(r.replica_regions_checked); });
  number_row(t, runs, "mismatches", -1, "", [](R r) { return static_cast<double>(r.mismatches.size()); });
  number_row(t, runs, "hash requests unanswered", -1, "", [&](R r) { return d(r.hash_unanswered); });
  number_row(t, runs, "unexpected disconnects", -1, "", [](R r) { return r.unexpected_disconnects; });
  number_row(t, runs, "connect failures", -1, "", [](R r) { return r.connect_failures; });
  number_row(t, runs, "redirects followed", -1, "", [&](R r) { return d(r.redirects); });
  number_row(t, runs, "walk steps", -1, "", [&](R r) { return d(r.walk_steps); });
  number_row(t, runs, "shared chunk cache hits", -1, "", [&](R r) { return d(r.shared_chunk_hits); });
  number_row(t, runs, "shared update hits", -1, "", [&](R r) { return d(r.shared_update_hits); });

  bool server = false;
  for (const Run& run : runs) server = server || run.r->server.has_value();
  if (server) {
    t.section("The server over the run (its /metrics)");
    auto srow = [&](const std::string& label, auto f) {
      std::vector<std::string> values;
      for (const Run& run : runs) values.push_back(run.r->server ? f(*run.r->server) : std::string("-"));
      t.row(label, std::move(values));
    };
    srow("scrapes (failed)", [](const ServerFigures& f) {
      return std::to_string(f.scrapes) + " (" + std::to_string(f.scrape_errors) + ")";
    });
    srow("CPU", [](const ServerFigures& f) {
      return fixed(f.cpu_s, 1) + " s over " + fixed(f.wall_s, 1) + " s (" +
             fixed(f.wall_s > 0 ? 100 * f.cpu_s / f.wall_s : 0, 0) + " % of one core)";
    });
    srow("resident memory, peak", [](const ServerFigures& f) {
      return fixed(static_cast<double>(f.rss_peak) / (1 << 20), 0) + " MiB";
    });
    srow("ticks (late)", [](const ServerFigures& f) {
      return count(f.ticks) + " (" + count(f.ticks_late) + ")";
    });
    srow("tick p99", [](const ServerFigures& f) { return bound_ms(f.tick_p99_ms); });
    srow("commit p99", [](const ServerFigures& f) { return bound_ms(f.commit_p99_ms); });
    srow("fan-out p99", [](const ServerFigures& f) { return bound_ms(f.fanout_p99_ms); });
    srow("edit to ack inside the server, p99", [](const ServerFigures& f) { return bound_ms(f.edit_ack_p99_ms); });
    srow("edits applied / rejected", [](const ServerFigures& f) {
      return count(f.edits_applied) + " / " + count(f.edits_rejected);
    });
    srow("streaming paused (server behind)", [](const ServerFigures& f) {
      return std::to_string(f.stream_gate_closings) + " times, " + fixed(f.stream_gate_closed_s, 1) + " s";
    });
    srow("sessions ended", [](const ServerFigures& f) { return count(f.disconnects); });
  }
  return t.html(names);
}

std::string traffic_table(const std::vector<Run>& runs) {
  std::ostringstream h;
  h << "<table class=\"traffic\"><tr><th>the bots' traffic by message type</th>";
  for (std::size_t i = 0; i < runs.size(); ++i) {
    const std::string p = runs.size() > 1 ? tag(i) + ": " : "";
    h << "<th>" << p << "frames in</th><th>" << p << "bytes in</th><th>" << p << "frames out</th><th>" << p
      << "bytes out</th>";
  }
  h << "</tr>\n";
  for (std::size_t t = 0; t < kMessageTypeCount; ++t) {
    bool any = false;
    for (const Run& run : runs) {
      const auto& m = run.r->by_message_type[t];
      any = any || m.frames_in > 0 || m.frames_out > 0;
    }
    if (!any) continue;
    h << "<tr><td>" << html_esc(message_type_name(t)) << "</td>";
    for (const Run& run : runs) {
      const auto& m = run.r->by_message_type[t];
      h << "<td>" << count(m.frames_in) << "</td><td>" << count(m.bytes_in) << "</td><td>" << count(m.frames_out)
        << "</td><td>" << count(m.bytes_out) << "</td>";
    }
    h << "</tr>\n";
  }
  h << "</table>\n";
  return h.str();
}

std::string thresholds_table(const std::vector<Run>& runs) {
  bool any = false;
  for (const Run& run : runs) any = any || !run.r->thresholds.empty();
  if (!any) return "";
  std::ostringstream h;
  h << "<h2>Thresholds</h2>\n<table class=\"thresholds\"><tr>" << (runs.size() > 1 ? "<th>run</th>" : "")
    << "<th>threshold</th><th>value</th><th></th></tr>\n";
  for (std::size_t i = 0; i < runs.size(); ++i)
    for (const ThresholdResult& t : runs[i].r->thresholds)
      h << "<tr>" << (runs.size() > 1 ? "<td>" + tag(i) + "</td>" : "") << "<td><code>"
        << html_esc(t.threshold.expression) << "</code></td><td>" << fixed(t.value, 2) << per_second_detail(t)
        << "</td><td class=\""
        << (t.passed ? "pass\">passed" : "fail\">BROKEN") << "</td></tr>\n";
  h << "</table>\n";
  return h.str();
}

std::string verdicts(const std::vector<Run>& runs) {
  std::ostringstream h;
  for (std::size_t i = 0; i < runs.size(); ++i) {
    const BotsReport& r = *runs[i].r;
    std::vector<std::string> why = r.failures();
    for (std::string& broken : r.broken_thresholds()) why.push_back(std::move(broken));
    h << "<p>" << (runs.size() > 1 ? "<b>" + tag(i) + "</b> " + html_esc(runs[i].name) + ": " : "") << r.bots
      << " bots, " << behavior_name(r.options.behavior) << ", " << fixed(r.duration_s, 1) << " s &mdash; <span class=\""
      << (why.empty() ? "pass\">passed" : "fail\">FAILED") << "</span></p>\n";
    if (!why.empty()) {
      h << "<ul class=\"failures\">\n";
      for (const std::string& w : why) h << "<li>" << html_esc(w) << "</li>\n";
      h << "</ul>\n";
    }
    const std::size_t shown = std::min<std::size_t>(r.mismatches.size(), 20);
    if (shown > 0) {
      h << "<table class=\"mismatches\"><tr><th>bot</th><th>chunk</th><th>replica / server revision</th><th>reason</th></tr>\n";
      for (std::size_t m = 0; m < shown; ++m) {
        const Mismatch& x = r.mismatches[m];
        h << "<tr><td>" << x.bot << "</td><td>(" << x.chunk.x << ", " << x.chunk.y << ", " << x.chunk.z << ")</td><td>"
          << x.replica_revision << " / " << x.server_revision << "</td><td>" << html_esc(x.reason)
          << (x.final_check ? " (final check)" : "") << "</td></tr>\n";
      }
      h << "</table>\n";
      if (r.mismatches.size() > shown) h << "<p>" << r.mismatches.size() - shown << " more in the JSON report.</p>\n";
    }
  }
  return h.str();
}

std::string page(const std::vector<Run>& runs) {
  std::vector<std::string> names;
  for (const Run& run : runs) names.push_back(run.name);
  std::ostringstream h;
  const BotsReport& first = *runs.front().r;
  std::string title = runs.size() > 1 ? "terrane-bots: " + runs[0].name + " vs " + runs[1].name
                                      : "terrane-bots: " + std::to_string(first.bots) + " bots, " +
                                            behavior_name(first.options.behavior);
  h << "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\n<title>" << html_esc(title)
    << "</title>\n<style>\n"
    << assets::kUplotCss << "\n</style>\n<style>\n"
    << assets::kReportCss << "\n</style>\n</head><body>\n";
  h << "<h1>" << html_esc(title) << "</h1>\n";
  // report.js replaces this: "ok charts=N" or what went wrong.
  h << "<pre id=\"report-status\">the charts' script did not run</pre>\n";
  h << verdicts(runs);
  h << thresholds_table(runs);
  h << "<h2>Charts</h2>\n<div id=\"charts\"></div>\n";
  h << "<h2>Latency</h2>\n" << latency_table(runs);
  h << "<h2>Figures</h2>\n" << figures_table(runs, names);
  h << "<h2>Traffic</h2>\n" << traffic_table(runs);
  h << "<h2>Scenario</h2>\n";
  for (std::size_t i = 0; i < runs.size(); ++i)
    h << (runs.size() > 1 ? "<h3>" + tag(i) + ": " + html_esc(runs[i].name) + "</h3>\n" : "") << "<pre>"
      << html_esc(scenario_text(runs[i].r->options)) << "</pre>\n";
  // The data: every run's JSON report (what --report writes), one object.
  std::string data = "{\"runs\": [";
  for (std::size_t i = 0; i < runs.size(); ++i)
    data += (i ? ", " : "") + std::string("{\"name\": \"") + json_escape(runs[i].name) +
            "\", \"report\": " + report_json(*runs[i].r) + "}";
  data += "]}";
  h << "<script type=\"application/json\" id=\"report-data\">" << script_safe_json(data) << "</script>\n";
  // report.js first: it catches the errors of what follows.
  h << "<script>\n" << assets::kReportJs << "\n</script>\n";
  h << "<script>\n" << assets::kUplotJs << "\n</script>\n";
  h << "<details><summary>Charts drawn with uPlot 1.6.32 (MIT licence)</summary><pre>"
    << html_esc(assets::kUplotLicense) << "</pre></details>\n";
  h << "</body></html>\n";
  return h.str();
}

}  // namespace

std::string report_html(const BotsReport& r) { return page({{"this run", &r}}); }

std::string compare_html(const std::string& name_a, const BotsReport& a, const std::string& name_b,
                         const BotsReport& b) {
  return page({{name_a, &a}, {name_b, &b}});
}

}  // namespace terrane::bots
