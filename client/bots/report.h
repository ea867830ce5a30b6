// The bots report in three forms — JSON (the record), a human table and a
// self-contained HTML page with inline SVG charts — and `compare`, which
// puts two JSON reports side by side. docs/load-testing.md lists every field.
// Thread-safety: pure functions.
#pragma once

#include <map>
#include <string>

#include "client/bots/runner.h"

namespace terrane::bots {

std::string report_json(const BotsReport& r);
std::string report_table(const BotsReport& r);
std::string report_html(const BotsReport& r);

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
