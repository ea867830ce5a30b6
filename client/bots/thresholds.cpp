#include "client/bots/thresholds.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <iterator>
#include <limits>

#include "common/cli/cli.h"

namespace terrane::bots {

const char* threshold_op_text(ThresholdOp op) {
  switch (op) {
    case ThresholdOp::kLess: return "<";
    case ThresholdOp::kLessEqual: return "<=";
    case ThresholdOp::kGreater: return ">";
    case ThresholdOp::kGreaterEqual: return ">=";
    case ThresholdOp::kEqual: return "==";
    case ThresholdOp::kNotEqual: return "!=";
  }
  return "?";
}

bool Threshold::holds(double value) const {
  switch (op) {
    case ThresholdOp::kLess: return value < limit;
    case ThresholdOp::kLessEqual: return value <= limit;
    case ThresholdOp::kGreater: return value > limit;
    case ThresholdOp::kGreaterEqual: return value >= limit;
    case ThresholdOp::kEqual: return value == limit;
    case ThresholdOp::kNotEqual: return value != limit;
  }
  return false;
}

const std::vector<ThresholdMetric>& threshold_metrics() {
  // Latencies in ms over the measured run (the report's distributions, from
  // their histograms); the rest are the report's counts.
  static const std::vector<ThresholdMetric> k = {
      {"fanout_p50", "edit fan-out ms, p50", true},
      {"fanout_p95", "edit fan-out ms, p95", true},
      {"fanout_p99", "edit fan-out ms, p99", true},
      {"fanout_max", "edit fan-out ms, largest", true},
      {"fanout_other_server_p99", "edit fan-out ms to receivers on another server, p99"},
      {"ack_p50", "edit ack ms, p50", true},
      {"ack_p95", "edit ack ms, p95", true},
      {"ack_p99", "edit ack ms, p99", true},
      {"ack_max", "edit ack ms, largest", true},
      {"join_coarse_p50", "join ms until the coarse view, p50"},
      {"join_coarse_p95", "join ms until the coarse view, p95"},
      {"join_coarse_p99", "join ms until the coarse view, p99"},
      {"join_full_p50", "join ms until the full-resolution region, p50"},
      {"join_full_p95", "join ms until the full-resolution region, p95"},
      {"join_full_p99", "join ms until the full-resolution region, p99"},
      {"round_trip_p99", "keepalive round trip ms, p99", true},
      {"io_lag_p99", "the bots' own io lag ms, p99"},
      {"mismatches", "replica mismatches"},
      {"disconnects", "unexpected disconnects"},
      {"connect_failures", "bots that could not connect"},
      {"joins_incomplete", "bots that never completed their join"},
      {"edits_acked", "edits acknowledged"},
      {"rejected_pct", "edits rejected, % of those sent (0 when none was sent)"},
      {"bytes_per_bot_s", "bytes received per bot per second of the run", true},
      {"steady_bytes_per_bot_s", "bytes received per bot per second after each bot's join (the byte budget)"},
      {"hash_unanswered", "chunk-hash requests the server never answered"},
  };
  return k;
}

namespace {

// Every operator, each spelt by threshold_op_text.
constexpr ThresholdOp kOps[] = {ThresholdOp::kLess,         ThresholdOp::kLessEqual, ThresholdOp::kGreater,
                                ThresholdOp::kGreaterEqual, ThresholdOp::kEqual,     ThresholdOp::kNotEqual};

std::string known_metrics(bool per_second_only = false) {
  std::string out;
  for (const ThresholdMetric& m : threshold_metrics())
    if (m.per_second || !per_second_only) out += (out.empty() ? "" : ", ") + std::string(m.name);
  return out;
}

// Whether op orders values (< <= > >=), and a is then worse than b: a
// per-second threshold reports its worst second.
bool ordered(ThresholdOp op) { return op != ThresholdOp::kEqual && op != ThresholdOp::kNotEqual; }
bool worse(ThresholdOp op, double a, double b) {
  return op == ThresholdOp::kLess || op == ThresholdOp::kLessEqual ? a > b : a < b;
}

}  // namespace

std::string parse_threshold(const std::string& expression, Threshold* out) {
  const std::string whole = trim_blanks(expression);
  const std::string named = "'" + whole + "': ";
  // A window after '@': "1s" is the one there is.
  std::string e = whole;
  bool per_second = false;
  if (const std::size_t w = whole.rfind('@'); w != std::string::npos) {
    const std::string window = trim_blanks(whole.substr(w + 1));
    if (window != "1s") return named + "'@" + window + "' is not a window (the one there is: @1s, every second)";
    e = trim_blanks(whole.substr(0, w));
    per_second = true;
  }
  const std::size_t at = e.find_first_of("<>=!");
  if (at == std::string::npos) return named + "no operator (one of < <= > >= == !=), as in fanout_p99<100";
  // The operator: two characters where the second is '=', else one; a lone
  // '=' or '!' is none.
  std::size_t len = at + 1 < e.size() && e[at + 1] == '=' ? 2 : 1;
  const std::string op = e.substr(at, len);
  Threshold t;
  const auto known_op = std::find_if(std::begin(kOps), std::end(kOps),
                                     [&](ThresholdOp o) { return op == threshold_op_text(o); });
  if (known_op == std::end(kOps)) return named + "'" + op + "' is not an operator (one of < <= > >= == !=)";
  t.op = *known_op;
  t.metric = trim_blanks(e.substr(0, at));
  const std::string limit = trim_blanks(e.substr(at + len));
  if (t.metric.empty()) return named + "no metric before '" + op + "'";
  const auto metric = std::find_if(threshold_metrics().begin(), threshold_metrics().end(),
                                   [&](const ThresholdMetric& m) { return t.metric == m.name; });
  if (metric == threshold_metrics().end())
    return named + "unknown metric '" + t.metric + "' (known: " + known_metrics() + ")";
  if (limit.empty()) return named + "no number after '" + op + "'";
  auto [p, ec] = std::from_chars(limit.data(), limit.data() + limit.size(), t.limit);
  if (ec != std::errc() || p != limit.data() + limit.size() || !std::isfinite(t.limit))
    return named + "'" + limit + "' is not a number";
  if (per_second && !metric->per_second)
    return named + "'" + t.metric + "' has no value per second (those that have: " + known_metrics(true) + ")";
  t.per_second = per_second;
  t.expression = whole;
  *out = t;
  return "";
}

std::vector<ThresholdResult> evaluate_thresholds(const std::vector<Threshold>& thresholds,
                                                 const std::map<std::string, double>& values,
                                                 const std::vector<SecondValues>& seconds) {
  std::vector<ThresholdResult> out;
  out.reserve(thresholds.size());
  for (const Threshold& t : thresholds) {
    ThresholdResult r;
    r.threshold = t;
    if (t.per_second) {
      for (const SecondValues& s : seconds) {
        const auto it = s.values.find(t.metric);
        if (it == s.values.end()) continue;
        const double v = it->second;
        ++r.seconds;
        const bool broken = !t.holds(v);
        if (broken) ++r.seconds_broken;
        // The first second, then a worse one (ordered goals) or the first
        // that broke (== and !=).
        const bool take = r.seconds == 1 || (ordered(t.op) ? worse(t.op, v, r.value) : broken && r.seconds_broken == 1);
        if (take) {
          r.value = v;
          r.worst_t_s = s.t_s;
        }
      }
      if (r.seconds == 0) r.value = std::numeric_limits<double>::quiet_NaN();  // none had a value
      r.passed = r.seconds_broken == 0;
      out.push_back(r);
      continue;
    }
    const auto it = values.find(t.metric);
    r.value = it != values.end() ? it->second : std::numeric_limits<double>::quiet_NaN();
    r.passed = it != values.end() && t.holds(r.value);
    out.push_back(r);
  }
  return out;
}

}  // namespace terrane::bots
