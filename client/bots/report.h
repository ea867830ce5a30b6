// The bots report in three forms — JSON (the record), a human table and a
// self-contained HTML page (tables, and charts drawn in the browser by the
// uPlot library embedded in the page: report_html.cpp) — and `compare`,
// which puts two JSON reports side by side, as a table or as one page with
// both runs on the same charts. docs/load-testing.md lists every field.
// Thread-safety: pure functions.
#pragma once

#include <map>
#include <string>

#include "client/bots/runner.h"

namespace terrane::bots {

std::string report_json(const BotsReport& r);
std::string report_table(const BotsReport& r);
// A figure for people: d decimals ("-" when not finite).
std::string fixed(double v, int d);
// What a per-second threshold's value is, for the table and the page:
// " in the worst second (ending at T s), B of S seconds broken"; "" for a
// threshold on the whole run.
std::string per_second_detail(const ThresholdResult& t);
// One HTML file that needs nothing else (no network): the figures as
// tables, the charts drawn by its script from the JSON report it embeds.
// Its <pre id="report-status"> reads "ok charts=N" once the charts are
// drawn, else the script's errors or the charts left empty.
std::string report_html(const BotsReport& r);
// The same page for two runs: both on every chart (B dashed), the tables
// side by side with B/A.
std::string compare_html(const std::string& name_a, const BotsReport& a, const std::string& name_b,
                         const BotsReport& b);

// A JSON document flattened to "a.b.c" -> scalar text (numbers as written,
// strings unquoted, arrays indexed "a.0"). Returns "" or the error with
// its byte offset. Depth and size are bounded (reports are ours, but a
// file is still input).
std::string flatten_json(const std::string& text, std::map<std::string, std::string>* out);

// Side-by-side table of two reports' key figures; "" and *error set on a
// malformed input (naming the file).
std::string compare_reports(const std::string& name_a, const std::string& a, const std::string& name_b,
                            const std::string& b, std::string* error);

}  // namespace terrane::bots
