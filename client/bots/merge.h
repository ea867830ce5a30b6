// `terrane-bots merge`: the JSON reports of the parts of one sharded run
// (--shard I/N) read back and combined into the report one process running
// every bot would have written. Counts add up; latency distributions merge
// their histograms (client/bots/histogram.h), so the whole run's
// percentiles are read from the whole run's samples, never averaged;
// means weigh each part by what it measured; the timeline merges second
// by second (each part's seconds count from its own first connection). The
// server's own figures (--server-metrics) are one server's, scraped by
// each part: the merged report keeps the first part's. Thresholds are
// evaluated again on the merged figures. Fan-out is timed within one
// process: a part measures an edit at its own receivers only, which the
// merged receiver counts say.
// Thread-safety: pure functions.
#pragma once

#include <string>
#include <vector>

#include "client/bots/runner.h"

namespace terrane::bots {

// A JSON report (report_json) read back. Returns "" or what is wrong,
// naming the key. Every latency that counted something must carry its
// histogram (reports of terrane-bots before histograms cannot be merged).
std::string report_from_json(const std::string& text, BotsReport* out);

// The parts of one run: every part of one scenario (the same options but
// --shard), each shard 0..N-1 exactly once. Returns "" and the merged
// report (unsharded options), or what is wrong with the parts.
std::string merge_reports(const std::vector<BotsReport>& parts, BotsReport* out);

}  // namespace terrane::bots
