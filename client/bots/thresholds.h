// Goals a run is held to: `--threshold EXPR` (and `threshold = EXPR` lines
// of a scenario file), each METRIC OP NUMBER such as "fanout_p99<100" or
// "mismatches==0", evaluated on the whole run's figures. A broken one fails
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

  // Whether value meets the goal.
  bool holds(double value) const;
};

// A metric a threshold can name, and what it is (for --help and errors).
struct ThresholdMetric {
  const char* name;
  const char* what;
};
const std::vector<ThresholdMetric>& threshold_metrics();

// Parses "METRIC OP NUMBER" (spaces allowed around each part). Returns ""
// or what is wrong, opening with the expression quoted: no operator, an
// unknown metric (listing the known ones), a limit that is not a finite
// number.
std::string parse_threshold(const std::string& expression, Threshold* out);

struct ThresholdResult {
  Threshold threshold;
  double value = 0;
  bool passed = true;
};

// Each threshold against values (metric name -> value; every metric of
// threshold_metrics() is expected there: one missing is broken, value NaN).
std::vector<ThresholdResult> evaluate_thresholds(const std::vector<Threshold>& thresholds,
                                                 const std::map<std::string, double>& values);

}  // namespace terrane::bots
