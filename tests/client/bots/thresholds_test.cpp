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

// "@1s": a window after the goal; the metrics that have a value per second.
TEST(Thresholds, PerSecondExpressionsNameTheirWindowAndMetric) {
  const Threshold t = parsed(" fanout_p99 < 100 @ 1s ");
  EXPECT_TRUE(t.per_second);
  EXPECT_EQ(t.metric, "fanout_p99");
  EXPECT_EQ(t.limit, 100);
  EXPECT_EQ(t.expression, "fanout_p99 < 100 @ 1s");
  EXPECT_FALSE(parsed("fanout_p99<100").per_second);
  Threshold u;
  EXPECT_EQ(parse_threshold("fanout_p99<100@5s", &u),
            "'fanout_p99<100@5s': '@5s' is not a window (the one there is: @1s, every second)");
  EXPECT_EQ(parse_threshold("fanout_p99<100@", &u),
            "'fanout_p99<100@': '@' is not a window (the one there is: @1s, every second)");
  const std::string count = parse_threshold("mismatches==0@1s", &u);
  EXPECT_EQ(count.rfind("'mismatches==0@1s': 'mismatches' has no value per second (those that have: fanout_p50, ", 0),
            0u)
      << count;
  for (const ThresholdMetric& m : threshold_metrics()) {
    EXPECT_EQ(count.find(std::string(" ") + m.name + ",") != std::string::npos ||
                  count.find(std::string(" ") + m.name + ")") != std::string::npos,
              m.per_second)
        << m.name;
    EXPECT_EQ(parse_threshold(std::string(m.name) + ">=0@1s", &u).empty(), m.per_second) << m.name;
  }
  // Every per-second metric has a value in a second that had everything.
  BotsReport r;
  TimelinePoint p;
  p.t_s = 1;
  p.bots_connected = 2;
  p.mb_per_s_in = 0.01;
  LatencyHistogram h;
  h.record(5);
  p.fanout_ms = p.ack_ms = p.round_trip_ms = summarize(h);
  r.timeline = {p};
  const std::vector<SecondValues> seconds = r.per_second_threshold_values();
  ASSERT_EQ(seconds.size(), 1u);
  for (const ThresholdMetric& m : threshold_metrics())
    EXPECT_EQ(seconds[0].values.count(m.name), m.per_second ? 1u : 0u) << m.name;
  EXPECT_DOUBLE_EQ(seconds[0].values.at("bytes_per_bot_s"), 5000);  // 10,000 bytes / 2 bots
}

// A per-second goal holds in every measured second with a value; the report
// names the worst second, when it ended and how many broke it.
TEST(Thresholds, APerSecondGoalIsHeldInEverySecondAndTheWorstIsReported) {
  BotsReport r;
  r.bots = 2;
  r.duration_s = 6;
  r.joined_s = 1.5;  // measured from 1.5 s: the second ending at 2 s began before
  const auto second = [](double t_s, std::vector<double> fanout_ms, double mb_in) {
    TimelinePoint p;
    p.t_s = t_s;
    p.bots_connected = 2;
    p.mb_per_s_in = mb_in;
    LatencyHistogram h;
    for (double ms : fanout_ms) h.record(ms);
    p.fanout_ms = summarize(h);
    return p;
  };
  r.timeline = {second(1, {900}, 0.5),  second(2, {800}, 0.5), second(3, {10, 20}, 0.004),
                second(4, {150}, 0.002), second(5, {}, 0.003),  second(6, {40, 230}, 0.001)};
  LatencyHistogram whole;
  for (double ms : {10, 20, 150, 40, 230}) whole.record(ms);
  r.edit_fanout_ms = summarize(whole);
  r.options.thresholds = {parsed("fanout_p99<100@1s"), parsed("fanout_p99<1000"), parsed("bytes_per_bot_s>1200@1s"),
                          parsed("fanout_max<1000@1s")};
  r.thresholds = r.evaluate_own_thresholds();
  ASSERT_EQ(r.thresholds.size(), 4u);
  const ThresholdResult& fanout = r.thresholds[0];
  EXPECT_FALSE(fanout.passed);
  EXPECT_EQ(fanout.seconds, 3u);  // 3, 4 and 6: the first two began before the measurement, 5 had no edit
  EXPECT_EQ(fanout.seconds_broken, 2u);
  EXPECT_NEAR(fanout.value, 230, 230 * LatencyHistogram::kRelativePrecision);
  EXPECT_EQ(fanout.worst_t_s, 6);
  EXPECT_TRUE(r.thresholds[1].passed);  // the whole run's p99 of the same edits
  // ">": the worst second is the smallest (0.001 MB / 2 bots = 500 B), and
  // every measured second has bytes.
  const ThresholdResult& bytes = r.thresholds[2];
  EXPECT_FALSE(bytes.passed);
  EXPECT_EQ(bytes.seconds, 4u);
  EXPECT_EQ(bytes.seconds_broken, 2u);  // 1,000 and 500 B
  EXPECT_DOUBLE_EQ(bytes.value, 500);
  EXPECT_EQ(bytes.worst_t_s, 6);
  EXPECT_TRUE(r.thresholds[3].passed);  // 900 and 800 ms came before the measurement
  ASSERT_EQ(r.broken_thresholds().size(), 2u);
  EXPECT_EQ(r.broken_thresholds()[1],
            "threshold bytes_per_bot_s>1200@1s broken: bytes_per_bot_s = 500 in 2 of 4 seconds, the worst ending at 6 s");
  EXPECT_EQ(r.exit_status(), kExitThresholds);
  std::map<std::string, std::string> json;
  ASSERT_EQ(flatten_json(report_json(r), &json), "");
  EXPECT_EQ(json["thresholds.2.per_second.seconds"], "4");
  EXPECT_EQ(json["thresholds.2.per_second.seconds_broken"], "2");
  EXPECT_EQ(json["thresholds.2.per_second.worst_t_s"], "6");
  EXPECT_EQ(json.count("thresholds.1.per_second.seconds"), 0u);
  const std::string table = report_table(r);
  EXPECT_NE(table.find("bytes_per_bot_s = 500 in the worst second (ending at 6 s), 2 of 4 seconds broken"),
            std::string::npos)
      << table;
  // == and !=: the first broken second is the one reported.
  const auto eq = evaluate_thresholds({parsed("fanout_max==150@1s")}, {}, r.per_second_threshold_values());
  EXPECT_FALSE(eq[0].passed);
  EXPECT_EQ(eq[0].seconds_broken, 2u);
  EXPECT_EQ(eq[0].worst_t_s, 3);
  // No second with a value: nothing broke it.
  const auto none = evaluate_thresholds({parsed("ack_p99<1@1s")}, {}, r.per_second_threshold_values());
  EXPECT_TRUE(none[0].passed);
  EXPECT_EQ(none[0].seconds, 0u);
  EXPECT_TRUE(std::isnan(none[0].value));
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
