// Goals a run is held to: `--threshold EXPR` (and `threshold = EXPR` lines
// of a scenario file), each METRIC OP NUMBER such as "fanout_p99<100" or
// "mismatches==0", evaluated on the whole run's figures, or with "@1s"
// after it ("fanout_p99<100@1s") in every measured second of the run that
// has a value of the metric. A broken one fails
// the run with its own exit status (kExitThresholds). The metrics' values
// come from the report (BotsReport::threshold_values, runner.h); this file
// knows their names, the operators and the arithmetic only.
// Thread-safety: plain data and pure functions.
#pragma once

#include <map>
#include <string>
#include <vector>

namespace terrane::bots {

// Exit statuses of terrane-bots (its --help and docs/load-testing.md list
// them): a run's own failures come before its thresholds.
constexpr int kExitPassed = 0;
constexpr int kExitFailed = 1;      // replica mismatch, disconnect, server unreachable, ...
constexpr int kExitUsage = 2;       // bad flags, scenario or threshold expression
constexpr int kExitThresholds = 3;  // the run was sound, but a threshold was broken

enum class ThresholdOp : unsigned char { kLess, kLessEqual, kGreater, kGreaterEqual, kEqual, kNotEqual };
const char* threshold_op_text(ThresholdOp op);

struct Threshold {
  std::string expression;  // as given, spaces trimmed
  std::string metric;
  ThresholdOp op = ThresholdOp::kLess;
  double limit = 0;
  // "@1s": the goal holds in every measured second that has a value of the
  // metric (a latency: a second with a sample), not only over the run.
  bool per_second = false;

  // Whether value meets the goal.
  bool holds(double value) const;
};

// A metric a threshold can name, and what it is (for --help and errors).
struct ThresholdMetric {
  const char* name;
  const char* what;
  bool per_second = false;  // has a value in each second of the timeline ("@1s")
};
const std::vector<ThresholdMetric>& threshold_metrics();

// Parses "METRIC OP NUMBER" or "METRIC OP NUMBER@1s" (spaces allowed
// around each part). Returns "" or what is wrong, opening with the
// expression quoted: no operator, an unknown metric (listing the known
// ones), a limit that is not a finite number, a window other than 1s, a
// metric with no per-second value under "@1s" (listing those that have).
std::string parse_threshold(const std::string& expression, Threshold* out);

struct ThresholdResult {
  Threshold threshold;
  // The whole run's value; per second, the worst second's (the largest for
  // < and <=, the smallest for > and >=, the first broken one for == and
  // !=, else the first second's).
  double value = 0;
  bool passed = true;
  // Per second: the seconds that had a value, those that broke the goal,
  // and the end of the worst one (seconds since the first connection).
  std::size_t seconds = 0, seconds_broken = 0;
  double worst_t_s = 0;
};

// One second of the run's timeline: the per-second metrics that had a
// value in it (BotsReport::per_second_threshold_values).
struct SecondValues {
  double t_s = 0;  // end of the second, since the first connection
  std::map<std::string, double> values;
};

// Each threshold against values (metric name -> value; every metric of
// threshold_metrics() is expected there: one missing is broken, value NaN),
// a per-second one against each of seconds instead (a metric no second had
// a value of holds, with seconds = 0 and value NaN: nothing broke it).
std::vector<ThresholdResult> evaluate_thresholds(const std::vector<Threshold>& thresholds,
                                                 const std::map<std::string, double>& values,
                                                 const std::vector<SecondValues>& seconds = {});

}  // namespace terrane::bots
