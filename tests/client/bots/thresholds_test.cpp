// Thresholds (client/bots/thresholds.h) and how a run's report holds them
// (BotsReport::threshold_values, broken_thresholds, exit_status): each
// operator, each metric resolving, bad expressions named, scenario lines.
// The exit status of a real run is tested in tests/client/bots_test.cpp.
#include "client/bots/thresholds.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "client/bots/options.h"
#include "client/bots/report.h"
#include "client/bots/runner.h"
#include "tests/client/bots/parse_flags.h"

namespace terrane::bots {
namespace {

Threshold parsed(const std::string& expression) {
  Threshold t;
  EXPECT_EQ(parse_threshold(expression, &t), "") << expression;
  return t;
}

TEST(Thresholds, EachOperatorComparesTheValueWithTheLimit) {
  struct Case {
    const char* expression;
    ThresholdOp op;
    bool at_below, at_limit, at_above;  // value 99, 100, 101
  };
  const Case cases[] = {
      {"fanout_p99<100", ThresholdOp::kLess, true, false, false},
      {"fanout_p99<=100", ThresholdOp::kLessEqual, true, true, false},
      {"fanout_p99>100", ThresholdOp::kGreater, false, false, true},
      {"fanout_p99>=100", ThresholdOp::kGreaterEqual, false, true, true},
      {"fanout_p99==100", ThresholdOp::kEqual, false, true, false},
      {"fanout_p99!=100", ThresholdOp::kNotEqual, true, false, true},
  };
  for (const Case& c : cases) {
    const Threshold t = parsed(c.expression);
    EXPECT_EQ(t.metric, "fanout_p99");
    EXPECT_EQ(t.op, c.op) << c.expression;
    EXPECT_EQ(t.limit, 100);
    EXPECT_EQ(t.expression, c.expression);
    EXPECT_EQ(std::string("fanout_p99") + threshold_op_text(t.op) + "100", c.expression);
    EXPECT_EQ(t.holds(99), c.at_below) << c.expression;
    EXPECT_EQ(t.holds(100), c.at_limit) << c.expression;
    EXPECT_EQ(t.holds(101), c.at_above) << c.expression;
  }
  // Spaces around the parts; fractional and negative limits.
  const Threshold spaced = parsed("  rejected_pct  <=  1.5 ");
  EXPECT_EQ(spaced.metric, "rejected_pct");
  EXPECT_EQ(spaced.op, ThresholdOp::kLessEqual);
  EXPECT_EQ(spaced.limit, 1.5);
  EXPECT_EQ(spaced.expression, "rejected_pct  <=  1.5");
  EXPECT_EQ(parsed("ack_p95>-1").limit, -1);
}

TEST(Thresholds, BadExpressionsAreNamedWithWhatIsWrong) {
  Threshold t;
  EXPECT_EQ(parse_threshold("fanout_p99 100", &t),
            "'fanout_p99 100': no operator (one of < <= > >= == !=), as in fanout_p99<100");
  EXPECT_EQ(parse_threshold("fanout_p99=100", &t), "'fanout_p99=100': '=' is not an operator (one of < <= > >= == !=)");
  EXPECT_EQ(parse_threshold("fanout_p99!100", &t), "'fanout_p99!100': '!' is not an operator (one of < <= > >= == !=)");
  EXPECT_EQ(parse_threshold("<100", &t), "'<100': no metric before '<'");
  EXPECT_EQ(parse_threshold("fanout_p99<", &t), "'fanout_p99<': no number after '<'");
  EXPECT_EQ(parse_threshold("fanout_p99<fast", &t), "'fanout_p99<fast': 'fast' is not a number");
  EXPECT_EQ(parse_threshold("fanout_p99<<100", &t), "'fanout_p99<<100': '<100' is not a number");
  EXPECT_EQ(parse_threshold("fanout_p99<100ms", &t), "'fanout_p99<100ms': '100ms' is not a number");
  EXPECT_EQ(parse_threshold("fanout_p99<inf", &t), "'fanout_p99<inf': 'inf' is not a number");
  // An unknown metric lists every known one.
  const std::string unknown = [&] {
    Threshold u;
    return parse_threshold("fanout_p999<100", &u);
  }();
  EXPECT_EQ(unknown.rfind("'fanout_p999<100': unknown metric 'fanout_p999' (known: fanout_p50, ", 0), 0u) << unknown;
  for (const ThresholdMetric& m : threshold_metrics())
    EXPECT_NE(unknown.find(std::string(m.name)), std::string::npos) << m.name;
}

TEST(Thresholds, EveryMetricResolvesInAReportAndIsInTheHelp) {
  BotsReport r;
  r.bots = 4;
  r.duration_s = 10;
  r.bytes_received = 80000;
  r.edits_sent = 200;
  r.edits_rejected = 3;
  r.edits_acked = 197;
  r.unexpected_disconnects = 2;
  r.mismatches.resize(5);
  LatencyHistogram fanout;
  for (int ms = 1; ms <= 100; ++ms) fanout.record(ms);
  r.edit_fanout_ms = summarize(fanout);
  const std::map<std::string, double> values = r.threshold_values();
  EXPECT_EQ(values.size(), threshold_metrics().size());
  for (const ThresholdMetric& m : threshold_metrics()) {
    EXPECT_EQ(values.count(m.name), 1u) << m.name << " does not resolve";
    EXPECT_NE(std::string(kBotsHelp).find(std::string(" ") + m.name), std::string::npos)
        << m.name << " is not in --help";
    Threshold t;
    EXPECT_EQ(parse_threshold(std::string(m.name) + ">=0", &t), "") << m.name;
  }
  // Read from the histogram: within its precision.
  EXPECT_NEAR(values.at("fanout_p99"), 99, 99 * LatencyHistogram::kRelativePrecision);
  EXPECT_NEAR(values.at("fanout_p50"), 50, 50 * LatencyHistogram::kRelativePrecision);
  EXPECT_EQ(values.at("fanout_max"), 100);
  EXPECT_EQ(values.at("mismatches"), 5);
  EXPECT_EQ(values.at("disconnects"), 2);
  EXPECT_EQ(values.at("rejected_pct"), 1.5);
  EXPECT_EQ(values.at("edits_acked"), 197);
  EXPECT_EQ(values.at("bytes_per_bot_s"), 2000);  // 80,000 bytes / 4 bots / 10 s
  EXPECT_EQ(values.at("ack_p99"), 0);             // nothing measured
}

TEST(Thresholds, ABrokenThresholdIsNamedWithItsValueAndSetsTheExitStatus) {
  BotsReport r;
  r.bots = 1;
  r.duration_s = 1;
  LatencyHistogram fanout;
  fanout.record(153.25);
  r.edit_fanout_ms = summarize(fanout);
  r.thresholds = evaluate_thresholds({parsed("fanout_p99<100"), parsed("mismatches==0")}, r.threshold_values());
  ASSERT_EQ(r.thresholds.size(), 2u);
  EXPECT_FALSE(r.thresholds[0].passed);
  EXPECT_EQ(r.thresholds[0].value, 153.25);
  EXPECT_TRUE(r.thresholds[1].passed);
  ASSERT_EQ(r.broken_thresholds().size(), 1u);
  EXPECT_EQ(r.broken_thresholds()[0], "threshold fanout_p99<100 broken: fanout_p99 = 153.25");
  EXPECT_FALSE(r.passed());
  EXPECT_EQ(r.exit_status(), kExitThresholds);
  // The table, the JSON and the HTML list each threshold with its value.
  const std::string table = report_table(r);
  EXPECT_NE(table.find("FAILED: threshold fanout_p99<100 broken: fanout_p99 = 153.25"), std::string::npos) << table;
  EXPECT_NE(table.find("ok   mismatches==0"), std::string::npos) << table;
  std::map<std::string, std::string> json;
  ASSERT_EQ(flatten_json(report_json(r), &json), "");
  EXPECT_EQ(json["thresholds.0.expression"], "fanout_p99<100");
  EXPECT_EQ(json["thresholds.0.value"], "153.25");
  EXPECT_EQ(json["thresholds.0.passed"], "false");
  EXPECT_EQ(json["thresholds.1.passed"], "true");
  EXPECT_EQ(json["passed"], "false");
  EXPECT_EQ(json["exit_status"], "3");
  EXPECT_EQ(json["failures.0"], "threshold fanout_p99<100 broken: fanout_p99 = 153.25");
  const std::string html = report_html(r);
  EXPECT_NE(html.find("<code>fanout_p99&lt;100</code></td><td>153.25</td><td class=\"fail\">BROKEN"),
            std::string::npos);
  // A run that failed on its own exits 1 whatever its thresholds.
  r.unexpected_disconnects = 1;
  EXPECT_EQ(r.exit_status(), kExitFailed);
  r.unexpected_disconnects = 0;
  r.thresholds = evaluate_thresholds({parsed("fanout_p99<200")}, r.threshold_values());
  EXPECT_EQ(r.exit_status(), kExitPassed);
  EXPECT_TRUE(r.passed());
  // A metric missing from the values is broken, never passed by default.
  const auto missing = evaluate_thresholds({parsed("mismatches==0")}, {});
  EXPECT_FALSE(missing[0].passed);
  EXPECT_TRUE(std::isnan(missing[0].value));
}

TEST(Thresholds, FlagsAndScenarioLinesGiveThemAndTheCommandLineReplacesTheFile) {
  OptionValues kv;
  ASSERT_EQ(parse_scenario_text("connect = h:1\nthreshold = fanout_p99<100\nthreshold = mismatches==0\n", "s.txt", &kv),
            "");
  BotsOptions o;
  ASSERT_EQ(apply_option_values(kv, &o), "");
  ASSERT_EQ(o.thresholds.size(), 2u);
  EXPECT_EQ(o.thresholds[0].expression, "fanout_p99<100");
  EXPECT_EQ(o.thresholds[1].expression, "mismatches==0");
  // The saved scenario keeps them.
  OptionValues again_kv;
  ASSERT_EQ(parse_scenario_text(scenario_text(o), "saved", &again_kv), "");
  BotsOptions again;
  ASSERT_EQ(apply_option_values(again_kv, &again), "");
  EXPECT_EQ(scenario_text(again), scenario_text(o));
  ASSERT_EQ(again.thresholds.size(), 2u);
  // A bad one names the file and line, or the flag, and the expression.
  kv.clear();
  ASSERT_EQ(parse_scenario_text("threshold = fanout_p99<\n", "s.txt", &kv), "");
  EXPECT_EQ(apply_option_values(kv, &o), "s.txt:1: threshold: 'fanout_p99<': no number after '<'");
  BotsOptions flags;
  ASSERT_EQ(parse_flags({"--connect", "h:1", "--threshold", "ack_p95<50", "--threshold=rejected_pct<=1"}, &flags), "");
  ASSERT_EQ(flags.thresholds.size(), 2u);
  EXPECT_EQ(flags.thresholds[0].expression, "ack_p95<50");
  EXPECT_EQ(flags.thresholds[1].expression, "rejected_pct<=1");
  // A scenario file's thresholds give way to the command line's.
  const std::string file = ::testing::TempDir() + "thresholds-scenario.conf";
  {
    std::FILE* f = std::fopen(file.c_str(), "w");
    ASSERT_NE(f, nullptr);
    std::fputs("connect = h:1\nthreshold = fanout_p99<100\nthreshold = mismatches==0\n", f);
    std::fclose(f);
  }
  BotsOptions both;
  ASSERT_EQ(parse_flags({"--scenario", file, "--threshold", "ack_p99<20"}, &both), "");
  ASSERT_EQ(both.thresholds.size(), 1u);
  EXPECT_EQ(both.thresholds[0].expression, "ack_p99<20");
  BotsOptions file_only;
  ASSERT_EQ(parse_flags({"--scenario", file}, &file_only), "");
  EXPECT_EQ(file_only.thresholds.size(), 2u);
  std::remove(file.c_str());
  EXPECT_EQ(parse_flags({"--connect", "h:1", "--threshold", "p99<1"}, &flags)
                .rfind("--threshold: 'p99<1': unknown metric 'p99' (known: ", 0),
            0u);
}

}  // namespace
}  // namespace terrane::bots
